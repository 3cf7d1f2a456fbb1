@file:OptIn(DelicateCameraXPath::class)

package org.campro.android

import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.params.ColorSpaceTransform
import android.hardware.camera2.params.RggbChannelVector
import android.hardware.camera2.params.TonemapCurve
import android.hardware.camera2.CameraManager
import androidx.camera.camera2.interop.Camera2CameraControl
import androidx.camera.camera2.interop.Camera2CameraInfo
import androidx.camera.camera2.interop.CaptureRequestOptions
import androidx.camera.core.Camera
import androidx.camera.core.CameraControl
import androidx.camera.core.CameraInfo
import androidx.camera.core.CameraSelector
import androidx.camera.core.ImageAnalysis
import androidx.camera.core.UseCase
import androidx.camera.lifecycle.ProcessCameraProvider
import androidx.lifecycle.LifecycleOwner
import androidx.camera.core.ImageInfo
import androidx.camera.core.ImageProxy
import com.google.common.util.concurrent.ListenableFuture
import org.campro.CamProPipeline
import org.campro.Fixtures
import org.campro.PixelProbe
import org.campro.ProtectionState
import org.junit.After
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
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
import java.util.concurrent.Executor
import java.util.concurrent.TimeUnit

/** The Android-typed glue on Robolectric's real framework classes (android-all, API 34). */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34])
class GlueTest {
    private val session = Fixtures.session()

    @After
    fun close() = session.close()

    private fun result(vararg values: Pair<CaptureResult.Key<*>, Any>) = scriptedResult(*values)

    /** The result a device that honours [settings] reports (what CaptureRequest carried, read back). */
    private fun honouring(settings: List<Pair<CaptureRequest.Key<*>, Any>>, ts: Long): CaptureResult {
        val byName = settings.associate { (k, v) -> k.name to v }
        return result(
            CaptureResult.CONTROL_AWB_MODE to byName.getValue("android.control.awbMode"),
            CaptureResult.COLOR_CORRECTION_MODE to byName.getValue("android.colorCorrection.mode"),
            CaptureResult.TONEMAP_MODE to byName.getValue("android.tonemap.mode"),
            CaptureResult.COLOR_CORRECTION_TRANSFORM to byName.getValue("android.colorCorrection.transform"),
            CaptureResult.TONEMAP_CURVE to byName.getValue("android.tonemap.curve"),
            CaptureResult.COLOR_CORRECTION_GAINS to byName.getValue("android.colorCorrection.gains"),
            CaptureResult.SENSOR_TIMESTAMP to ts,
        )
    }

    @Test
    fun reportsReadEveryKeyAndNullWhereAbsent() {
        val t = Fixtures.PHONE
        val curve = floatArrayOf(0f, 0f, 0.25f, 0.5f, 1f, 1f)
        val r = result(
            CaptureResult.CONTROL_AWB_MODE to 0,
            CaptureResult.CONTROL_AWB_STATE to 2,
            CaptureResult.COLOR_CORRECTION_MODE to 0,
            CaptureResult.TONEMAP_MODE to 0,
            CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(t),
            CaptureResult.TONEMAP_CURVE to TonemapCurve(curve, curve, floatArrayOf(0f, 1f, 1f, 0f)),
            CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1.01f, 1.6f),
        )
        val rep = r.camproReport()
        assertEquals(0, rep.awbMode); assertEquals(0, rep.colorCorrectionMode); assertEquals(0, rep.tonemapMode)
        assertTrue(t.contentEquals(rep.transform!!))
        assertTrue(curve.contentEquals(rep.curves!![0]) && curve.contentEquals(rep.curves!![1]))
        assertTrue(floatArrayOf(0f, 1f, 1f, 0f).contentEquals(rep.curves!![2]))
        assertTrue(floatArrayOf(2f, 1f, 1.01f, 1.6f).contentEquals(rep.gains!!))
        val m = r.meteringReport()
        assertEquals(2, m.awbState)
        assertTrue(t.contentEquals(m.transform!!))
        val empty = result().camproReport()
        assertNull(empty.awbMode); assertNull(empty.transform); assertNull(empty.curves); assertNull(empty.gains)
    }

    @Test
    fun characteristicsDecideSupportPerFrameControlAndDepth() {
        val c = supportedCharacteristics(syncLatency = 0, points = 32, depth = 6)
        val sup = c.camproSupport()
        assertTrue("$sup", sup is org.campro.DeviceSupport.Result.Supported && sup.maxCurvePoints == 32)
        assertTrue(c.hasPerFrameControl())
        assertEquals(6, c.pipelineDepth())
        val d = ShadowCameraCharacteristics.newCameraCharacteristics()
        val sd = Shadow.extract<ShadowCameraCharacteristics>(d)
        sd.set(CameraCharacteristics.SYNC_MAX_LATENCY, 2)
        assertFalse(d.hasPerFrameControl())
        assertEquals(8, d.pipelineDepth())
        assertTrue(d.camproSupport() is org.campro.DeviceSupport.Result.Unsupported)
        // Everything else as the supported camera, but SYNC_MAX_LATENCY UNKNOWN: Unsupported.
        val unknown = supportedCharacteristics(syncLatency = -1).camproSupport()
        assertTrue("$unknown", unknown is org.campro.DeviceSupport.Result.Unsupported && unknown.reasons.single().contains("SYNC_MAX_LATENCY is -1"))
    }

    @Test
    fun settingsCarryTheSessionsValues() {
        session.updateFromTransform(Fixtures.PHONE)
        val curves = session.curvesForRequest()
        val s = camproSettings(session.transform, curves, Fixtures.GAINS).toMap()
        assertEquals(CaptureRequest.CONTROL_AWB_MODE_OFF, s[CaptureRequest.CONTROL_AWB_MODE])
        val t = IntArray(18).also { (s[CaptureRequest.COLOR_CORRECTION_TRANSFORM] as ColorSpaceTransform).copyElements(it, 0) }
        assertTrue(session.transform.contentEquals(t))
        val tc = s[CaptureRequest.TONEMAP_CURVE] as TonemapCurve
        for (ch in 0..2) {
            val got = FloatArray(2 * tc.getPointCount(ch)).also { tc.copyColorCurve(ch, it, 0) }
            assertTrue(curves[ch].contentEquals(got))
        }
        // The HAL's face statistics are off: results carry no face rectangles or landmarks.
        assertEquals(CaptureRequest.STATISTICS_FACE_DETECT_MODE_OFF, s[CaptureRequest.STATISTICS_FACE_DETECT_MODE])
        // An empty curve (no update yet) is refused by name, never sent.
        val e = runCatching { camproSettings(session.transform, arrayOf(curves[0], FloatArray(0), curves[2]), Fixtures.GAINS) }.exceptionOrNull()
        assertTrue("$e", e is IllegalArgumentException && e.message!!.contains("curve"))
    }

    /** A 64 x 48 frame whose Y plane holds [luma] everywhere (the probe reads only it). */
    private class FakeProxy(val ts: Long, val luma: Int = 0) : ImageProxy {
        var closed = false
        override val imageInfo = object : ImageInfo { override val timestamp = ts }
        override val width = 64
        override val height = 48
        override val planes: Array<ImageProxy.PlaneProxy> = arrayOf(
            object : ImageProxy.PlaneProxy {
                override val rowStride = 64
                override val pixelStride = 1
                override val buffer: java.nio.ByteBuffer = java.nio.ByteBuffer.wrap(ByteArray(64 * 48) { luma.toByte() })
            },
        )
        override fun close() { closed = true }
    }

    private class RecordingControl : Camera2CameraControl(), CameraControl {
        /** Futures handed out, in order, when [holdFutures]: tests complete them. */
        var holdFutures = false
        val futures = mutableListOf<SettableFuture>()

        val sent = mutableListOf<CaptureRequestOptions>()
        /** Calls to clearCaptureRequestOptions: CamPro's settings taken off the camera. */
        var cleared = 0
        var failWith: RuntimeException? = null
        override fun clearCaptureRequestOptions(): ListenableFuture<Void?> {
            cleared++
            return done()
        }
        override fun setCaptureRequestOptions(options: CaptureRequestOptions): ListenableFuture<Void?> {
            failWith?.let { throw it }
            sent += options
            if (holdFutures) return SettableFuture().also { futures += it }
            return done()
        }

        private fun done(): ListenableFuture<Void?> {
            return object : ListenableFuture<Void?> {
                override fun addListener(listener: Runnable, executor: Executor) = executor.execute(listener)
                override fun cancel(mayInterruptIfRunning: Boolean) = false
                override fun isCancelled() = false
                override fun isDone() = true
                override fun get(): Void? = null
                override fun get(timeout: Long, unit: TimeUnit): Void? = null
            }
        }
    }

    @Test
    fun cameraXMetersThenProtectsAndGatesEveryFrame() {
        val direct = Executor { it.run() }
        val shown = mutableListOf<Long>()
        val states = mutableListOf<ProtectionState>()
        val x = CamProCameraX(session, direct, deliver = { shown += it.imageInfo.timestamp; it.close() }, onState = { states += it })
        val builder = ImageAnalysis.Builder()
        x.extend(builder)
        assertEquals(CamProPipeline.imageQueueDepth(8), builder.queueDepth)
        assertEquals(ImageAnalysis.STRATEGY_BLOCK_PRODUCER, builder.backpressure)
        assertTrue("the result callback is on the analysis use case", builder.sessionCaptureCallback != null)
        assertTrue("extend twice would check results twice", runCatching { x.extend(ImageAnalysis.Builder()) }.isFailure)

        val control = RecordingControl()
        // Started before any session update: metering first, never an empty curve.
        x.start(control, Fixtures.supported())
        assertEquals(1, control.sent.size)
        assertEquals(CaptureRequest.CONTROL_AWB_MODE_AUTO, control.sent[0].getCaptureRequestOption(CaptureRequest.CONTROL_AWB_MODE))
        assertNull(control.sent[0].getCaptureRequestOption(CaptureRequest.TONEMAP_CURVE))
        assertEquals(ProtectionState.Verifying, x.state)

        // Frames during metering never reach the app.
        val f1 = FakeProxy(10)
        x.analyzer.analyze(f1)
        x.onResult(result(CaptureResult.CONTROL_AWB_MODE to 1, CaptureResult.CONTROL_AWB_STATE to 1, CaptureResult.SENSOR_TIMESTAMP to 10L))
        x.onResult(
            result(
                CaptureResult.CONTROL_AWB_MODE to 1, CaptureResult.CONTROL_AWB_STATE to 2, CaptureResult.SENSOR_TIMESTAMP to 11L,
                CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(Fixtures.PHONE),
                CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
            ),
        )
        // The pixel probe: a constant curve, then a near-zero transform; its frames' luma is read and
        // the frames closed unseen; results are routed to it while it runs.
        assertEquals(2, control.sent.size)
        assertTrue(f1.closed)
        for ((i, step) in PixelProbe.Step.values().withIndex()) {
            val probe = control.sent[1 + i]
            val probeCurve = probe.getCaptureRequestOption(CaptureRequest.TONEMAP_CURVE)!!
            assertEquals(PixelProbe.curve(step)[1], probeCurve.getPoint(TonemapCurve.CHANNEL_GREEN, 0).y)
            val ts = 12L + i
            val pf = FakeProxy(ts, Fixtures.probeLevel(PixelProbe.curve(step)))
            x.analyzer.analyze(pf)
            assertTrue(pf.closed)
            val probeSettings = listOf(
                CaptureRequest.CONTROL_AWB_MODE, CaptureRequest.COLOR_CORRECTION_MODE, CaptureRequest.TONEMAP_MODE,
                CaptureRequest.COLOR_CORRECTION_TRANSFORM, CaptureRequest.TONEMAP_CURVE, CaptureRequest.COLOR_CORRECTION_GAINS,
            ).map { k -> k as CaptureRequest.Key<*> to probe.getCaptureRequestOption(k)!! }
            x.onResult(honouring(probeSettings, ts))
        }
        assertEquals(4, control.sent.size)
        val sent = control.sent[3]
        assertEquals(CaptureRequest.CONTROL_AWB_MODE_OFF, sent.getCaptureRequestOption(CaptureRequest.CONTROL_AWB_MODE))
        assertTrue(shown.isEmpty())
        assertEquals(ProtectionState.Verifying, x.state)

        // Protected: each frame shown only after its own result verified.
        val settings = listOf(
            CaptureRequest.CONTROL_AWB_MODE, CaptureRequest.COLOR_CORRECTION_MODE, CaptureRequest.TONEMAP_MODE,
            CaptureRequest.COLOR_CORRECTION_TRANSFORM, CaptureRequest.TONEMAP_CURVE, CaptureRequest.COLOR_CORRECTION_GAINS,
        ).map { k -> k as CaptureRequest.Key<*> to sent.getCaptureRequestOption(k)!! }
        val f2 = FakeProxy(20)
        x.analyzer.analyze(f2)
        assertTrue(shown.isEmpty())
        x.onResult(honouring(settings, 20))
        assertEquals(listOf(20L), shown)
        assertEquals(ProtectionState.Protected, x.state)
        // The device ignored the curve on frame 30: that frame is closed unseen.
        val f3 = FakeProxy(30)
        x.analyzer.analyze(f3)
        val line = floatArrayOf(0f, 0f, 1f, 1f)
        val ignored = settings.map { (k, v) -> k to (if (k == CaptureRequest.TONEMAP_CURVE) TonemapCurve(line, line, line) else v) }
        x.onResult(honouring(ignored, 30))
        assertTrue(f3.closed)
        assertEquals(listOf(20L), shown)
        assertTrue(x.state is ProtectionState.Violated)
        // Recovers on the next good frame.
        x.analyzer.analyze(FakeProxy(40))
        x.onResult(honouring(settings, 40))
        assertEquals(listOf(20L, 40L), shown)
        // White balance re-measured on request (closed meanwhile).
        x.remeter()
        assertEquals(ProtectionState.Verifying, x.state)
        assertEquals(CaptureRequest.CONTROL_AWB_MODE_AUTO, control.sent.last().getCaptureRequestOption(CaptureRequest.CONTROL_AWB_MODE))
        assertEquals(listOf("Verifying", "Protected", "Violated", "Protected", "Verifying"), states.map { it.javaClass.simpleName })

        // The camera going away mid-stream (CameraX throws from interop): closed, frames dropped.
        control.failWith = IllegalStateException("Camera is closed")
        x.onResult(
            result(
                CaptureResult.CONTROL_AWB_MODE to 1, CaptureResult.CONTROL_AWB_STATE to 3, CaptureResult.SENSOR_TIMESTAMP to 50L,
                CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(Fixtures.PHONE),
                CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
            ),
        )
        assertTrue("${x.state}", x.state is ProtectionState.Stopped)
        val f6 = FakeProxy(60)
        x.analyzer.analyze(f6)
        assertTrue(f6.closed)
        assertEquals(listOf(20L, 40L), shown)
    }

    /** A future a test completes: listeners run when it does. */
    private class SettableFuture : ListenableFuture<Void?> {
        private var failure: Throwable? = null
        private var done = false
        private val listeners = mutableListOf<Runnable>()
        fun succeed() { done = true; listeners.forEach { it.run() } }
        fun fail(t: Throwable) { failure = t; succeed() }
        override fun addListener(listener: Runnable, executor: Executor) { if (done) executor.execute(listener) else listeners += Runnable { executor.execute(listener) } }
        override fun cancel(mayInterruptIfRunning: Boolean) = false
        override fun isCancelled() = false
        override fun isDone() = done
        override fun get(): Void? = failure?.let { throw java.util.concurrent.ExecutionException(it) }
        override fun get(timeout: Long, unit: TimeUnit): Void? = get()
    }

    private class FakeInfo(override val cameraId: String) : Camera2CameraInfo(), CameraInfo

    private class RecordingProvider(private val camera: Camera) : ProcessCameraProvider() {
        val calls = mutableListOf<String>()
        val boundCases = mutableListOf<UseCase>()
        override fun bindToLifecycle(lifecycleOwner: LifecycleOwner, cameraSelector: CameraSelector, vararg useCases: UseCase): Camera {
            calls += "bind ${useCases.size}"
            boundCases += useCases
            return camera
        }
        override fun isBound(useCase: UseCase) = useCase in boundCases
        override fun unbind(vararg useCases: UseCase) { calls += "unbind ${useCases.size}"; boundCases -= useCases.toSet() }
        override fun unbindAll() { calls += "unbindAll"; boundCases.clear() }
    }

    private fun cameraManager(id: String, chars: CameraCharacteristics): CameraManager {
        val manager = RuntimeEnvironment.getApplication().getSystemService(CameraManager::class.java)
        shadowOf(manager).addCamera(id, chars)
        return manager
    }

    /** A CameraX camera whose Camera2 id is [id], its control [control]. */
    private fun cameraOf(id: String, control: RecordingControl) = object : Camera {
        override val cameraControl: CameraControl = control
        override val cameraInfo: CameraInfo = FakeInfo(id)
    }

    @Test
    fun cameraXBindOwnsTheBindingAndRestartsWithEachSession() {
        val direct = Executor { it.run() }
        val control = RecordingControl()
        val provider = RecordingProvider(cameraOf("7", control))
        val x = CamProCameraX(session, direct, deliver = { it.close() })
        val owner = Fixtures.TestOwner()
        x.bind(provider, owner, CameraSelector.DEFAULT_BACK_CAMERA, cameraManager("7", supportedCharacteristics()), direct) { it.setImageQueueDepth(1) }
        // The app's other use cases are left alone (DelicateCameraXPath says why); CamPro's analysis is extended (its queue, not the app's).
        assertEquals(listOf("bind 1"), provider.calls)
        val analysis = provider.boundCases.single() as ImageAnalysis
        assertEquals(CamProPipeline.imageQueueDepth(8), analysis.builder.queueDepth)
        assertTrue(analysis.builder.sessionCaptureCallback != null && analysis.builder.sessionStateCallback != null && analysis.builder.analyzer != null)
        assertTrue("${x.support}", x.support is org.campro.DeviceSupport.Result.Supported)
        assertEquals(CaptureRequest.CONTROL_AWB_MODE_AUTO, control.sent.single().getCaptureRequestOption(CaptureRequest.CONTROL_AWB_MODE))
        assertTrue("bind twice", runCatching { x.bind(provider, owner, CameraSelector.DEFAULT_BACK_CAMERA, cameraManager("7", supportedCharacteristics()), direct) }.isFailure)
        // The first session is the one bind started; the lifecycle pauses (closed) and resumes (a new session): metering again.
        x.onSessionConfigured()
        assertEquals(1, control.sent.size)
        x.onSessionClosed()
        assertTrue("${x.state}", x.state is ProtectionState.Stopped)
        x.onSessionConfigured()
        assertEquals(2, control.sent.size)
        assertEquals(CaptureRequest.CONTROL_AWB_MODE_AUTO, control.sent.last().getCaptureRequestOption(CaptureRequest.CONTROL_AWB_MODE))
        assertEquals(ProtectionState.Verifying, x.state)
        x.unbind()
        assertEquals("unbind 1", provider.calls.last())
        assertTrue(provider.boundCases.isEmpty())
        assertEquals("CamPro's matrix, curve and AWB-off taken off the camera", 1, control.cleared)
        // Switching cameras: unbind, then bind another one.
        val front = RecordingControl()
        val provider2 = RecordingProvider(cameraOf("9", front))
        x.bind(provider2, owner, CameraSelector.DEFAULT_FRONT_CAMERA, cameraManager("9", supportedCharacteristics()), direct)
        assertEquals(listOf("bind 1"), provider2.calls)
        assertEquals(ProtectionState.Verifying, x.state)
        assertEquals(CaptureRequest.CONTROL_AWB_MODE_AUTO, front.sent.single().getCaptureRequestOption(CaptureRequest.CONTROL_AWB_MODE))
        assertEquals("nothing more to the first camera", 2, control.sent.size)
        x.unbind()
    }

    @Test
    fun cameraXBindOnAnUnsupportedCameraDeliversNothing() {
        val direct = Executor { it.run() }
        val control = RecordingControl()
        val x = CamProCameraX(session, direct, deliver = { it.close() })
        val provider = RecordingProvider(cameraOf("8", control))
        x.bind(provider, Fixtures.TestOwner(), CameraSelector.DEFAULT_FRONT_CAMERA, cameraManager("8", supportedCharacteristics(syncLatency = -1)), direct)
        val s = x.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("SYNC_MAX_LATENCY"))
        assertTrue("nothing sent to an unsupported camera", control.sent.isEmpty())
        // Unsupported is final: the analysis is unbound, so the camera stops streaming (the privacy indicator goes off).
        assertEquals(listOf("bind 1", "unbind 1"), provider.calls)
    }

    @Test
    fun cameraXFailedFuturesStopClosedUnlessSuperseded() {
        val direct = Executor { it.run() }
        val control = RecordingControl().apply { holdFutures = true }
        val x = CamProCameraX(session, direct, deliver = { it.close() })
        x.start(control, Fixtures.supported())
        x.remeter()
        assertEquals(2, control.futures.size)
        // The first call was replaced by the second: CameraX cancels it, which is no failure.
        control.futures[0].fail(CameraControl.OperationCanceledException("superseded"))
        assertEquals(ProtectionState.Verifying, x.state)
        control.futures[1].succeed()
        assertEquals(ProtectionState.Verifying, x.state)
        // The latest call refused (the camera is not active): stopped closed, with the reason.
        x.remeter()
        control.futures[2].fail(CameraControl.OperationCanceledException("Camera is not active."))
        val s = x.state
        assertTrue("$s", s is ProtectionState.Stopped && s.reason.contains("Camera is not active"))
    }

    @Test
    fun pipelineConstantsMatchTheFramework() {
        assertEquals(android.hardware.camera2.CameraMetadata.CONTROL_AWB_STATE_CONVERGED, CamProPipeline.AWB_STATE_CONVERGED)
        assertEquals(android.hardware.camera2.CameraMetadata.CONTROL_AWB_STATE_LOCKED, CamProPipeline.AWB_STATE_LOCKED)
        assertEquals(android.hardware.camera2.CameraMetadata.SYNC_MAX_LATENCY_PER_FRAME_CONTROL, CamProPipeline.SYNC_MAX_LATENCY_PER_FRAME_CONTROL)
        assertEquals(android.hardware.camera2.CameraMetadata.SYNC_MAX_LATENCY_UNKNOWN, org.campro.DeviceSupport.SYNC_MAX_LATENCY_UNKNOWN)
        assertEquals(android.hardware.camera2.CameraMetadata.CONTROL_AWB_MODE_AUTO, CamProPipeline.AWB_MODE_AUTO)
        assertEquals(android.hardware.camera2.CameraMetadata.CONTROL_AWB_MODE_OFF, org.campro.DeviceSupport.CONTROL_AWB_MODE_OFF)
        assertEquals(android.hardware.camera2.CameraMetadata.TONEMAP_MODE_CONTRAST_CURVE, org.campro.DeviceSupport.TONEMAP_MODE_CONTRAST_CURVE)
        assertEquals(android.hardware.camera2.CameraMetadata.REQUEST_AVAILABLE_CAPABILITIES_MANUAL_POST_PROCESSING, org.campro.DeviceSupport.CAPABILITY_MANUAL_POST_PROCESSING)
        assertEquals(android.hardware.camera2.CameraMetadata.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX, org.campro.ProtectionGuard.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX)
    }
}
