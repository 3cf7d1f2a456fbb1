package org.campro.android

// CameraX support: CamProPipeline on a CameraX camera. CamPro's values (and the metering
// switches) are set through Camera2 interop, every result is checked by the same fail-closed
// ProtectionGuard, and ImageAnalysis frames wait in the FrameGate until their own result
// verifies. A plain Preview use case is NOT fail-closed: CameraX feeds it straight from the
// camera, before any result is checked. Show the gated ImageAnalysis frames instead.
//
//     val campro = CamProCameraX(session, mainExecutor, deliver = { image -> render(image) }, onState = ::show)
//     val analysis = ImageAnalysis.Builder().also { campro.extend(it) }.build()
//     analysis.setAnalyzer(cameraExecutor, campro.analyzer)
//     val camera = provider.bindToLifecycle(owner, selector, analysis)   // no Preview
//     campro.start(Camera2CameraControl.from(camera.cameraControl), support)
//
// Compiled against Robolectric's android-all and android/jvm-test/stubs (the CameraX API it
// uses; Google's Maven is not reachable here) and run under Robolectric by android/check-on-jvm.sh.

import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.TotalCaptureResult
import androidx.annotation.OptIn
import androidx.camera.camera2.interop.Camera2CameraControl
import androidx.camera.camera2.interop.Camera2Interop
import androidx.camera.camera2.interop.CaptureRequestOptions
import androidx.camera.camera2.interop.ExperimentalCamera2Interop
import androidx.camera.core.ImageAnalysis
import androidx.camera.core.ImageProxy
import org.campro.CamProPipeline
import org.campro.CamProSession
import org.campro.CameraRequests
import org.campro.DeviceSupport
import org.campro.PixelProbe
import org.campro.ProtectionState
import java.util.concurrent.Executor

/**
 * CamPro on a CameraX camera, fail closed per frame.
 *
 * CameraX has no per-request tags or bursts, so metering is phased: [start] (and [remeter])
 * switch the camera to auto white balance until it converges, take the device's transform
 * and gains, then send CamPro's values; frames are closed unseen meanwhile. Call [remeter]
 * when the light changes (e.g. every few seconds, or on a scene change): white balance is
 * otherwise frozen at the last metering.
 */
@OptIn(markerClass = [ExperimentalCamera2Interop::class])
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
) {
    @Volatile
    private var control: Camera2CameraControl? = null

    private var extended = false

    private val requests = object : CameraRequests {
        override fun meter() = send(listOf(CaptureRequest.CONTROL_AWB_MODE to CaptureRequest.CONTROL_AWB_MODE_AUTO))

        override fun protect(transform: IntArray, curve: FloatArray, gains: FloatArray, interleaveMetering: Boolean, meteringInterval: Int, meteringRun: Int) =
            send(camproSettings(transform, curve, gains))

        override fun probe(transform: IntArray, curve: FloatArray, gains: FloatArray) = send(camproSettings(transform, curve, gains))

        override fun halt() {
            // CameraX owns the repeating request; the gate is closed by the pipeline.
        }
    }

    /** The loop: states, gate and metering (phased: CameraX has no per-frame control over interop). */
    val pipeline = CamProPipeline<ImageProxy>(
        session, requests, appExecutor,
        perFrameControl = false,
        pipelineDepth = pipelineDepth,
        imageQueueDepth = QUEUE_DEPTH,
        trustMissingKeys = trustMissingKeys,
        deliver = deliver,
        drop = { it.close() },
        onState = onState,
    )

    /** The current state; frames reach the app only while it is Protected. */
    val state: ProtectionState get() = pipeline.state

    /**
     * Adds CamPro's result check to the ImageAnalysis builder and sets the queue it needs.
     * Once only, and only on the use case whose frames are gated: a second callback would
     * check every result twice.
     */
    fun extend(builder: ImageAnalysis.Builder) {
        check(!extended) { "CamProCameraX.extend: already extended (one ImageAnalysis use case only)" }
        extended = true
        builder.setImageQueueDepth(QUEUE_DEPTH)
        builder.setBackpressureStrategy(ImageAnalysis.STRATEGY_BLOCK_PRODUCER)
        Camera2Interop.Extender(builder).setSessionCaptureCallback(captureCallback)
    }

    /**
     * The analyzer to set on that use case: frames go through the gate; while the pipeline
     * probes the device ([org.campro.PixelProbe]), their luma goes to the probe and the
     * frame is closed unseen.
     */
    val analyzer: ImageAnalysis.Analyzer = ImageAnalysis.Analyzer { image ->
        if (pipeline.isProbing) {
            image.use {
                val y = it.planes.firstOrNull()
                val luma = if (y == null) ByteArray(0) else PixelProbe.lumaOfPlane(y.buffer, it.width, it.height, y.rowStride, y.pixelStride)
                pipeline.onProbeFrame(it.imageInfo.timestamp, luma)
            }
        } else {
            pipeline.onFrame(image.imageInfo.timestamp, image)
        }
    }

    /** Starts metering on the bound camera ([support] from its characteristics); closed until verified. */
    fun start(control: Camera2CameraControl, support: DeviceSupport.Result) {
        this.control = control
        pipeline.start(support)
    }

    /** Meters again (closed meanwhile). */
    fun remeter() = pipeline.remeter()

    /** Closes the gate; frames are dropped from now on. */
    fun stop() = pipeline.stop()

    private fun send(settings: List<Pair<CaptureRequest.Key<*>, Any>>) {
        val c = control ?: error("start() has not been given a Camera2CameraControl")
        val b = CaptureRequestOptions.Builder()
        for ((k, v) in settings) b.setAny(k, v)
        c.setCaptureRequestOptions(b.build())
    }

    @Suppress("UNCHECKED_CAST")
    private fun CaptureRequestOptions.Builder.setAny(key: CaptureRequest.Key<*>, value: Any) =
        setCaptureRequestOption(key as CaptureRequest.Key<Any>, value)

    internal val captureCallback = object : CameraCaptureSession.CaptureCallback() {
        override fun onCaptureCompleted(s: CameraCaptureSession, request: CaptureRequest, result: TotalCaptureResult) = onResult(result)
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

    companion object {
        /** ImageAnalysis queue depth the gate needs: frames wait there for their results. */
        const val QUEUE_DEPTH = 6
    }
}
