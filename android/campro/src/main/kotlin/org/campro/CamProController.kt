package org.campro

import kotlin.math.abs
import kotlin.math.max

/**
 * The deployment logic of the sample app, free of Android types so host tests reach it.
 *
 * With CamPro on, frames run with `CONTROL_AWB_MODE_OFF`, `COLOR_CORRECTION_MODE_TRANSFORM_MATRIX`
 * and `TONEMAP_MODE_CONTRAST_CURVE`. AWB being off, the device no longer estimates the
 * light, so each repeating burst of [meteringInterval] frames ends with [meteringRun]
 * metering frames in auto mode (AWB on) that never reach the app. A run, not one frame:
 * switching AWB into AUTO resets its state to INACTIVE, so a conforming device can report
 * CONVERGED only from a later AUTO frame of the run. Its `CaptureResult` gives the device's
 * current `COLOR_CORRECTION_TRANSFORM` and `COLOR_CORRECTION_GAINS` ([onMeteringResult]); the
 * protected request is rebuilt only when the native skip rule or the gains say the change
 * matters.
 *
 * Metering adapts ([runEnded]): a run that saw no CONVERGED result doubles the run (up to
 * [maxRun]: an AWB that settles over 20 frames still converges, instead of the values
 * freezing at the first metering); [stableRunsToWiden] converged runs in a row that changed
 * nothing double the interval (up to [maxInterval] frames: fewer holes in a steady scene); a
 * rebuild brings the interval back to [baseInterval]. The interval is always at least four
 * runs, so at most a quarter of the frames meter.
 *
 * Hysteresis: a gain rebuilds the request only when it moved more than [gainTolerance]
 * (relative) from the gain *sent*, not from the last one seen, so an AWB that jitters
 * within the band never rebuilds (each rebuild closes the preview until a result of the new
 * request verifies), and a slow drift rebuilds once it has moved that far.
 */
class CamProController(
    val session: CamProSession,
    /** Frames of the repeating burst at the start and after each rebuild (> 4 x [baseRun]). */
    val baseInterval: Int = 30,
    /** Metering frames a burst at the start (>= 1): 3 of 30, a tenth of the frames. */
    val baseRun: Int = 3,
    /**
     * Relative change of a white-balance gain, from the one sent, that rebuilds the request.
     * 2%: a white-balance error under it is about 1 CIELAB unit on a grey, below what a
     * viewer sees; the protection (transform and curve) does not depend on it.
     */
    val gainTolerance: Float = 0.02f,
    /** Longest metering run (frames). */
    val maxRun: Int = 24,
    /** Longest burst (frames): 8 s at 30 fps. */
    val maxInterval: Int = 240,
    /** Converged runs in a row without a rebuild after which the interval doubles. */
    val stableRunsToWiden: Int = 3,
) {
    init {
        require(baseRun >= 1) { "baseRun must be >= 1, got $baseRun" }
        require(baseInterval >= 4 * baseRun) { "baseInterval must be >= 4 x baseRun ($baseRun), got $baseInterval" }
        require(maxRun >= baseRun) { "maxRun must be >= baseRun, got $maxRun" }
        require(maxInterval >= maxOf(baseInterval, 4 * maxRun)) { "maxInterval must be >= baseInterval and 4 x maxRun, got $maxInterval" }
        require(stableRunsToWiden >= 1) { "stableRunsToWiden must be >= 1, got $stableRunsToWiden" }
        require(gainTolerance >= 0f && gainTolerance.isFinite()) { "gainTolerance must be finite and >= 0, got $gainTolerance" }
    }

    /** Metering frames at the end of each burst now. */
    var meteringRun = baseRun
        private set

    /** Frames of the repeating burst now. */
    var meteringInterval = baseInterval
        private set

    private var stableRuns = 0

    /**
     * A metering run ended: whether it saw a CONVERGED result and whether that rebuilt the
     * request. Returns whether the plan ([meteringRun], [meteringInterval]) changed, so the
     * burst must be sent again.
     */
    fun runEnded(converged: Boolean, rebuilt: Boolean): Boolean {
        val run = meteringRun
        val interval = meteringInterval
        when {
            !converged -> {
                stableRuns = 0
                meteringRun = minOf(2 * meteringRun, maxRun)
                meteringInterval = maxOf(meteringInterval, 4 * meteringRun)
            }
            rebuilt -> {
                stableRuns = 0
                meteringInterval = maxOf(baseInterval, 4 * meteringRun)
            }
            ++stableRuns >= stableRunsToWiden -> {
                stableRuns = 0
                meteringInterval = minOf(2 * meteringInterval, maxInterval)
            }
        }
        return run != meteringRun || interval != meteringInterval
    }

    /** Back to the starting plan (a new start). */
    fun resetPlan() {
        meteringRun = baseRun
        meteringInterval = baseInterval
        stableRuns = 0
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
