package org.campro

/**
 * Whether the camera is protecting, decided from every protected frame's `CaptureResult`.
 * A privacy camera fails closed: frames reach the app only while [Protected].
 */
sealed class ProtectionState {
    /** No protected result has been checked yet (after start, or after the request changed). */
    object Verifying : ProtectionState() {
        override fun toString() = "Verifying"
    }

    /** The last protected result read back the transform and curve within the bound, with every mode as requested. */
    object Protected : ProtectionState() {
        override fun toString() = "Protected"
    }

    /**
     * The last result read back the values within the bound, as for [Protected], but the
     * parameter set is not protective ([CamProSession.protective]: no protection rating in
     * its provenance, e.g. `identity` or an app's own JSON): frames flow and faces are NOT
     * hidden. Reached only through an explicit opt-in (`CamProOptions.allowUnprotective`).
     */
    object Applied : ProtectionState() {
        override fun toString() = "Applied"
    }

    /** The last protected result shows the device did not apply CamPro: [reason] says how (for people), [problem] what kind (for code). */
    data class Violated(val reason: String, val problem: Problem = Problem.Other) : ProtectionState()

    /** The camera cannot run CamPro at all (final): [reason] says why, [problem] what kind. */
    data class Unsupported(val reason: String, val problem: Problem = Problem.Other) : ProtectionState()

    /**
     * The camera is not running: never opened, closed, disconnected, failed, or the
     * permission was refused; [reason] says which, [problem] what kind. Not final: a new
     * start verifies again.
     */
    data class Stopped(val reason: String, val problem: Problem = Problem.Other) : ProtectionState()
}

/** What kind of problem a [ProtectionState] names: for code to act on (the reason is for people). */
enum class Problem {
    /** The camera lacks what CamPro needs (MANUAL_POST_PROCESSING, CONTRAST_CURVE, per-frame sync, a YUV size), or there is no such camera. */
    DeviceCapability,

    /** The pixel probe saw the device's pixels not follow the values it reports. */
    PixelProbe,

    /** Results leave out a key CamPro must read back (transform, curve, gains, AWB state). */
    MissingKey,

    /** The device applies other values or modes than sent (off the preset's grids). */
    Deviation,

    /** The active physical camera of a logical camera changed (metering runs again). */
    PhysicalCamera,

    /** Frames and results do not match (the images' timestamp base is not the sensor's). */
    Timestamps,

    /** The preset: not protective without the opt-in, a grid it was not measured on, not found. */
    Preset,

    /** The camera permission is not granted. */
    Permission,

    /** Black frames: the camera privacy toggle is on, or the sensor stopped (the probe goes on). */
    PrivacyToggle,

    /** The camera closed, was disconnected or taken, or the app stopped or paused it. */
    CameraClosed,

    /** Anything else: an exception from the camera or native code, a refused setting. */
    Other,
}

/**
 * A grid a phone's HAL may put CamPro's values on: matrix entries rounded to [MatrixBits.bits]
 * fractional bits (`qB`), or each curve resampled to [CurvePoints.points] evenly spaced points
 * (`lutN`). A preset records the grids its protection was measured to hold on
 * (`provenance.protection.device_grids.held`, `campro check` with `--matrix-frac-bits` /
 * `--lut-size`); the guard accepts a device whose reported values differ from the request by
 * one such grid and nothing else, however large the readback's bound (Q7 states 57 LSB for
 * `campro-omega-0.5`, yet its faces stay as hidden as with exact values, while a 17-point
 * curve, 92 LSB, lets 104 of 119 through: the bound says nothing about which).
 */
sealed class DeviceGrid {
    /** Matrix entries rounded to [bits] fractional bits (1..24). */
    data class MatrixBits(val bits: Int) : DeviceGrid() {
        override fun toString() = "q$bits"
    }

    /** Each curve resampled to [points] evenly spaced points (2..4096). */
    data class CurvePoints(val points: Int) : DeviceGrid() {
        override fun toString() = "lut$points"
    }

    companion object {
        /** `qB` or `lutN`; `null` for anything else or out of range. */
        @JvmStatic
        fun parse(s: String): DeviceGrid? = when {
            s.startsWith("q") -> s.substring(1).toIntOrNull()?.takeIf { it in 1..24 }?.let { MatrixBits(it) }
            s.startsWith("lut") -> s.substring(3).toIntOrNull()?.takeIf { it in 2..4096 }?.let { CurvePoints(it) }
            else -> null
        }

        /** A comma-separated list (what the native side gives); names that do not parse are left out. */
        fun parseList(s: String): Set<DeviceGrid> = s.split(',').mapNotNull { parse(it.trim()) }.toSet()

        /**
         * Whether [reported] is [requested] (18 ints: numerator, denominator pairs) with every
         * entry rounded to a multiple of 2^-[bits]: each reported entry on that grid and within
         * half a step (and float rounding) of the requested one.
         */
        fun matrixOnGrid(requested: IntArray, reported: IntArray, bits: Int): Boolean {
            if (requested.size != 18 || reported.size != 18) return false
            val scale = Math.scalb(1.0, bits)
            for (e in 0 until 9) {
                if (requested[2 * e + 1] == 0 || reported[2 * e + 1] == 0) return false
                val want = requested[2 * e].toDouble() / requested[2 * e + 1]
                val got = reported[2 * e].toDouble() / reported[2 * e + 1]
                val steps = got * scale
                if (kotlin.math.abs(steps - Math.rint(steps)) > 1e-9 * maxOf(1.0, kotlin.math.abs(steps))) return false
                if (kotlin.math.abs(got - want) > 0.5 / scale + 1e-12) return false
            }
            return true
        }

        /**
         * Whether [reported] (flat (Pin, Pout) pairs) is [requested] ([count] floats of flat
         * pairs from [offset]) resampled at [points] evenly spaced inputs: exactly that many
         * points, input i at i/(points-1), each output on the requested curve (within 1e-4).
         */
        fun curveOnGrid(requested: FloatArray, offset: Int, count: Int, reported: FloatArray, points: Int): Boolean {
            if (reported.size != 2 * points || count < 4 || points < 2) return false
            for (i in 0 until points) {
                val x = reported[2 * i]
                if (kotlin.math.abs(x - i.toFloat() / (points - 1)) > 1e-4f) return false
                if (kotlin.math.abs(reported[2 * i + 1] - interpolate(requested, offset, count, x)) > 1e-4f) return false
            }
            return true
        }

        /** The piecewise-linear curve of [count] floats of flat pairs from [offset] at [x] (clamped at its ends). */
        private fun interpolate(c: FloatArray, offset: Int, count: Int, x: Float): Float {
            val n = count / 2
            if (x <= c[offset]) return c[offset + 1]
            for (k in 1 until n) {
                val x1 = c[offset + 2 * k]
                if (x <= x1) {
                    val x0 = c[offset + 2 * k - 2]
                    val y0 = c[offset + 2 * k - 1]
                    val y1 = c[offset + 2 * k + 1]
                    return if (x1 > x0) y0 + (y1 - y0) * (x - x0) / (x1 - x0) else y1
                }
            }
            return c[offset + 2 * n - 1]
        }

        /** Whether [reported] is exactly the requested curve ([count] floats from [offset]), point for point. */
        fun curveExact(requested: FloatArray, offset: Int, count: Int, reported: FloatArray): Boolean =
            reported.size == count && reported.indices.all { kotlin.math.abs(reported[it] - requested[offset + it]) <= 1e-6f }
    }
}

/** Whether the device applies the values as sent: [ProtectionState.Protected] or [ProtectionState.Applied]; frames flow only then. */
val ProtectionState.applied: Boolean get() = this == ProtectionState.Protected || this == ProtectionState.Applied

/**
 * What one `CaptureResult` reported, as plain values: `null` where the key is absent.
 * The Android glue fills it ([org.campro.android.camproReport]); tests script it.
 */
class CaptureReport(
    /** `CONTROL_AWB_MODE`. */
    val awbMode: Int?,
    /** `COLOR_CORRECTION_MODE`. */
    val colorCorrectionMode: Int?,
    /** `TONEMAP_MODE`. */
    val tonemapMode: Int?,
    /** `COLOR_CORRECTION_TRANSFORM`: 18 ints (numerator, denominator pairs). */
    val transform: IntArray?,
    /** `TONEMAP_CURVE` per channel (red, green, blue): flat (Pin, Pout) pairs. */
    val curves: List<FloatArray>?,
    /** `COLOR_CORRECTION_GAINS` as (R, G_even, G_odd, B); `null` when absent. */
    val gains: FloatArray? = null,
    /** `LOGICAL_MULTI_CAMERA_ACTIVE_PHYSICAL_ID`: the physical camera this frame came from (`null`: not a logical camera). */
    val physicalId: String? = null,
)

/**
 * The fail-closed rule, free of Android types (host-tested on scripted result sequences).
 *
 * Feed it the result of every protected request ([onProtectedResult]; metering frames in
 * auto mode never reach consumers and are not fed). A result passes when AWB is off,
 * the colour-correction mode is TRANSFORM_MATRIX, the tone-map mode is CONTRAST_CURVE,
 * the reported transform and all three curves read back, through the Rust core's
 * [CamProNative.readback], within [maxDeviationLsb] 8-bit LSB of what was requested, and
 * the reported white-balance gains match the requested ones within [maxGainRelative].
 *
 * A missing key counts as a violation: a device that does not say what it applied cannot
 * be shown to protect. [trustMissingKeys] lets an app accept a device that leaves out the
 * *values* (transform, curve, gains); it then trusts that the device applied the request it
 * acknowledged in the modes, which a device that ignores `COLOR_CORRECTION_TRANSFORM` or
 * `TONEMAP_CURVE` silently breaks: unprotected faces would then reach the app. The three
 * *modes* must always be reported and right, trusted or not.
 *
 * A strict guard whose device leaves a value key out of [missingKeyLimit] results in a row
 * ends in [ProtectionState.Unsupported]: such a device can never be verified, and saying so
 * beats a preview that stays blank in `Violated` for ever.
 *
 * Thread safety: every method is synchronized; [state] may be read from any thread.
 */
class ProtectionGuard(
    private val session: CamProSession,
    /** Largest output deviation accepted, 8-bit LSB (the conversion's own bound is far below 0.5). */
    val maxDeviationLsb: Double = 0.5,
    /** Accept results that leave out the transform, the curve or the gains (see the class doc: this risks unprotected frames). */
    val trustMissingKeys: Boolean = false,
    /**
     * Largest relative difference between a requested and a reported gain. A gain off by a
     * relative `e` moves a linear value by `e` of itself before the curve: 0.002 is half an
     * 8-bit LSB at full scale, above the float rounding HALs report gains with.
     */
    val maxGainRelative: Double = 0.002,
    /** Results in a row missing a value key after which a strict guard gives up: Unsupported (>= 1). */
    val missingKeyLimit: Int = 30,
    /**
     * Results in a row whose reported values differ from the request (a HAL that rounds the
     * matrix or resamples the curve) after which the guard gives up: Unsupported (>= 1).
     * Such a device never verifies, and saying so beats Violated for ever.
     */
    val deviationLimit: Int = 30,
    /**
     * Grids a device may put the values on ([DeviceGrid]): a result whose values differ from
     * the request beyond [maxDeviationLsb] passes when the difference is exactly one of these
     * (the transform rounded to an accepted `qB` with the curves as sent, or every curve
     * resampled to an accepted `lutN` with the transform as sent). `null`: the session's
     * measured grids ([CamProSession.deviceGrids]).
     */
    deviceGrids: Set<DeviceGrid>? = null,
) {
    init {
        require(maxDeviationLsb.isFinite() && maxDeviationLsb >= 0.0) { "maxDeviationLsb must be finite and >= 0, got $maxDeviationLsb" }
        require(maxGainRelative.isFinite() && maxGainRelative >= 0.0) { "maxGainRelative must be finite and >= 0, got $maxGainRelative" }
        require(missingKeyLimit >= 1) { "missingKeyLimit must be >= 1, got $missingKeyLimit" }
        require(deviationLimit >= 1) { "deviationLimit must be >= 1, got $deviationLimit" }
    }

    /** The current state. */
    @Volatile
    var state: ProtectionState = ProtectionState.Verifying
        private set

    /** The grids accepted ([DeviceGrid]): those asked for, or the session's measured ones. */
    val deviceGrids: Set<DeviceGrid> = deviceGrids ?: session.deviceGrids

    /** Whether the session's parameter set protects faces (read once): verified results read [ProtectionState.Protected] only then, [ProtectionState.Applied] otherwise. */
    val protective: Boolean = session.protective

    /** Whether frames may reach the app's consumers now: the device applies the values as sent (Protected, or Applied for an unprotective set). */
    val framesAllowed: Boolean get() = state.applied

    /** The largest deviation a checked result showed, 8-bit LSB. */
    @Volatile
    var worstDeviationLsb = 0.0
        private set

    private val out = DoubleArray(CamProNative.READBACK_LEN)
    private var requestedGains: FloatArray? = null
    private var requestedPhysicalId: String? = null
    private var missingInARow = 0
    private var deviatingInARow = 0
    private var unmatched: String? = null

    /** What the last violation was: the counters, the pipeline and the app read this, never the message. */
    private var lastKind = Problem.Other

    /** Whether the last violation was reported values off the request (the deviation counter's kind; a wrong mode is not). */
    private var valueDeviation = false

    /** Marks the violation a mode or value deviation ([Problem.Deviation]); returns null so the caller's reason follows. */
    private fun deviates(): String? {
        lastKind = Problem.Deviation
        return null
    }

    /** The camera cannot run CamPro ([problem]: what kind): final. */
    @Synchronized
    fun unsupported(reason: String, problem: Problem = Problem.DeviceCapability) {
        state = ProtectionState.Unsupported(reason, problem)
    }

    /** The camera stopped (closed, disconnected, failed, no permission): closed until a new request verifies. */
    @Synchronized
    fun stopped(reason: String, problem: Problem = Problem.CameraClosed) {
        if (state !is ProtectionState.Unsupported) state = ProtectionState.Stopped(reason, problem)
    }

    /**
     * New values were sent (with these white-balance [gains], R, G_even, G_odd, B; `null`
     * when the request sets none): nothing is protected until a result of it verifies.
     */
    @Synchronized
    fun requestChanged(gains: FloatArray? = null, physicalId: String? = null) {
        require(gains == null || gains.size == 4) { "gains must have 4 elements (R, G_even, G_odd, B), got ${gains?.size}" }
        requestedGains = gains?.copyOf()
        requestedPhysicalId = physicalId
        missingInARow = 0
        deviatingInARow = 0
        unmatched = null
        if (state !is ProtectionState.Unsupported) state = ProtectionState.Verifying
    }

    /**
     * The gate's health ([FrameGate]): [reason] when verified results keep finding no frame
     * (the images' timestamps are not the results' `SENSOR_TIMESTAMP`: a display or readout
     * timestamp base), `null` once a frame matched again. While set, no result verifies:
     * Protected would be a lie with nothing delivered.
     */
    @Synchronized
    fun framesUnmatched(reason: String?) {
        unmatched = reason
        if (reason != null && state.applied) state = ProtectionState.Violated(reason, Problem.Timestamps)
    }

    /** Whether the last violation was the active physical camera changing (the pipeline meters again). */
    val physicalCameraChanged: Boolean @Synchronized get() = state is ProtectionState.Violated && lastKind == Problem.PhysicalCamera

    /** Checks one protected result; returns the new state. */
    @Synchronized
    fun onProtectedResult(r: CaptureReport): ProtectionState {
        // Unsupported is final; Stopped holds until a new request (late results of a stopped camera change nothing).
        if (state is ProtectionState.Unsupported || state is ProtectionState.Stopped) return state
        val own = violation(r)
        val reason = own ?: unmatched
        val kind = if (own != null) lastKind else Problem.Timestamps
        if (reason != null && own != null && valueDeviation) deviatingInARow++ else deviatingInARow = 0
        state = when {
            reason == null -> if (protective) ProtectionState.Protected else ProtectionState.Applied
            missingInARow >= missingKeyLimit -> ProtectionState.Unsupported(
                "$reason in $missingInARow results in a row: this device cannot be verified",
                Problem.MissingKey,
            )
            deviatingInARow >= deviationLimit -> ProtectionState.Unsupported(
                "$reason in $deviatingInARow results in a row: the device does not apply the values as sent (it rounds or resamples them)",
                Problem.Deviation,
            )
            else -> ProtectionState.Violated(reason, kind)
        }
        return state
    }

    /** Why [r] does not show protection, or null when it does. */
    private fun violation(r: CaptureReport): String? {
        lastKind = Problem.MissingKey
        valueDeviation = false
        when {
            r.awbMode == null -> return "the result does not report CONTROL_AWB_MODE"
            r.awbMode != DeviceSupport.CONTROL_AWB_MODE_OFF -> return deviates()
                ?: "auto white balance is on (mode ${r.awbMode}): the device overrides the colour transform"
            r.colorCorrectionMode == null -> return "the result does not report COLOR_CORRECTION_MODE"
            r.colorCorrectionMode != COLOR_CORRECTION_MODE_TRANSFORM_MATRIX -> return deviates()
                ?: "colour correction mode ${r.colorCorrectionMode} instead of TRANSFORM_MATRIX"
            r.tonemapMode == null -> return "the result does not report TONEMAP_MODE"
            r.tonemapMode != DeviceSupport.TONEMAP_MODE_CONTRAST_CURVE -> return deviates()
                ?: "tone-map mode ${r.tonemapMode} instead of CONTRAST_CURVE"
        }
        val wantPhysical = requestedPhysicalId
        if (wantPhysical != null && r.physicalId != null && r.physicalId != wantPhysical) {
            lastKind = Problem.PhysicalCamera
            return "the active physical camera changed from $wantPhysical to ${r.physicalId}: the values were computed for the other sensor"
        }
        val transform = r.transform
        val curves = r.curves
        val wantGains = requestedGains
        val missing = when {
            transform == null -> "COLOR_CORRECTION_TRANSFORM"
            curves == null -> "TONEMAP_CURVE"
            wantGains != null && r.gains == null -> "COLOR_CORRECTION_GAINS"
            else -> null
        }
        if (missing != null && !trustMissingKeys) {
            missingInARow++
            return "the result does not report $missing: what the device applied cannot be verified"
        }
        missingInARow = 0
        val gains = r.gains
        if (wantGains != null && gains != null) {
            if (gains.size != 4) return "COLOR_CORRECTION_GAINS has ${gains.size} values, not 4"
            for (i in 0 until 4) {
                val rel = kotlin.math.abs(gains[i] - wantGains[i]).toDouble() / kotlin.math.max(kotlin.math.abs(wantGains[i]).toDouble(), 1e-6)
                if (!(rel <= maxGainRelative)) {
                    lastKind = Problem.Deviation
                valueDeviation = true
                    return "the reported gain ${GAIN_NAMES[i]} is ${gains[i]}, not the requested ${wantGains[i]}"
                }
            }
        }
        if (transform == null || curves == null) return null // trusted: see trustMissingKeys
        if (transform.size != 18) return "COLOR_CORRECTION_TRANSFORM has ${transform.size} values, not 18"
        if (curves.size != 3) return "TONEMAP_CURVE has ${curves.size} channels, not 3"
        // Which accepted grid the values are on: asked only of a result beyond the bound (the
        // interpolation is not free, and almost every result reads back as sent).
        val grid by lazy(LazyThreadSafetyMode.NONE) { gridOf(transform, curves) }
        var beyond = false
        var worst = 0.0
        for ((c, curve) in curves.withIndex()) {
            val bound = try {
                synchronized(session) {
                    CamProNative.readback(
                        session.transform, session.curve, session.curveOffset(c), 2 * session.curvePoints(c),
                        transform, curve, curve.size, c, out,
                    )
                }
                out[CamProNative.READBACK_BOUND] * 255.0
            } catch (e: IllegalArgumentException) {
                lastKind = Problem.Deviation
                valueDeviation = true
                return "the reported values do not read back (${e.message})"
            }
            worst = maxOf(worst, bound)
            if (!(bound <= maxDeviationLsb)) {
                beyond = true
                if (grid == null) {
                    val what = if (out[CamProNative.READBACK_MATRIX_MAX_ABS] * 255.0 > maxDeviationLsb / 2) "transform" else "curve"
                    lastKind = Problem.Deviation
                    valueDeviation = true
                    return "the reported $what differs from the request (channel ${"RGB"[c]}): up to %.3f LSB, more than %.3f".format(bound, maxDeviationLsb)
                }
            }
        }
        worstDeviationLsb = maxOf(worstDeviationLsb, worst)
        gridSeen = if (beyond) grid else null
        return null
    }

    /** The grid a passing result's values were on, when they differed from the request beyond [maxDeviationLsb] by one; `null`: within it. */
    @Volatile
    var gridSeen: DeviceGrid? = null
        private set

    /**
     * The one accepted grid the reported values differ from the request by, or `null` when
     * they are not on one (as sent, or off by something else: the bound then decides).
     */
    private fun gridOf(transform: IntArray, curves: List<FloatArray>): DeviceGrid? {
        if (deviceGrids.isEmpty()) return null
        synchronized(session) {
            val want = session.transform
            val matrixAsSent = (0 until 9).all { e ->
                transform[2 * e + 1] != 0 && want[2 * e + 1] != 0 &&
                    kotlin.math.abs(transform[2 * e].toDouble() / transform[2 * e + 1] - want[2 * e].toDouble() / want[2 * e + 1]) <= 1e-9
            }
            val curvesAsSent = curves.withIndex().all { (c, curve) -> DeviceGrid.curveExact(session.curve, session.curveOffset(c), 2 * session.curvePoints(c), curve) }
            for (g in deviceGrids) {
                when (g) {
                    is DeviceGrid.MatrixBits -> if (curvesAsSent && DeviceGrid.matrixOnGrid(want, transform, g.bits)) return g
                    is DeviceGrid.CurvePoints -> if (matrixAsSent && curves.withIndex().all { (c, curve) ->
                            DeviceGrid.curveOnGrid(session.curve, session.curveOffset(c), 2 * session.curvePoints(c), curve, g.points)
                        }
                    ) return g
                }
            }
        }
        return null
    }

    companion object {
        /** `CameraMetadata.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX`. */
        const val COLOR_CORRECTION_MODE_TRANSFORM_MATRIX = 0
        private val GAIN_NAMES = listOf("R", "G_even", "G_odd", "B")
    }
}

/**
 * Holds each frame until its own result has been checked, so a frame the device did not
 * protect never reaches a consumer, even when the violation shows up only in that frame's
 * result. Frames and results are matched by sensor timestamp. Free of Android types: `T`
 * is an `android.media.Image` or `ImageProxy` on a phone (closed through [drop]) and
 * anything in tests.
 *
 * Sizes: a result may arrive up to the camera's pipeline depth
 * (`REQUEST_PIPELINE_MAX_DEPTH`, at most 8 on current devices) frames before its image, and
 * an image before its result by as many frames as the image queue holds. [maxWaitingFrames]
 * frames wait for results (the oldest is dropped beyond it: its result never came) and
 * [maxPendingVerdicts] verdicts wait for frames (the oldest is forgotten beyond it; its
 * frame, if it ever comes, then waits for a result that never comes and is dropped: a
 * verdict store too small drops good frames, never lets a bad one through).
 *
 * Threads: [onFrame] and [onResult] may come from any threads. Frames that pass are handed
 * to [deliver] through [executor] (the app's), after the gate's lock is released, so a slow
 * consumer never blocks the camera thread or the gate; frames that fail are handed to [drop]
 * on the calling thread, also outside the lock.
 */
class FrameGate<T>(
    private val guard: ProtectionGuard,
    /** Frames waiting for their result, at most (>= 1): the image queue depth less one. */
    val maxWaitingFrames: Int = 4,
    /** Verdicts waiting for their frame, at most (>= 1): at least the pipeline depth. */
    val maxPendingVerdicts: Int = 8,
    /** Runs deliveries (the app's executor; a direct executor in tests). */
    private val executor: java.util.concurrent.Executor,
    /** Called on [executor] with each frame that may reach the app; it owns (and closes) the frame. */
    private val deliver: (T) -> Unit,
    /** Called with each frame that must not (an Image is closed here). */
    private val drop: (T) -> Unit,
) {
    private val waiting = LinkedHashMap<Long, T>()
    private val verdicts = LinkedHashMap<Long, Boolean>()
    /** Timestamps of frames the camera said it lost ([onFrameLost]) whose results have not come yet. */
    private val lost = LinkedHashSet<Long>()
    private var stopped = false
    /** Passing verdicts in a row that found no frame (the health check; see [unmatchedLimit]). */
    private var unmatchedInARow = 0

    /**
     * Passing verdicts in a row forgotten without their frame after which the gate tells the
     * guard that frames and results do not match ([ProtectionGuard.framesUnmatched]): three
     * verdict stores' worth, so that lost or late results alone never trip it.
     */
    val unmatchedLimit: Int get() = 3 * maxPendingVerdicts

    init {
        require(maxWaitingFrames >= 1) { "maxWaitingFrames must be >= 1, got $maxWaitingFrames" }
        require(maxPendingVerdicts >= 1) { "maxPendingVerdicts must be >= 1, got $maxPendingVerdicts" }
    }

    /** Frames delivered and dropped so far. */
    @Volatile
    var delivered = 0L
        private set

    @Volatile
    var dropped = 0L
        private set

    /** A frame arrived (sensor timestamp [timestampNs]). */
    fun onFrame(timestampNs: Long, frame: T) {
        val out = ArrayList<Pair<T, Boolean>>(2)
        synchronized(this) {
            if (stopped) {
                out += frame to false
            } else {
                val verdict = verdicts.remove(timestampNs)
                if (verdict != null) {
                    matched()
                    out += frame to verdict
                } else if (waiting.containsKey(timestampNs)) {
                    // Two frames claim one sensor time: neither can be matched to its own
                    // result, so both are dropped (closed, never leaked, never shown).
                    out += waiting.remove(timestampNs)!! to false
                    out += frame to false
                } else {
                    waiting[timestampNs] = frame
                    while (waiting.size > maxWaitingFrames) {
                        val oldest = waiting.keys.first()
                        out += waiting.remove(oldest)!! to false
                    }
                }
            }
        }
        release(out)
    }

    /**
     * The camera will never deliver the frame at [timestampNs] (`onCaptureBufferLost`: the
     * app holds every buffer of the stream, or the HAL dropped it). Its verdict is then no
     * sign of mismatched timestamps: it is forgotten without counting towards
     * [unmatchedLimit], so an app that holds its frames for a while never reads Violated.
     */
    fun onFrameLost(timestampNs: Long) {
        synchronized(this) {
            if (verdicts.remove(timestampNs) == null) {
                lost += timestampNs
                while (lost.size > maxPendingVerdicts) lost.remove(lost.first())
            }
        }
    }

    /**
     * The capture at [timestampNs] was not a protected one (a probe frame of the burst): its
     * frame is dropped, now if it waits, else when it comes. The guard is not consulted.
     */
    fun reject(timestampNs: Long) {
        val out = ArrayList<Pair<T, Boolean>>(1)
        synchronized(this) {
            val frame = waiting.remove(timestampNs)
            if (frame != null) {
                out += frame to false
            } else if (!stopped) {
                verdicts[timestampNs] = false
                while (verdicts.size > maxPendingVerdicts) verdicts.remove(verdicts.keys.first())
            }
        }
        release(out)
    }

    /** The result of the protected frame at [timestampNs] arrived: checks it and releases that frame. */
    fun onResult(timestampNs: Long, report: CaptureReport): ProtectionState {
        val out = ArrayList<Pair<T, Boolean>>(1)
        val state: ProtectionState
        synchronized(this) {
            state = guard.onProtectedResult(report)
            val ok = state.applied && !stopped
            val frame = waiting.remove(timestampNs)
            if (frame != null) {
                matched()
                out += frame to ok
            } else if (lost.remove(timestampNs)) {
                // Its frame was lost: the verdict has nothing to release.
            } else if (!stopped) {
                verdicts[timestampNs] = ok
                while (verdicts.size > maxPendingVerdicts) {
                    if (verdicts.remove(verdicts.keys.first()) == true && ++unmatchedInARow >= unmatchedLimit) {
                        guard.framesUnmatched(
                            "$unmatchedInARow verified results in a row matched no frame: the images' timestamps are not the results' SENSOR_TIMESTAMP (the output's timestamp base), so no frame can be shown",
                        )
                    }
                }
            }
        }
        release(out)
        return state
    }

    /** A frame met its verdict: the gate is healthy. Called under the gate's lock. */
    private fun matched() {
        if (unmatchedInARow >= unmatchedLimit) guard.framesUnmatched(null)
        unmatchedInARow = 0
    }

    /** Drops every waiting frame and forgets every verdict (the request changed or the camera stopped). */
    fun clear() {
        val out: List<Pair<T, Boolean>>
        synchronized(this) {
            out = waiting.values.map { it to false }
            waiting.clear()
            verdicts.clear()
            lost.clear()
        }
        release(out)
    }

    /** Drops everything now and every frame from now on: the gate is finished. */
    fun stop() {
        synchronized(this) { stopped = true }
        clear()
    }

    private fun release(frames: List<Pair<T, Boolean>>) {
        for ((frame, ok) in frames) {
            val sent = ok && try {
                executor.execute { deliver(frame) }
                true
            } catch (e: java.util.concurrent.RejectedExecutionException) {
                false // the app's executor is shut down: the frame is closed here, never leaked
            }
            synchronized(this) { if (sent) delivered++ else dropped++ }
            if (!sent) drop(frame)
        }
    }
}
