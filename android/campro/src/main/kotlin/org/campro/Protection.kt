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

    /** The last protected result shows the device did not apply CamPro: [reason] says how. */
    data class Violated(val reason: String) : ProtectionState()

    /** The camera cannot run CamPro at all (final): [reason] says why. */
    data class Unsupported(val reason: String) : ProtectionState()
}

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
)

/**
 * The fail-closed rule, free of Android types (host-tested on scripted result sequences).
 *
 * Feed it the result of every protected request ([onProtectedResult]; metering frames in
 * auto mode never reach consumers and are not fed). A result passes when AWB is off,
 * the colour-correction mode is TRANSFORM_MATRIX, the tone-map mode is CONTRAST_CURVE,
 * and the reported transform and all three curves read back, through the Rust core's
 * [CamProNative.readback], within [maxDeviationLsb] 8-bit LSB of what was requested.
 *
 * A missing read-back key counts as a violation: a device that does not say what it
 * applied cannot be shown to protect. [trustMissingKeys] lets an app accept such a device
 * anyway; it then trusts that the device applied the request it acknowledged in the
 * modes, which a device that ignores `COLOR_CORRECTION_TRANSFORM` or `TONEMAP_CURVE`
 * silently breaks: unprotected faces would then reach the app. Modes must still read back.
 */
class ProtectionGuard(
    private val session: CamProSession,
    /** Largest output deviation accepted, 8-bit LSB (the conversion's own bound is far below 0.5). */
    val maxDeviationLsb: Double = 0.5,
    /** Accept results that leave out the transform or the curve (see the class doc: this risks unprotected frames). */
    val trustMissingKeys: Boolean = false,
) {
    init {
        require(maxDeviationLsb.isFinite() && maxDeviationLsb >= 0.0) { "maxDeviationLsb must be finite and >= 0, got $maxDeviationLsb" }
    }

    /** The current state. */
    @Volatile
    var state: ProtectionState = ProtectionState.Verifying
        private set

    /** Whether frames may reach the app's consumers now. */
    val framesAllowed: Boolean get() = state == ProtectionState.Protected

    /** The largest deviation a checked result showed, 8-bit LSB. */
    var worstDeviationLsb = 0.0
        private set

    private val out = DoubleArray(CamProNative.READBACK_LEN)

    /** The camera cannot run CamPro (from [DeviceSupport.check]): final. */
    fun unsupported(reason: String) {
        state = ProtectionState.Unsupported(reason)
    }

    /** The request changed (new values sent): nothing is protected until a result of it verifies. */
    fun requestChanged() {
        if (state !is ProtectionState.Unsupported) state = ProtectionState.Verifying
    }

    /** Checks one protected result; returns the new state. */
    fun onProtectedResult(r: CaptureReport): ProtectionState {
        if (state is ProtectionState.Unsupported) return state
        val reason = violation(r)
        state = if (reason == null) ProtectionState.Protected else ProtectionState.Violated(reason)
        return state
    }

    /** Why [r] does not show protection, or null when it does. */
    private fun violation(r: CaptureReport): String? {
        when {
            r.awbMode == null && !trustMissingKeys -> return "the result does not report CONTROL_AWB_MODE"
            r.awbMode != null && r.awbMode != DeviceSupport.CONTROL_AWB_MODE_OFF ->
                return "auto white balance is on (mode ${r.awbMode}): the device overrides the colour transform"
            r.colorCorrectionMode == null && !trustMissingKeys -> return "the result does not report COLOR_CORRECTION_MODE"
            r.colorCorrectionMode != null && r.colorCorrectionMode != COLOR_CORRECTION_MODE_TRANSFORM_MATRIX ->
                return "colour correction mode ${r.colorCorrectionMode} instead of TRANSFORM_MATRIX"
            r.tonemapMode == null && !trustMissingKeys -> return "the result does not report TONEMAP_MODE"
            r.tonemapMode != null && r.tonemapMode != DeviceSupport.TONEMAP_MODE_CONTRAST_CURVE ->
                return "tone-map mode ${r.tonemapMode} instead of CONTRAST_CURVE"
        }
        val transform = r.transform
        val curves = r.curves
        if (transform == null || curves == null) {
            if (trustMissingKeys) return null
            return "the result does not report " + (if (transform == null) "COLOR_CORRECTION_TRANSFORM" else "TONEMAP_CURVE") +
                ": what the device applied cannot be verified"
        }
        if (transform.size != 18) return "COLOR_CORRECTION_TRANSFORM has ${transform.size} values, not 18"
        if (curves.size != 3) return "TONEMAP_CURVE has ${curves.size} channels, not 3"
        var worst = 0.0
        for ((c, curve) in curves.withIndex()) {
            val bound = try {
                synchronized(session) {
                    CamProNative.readback(session.transform, session.curve, 2 * session.curvePoints, transform, curve, curve.size, out)
                }
                out[CamProNative.READBACK_BOUND] * 255.0
            } catch (e: IllegalArgumentException) {
                return "the reported values do not read back (${e.message})"
            }
            worst = maxOf(worst, bound)
            if (!(bound <= maxDeviationLsb)) {
                val what = if (out[CamProNative.READBACK_MATRIX_MAX_ABS] * 255.0 > maxDeviationLsb / 2) "transform" else "curve"
                return "the reported $what differs from the request (channel ${"RGB"[c]}): up to %.3f LSB, more than %.3f".format(bound, maxDeviationLsb)
            }
        }
        worstDeviationLsb = maxOf(worstDeviationLsb, worst)
        return null
    }

    companion object {
        /** `CameraMetadata.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX`. */
        const val COLOR_CORRECTION_MODE_TRANSFORM_MATRIX = 0
    }
}

/**
 * Holds each frame until its own result has been checked, so a frame the device did not
 * protect never reaches a consumer, even when the violation shows up only in that frame's
 * result. Frames and results are matched by sensor timestamp; a frame whose result never
 * arrives is dropped once [capacity] newer frames wait. Free of Android types: `T` is an
 * `android.media.Image` on a phone (closed through [drop]) and anything in tests.
 */
class FrameGate<T>(
    private val guard: ProtectionGuard,
    /** Frames waiting for their result, at most. */
    val capacity: Int = 4,
    /** Called with each frame that may reach the app. */
    private val deliver: (T) -> Unit,
    /** Called with each frame that must not (an Image is closed here). */
    private val drop: (T) -> Unit,
) {
    private val waiting = LinkedHashMap<Long, T>()
    private val verdicts = LinkedHashMap<Long, Boolean>()

    init {
        require(capacity >= 1) { "capacity must be >= 1, got $capacity" }
    }

    /** Frames delivered and dropped so far. */
    var delivered = 0L
        private set
    var dropped = 0L
        private set

    /** A frame arrived (sensor timestamp [timestampNs]). */
    @Synchronized
    fun onFrame(timestampNs: Long, frame: T) {
        val verdict = verdicts.remove(timestampNs)
        if (verdict != null) return release(frame, verdict)
        waiting[timestampNs] = frame
        while (waiting.size > capacity) {
            val oldest = waiting.keys.first()
            release(waiting.remove(oldest)!!, false)
        }
    }

    /** The result of the protected frame at [timestampNs] arrived: checks it and releases that frame. */
    @Synchronized
    fun onResult(timestampNs: Long, report: CaptureReport): ProtectionState {
        val state = guard.onProtectedResult(report)
        val ok = state == ProtectionState.Protected
        val frame = waiting.remove(timestampNs)
        if (frame != null) {
            release(frame, ok)
        } else {
            verdicts[timestampNs] = ok
            while (verdicts.size > capacity) verdicts.remove(verdicts.keys.first())
        }
        return state
    }

    /** Drops every waiting frame (the session stopped). */
    @Synchronized
    fun clear() {
        for (f in waiting.values) release(f, false)
        waiting.clear()
        verdicts.clear()
    }

    private fun release(frame: T, ok: Boolean) {
        if (ok) {
            delivered++
            deliver(frame)
        } else {
            dropped++
            drop(frame)
        }
    }
}
