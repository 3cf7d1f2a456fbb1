package org.campro

/**
 * Whether a camera can run CamPro through Camera2, decided from plain values so the
 * rule runs (and is tested) off the phone; `org.campro.android.camproSupport` reads them
 * from `CameraCharacteristics`.
 *
 * Camera2's rules: `TONEMAP_CURVE` is honoured only in `TONEMAP_MODE_CONTRAST_CURVE`,
 * which a device lists in `TONEMAP_AVAILABLE_TONE_MAP_MODES` (guaranteed with the
 * `MANUAL_POST_PROCESSING` capability); `COLOR_CORRECTION_TRANSFORM` is used only with
 * `COLOR_CORRECTION_MODE_TRANSFORM_MATRIX` *and* `CONTROL_AWB_MODE_OFF`, so AWB must be
 * switchable off; `TONEMAP_MAX_CURVE_POINTS` bounds the curve (the documentation promises
 * at least 64, but some devices report 32 and some HALs take fewer: the curve is fitted to
 * what the device reports, and the fit's error is stated).
 */
object DeviceSupport {
    /** `CameraMetadata.REQUEST_AVAILABLE_CAPABILITIES_MANUAL_POST_PROCESSING`. */
    const val CAPABILITY_MANUAL_POST_PROCESSING = 2
    /** `CameraMetadata.TONEMAP_MODE_CONTRAST_CURVE`. */
    const val TONEMAP_MODE_CONTRAST_CURVE = 0
    /** `CameraMetadata.CONTROL_AWB_MODE_OFF`. */
    const val CONTROL_AWB_MODE_OFF = 0

    sealed class Result {
        /** CamPro can be deployed; the curve is fitted to [maxCurvePoints]. */
        data class Supported(val maxCurvePoints: Int, val note: String?) : Result()
        /** It cannot, for these [reasons] (each one sentence). */
        data class Unsupported(val reasons: List<String>) : Result()
    }

    /** `CameraMetadata.SYNC_MAX_LATENCY_UNKNOWN`. */
    const val SYNC_MAX_LATENCY_UNKNOWN = -1

    /**
     * Arguments are the characteristics' values, `null` where the device reports none.
     * Strict: without `MANUAL_POST_PROCESSING` nothing promises that the curve and the
     * matrix are applied as sent, and with `SYNC_MAX_LATENCY` UNKNOWN ("app developers do
     * not have a way to know when sensor settings have been applied") no frame can be tied
     * to the settings it was made with: both are Unsupported.
     */
    fun check(
        capabilities: IntArray?,
        toneMapModes: IntArray?,
        maxCurvePoints: Int?,
        awbModes: IntArray?,
        syncMaxLatency: Int? = CamProPipeline.SYNC_MAX_LATENCY_PER_FRAME_CONTROL,
    ): Result {
        val reasons = mutableListOf<String>()
        val manualPost = capabilities?.contains(CAPABILITY_MANUAL_POST_PROCESSING) == true
        if (toneMapModes?.contains(TONEMAP_MODE_CONTRAST_CURVE) != true) {
            reasons += "the camera has no CONTRAST_CURVE tone-map mode" + if (manualPost) "" else " (no MANUAL_POST_PROCESSING capability)"
        } else if (!manualPost) {
            reasons += "no MANUAL_POST_PROCESSING capability: CONTRAST_CURVE is listed, but nothing promises the curve and matrix are applied as sent"
        }
        if (syncMaxLatency == null || syncMaxLatency == SYNC_MAX_LATENCY_UNKNOWN) {
            reasons += "SYNC_MAX_LATENCY is ${syncMaxLatency ?: "not reported"}: the device does not say when settings apply, so no frame can be tied to its settings"
        }
        if (maxCurvePoints == null || maxCurvePoints < 2) {
            reasons += "the camera reports no usable TONEMAP_MAX_CURVE_POINTS (${maxCurvePoints ?: "none"})"
        }
        if (awbModes?.contains(CONTROL_AWB_MODE_OFF) != true) {
            reasons += "auto white balance cannot be switched off, so COLOR_CORRECTION_TRANSFORM would be ignored"
        }
        if (reasons.isNotEmpty()) return Result.Unsupported(reasons)
        val note = when {
            maxCurvePoints!! < 64 -> "only $maxCurvePoints curve points: the tone curve is simplified (error reported)"
            else -> null
        }
        return Result.Supported(maxCurvePoints!!, note)
    }
}
