package org.campro.android

import android.Manifest
import android.graphics.ImageFormat
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraManager
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.params.ColorSpaceTransform
import android.hardware.camera2.params.RggbChannelVector
import android.hardware.camera2.params.TonemapCurve
import android.media.Image
import android.os.Looper
import android.util.Size
import android.view.View
import androidx.lifecycle.Lifecycle
import org.campro.Fixtures
import org.campro.PixelProbe
import org.campro.ProtectionState
import org.campro.StillResult
import org.junit.After
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertNull
import org.junit.Assert.assertTrue
import org.junit.Test
import org.junit.runner.RunWith
import org.robolectric.RobolectricTestRunner
import org.robolectric.RuntimeEnvironment
import org.robolectric.Shadows.shadowOf
import org.robolectric.annotation.Config
import org.robolectric.shadow.api.Shadow
import org.robolectric.shadows.ShadowCameraCharacteristics
import org.robolectric.shadows.StreamConfigurationMapBuilder
import java.io.ByteArrayInputStream
import java.io.File
import java.nio.ByteBuffer
import java.nio.file.Files
import javax.imageio.ImageIO

/**
 * [CamPro.open] on Robolectric's camera service: the lifecycle opens and closes the camera,
 * another app taking it stops protection until it is free again, and stills and the
 * preview get only frames whose result verified (frames and results scripted through the
 * Camera2 glue, as a HAL would send them).
 */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34])
class CamProCameraTest {
    private val app = RuntimeEnvironment.getApplication()
    private val manager = app.getSystemService(CameraManager::class.java)
    private val dir: File = Files.createTempDirectory("campro-camera").toFile()
    private var cam: CamProCamera? = null

    @After
    fun cleanUp() {
        cam?.close()
        cam?.let { settle(it) }
        dir.deleteRecursively()
    }

    /** A camera CamPro supports, back-facing, sensor at 90, listing YUV 1280 x 720 and 640 x 480. */
    private fun chars(supported: Boolean = true, facing: Int = CameraCharacteristics.LENS_FACING_BACK): CameraCharacteristics {
        val c = ShadowCameraCharacteristics.newCameraCharacteristics()
        val s = Shadow.extract<ShadowCameraCharacteristics>(c)
        s.set(CameraCharacteristics.REQUEST_AVAILABLE_CAPABILITIES, if (supported) intArrayOf(0, 2) else intArrayOf(0))
        s.set(CameraCharacteristics.TONEMAP_AVAILABLE_TONE_MAP_MODES, if (supported) intArrayOf(0, 1, 2) else intArrayOf(1, 2))
        s.set(CameraCharacteristics.TONEMAP_MAX_CURVE_POINTS, 64)
        s.set(CameraCharacteristics.CONTROL_AWB_AVAILABLE_MODES, intArrayOf(0, 1))
        // Settings apply 2 frames late: protected frames repeat alone (Robolectric's session takes repeating requests, not bursts).
        s.set(CameraCharacteristics.SYNC_MAX_LATENCY, 2)
        s.set(CameraCharacteristics.REQUEST_PIPELINE_MAX_DEPTH, 4.toByte())
        s.set(CameraCharacteristics.LENS_FACING, facing)
        s.set(CameraCharacteristics.SENSOR_ORIENTATION, 90)
        s.set(
            CameraCharacteristics.SCALER_STREAM_CONFIGURATION_MAP,
            StreamConfigurationMapBuilder.newBuilder()
                .addOutputSize(ImageFormat.YUV_420_888, Size(1280, 720))
                .addOutputSize(ImageFormat.YUV_420_888, Size(640, 480))
                .build(),
        )
        return c
    }

    /** Runs what the camera, frame and main threads have queued, until all are idle. */
    private fun settle(c: CamProCamera) {
        repeat(4) {
            for (l in listOf(c.cameraLooper, c.frameLooper)) {
                // A closed camera's threads have quit (or are quitting): nothing to run there.
                if (l != null && l.thread.isAlive) runCatching { shadowOf(l).idle() }
            }
            shadowOf(Looper.getMainLooper()).idle()
        }
    }

    private fun open(owner: Fixtures.TestOwner): CamProCamera {
        Fixtures.load()
        return CamPro.open(app, owner, Lens.Back, Preset.Json(Fixtures.params())).also { cam = it }
    }

    private fun result(vararg values: Pair<CaptureResult.Key<*>, Any>) = scriptedResult(*values)

    /** Meters, answers the pixel probe and verifies one protected result at [ts], as an honest HAL (on the camera thread). */
    private fun protect(c: CamProCamera, ts: Long) {
        val g = c.glue!!
        onCamera(c) {
            g.onResult(
                CamProCamera2.METERING,
                result(
                    CaptureResult.CONTROL_AWB_MODE to 1, CaptureResult.CONTROL_AWB_STATE to 2,
                    CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(Fixtures.PHONE),
                    CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
                ),
            )
            for ((i, step) in PixelProbe.Step.values().withIndex()) {
                val curve = PixelProbe.curve(step)
                g.onResult(CamProCamera2.PROBE, honoured(g, 100L + i, PixelProbe.transform(step, g.session.transform), curve))
                g.pipeline.onProbeFrame(100L + i, ByteArray(4800) { Fixtures.probeLevel(curve).toByte() })
            }
        }
        verify(c, ts)
    }

    private fun honoured(g: CamProCamera2, ts: Long, transform: IntArray = g.session.transform.copyOf(), curve: FloatArray = g.session.curveForRequest()) = result(
        CaptureResult.CONTROL_AWB_MODE to 0, CaptureResult.COLOR_CORRECTION_MODE to 0, CaptureResult.TONEMAP_MODE to 0,
        CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(transform),
        CaptureResult.TONEMAP_CURVE to TonemapCurve(curve, curve, curve),
        CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
        CaptureResult.SENSOR_TIMESTAMP to ts,
    )

    private fun verify(c: CamProCamera, ts: Long) {
        val g = c.glue!!
        onCamera(c) { g.onResult(CamProCamera2.PROTECTED, honoured(g, ts)) }
    }

    private fun onCamera(c: CamProCamera, body: () -> Unit) {
        android.os.Handler(c.cameraLooper!!).post(body)
        settle(c)
    }

    /** A YUV 4:2:0 frame of flat 8 x 8 blocks (I420 planes), closed through [closed]. */
    private class FakeImage(val w: Int, val h: Int, private val ts: Long, val closed: MutableList<Long>) : Image() {
        val y = ByteArray(w * h) { k -> (40 + 13 * ((k % w) / 8 + 3 * ((k / w) / 8))).toByte() }
        val u = ByteArray(w * h / 4) { k -> (90 + 11 * ((k % (w / 2)) / 4)).toByte() }
        val v = ByteArray(w * h / 4) { k -> (170 - 9 * ((k / (w / 2)) / 4)).toByte() }
        private fun plane(b: ByteArray, stride: Int) = object : Plane() {
            override fun getRowStride() = stride
            override fun getPixelStride() = 1
            override fun getBuffer(): ByteBuffer = ByteBuffer.wrap(b)
        }
        override fun getFormat() = ImageFormat.YUV_420_888
        override fun getWidth() = w
        override fun getHeight() = h
        override fun getTimestamp() = ts
        override fun getTransform() = 0
        override fun getScalingMode() = 0
        override fun getPlanes(): Array<Plane> = arrayOf(plane(y, w), plane(u, w / 2), plane(v, w / 2))
        override fun close() { closed += ts }
    }

    @Test
    fun checkDeviceListsEveryCameraAndWhy() {
        shadowOf(manager).addCamera("0", chars())
        shadowOf(manager).addCamera("1", chars(supported = false, facing = CameraCharacteristics.LENS_FACING_FRONT))
        val check = CamPro.checkDevice(app)
        assertEquals(listOf("0", "1"), check.cameras.map { it.cameraId })
        assertTrue(check.supported && check.supports(Lens.Back) && !check.supports(Lens.Front))
        assertFalse(check.cameras[0].perFrameControl)
        assertEquals(64, check.cameras[0].curvePoints)
        assertTrue(check.summary(), check.summary().startsWith("CamPro can protect: camera 0"))
        val only = DeviceCheck(check.cameras.drop(1))
        assertTrue(only.summary(), only.summary().startsWith("no camera can run CamPro: camera 1: ") && only.summary().contains("CONTRAST_CURVE"))
    }

    @Test
    fun theLifecycleOpensClosesAndReopensTheCamera() {
        shadowOf(manager).addCamera("0", chars())
        shadowOf(app).grantPermissions(Manifest.permission.CAMERA)
        val owner = Fixtures.TestOwner()
        val c = open(owner)
        settle(c)
        assertTrue("nothing opens before the owner starts: ${c.state.value}", c.state.value is ProtectionState.Stopped && c.glue == null)
        val seen = ArrayList<ProtectionState>()
        c.addStateListener({ it.run() }) { seen += it }
        owner.moveTo(Lifecycle.State.RESUMED)
        settle(c)
        assertNotNull("started: the camera is open and metering", c.glue)
        assertEquals(ProtectionState.Verifying, c.state.value)
        protect(c, 1000)
        assertEquals(ProtectionState.Protected, c.state.value)

        // The owner stops: closed, Stopped, the glue gone.
        owner.moveTo(Lifecycle.State.CREATED)
        settle(c)
        assertNull(c.glue)
        assertEquals(ProtectionState.Stopped("paused: the app is not in the foreground"), c.state.value)
        // Started again: reopened, verifying anew.
        owner.moveTo(Lifecycle.State.STARTED)
        settle(c)
        assertNotNull(c.glue)
        assertEquals(ProtectionState.Verifying, c.state.value)

        // Another app takes the camera (multi-window): Stopped until the camera is available again.
        shadowOf(manager).triggerDisconnect()
        settle(c)
        assertNull(c.glue)
        val s = c.state.value
        assertTrue("$s", s is ProtectionState.Stopped && s.reason.contains("taken by another app"))
        shadowOf(manager).removeCamera("0")
        shadowOf(manager).addCamera("0", chars()) // the service says it is available again
        settle(c)
        assertNotNull("reopened when the camera came back", c.glue)

        // Destroyed: closed for good.
        owner.moveTo(Lifecycle.State.DESTROYED)
        settle(c)
        assertNull(c.glue)
        assertEquals(ProtectionState.Stopped("closed by the app"), c.state.value)
        assertEquals(listOf("Stopped", "Verifying", "Protected", "Stopped", "Verifying", "Stopped", "Verifying", "Stopped"), seen.map { it.javaClass.simpleName }.distinctConsecutive())
    }

    private fun <T> List<T>.distinctConsecutive(): List<T> = filterIndexed { i, x -> i == 0 || this[i - 1] != x }

    @Test
    fun withoutPermissionOrSupportNothingOpens() {
        shadowOf(manager).addCamera("0", chars())
        val owner = Fixtures.TestOwner()
        val c = open(owner)
        owner.moveTo(Lifecycle.State.RESUMED)
        settle(c)
        assertEquals(ProtectionState.Stopped("the camera permission is not granted"), c.state.value)
        assertNull(c.glue)
        val e = runCatching { c.startRecording(File(dir, "a.mp4")) }.exceptionOrNull()
        assertTrue("$e", e is IllegalStateException && e.message!!.startsWith("the camera is not open"))
        val stills = ArrayList<StillResult>()
        c.takePicture(File(dir, "a.jpg")) { stills += it }
        settle(c)
        assertTrue("${stills.single()}", (stills.single() as StillResult.Failed).reason.startsWith("the camera is not open"))
        c.close()
        settle(c)

        shadowOf(manager).removeCamera("0")
        shadowOf(manager).addCamera("0", chars(supported = false))
        shadowOf(app).grantPermissions(Manifest.permission.CAMERA)
        val owner2 = Fixtures.TestOwner()
        val c2 = open(owner2)
        owner2.moveTo(Lifecycle.State.RESUMED)
        settle(c2)
        val s = c2.state.value
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("CONTRAST_CURVE"))
        assertNull(c2.glue)
    }

    /** Frames reach the preview and a still only once their own result verified; the still is the frame's pixels with the orientation alone. */
    @Test
    fun previewAndStillsGetOnlyVerifiedFrames() {
        shadowOf(manager).addCamera("0", chars())
        shadowOf(app).grantPermissions(Manifest.permission.CAMERA)
        val owner = Fixtures.TestOwner()
        val c = open(owner)
        val view = CamProPreviewView(app)
        c.setPreview(view)
        owner.moveTo(Lifecycle.State.RESUMED)
        settle(c)
        assertEquals(View.VISIBLE, view.cover.visibility)
        val closed = ArrayList<Long>()
        // A frame before anything verified: dropped by the gate, never rendered.
        onCamera(c) { c.glue!!.pipeline.onFrame(500, FakeImage(64, 48, 500, closed)) }
        protect(c, 1000)
        assertEquals(ProtectionState.Protected, c.state.value)
        assertEquals("the cover lifts once Protected", View.GONE, view.cover.visibility)
        assertEquals(listOf(500L), closed)
        assertEquals(0L, view.framesShown + view.framesDropped)

        val out = File(dir, "still.jpg")
        val stills = ArrayList<StillResult>()
        c.takePicture(out) { stills += it }
        val frame = FakeImage(64, 48, 2000, closed)
        onCamera(c) { c.glue!!.pipeline.onFrame(2000, frame) }
        assertTrue("waits for its result", stills.isEmpty())
        verify(c, 2000)
        Thread.sleep(200) // the JPEG is encoded on campro-still
        settle(c)
        val taken = stills.single() as StillResult.Taken
        assertEquals(2000L, taken.timestampNs)
        assertTrue(out.isFile && out.readBytes().contentEquals(taken.jpeg))
        assertEquals("the preview took the verified frame (no surface here: closed unshown)", 1L, view.framesDropped)
        assertEquals(listOf(500L, 2000L), closed)
        // EXIF: one entry, Orientation 6 (sensor at 90, display unturned), no GPS.
        val app1 = taken.jpeg.indexOfSequence("Exif\u0000\u0000".toByteArray())
        assertTrue(app1 > 0)
        val tiff = app1 + 6
        assertEquals(1, le16(taken.jpeg, tiff + 8))
        assertEquals(0x0112, le16(taken.jpeg, tiff + 10))
        assertEquals(6, le16(taken.jpeg, tiff + 18))
        assertEquals(-1, taken.jpeg.indexOfSequence(byteArrayOf(0x25, 0x88.toByte())))
        // Pixels: the frame's JFIF colours within 3 codes (flat 8 x 8 blocks, quality 95).
        val img = ImageIO.read(ByteArrayInputStream(taken.jpeg))
        var worst = 0
        for (yy in 0 until 48) for (xx in 0 until 64) {
            val yv = frame.y[yy * 64 + xx].toInt() and 255
            val cb = (frame.u[(yy / 2) * 32 + xx / 2].toInt() and 255) - 128
            val cr = (frame.v[(yy / 2) * 32 + xx / 2].toInt() and 255) - 128
            val want = listOf(yv + 1.402 * cr, yv - 0.344136 * cb - 0.714136 * cr, yv + 1.772 * cb).map { Math.round(it).toInt().coerceIn(0, 255) }
            val rgb = img.getRGB(xx, yy)
            val got = listOf((rgb shr 16) and 255, (rgb shr 8) and 255, rgb and 255)
            for (k in 0 until 3) worst = maxOf(worst, kotlin.math.abs(got[k] - want[k]))
        }
        assertTrue("still off by $worst", worst <= 3)

        // A second still into the same file is refused without overwrite; the first is left alone.
        c.takePicture(out) { stills += it }
        settle(c)
        assertTrue((stills.last() as StillResult.Failed).reason.contains("exists"))
        // A still waiting when the camera closes fails with the reason.
        c.takePicture(File(dir, "late.jpg")) { stills += it }
        owner.moveTo(Lifecycle.State.CREATED)
        settle(c)
        Thread.sleep(100)
        settle(c)
        assertEquals("paused: the app is not in the foreground", (stills.last() as StillResult.Failed).reason)
        assertFalse(File(dir, "late.jpg").exists())
        assertEquals(View.VISIBLE, view.cover.visibility)
    }

    private fun le16(b: ByteArray, at: Int) = (b[at].toInt() and 255) or ((b[at + 1].toInt() and 255) shl 8)

    private fun ByteArray.indexOfSequence(s: ByteArray): Int {
        outer@ for (i in 0..size - s.size) {
            for (j in s.indices) if (this[i + j] != s[j]) continue@outer
            return i
        }
        return -1
    }
}
