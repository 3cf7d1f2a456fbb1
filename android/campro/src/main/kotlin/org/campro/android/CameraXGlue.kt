package org.campro.android

// CameraX support: CamProPipeline on a CameraX camera. CamPro's values (and the metering
// switches) are set through Camera2 interop, every result is checked by the same fail-closed
// ProtectionGuard, and ImageAnalysis frames wait in the FrameGate until their own result
// verifies. `bind` binds its gated ImageAnalysis; a Preview, ImageCapture or VideoCapture the
// app binds to the same camera would be fed straight from the camera, before any result is
// checked, and CameraX cannot let a library see or refuse them: the path is delicate, opted
// into with @OptIn(DelicateCameraXPath::class) (CamPro.open, on Camera2, has no such hole):
//
//     val campro = CamProCameraX(session, mainExecutor, deliver = { image -> render(image) }, onState = ::show)
//     campro.bind(provider, owner, CameraSelector.DEFAULT_BACK_CAMERA, cameraManager, cameraExecutor)
//
// Compiled against Robolectric's android-all and android/jvm-test/stubs (the CameraX API it
// uses; Google's Maven is not reachable here) and run under Robolectric by android/check-on-jvm.sh.

import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CameraManager
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.TotalCaptureResult
import androidx.annotation.OptIn
import androidx.camera.camera2.interop.Camera2CameraControl
import androidx.camera.camera2.interop.Camera2CameraInfo
import androidx.camera.camera2.interop.Camera2Interop
import androidx.camera.camera2.interop.CaptureRequestOptions
import androidx.camera.camera2.interop.ExperimentalCamera2Interop
import androidx.camera.core.Camera
import androidx.camera.core.CameraControl
import androidx.camera.core.CameraSelector
import androidx.camera.core.ImageAnalysis
import androidx.camera.core.ImageProxy
import androidx.camera.lifecycle.ProcessCameraProvider
import androidx.lifecycle.LifecycleOwner
import org.campro.CamProPipeline
import org.campro.CamProSession
import org.campro.CameraRequests
import org.campro.DeviceSupport
import org.campro.PixelProbe
import org.campro.ProtectionState
import java.util.concurrent.ExecutionException
import java.util.concurrent.Executor

/**
 * The CameraX path can leak: any `Preview`, `ImageCapture` or `VideoCapture` an app binds to
 * the same camera gets frames before CamPro has verified them, and CameraX gives a library no
 * way to list or refuse use cases. Use [CamProCameraX] only where the app binds nothing else
 * to that camera; `CamPro.open` (Camera2, the library owns every stream) has no such hole.
 */
@RequiresOptIn(
    level = RequiresOptIn.Level.ERROR,
    message = "CamProCameraX cannot stop an app's own Preview, ImageCapture or VideoCapture on the same camera from getting unverified frames: bind nothing else to it, or use CamPro.open",
)
@Retention(AnnotationRetention.BINARY)
@Target(AnnotationTarget.CLASS, AnnotationTarget.FUNCTION)
annotation class DelicateCameraXPath

/**
 * CamPro on a CameraX camera, fail closed per frame ([DelicateCameraXPath]: bind nothing else
 * to the camera).
 *
 * CameraX has no per-request tags or bursts, so metering is phased: [start] (and [remeter])
 * switch the camera to auto white balance until it converges, take the device's transform
 * and gains, then send CamPro's values; frames are closed unseen meanwhile. Call [remeter]
 * when the light changes (e.g. every few seconds, or on a scene change): white balance is
 * otherwise frozen at the last metering.
 */
@OptIn(markerClass = [ExperimentalCamera2Interop::class])
@DelicateCameraXPath
class CamProCameraX(
    val session: CamProSession,
    /** The app's executor: frames and states are delivered there. */
    appExecutor: Executor,
    /** Called on [appExecutor] with each verified frame; it must close it. */
    deliver: (ImageProxy) -> Unit,
    /** Called on [appExecutor] with each new state. */
    onState: (ProtectionState) -> Unit = {},
    /** See [org.campro.ProtectionGuard.trustMissingKeys]: accepting it risks unprotected frames. */
    trustMissingKeys: Boolean = false,
    /** `REQUEST_PIPELINE_MAX_DEPTH` of the bound camera (CameraX hides it; 8 covers current devices). */
    pipelineDepth: Int = 8,
    /** See [org.campro.CamProPipeline]'s `maxDeviationLsb` (8-bit LSB). */
    maxDeviationLsb: Double = 0.5,
) {
    /** The analysis queue depth the gate needs for [pipelineDepth] ([CamProPipeline.imageQueueDepth]). */
    val queueDepth: Int = CamProPipeline.imageQueueDepth(pipelineDepth)

    @Volatile
    private var control: Camera2CameraControl? = null

    private var extended = false

    private val requests = object : CameraRequests {
        override fun meter() = send(listOf(CaptureRequest.CONTROL_AWB_MODE to CaptureRequest.CONTROL_AWB_MODE_AUTO))

        override fun protect(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray, burst: org.campro.Burst?) =
            send(camproSettings(transform, curves, gains))

        override fun probe(transform: IntArray, curve: FloatArray, gains: FloatArray) = send(camproSettings(transform, arrayOf(curve, curve, curve), gains))

        /**
         * CamPro stopped for good (the app stopped it, Unsupported, a failure): its colour
         * matrix, curve and AWB-off leave the camera (`clearCaptureRequestOptions`), and the
         * analysis [bind] bound is unbound, so the camera stops streaming and the privacy
         * indicator goes off. The gate is closed by the pipeline.
         */
        override fun halt() {
            try {
                control?.clearCaptureRequestOptions()
            } catch (e: RuntimeException) {
                // The camera is gone: nothing of CamPro's is left on it.
            }
            onMain { releaseBinding() }
        }
    }

    /** The loop: states, gate and metering (phased: CameraX has no per-frame control over interop). */
    val pipeline = CamProPipeline<ImageProxy>(
        session, requests, appExecutor,
        perFrameControl = false,
        pipelineDepth = pipelineDepth,
        imageQueueDepth = queueDepth,
        trustMissingKeys = trustMissingKeys,
        deliver = deliver,
        drop = { it.close() },
        onState = onState,
        maxDeviationLsb = maxDeviationLsb,
        lumaOf = { image ->
            val y = image.planes.firstOrNull()
            if (y == null) ByteArray(0) else PixelProbe.lumaOfPlane(y.buffer, image.width, image.height, y.rowStride, y.pixelStride)
        },
    )

    /** The current state; frames reach the app only while it is Protected. */
    val state: ProtectionState get() = pipeline.state

    /**
     * Adds CamPro's result check to the ImageAnalysis builder and sets the queue it needs.
     * Once only, and only on the use case whose frames are gated: a second callback would
     * check every result twice.
     */
    internal fun extend(builder: ImageAnalysis.Builder) {
        check(!extended) { "CamProCameraX.extend: already extended (one ImageAnalysis use case only)" }
        extended = true
        builder.setImageQueueDepth(queueDepth)
        builder.setBackpressureStrategy(ImageAnalysis.STRATEGY_BLOCK_PRODUCER)
        Camera2Interop.Extender(builder).setSessionCaptureCallback(captureCallback)
    }

    /**
     * The analyzer to set on that use case: frames go through the gate; while the pipeline
     * probes the device ([org.campro.PixelProbe]), their luma goes to the probe and the
     * frame is closed unseen (the pipeline decides).
     */
    internal val analyzer: ImageAnalysis.Analyzer = ImageAnalysis.Analyzer { image -> pipeline.onFrame(image.imageInfo.timestamp, image) }

    /** The provider and use case of [bind] (`null`: not bound by the library). Main thread. */
    @Volatile
    private var bound: Pair<ProcessCameraProvider, ImageAnalysis>? = null

    /**
     * Binds CamPro's gated `ImageAnalysis` to [owner] on the camera [selector] picks, and
     * starts. The app's other use cases are left alone (an earlier version unbound them all):
     * a `Preview`, `ImageCapture` or `VideoCapture` on the same camera would get frames
     * straight from the camera (metering frames in auto mode, frames whose result never
     * verified), and interop options would apply to still captures too, so bind none
     * ([DelicateCameraXPath]); show and record the gated frames instead. [unbind], then
     * [bind] with another selector, switches cameras. The camera's support is read from its Camera2
     * characteristics ([cameras]); an unsupported camera ends Unsupported with nothing
     * delivered. [configure] may set the analysis' resolution or output format; its queue
     * depth, back-pressure and callbacks are CamPro's. Frames are analysed on
     * [analysisExecutor]. CameraX closes and reopens the camera with [owner]'s lifecycle:
     * each new capture session starts CamPro again (metering, the pixel probe), and a closed
     * one stops it.
     *
     * What CameraX cannot let a library prove (and the stubs cannot show): that the app
     * binds nothing to this provider afterwards. CameraX has no way to list or refuse use
     * cases; binding one more reconfigures the session, which restarts CamPro's checks but
     * cannot close the other use case's stream.
     */
    fun bind(
        provider: ProcessCameraProvider,
        owner: LifecycleOwner,
        selector: CameraSelector,
        cameras: CameraManager,
        analysisExecutor: Executor,
        configure: (ImageAnalysis.Builder) -> Unit = {},
    ): Camera {
        check(bound == null) { "CamProCameraX.bind: already bound (unbind() first)" }
        extended = false
        sessionsConfigured.set(0)
        val builder = ImageAnalysis.Builder()
        configure(builder)
        extend(builder)
        Camera2Interop.Extender(builder).setSessionStateCallback(sessionCallback)
        val analysis = builder.build()
        analysis.setAnalyzer(analysisExecutor, analyzer)
        val camera = provider.bindToLifecycle(owner, selector, analysis)
        bound = provider to analysis
        val support = try {
            cameras.getCameraCharacteristics(Camera2CameraInfo.from(camera.cameraInfo).cameraId).camproSupport()
        } catch (e: Exception) {
            DeviceSupport.Result.Unsupported(listOf("the camera's characteristics cannot be read: ${e.javaClass.simpleName}: ${e.message}"))
        }
        this.support = support
        start(Camera2CameraControl.from(camera.cameraControl), support)
        return camera
    }

    /** Stops CamPro (its options cleared from the camera) and unbinds its analysis from the provider of [bind]. Main thread. */
    fun unbind() {
        stop()
        releaseBinding()
    }

    /** Unbinds the analysis [bind] bound, once (main thread). */
    private fun releaseBinding() {
        val (provider, analysis) = bound ?: return
        bound = null
        control = null
        provider.unbind(analysis)
    }

    /** Runs [body] on the main thread (CameraX binds there): at once when already on it. */
    private fun onMain(body: () -> Unit) {
        val main = android.os.Looper.getMainLooper()
        if (android.os.Looper.myLooper() == main) body() else android.os.Handler(main).post(body)
    }

    /** The support of the camera bound by [bind] (`null` before). */
    @Volatile
    var support: DeviceSupport.Result? = null
        private set

    /** Starts metering on the bound camera ([support] from its characteristics); closed until verified. */
    fun start(control: Camera2CameraControl, support: DeviceSupport.Result) {
        this.control = control
        this.support = support
        pipeline.start(support)
    }

    /**
     * The capture session's life (set by [bind]): CameraX closes the camera when the
     * lifecycle stops (pause, multi-window eviction) and opens a new session when it
     * starts again, so CamPro starts again on every configured session after the first.
     */
    private val sessionCallback = object : CameraCaptureSession.StateCallback() {
        override fun onConfigured(s: CameraCaptureSession) = onSessionConfigured()
        override fun onConfigureFailed(s: CameraCaptureSession) = pipeline.onCameraStopped("the capture session could not be configured")
        override fun onClosed(s: CameraCaptureSession) = onSessionClosed()
    }

    /** Sessions configured since [bind]. */
    private val sessionsConfigured = java.util.concurrent.atomic.AtomicInteger()

    /** A capture session of the bound camera is configured (internal: tests call it): every one after the first starts CamPro again. */
    internal fun onSessionConfigured() {
        val supp = support
        if (sessionsConfigured.getAndIncrement() > 0 && control != null && supp != null) pipeline.start(supp)
    }

    /** The bound camera's capture session closed (internal: tests call it): stopped, nothing delivered until a new session verifies. */
    internal fun onSessionClosed() = pipeline.onCameraStopped("the capture session closed (the app paused, or another app took the camera)")

    /** Meters again (closed meanwhile). */
    fun remeter() = pipeline.remeter()

    /** Closes the gate; frames are dropped from now on. */
    fun stop() = pipeline.stop()

    /** Calls to [send] so far: a failed future of an older one was superseded, not refused. */
    private val sends = java.util.concurrent.atomic.AtomicLong()

    /**
     * Sets [settings] as the camera's interop options. CameraX reports failure through the
     * returned future, not an exception: the latest call's future failing (the camera is not
     * active, or refused the options) stops CamPro closed with the reason; an older one's
     * `OperationCanceledException` only means a newer call replaced it.
     */
    private fun send(settings: List<Pair<CaptureRequest.Key<*>, Any>>) {
        val c = control ?: error("start() has not been given a Camera2CameraControl")
        val b = CaptureRequestOptions.Builder()
        for ((k, v) in settings) b.setAny(k, v)
        val n = sends.incrementAndGet()
        val future = c.setCaptureRequestOptions(b.build())
        future.addListener({
            val failure = try {
                future.get()
                null
            } catch (e: ExecutionException) {
                e.cause ?: e
            } catch (e: java.util.concurrent.CancellationException) {
                e
            } catch (e: InterruptedException) {
                Thread.currentThread().interrupt()
                e
            }
            val superseded = failure is CameraControl.OperationCanceledException && n != sends.get()
            if (failure != null && !superseded) pipeline.onCameraStopped("CameraX refused CamPro's settings: ${failure.javaClass.simpleName}: ${failure.message}", org.campro.Problem.Other)
        }, Runnable::run)
    }

    @Suppress("UNCHECKED_CAST")
    private fun CaptureRequestOptions.Builder.setAny(key: CaptureRequest.Key<*>, value: Any) =
        setCaptureRequestOption(key as CaptureRequest.Key<Any>, value)

    /** Lost buffers matched to sensor timestamps in either callback order; a protected frame's only. */
    private val lostBuffers = org.campro.LostBuffers { ts -> if (!pipeline.isMetering && !pipeline.isProbing) pipeline.onFrameLost(ts) }

    internal val captureCallback = object : CameraCaptureSession.CaptureCallback() {
        override fun onCaptureStarted(s: CameraCaptureSession, request: CaptureRequest, timestamp: Long, frameNumber: Long) {
            lostBuffers.started(frameNumber, timestamp)
        }

        override fun onCaptureCompleted(s: CameraCaptureSession, request: CaptureRequest, result: TotalCaptureResult) = onResult(result)

        // The analysis stream is the only one the library binds: a lost buffer is one of its frames.
        override fun onCaptureBufferLost(s: CameraCaptureSession, request: CaptureRequest, target: android.view.Surface, frameNumber: Long) {
            lostBuffers.lost(frameNumber)
        }
    }

    /** One completed capture: metering while metering, a probe result while probing, otherwise a protected result (internal: tests feed scripted results). */
    internal fun onResult(result: CaptureResult) {
        if (pipeline.isMetering) {
            pipeline.onMeteringResult(result.meteringReport())
        } else if (pipeline.isProbing) {
            pipeline.onProbeResult(result.get(CaptureResult.SENSOR_TIMESTAMP) ?: Long.MIN_VALUE, result.camproReport())
        } else {
            pipeline.onProtectedResult(result.get(CaptureResult.SENSOR_TIMESTAMP) ?: Long.MIN_VALUE, result.camproReport())
        }
    }
}
