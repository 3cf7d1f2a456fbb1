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
import org.campro.Orientation
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
import org.campro.android.CameraScript.FakeImage
import org.campro.android.CameraScript.chars
import org.campro.android.CameraScript.onCamera
import org.campro.android.CameraScript.protect
import org.campro.android.CameraScript.settle
import org.campro.android.CameraScript.verify
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

    private fun open(owner: Fixtures.TestOwner): CamProCamera {
        Fixtures.load()
        return CamPro.open(app, owner, Lens.Back, Preset.Json(Fixtures.params())).also { cam = it }
    }

    private fun bundled(name: String) =
        File(System.getProperty("campro.params.dir") ?: error("campro.params.dir is not set"), "$name.json").readText()

    @Test
    fun aPresetThatDoesNotProtectIsRefusedWithoutOptInAndNeverReadsProtected() {
        shadowOf(manager).addCamera("0", chars())
        shadowOf(app).grantPermissions(Manifest.permission.CAMERA)
        Fixtures.load()
        for (name in listOf("identity", "srgb-passthrough", "color-inversion", "campro-omega-5")) {
            assertFalse(name, Preset.Json(bundled(name)).protective(app))
        }
        assertTrue(Preset.Json(Fixtures.params()).protective(app))

        // Without the opt-in: refused before the camera opens, final.
        val refused = Fixtures.TestOwner()
        val r = CamPro.open(app, refused, Lens.Back, Preset.Json(bundled("identity"))).also { cam = it }
        refused.moveTo(Lifecycle.State.RESUMED)
        settle(r)
        val s = r.state.value
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("does not protect faces") && s.reason.contains("allowUnprotective"))
        assertNull("nothing opened", r.glue)
        r.close()
        settle(r)

        // With it: the device applies it faithfully, and the state says Applied, never Protected.
        val owner = Fixtures.TestOwner()
        val c = CamPro.open(app, owner, Lens.Back, Preset.Json(bundled("identity")), CamProOptions(allowUnprotective = true)).also { cam = it }
        val seen = ArrayList<ProtectionState>()
        c.addStateListener({ it.run() }) { seen += it }
        owner.moveTo(Lifecycle.State.RESUMED)
        settle(c)
        protect(c, 1000)
        assertEquals(ProtectionState.Applied, c.state.value)
        assertFalse("never Protected: $seen", ProtectionState.Protected in seen)
    }

    @Test
    fun aGridThePresetWasNotMeasuredOnIsRefusedBeforeTheCameraOpens() {
        shadowOf(manager).addCamera("0", chars())
        shadowOf(app).grantPermissions(Manifest.permission.CAMERA)
        Fixtures.load()
        val owner = Fixtures.TestOwner()
        val c = CamPro.open(app, owner, Lens.Back, Preset.Json(Fixtures.params()), CamProOptions(deviceGrids = setOf("q10", "lut17"))).also { cam = it }
        owner.moveTo(Lifecycle.State.RESUMED)
        settle(c)
        val s = c.state.value
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("lut17") && !s.reason.contains("deviceGrids q10") && s.reason.contains("it holds: q10") && s.problem == org.campro.Problem.Preset)
        assertNull("nothing opened", c.glue)
        val e = runCatching { CamProOptions(deviceGrids = setOf("q0")) }.exceptionOrNull()
        assertTrue("$e", e is IllegalArgumentException && e.message!!.contains("q0 is not a grid"))
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
        assertEquals(ProtectionState.Stopped("paused: the app is not in the foreground", org.campro.Problem.CameraClosed), c.state.value)
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

        // A camera that keeps going away without protecting in between is left closed after 3
        // (the disconnect above was the first).
        repeat(2) { k ->
            shadowOf(manager).triggerDisconnect()
            settle(c)
            assertNull(c.glue)
            shadowOf(manager).removeCamera("0")
            shadowOf(manager).addCamera("0", chars())
            settle(c)
            assertEquals("loss ${k + 2}", k == 0, c.glue != null)
        }
        val given = c.state.value
        assertTrue("$given", given is ProtectionState.Stopped && given.reason.endsWith("not reopened until the app starts again)"))
        owner.moveTo(Lifecycle.State.CREATED)
        owner.moveTo(Lifecycle.State.STARTED)
        settle(c)
        assertNotNull("the owner's next start tries again", c.glue)

        // Destroyed: closed for good.
        owner.moveTo(Lifecycle.State.DESTROYED)
        settle(c)
        assertNull(c.glue)
        assertEquals(ProtectionState.Stopped("closed by the app", org.campro.Problem.CameraClosed), c.state.value)
        assertEquals(
            listOf("Stopped", "Verifying", "Protected", "Stopped", "Verifying", "Stopped", "Verifying", "Stopped", "Verifying", "Stopped", "Verifying", "Stopped"),
            seen.map { it.javaClass.simpleName }.distinctConsecutive(),
        )
    }

    private fun <T> List<T>.distinctConsecutive(): List<T> = filterIndexed { i, x -> i == 0 || this[i - 1] != x }

    @Test
    fun withoutPermissionOrSupportNothingOpens() {
        shadowOf(manager).addCamera("0", chars())
        val owner = Fixtures.TestOwner()
        val c = open(owner)
        owner.moveTo(Lifecycle.State.RESUMED)
        settle(c)
        assertEquals(ProtectionState.Stopped("the camera permission is not granted", org.campro.Problem.Permission), c.state.value)
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
        Thread.sleep(200) // the JPEG is encoded on campro-background
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
        // Pixels: the frame's JFIF colours within 3 codes (flat 8 x 8 blocks, quality 95), away
        // from block edges, where a decoder's chroma upsampling blends neighbouring blocks.
        val img = ImageIO.read(ByteArrayInputStream(taken.jpeg))
        var worst = 0
        for (yy in 0 until 48) for (xx in 0 until 64) {
            if (xx % 8 !in 2..5 || yy % 8 !in 2..5) continue
            val yv = frame.y[yy * 64 + xx].toInt() and 255
            val cb = (frame.u[(yy / 2) * 32 + xx / 2].toInt() and 255) - 128
            val cr = (frame.v[(yy / 2) * 32 + xx / 2].toInt() and 255) - 128
            val want = listOf(yv + 1.402 * cr, yv - 0.344136 * cb - 0.714136 * cr, yv + 1.772 * cb).map { Math.round(it).toInt().coerceIn(0, 255) }
            val rgb = img.getRGB(xx, yy)
            val got = listOf((rgb shr 16) and 255, (rgb shr 8) and 255, rgb and 255)
            for (k in 0 until 3) worst = maxOf(worst, kotlin.math.abs(got[k] - want[k]))
        }
        assertTrue("still off by $worst", worst <= 3)

        // Its record lies beside it, and the CLI (the Rust reader of the same format) verifies it.
        val record = taken.record!!
        assertEquals(File(dir, "still.jpg.campro.json"), record)
        val json = record.readText()
        assertTrue(json, json.contains("\"path\": \"camera2\"") && json.contains("\"input\": null") && json.contains("\"camera_id\": \"0\""))
        val (code, said) = cli("check", "--record", record.path, out.path)
        assertEquals(said, 0, code)
        assertTrue(said, said.contains("the output its record names") && said.contains("camera 0 sent its values"))
        val changed = File(dir, "changed.jpg").also { f -> f.writeBytes(out.readBytes().also { it[it.size / 2] = (it[it.size / 2] + 1).toByte() }) }
        val (code2, said2) = cli("check", "--record", record.path, changed.path)
        assertTrue(said2, code2 != 0 && said2.contains("NOT what its record names") && said2.contains("names no raw input"))

        // An app locked to portrait: the display stays at 0, the accelerometer says the phone is
        // turned 90 clockwise; the still is turned as the phone is held (sensor 90 + device 90: EXIF 3).
        assertEquals("no reading yet: the display's rotation", 0, c.currentDeviceOrientation())
        c.sensedOrientation = Orientation.deviceOrientation(100, 0)
        val turned = File(dir, "turned.jpg")
        c.takePicture(turned) { stills += it }
        onCamera(c) { c.glue!!.pipeline.onFrame(3000, FakeImage(64, 48, 3000, closed)) }
        verify(c, 3000)
        Thread.sleep(200)
        settle(c)
        val t2 = stills.last() as StillResult.Taken
        val app1b = t2.jpeg.indexOfSequence("Exif\u0000\u0000".toByteArray())
        assertEquals(3, le16(t2.jpeg, app1b + 6 + 18))

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

    /** Runs the campro CLI; returns its exit code and what it printed. */
    private fun cli(vararg args: String): Pair<Int, String> {
        val bin = System.getProperty("campro.cli") ?: error("campro.cli is not set: run android/check-on-jvm.sh")
        val p = ProcessBuilder(bin, *args).redirectErrorStream(true).start()
        val text = p.inputStream.readBytes().decodeToString()
        return p.waitFor() to text
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
