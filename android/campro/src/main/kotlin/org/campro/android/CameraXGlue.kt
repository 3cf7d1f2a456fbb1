package org.campro.android

// CameraX support: CamPro's values set through Camera2 interop, every result checked by
// the same fail-closed ProtectionGuard, and ImageAnalysis frames held by a FrameGate
// until their own result verifies. Android-typed glue only (never compiled on the host);
// the decisions are in org.campro.ProtectionGuard / FrameGate (host-tested).
//
//     val campro = CamProCameraX(session)
//     val preview = Preview.Builder().also { campro.extend(it) }.build()
//     val analysis = ImageAnalysis.Builder()
//         .setBackpressureStrategy(ImageAnalysis.STRATEGY_BLOCK_PRODUCER)
//         .setImageQueueDepth(CamProCameraX.QUEUE_DEPTH)
//         .also { campro.extend(it) }.build()
//     analysis.setAnalyzer(executor, campro.gated { image -> detectPeople(image) })
//     val camera = provider.bindToLifecycle(owner, selector, preview, analysis)
//     campro.start(Camera2CameraControl.from(camera.cameraControl), gains)
//     previewView.isVisible = campro.guard.framesAllowed  // refresh from campro.onState

import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.TotalCaptureResult
import android.hardware.camera2.params.ColorSpaceTransform
import android.hardware.camera2.params.RggbChannelVector
import android.hardware.camera2.params.TonemapCurve
import androidx.annotation.OptIn
import androidx.camera.camera2.interop.Camera2CameraControl
import androidx.camera.camera2.interop.Camera2Interop
import androidx.camera.camera2.interop.CaptureRequestOptions
import androidx.camera.camera2.interop.ExperimentalCamera2Interop
import androidx.camera.core.ExtendableBuilder
import androidx.camera.core.ImageAnalysis
import androidx.camera.core.ImageProxy
import org.campro.CamProSession
import org.campro.FrameGate
import org.campro.ProtectionGuard
import org.campro.ProtectionState

/** CamPro on a CameraX camera, fail closed. */
@OptIn(markerClass = [ExperimentalCamera2Interop::class])
class CamProCameraX(
    val session: CamProSession,
    /** See [ProtectionGuard.trustMissingKeys]: accepting it risks unprotected frames. */
    trustMissingKeys: Boolean = false,
    /** Called on the camera thread whenever the protection state changes. */
    var onState: (ProtectionState) -> Unit = {},
) {
    /** The fail-closed state: frames reach the app only while it is Protected. */
    val guard = ProtectionGuard(session, trustMissingKeys = trustMissingKeys)

    private var gate: FrameGate<ImageProxy>? = null

    /** Adds CamPro's result check to a use case (Preview, ImageAnalysis, ImageCapture builder). */
    fun <T> extend(builder: ExtendableBuilder<T>) {
        Camera2Interop.Extender(builder).setSessionCaptureCallback(callback)
    }

    /** Sends CamPro's values (and the white-balance [gains] measured in auto mode); closed until they verify. */
    fun start(control: Camera2CameraControl, gains: FloatArray) {
        val curve: FloatArray
        val transform: IntArray
        synchronized(session) {
            curve = session.curveForRequest()
            transform = session.transform.copyOf()
        }
        guard.requestChanged()
        onState(guard.state)
        control.setCaptureRequestOptions(
            CaptureRequestOptions.Builder()
                .setCaptureRequestOption(CaptureRequest.CONTROL_AWB_MODE, CaptureRequest.CONTROL_AWB_MODE_OFF)
                .setCaptureRequestOption(CaptureRequest.COLOR_CORRECTION_MODE, CaptureRequest.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX)
                .setCaptureRequestOption(CaptureRequest.COLOR_CORRECTION_GAINS, RggbChannelVector(gains[0], gains[1], gains[2], gains[3]))
                .setCaptureRequestOption(CaptureRequest.COLOR_CORRECTION_TRANSFORM, ColorSpaceTransform(transform))
                .setCaptureRequestOption(CaptureRequest.TONEMAP_MODE, CaptureRequest.TONEMAP_MODE_CONTRAST_CURVE)
                .setCaptureRequestOption(CaptureRequest.TONEMAP_CURVE, TonemapCurve(curve, curve, curve))
                .build(),
        )
    }

    /** An analyzer that sees only frames whose own result verified; the others are closed unseen. */
    fun gated(inner: ImageAnalysis.Analyzer): ImageAnalysis.Analyzer {
        val g = FrameGate<ImageProxy>(guard, QUEUE_DEPTH - 1, deliver = { inner.analyze(it) }, drop = { it.close() })
        gate = g
        return ImageAnalysis.Analyzer { image -> g.onFrame(image.imageInfo.timestamp, image) }
    }

    private val callback = object : CameraCaptureSession.CaptureCallback() {
        override fun onCaptureCompleted(s: CameraCaptureSession, request: CaptureRequest, result: TotalCaptureResult) {
            val before = guard.state
            val report = result.camproReport()
            val ts = result.get(CaptureResult.SENSOR_TIMESTAMP)
            val g = gate
            if (g != null && ts != null) g.onResult(ts, report) else guard.onProtectedResult(report)
            if (guard.state != before) onState(guard.state)
        }
    }

    companion object {
        /** ImageAnalysis queue depth the gate needs: frames wait there for their results. */
        const val QUEUE_DEPTH = 5
    }
}
