package org.campro.android

import android.hardware.camera2.CaptureResult
import org.robolectric.shadow.api.Shadow
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
