package org.campro

import kotlin.math.abs
import kotlin.math.max

/**
 * The deployment logic of the sample app, free of Android types so host tests reach it.
 *
 * With CamPro on, frames run with `CONTROL_AWB_MODE_OFF`, `COLOR_CORRECTION_MODE_TRANSFORM_MATRIX`
 * and `TONEMAP_MODE_CONTRAST_CURVE`. AWB being off, the device no longer estimates the
 * light, so each repeating burst of [meteringInterval] frames begins with [meteringRun]
 * metering frames in auto mode (AWB on) that go only to a small metering surface, never to
 * the preview. A run, not one frame: switching AWB into AUTO resets its state to INACTIVE,
 * so a conforming device can report CONVERGED only from a later AUTO frame of the run.
 * Its `CaptureResult` gives the device's current `COLOR_CORRECTION_TRANSFORM` and
 * `COLOR_CORRECTION_GAINS` ([onMeteringResult]); the protected request is rebuilt only
 * when the native skip rule or the gains say the change matters.
 */
class CamProController(
    val session: CamProSession,
    /** Frames of the repeating burst (> [meteringRun]). */
    val meteringInterval: Int = 30,
    /** Metering frames at the start of each burst (>= 1): 3 of 30 at the default, a tenth of the frames. */
    val meteringRun: Int = 3,
    /** Relative change of any white-balance gain that triggers a rebuild. */
    val gainTolerance: Float = 1e-3f,
) {
    init {
        require(meteringRun >= 1) { "meteringRun must be >= 1, got $meteringRun" }
        require(meteringInterval > meteringRun) { "meteringInterval must be > meteringRun ($meteringRun), got $meteringInterval" }
        require(gainTolerance >= 0f && gainTolerance.isFinite()) { "gainTolerance must be finite and >= 0, got $gainTolerance" }
    }

    /** `COLOR_CORRECTION_GAINS` to send (R, G_even, G_odd, B), from the last metering result. */
    val gains = FloatArray(4)

    /** Whether a metering result has arrived (protected requests need one). */
    var ready = false
        private set

    /** Metering results seen and rebuilds they caused. */
    var meteringResults = 0L
        private set
    var rebuilds = 0L
        private set

    private val readbackOut = DoubleArray(CamProNative.READBACK_LEN)

    /** Largest deviation seen between what was requested and what results reported. */
    var worstReadbackBound = 0.0
        private set

    /** Whether frame [frameIndex] of the repeating burst is a metering one. */
    fun isMeteringFrame(frameIndex: Long) = frameIndex % meteringInterval < meteringRun

    /**
     * An auto-mode result arrived: [deviceTransform] is its `COLOR_CORRECTION_TRANSFORM`
     * (18 ints), [newGains] its `COLOR_CORRECTION_GAINS` (4 floats). Returns whether the
     * protected request must be rebuilt.
     */
    fun onMeteringResult(deviceTransform: IntArray, newGains: FloatArray): Boolean {
        require(newGains.size == 4) { "gains must have 4 elements (R, G_even, G_odd, B), got ${newGains.size}" }
        for ((i, g) in newGains.withIndex()) {
            require(g.isFinite() && g > 0f) { "gains[$i] must be finite and > 0, got $g" }
        }
        meteringResults++
        var gainsMoved = !ready
        for (i in 0 until 4) {
            if (abs(newGains[i] - gains[i]) > gainTolerance * max(abs(gains[i]), 1e-6f)) gainsMoved = true
        }
        if (gainsMoved) newGains.copyInto(gains)
        val valuesChanged = session.updateFromTransform(deviceTransform)
        val rebuild = valuesChanged || gainsMoved || !ready
        ready = true
        if (rebuild) rebuilds++
        return rebuild
    }

    /**
     * A protected frame's result: compares what it reports with what was sent and
     * returns the bound on the output deviation this causes (output units).
     */
    fun onProtectedResult(reportedTransform: IntArray, reportedCurves: List<FloatArray>): Double {
        require(reportedCurves.size == 3) { "reportedCurves must hold red, green and blue, got ${reportedCurves.size}" }
        var worst = 0.0
        synchronized(session) {
            for ((c, curve) in reportedCurves.withIndex()) {
                CamProNative.readback(
                    session.transform, session.curve, session.curveOffset(c), 2 * session.curvePoints(c),
                    reportedTransform, curve, curve.size, c, readbackOut,
                )
                worst = max(worst, readbackOut[CamProNative.READBACK_BOUND])
            }
        }
        worstReadbackBound = max(worstReadbackBound, worst)
        return worst
    }

    /** One line for the app's status bar. */
    fun status(): String = if (!ready) "CamPro: waiting for a metering result" else
        "CamPro on: bound %.3f LSB, %d curve points, %d rebuilds / %d metering results, readback %.3f LSB".format(
            session.boundLsb, session.curvePoints, rebuilds, meteringResults, worstReadbackBound * 255.0,
        )
}
