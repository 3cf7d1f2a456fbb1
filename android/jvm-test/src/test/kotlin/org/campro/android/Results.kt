package org.campro.android

import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CaptureResult
import org.robolectric.shadow.api.Shadow
import org.robolectric.shadows.ShadowCameraCharacteristics
import org.robolectric.shadows.ShadowCaptureResult
import org.robolectric.shadows.ShadowTotalCaptureResult

/** A real `TotalCaptureResult` (Robolectric's shadow) holding exactly [values]; call inside a Robolectric test. */
fun scriptedResult(vararg values: Pair<CaptureResult.Key<*>, Any>): CaptureResult {
    val r = ShadowTotalCaptureResult.newTotalCaptureResult()
    val shadow = Shadow.extract<ShadowCaptureResult>(r)
    @Suppress("UNCHECKED_CAST")
    for ((k, v) in values) shadow.set(k as CaptureResult.Key<Any>, v)
    return r
}

/**
 * Real `CameraCharacteristics` (Robolectric's shadow) of a camera CamPro supports (manual
 * post-processing, CONTRAST_CURVE, AWB off, back-facing) with [points] curve points,
 * `SYNC_MAX_LATENCY` [syncLatency] and `REQUEST_PIPELINE_MAX_DEPTH` [depth]; call inside a
 * Robolectric test. A shadow key is set once, so each variant is a new object.
 */
fun supportedCharacteristics(syncLatency: Int = 0, points: Int = 64, depth: Int = 4): CameraCharacteristics {
    val c = ShadowCameraCharacteristics.newCameraCharacteristics()
    val s = Shadow.extract<ShadowCameraCharacteristics>(c)
    s.set(CameraCharacteristics.REQUEST_AVAILABLE_CAPABILITIES, intArrayOf(0, 2))
    s.set(CameraCharacteristics.TONEMAP_AVAILABLE_TONE_MAP_MODES, intArrayOf(0, 1, 2))
    s.set(CameraCharacteristics.TONEMAP_MAX_CURVE_POINTS, points)
    s.set(CameraCharacteristics.CONTROL_AWB_AVAILABLE_MODES, intArrayOf(0, 1))
    s.set(CameraCharacteristics.SYNC_MAX_LATENCY, syncLatency)
    s.set(CameraCharacteristics.REQUEST_PIPELINE_MAX_DEPTH, depth.toByte())
    s.set(CameraCharacteristics.LENS_FACING, CameraCharacteristics.LENS_FACING_BACK)
    return c
}
