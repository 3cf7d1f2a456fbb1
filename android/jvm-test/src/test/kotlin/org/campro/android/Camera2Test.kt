package org.campro.android

import android.hardware.camera2.CameraAccessException
import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraDevice
import android.hardware.camera2.CameraManager
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.params.ColorSpaceTransform
import android.hardware.camera2.params.OutputConfiguration
import android.hardware.camera2.params.RggbChannelVector
import android.hardware.camera2.params.TonemapCurve
import android.graphics.ImageFormat
import android.os.Handler
import android.os.Looper
import android.view.Surface
import org.robolectric.RuntimeEnvironment
import org.campro.Fixtures
import org.campro.PixelProbe
import org.campro.ProtectionState
import org.junit.After
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Test
import org.junit.runner.RunWith
import org.robolectric.RobolectricTestRunner
import org.robolectric.Shadows.shadowOf
import org.robolectric.annotation.Config
import org.robolectric.shadow.api.Shadow
import org.robolectric.shadows.ShadowCameraCharacteristics
import java.util.concurrent.Executor

/** CamProCamera2 on a Robolectric camera: tags, bursts, results, failures. */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34])
class Camera2Test {
    private val session = Fixtures.session()

    @After
    fun close() = session.close()

    /** A capture session that records what it is asked to repeat, and can fail like a disconnected camera. */
    private class FakeSession(private val dev: CameraDevice) : CameraCaptureSession() {
        val repeated = mutableListOf<List<CaptureRequest>>()
        var stops = 0
        var fail: Exception? = null
        override fun getDevice() = dev
        override fun prepare(surface: Surface) {}
        override fun prepare(maxCount: Int, surface: Surface) {}
        override fun tearDown(surface: Surface) {}
        override fun finalizeOutputConfigurations(outputConfigs: List<OutputConfiguration>) {}
        override fun capture(request: CaptureRequest, listener: CaptureCallback?, handler: Handler?) = 0
        override fun captureBurst(requests: List<CaptureRequest>, listener: CaptureCallback?, handler: Handler?) = 0
        override fun setRepeatingRequest(request: CaptureRequest, listener: CaptureCallback?, handler: Handler?): Int {
            fail?.let { throw it }
            repeated += listOf(request); return 1
        }
        override fun setRepeatingBurst(requests: List<CaptureRequest>, listener: CaptureCallback?, handler: Handler?): Int {
            fail?.let { throw it }
            repeated += requests; return 2
        }
        override fun stopRepeating() { stops++ }
        override fun abortCaptures() {}
        override fun isReprocessable() = false
        override fun getInputSurface(): Surface? = null
        override fun close() {}
    }


    private fun openDevice(chars: CameraCharacteristics): CameraDevice {
        val manager = RuntimeEnvironment.getApplication().getSystemService(CameraManager::class.java)
        shadowOf(manager).addCamera("0", chars)
        var opened: CameraDevice? = null
        manager.openCamera("0", object : CameraDevice.StateCallback() {
            override fun onOpened(d: CameraDevice) { opened = d }
            override fun onDisconnected(d: CameraDevice) {}
            override fun onError(d: CameraDevice, error: Int) {}
        }, Handler(Looper.getMainLooper()))
        shadowOf(Looper.getMainLooper()).idle()
        return opened ?: error("Robolectric did not open the camera")
    }

    private fun result(vararg values: Pair<CaptureResult.Key<*>, Any>) = scriptedResult(*values)

    private fun converged() = result(
        CaptureResult.CONTROL_AWB_MODE to 1, CaptureResult.CONTROL_AWB_STATE to 2,
        CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(Fixtures.PHONE),
        CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
    )

    private fun honoured(ts: Long, curves: Array<FloatArray> = session.curvesForRequest()) = result(
        CaptureResult.CONTROL_AWB_MODE to 0, CaptureResult.COLOR_CORRECTION_MODE to 0, CaptureResult.TONEMAP_MODE to 0,
        CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(session.transform.copyOf()),
        CaptureResult.TONEMAP_CURVE to TonemapCurve(curves[0], curves[1], curves[2]),
        CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
        CaptureResult.SENSOR_TIMESTAMP to ts,
    )

    /** The surfaces a built request targets (Camera2 keeps them in a hidden field). */
    private fun targets(req: CaptureRequest): Set<*> =
        req.javaClass.getDeclaredField("mSurfaceSet").apply { isAccessible = true }.get(req) as Set<*>

    /**
     * Answers the pixel probe as an honest device: each probe request (to the protected
     * stream itself, the stream the app sees, when it is readable) gets a result reporting
     * its settings and a flat frame at its level.
     */
    private fun passProbe(cam: CamProCamera2, fake: FakeSession) {
        for ((i, step) in PixelProbe.Step.values().withIndex()) {
            val req = fake.repeated.last().single()
            assertEquals(CamProCamera2.PROBE, req.tag)
            assertEquals("the probe runs on the protected stream", setOf(cam.probeSurface), targets(req))
            assertEquals(cam.protectedSurface, cam.probeSurface)
            val curve = PixelProbe.curve(step)
            val ts = 100L + i
            cam.onResult(
                CamProCamera2.PROBE,
                result(
                    CaptureResult.CONTROL_AWB_MODE to 0, CaptureResult.COLOR_CORRECTION_MODE to 0, CaptureResult.TONEMAP_MODE to 0,
                    CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(PixelProbe.transform(step, session.transform)),
                    CaptureResult.TONEMAP_CURVE to TonemapCurve(curve, curve, curve),
                    CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
                    CaptureResult.SENSOR_TIMESTAMP to ts,
                ),
            )
            cam.pipeline.onProbeFrame(ts, ByteArray(4800) { Fixtures.probeLevel(curve).toByte() })
        }
    }

    private fun camera(chars: CameraCharacteristics, states: MutableList<ProtectionState>) = CamProCamera2(
        session, chars, Handler(Looper.getMainLooper()), Executor { it.run() }, 640, 480,
        deliver = { it.close() }, onState = { states += it }, format = ImageFormat.YUV_420_888, usage = 0L,
    )

    @Test
    fun perFrameControlMetersInTheBurstAndVerifiesEveryResult() {
        val chars = supportedCharacteristics(syncLatency = 0)
        val dev = openDevice(chars)
        val states = mutableListOf<ProtectionState>()
        val cam = camera(chars, states)
        assertEquals(2, cam.outputs().size)
        val fake = FakeSession(dev)
        cam.onConfigured(dev, fake)
        assertEquals(listOf(listOf(CamProCamera2.METERING)), fake.repeated.map { r -> r.map { it.tag } })
        cam.onResult(CamProCamera2.METERING, result(CaptureResult.CONTROL_AWB_MODE to 1, CaptureResult.CONTROL_AWB_STATE to 1))
        assertEquals("not converged: still metering", 1, fake.repeated.size)
        cam.onResult(CamProCamera2.METERING, converged())
        passProbe(cam, fake)
        val burst = fake.repeated.last().map { it.tag }
        assertEquals(30, burst.size)
        assertEquals(List(27) { CamProCamera2.PROTECTED } + List(3) { CamProCamera2.METERING }, burst)
        cam.onResult(CamProCamera2.PROTECTED, honoured(1))
        assertEquals(ProtectionState.Protected, cam.pipeline.state)
        cam.onResult(CamProCamera2.PROTECTED, honoured(2, Array(3) { floatArrayOf(0f, 0f, 1f, 1f) }))
        assertTrue(cam.pipeline.state is ProtectionState.Violated)
        cam.onResult(CamProCamera2.PROTECTED, honoured(3))
        assertEquals(ProtectionState.Protected, cam.pipeline.state)
        // Disconnected mid-stream.
        cam.onCameraStopped("the camera was disconnected")
        cam.onResult(CamProCamera2.PROTECTED, honoured(4))
        assertEquals(ProtectionState.Stopped("the camera was disconnected", org.campro.Problem.CameraClosed), cam.pipeline.state)
        assertEquals(listOf("Verifying", "Protected", "Violated", "Protected", "Stopped"), states.map { it.javaClass.simpleName })
        cam.close()
    }

    /** A camera metered and probed on a device with `SYNC_MAX_LATENCY` [syncLatency]: its next result is a protected one. */
    private fun metered(syncLatency: Int): Pair<CamProCamera2, FakeSession> {
        val chars = supportedCharacteristics(syncLatency = syncLatency)
        val dev = openDevice(chars)
        val cam = camera(chars, mutableListOf())
        val fake = FakeSession(dev)
        cam.onConfigured(dev, fake)
        cam.onResult(CamProCamera2.METERING, converged())
        passProbe(cam, fake)
        return cam to fake
    }

    @Test
    fun withoutPerFrameControlNoAutoFramesInterleaveAndAccessErrorsStopClosed() {
        val (cam, fake) = metered(syncLatency = 2)
        assertEquals(listOf(CamProCamera2.PROTECTED), fake.repeated.last().map { it.tag })
        cam.onResult(CamProCamera2.PROTECTED, honoured(1))
        assertEquals(ProtectionState.Protected, cam.pipeline.state)
        fake.fail = CameraAccessException(CameraAccessException.CAMERA_DISCONNECTED)
        cam.pipeline.remeter()
        val s = cam.pipeline.state
        assertTrue("$s", s is ProtectionState.Stopped && s.reason.contains("CameraAccessException"))
        assertTrue(fake.stops >= 1)
        cam.close()
    }

    @Test
    fun lostBuffersAreNotTakenForMismatchedTimestamps() {
        val (cam, _) = metered(syncLatency = 0)
        val limit = cam.pipeline.gate.unmatchedLimit
        // The app holds every image: each protected capture starts, loses its buffer, and its result verifies.
        for (n in 1L..(2L * limit)) {
            cam.onStarted(CamProCamera2.PROTECTED, 1000L + n, n)
            cam.onBufferLost(CamProCamera2.PROTECTED, n, toFrames = true)
            cam.onResult(CamProCamera2.PROTECTED, honoured(1000L + n))
        }
        assertEquals("lost buffers are not a timestamp mismatch", ProtectionState.Protected, cam.pipeline.state)
        // A buffer lost to another stream, or a capture never seen starting, says nothing: the health check still trips.
        for (n in (2L * limit + 1)..(4L * limit)) {
            cam.onStarted(CamProCamera2.METERING, 1000L + n, n)
            cam.onBufferLost(CamProCamera2.PROTECTED, n, toFrames = true)
            cam.onResult(CamProCamera2.PROTECTED, honoured(1000L + n))
        }
        val s = cam.pipeline.state
        assertTrue("$s", s is ProtectionState.Violated && s.reason.contains("matched no frame"))
        cam.close()
    }

    @Test
    fun closeReleasesTheProtectedReaderOnlyAfterQueuedDeliveries() {
        val chars = supportedCharacteristics(syncLatency = 0)
        val dev = openDevice(chars)
        val app = Fixtures.QueueExecutor()
        val order = mutableListOf<String>()
        val cam = CamProCamera2(
            session, chars, Handler(Looper.getMainLooper()), app, 640, 480,
            deliver = { order += "delivered"; it.close() }, format = ImageFormat.YUV_420_888, usage = 0L,
        )
        cam.onConfigured(dev, FakeSession(dev))
        // A delivery (a state change here) is queued on the app's executor; close() comes before it runs.
        app.execute { order += "delivery with the reader " + if (cam.framesClosed) "closed" else "open" }
        cam.close()
        assertEquals(false, cam.framesClosed)
        app.runAll()
        assertTrue(cam.framesClosed)
        assertEquals(listOf("delivery with the reader open"), order)
        // Closing with a shut-down executor closes at once.
        val shut = java.util.concurrent.Executors.newSingleThreadExecutor().also { it.shutdown() }
        val cam2 = CamProCamera2(session, chars, Handler(Looper.getMainLooper()), shut, 640, 480, deliver = { it.close() }, format = ImageFormat.YUV_420_888, usage = 0L)
        cam2.close()
        assertTrue(cam2.framesClosed)
    }
}
