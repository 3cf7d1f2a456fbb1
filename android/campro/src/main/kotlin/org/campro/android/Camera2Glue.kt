package org.campro.android

// The only Android-typed code of the library: reading Camera2 metadata into plain arrays
// and writing CamPro's values into a request. Every decision is made in CamProController,
// CamProSession, DeviceSupport (host-tested) or in the Rust core.

import android.content.res.AssetManager
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.params.ColorSpaceTransform
import android.hardware.camera2.params.RggbChannelVector
import android.hardware.camera2.params.TonemapCurve
import org.campro.CamProSession
import org.campro.CaptureReport
import org.campro.DeviceSupport

/** Whether this camera can run CamPro, with the reasons when not. */
fun CameraCharacteristics.camproSupport(): DeviceSupport.Result = DeviceSupport.check(
    capabilities = get(CameraCharacteristics.REQUEST_AVAILABLE_CAPABILITIES),
    toneMapModes = get(CameraCharacteristics.TONEMAP_AVAILABLE_TONE_MAP_MODES),
    maxCurvePoints = get(CameraCharacteristics.TONEMAP_MAX_CURVE_POINTS),
    awbModes = get(CameraCharacteristics.CONTROL_AWB_AVAILABLE_MODES),
)

/** Copies the result's `COLOR_CORRECTION_TRANSFORM` (18 ints) into [out]; false when absent. */
fun CaptureResult.colorTransformInto(out: IntArray): Boolean {
    val t = get(CaptureResult.COLOR_CORRECTION_TRANSFORM) ?: return false
    t.copyElements(out, 0)
    return true
}

/** Copies `COLOR_CORRECTION_GAINS` as (R, G_even, G_odd, B) into [out]; false when absent. */
fun CaptureResult.gainsInto(out: FloatArray): Boolean {
    val g = get(CaptureResult.COLOR_CORRECTION_GAINS) ?: return false
    out[0] = g.red; out[1] = g.greenEven; out[2] = g.greenOdd; out[3] = g.blue
    return true
}

/**
 * What this result reports about CamPro's stages, for [org.campro.ProtectionGuard]: the
 * three modes, the transform and the three curves, `null` where a key is absent.
 */
fun CaptureResult.camproReport(): CaptureReport = CaptureReport(
    awbMode = get(CaptureResult.CONTROL_AWB_MODE),
    colorCorrectionMode = get(CaptureResult.COLOR_CORRECTION_MODE),
    tonemapMode = get(CaptureResult.TONEMAP_MODE),
    transform = get(CaptureResult.COLOR_CORRECTION_TRANSFORM)?.let { t -> IntArray(18).also { t.copyElements(it, 0) } },
    curves = get(CaptureResult.TONEMAP_CURVE)?.let { c ->
        listOf(TonemapCurve.CHANNEL_RED, TonemapCurve.CHANNEL_GREEN, TonemapCurve.CHANNEL_BLUE).map { ch ->
            FloatArray(2 * c.getPointCount(ch)).also { c.copyColorCurve(ch, it, 0) }
        }
    },
)

/**
 * Sets CamPro on a request: AWB off (Camera2 ignores TRANSFORM_MATRIX otherwise), the
 * gains measured in auto mode, CamPro's transform, and its curve on all three channels.
 */
fun CaptureRequest.Builder.applyCamPro(session: CamProSession, gains: FloatArray) {
    val curve: FloatArray
    val transform: IntArray
    synchronized(session) {
        curve = session.curveForRequest()
        transform = session.transform.copyOf()
    }
    set(CaptureRequest.CONTROL_AWB_MODE, CaptureRequest.CONTROL_AWB_MODE_OFF)
    set(CaptureRequest.COLOR_CORRECTION_MODE, CaptureRequest.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX)
    set(CaptureRequest.COLOR_CORRECTION_GAINS, RggbChannelVector(gains[0], gains[1], gains[2], gains[3]))
    set(CaptureRequest.COLOR_CORRECTION_TRANSFORM, ColorSpaceTransform(transform))
    set(CaptureRequest.TONEMAP_MODE, CaptureRequest.TONEMAP_MODE_CONTRAST_CURVE)
    set(CaptureRequest.TONEMAP_CURVE, TonemapCurve(curve, curve, curve))
}

/** A session from a parameter file in the APK's assets, read natively (NDK AAssetManager). */
fun openCamProAsset(
    assets: AssetManager,
    path: String,
    maxCurvePoints: Int,
    skipTolerance: Double = CamProSession.DEFAULT_SKIP_TOLERANCE,
): CamProSession = CamProSession.fromAsset(assets, path, maxCurvePoints, CamProSession.DEFAULT_MAX_DENOMINATOR, skipTolerance)
