package org.campro

/**
 * The pixel probe: proof, from pixels, that the camera applies the colour transform and the
 * tone curve it is sent, before any frame is called Protected. A result only says what the
 * device *reports* it applied; a HAL that echoes the request while applying its own curve
 * passes every result check and leaks every frame. Two short probe phases, on the protected
 * stream itself (the stream the app sees: vendor HALs may process streams of other sizes in
 * other passes; its probe frames never reach the app), make that impossible to miss:
 *
 * 1. [Step.Curve]: CamPro's transform and gains with a **constant** curve at [CURVE_LEVEL].
 *    A device that applies it gives a flat frame whatever the scene (no scene detail, no
 *    noise: everything maps to one code); one that applies its own curve shows the scene.
 * 2. [Step.Matrix]: a **near-zero** transform ([MATRIX_DIAGONAL] on the diagonal: invertible,
 *    so a HAL that refuses singular matrices and applies the identity instead is not falsely
 *    refused) with the curve `y = MATRIX_LEVEL + (1 - MATRIX_LEVEL) x`. A device that applies
 *    the transform gives a flat frame at the curve's start (every linear value times 1/256
 *    moves the output by at most half an 8-bit code); one that ignores it shows the scene.
 *
 * Both frames must be flat (the [FLAT_WINDOW] codes around the most common luma value hold at
 * least [FLAT_SHARE] of the samples), and the second must be at least [MIN_STEP] luma codes
 * brighter than the first (a device that applies neither, on a flat scene, gives the same
 * level twice). Luma is what every YUV stream carries per pixel; a flat RGB frame is flat
 * in luma under any YUV matrix and range, and 0.25 → 0.5 is 64 codes in full range and 55
 * in limited range, so [MIN_STEP] holds for both.
 *
 * A frame counts only when its own result reports the probe's settings (AWB off, the two
 * modes, the probe's curve; the near-zero transform for [Step.Matrix]): a device with latency
 * shows earlier settings for a few frames, and those frames say nothing.
 *
 * The probe runs at every start and physical camera, and again every
 * [CamProPipeline.reprobeInterval] protected frames in the metering slots of the repeating
 * burst (a mode switch such as HDR or low-light binning happens mid-session), so a device
 * that stops following is caught within that interval.
 *
 * Black frames at both steps (at most [BLACK_MAX]: a device applying the constant curve gives
 * about 64 whatever the scene) are the camera privacy toggle or a sensor that stopped: the
 * camera is `Stopped`, not `Unsupported`, and the probe goes on until real frames come.
 *
 * What it cannot prove: a per-pixel stage acting between the transform and the curve (the
 * scene is unknown, so no probe of it can predict the curve's input), and a HAL that recognises probe requests and treats them differently
 * from protected ones (adversarial firmware; out of scope: the camera's firmware is trusted
 * to be what it reports, the probe catches the ones that are not conforming by accident).
 * A scene that is flat to begin with (lens covered) passes step 2 whatever the transform;
 * step 1's level and the step between them are still checked.
 *
 * Plain Kotlin, free of Android types; [CamProPipeline] runs it, the glue feeds it luma.
 */
object PixelProbe {
    /** The two probe phases, in order. */
    enum class Step { Curve, Matrix }

    /** Output level of [Step.Curve]'s constant curve (0..1). */
    const val CURVE_LEVEL = 0.25f

    /** Output level of [Step.Matrix]'s curve at 0 (what a zero transform gives). */
    const val MATRIX_LEVEL = 0.5f

    /** Luma codes either side of the most common value that count as that level. */
    const val FLAT_WINDOW = 2

    /** Share of samples a flat frame holds within [FLAT_WINDOW] of its level. */
    const val FLAT_SHARE = 0.98

    /** Luma codes [Step.Matrix]'s level must exceed [Step.Curve]'s by. */
    const val MIN_STEP = 30

    /** The diagonal of [Step.Matrix]'s transform, as a Camera2 rational (1/256; the rest zero). */
    const val MATRIX_DIAGONAL_DENOMINATOR = 256

    /** Highest luma level of a black frame (limited-range black is 16); the constant curve's level is about 64. */
    const val BLACK_MAX = 24

    /** Fewest luma samples a probe frame must carry. */
    const val MIN_SAMPLES = 64

    /** The transform a probe step sends: CamPro's [protectedTransform] for the curve step, the near-zero diagonal for the matrix step. */
    fun transform(step: Step, protectedTransform: IntArray): IntArray = when (step) {
        Step.Curve -> protectedTransform.copyOf()
        Step.Matrix -> IntArray(18) { i ->
            val entry = i / 2
            when {
                i % 2 == 1 -> if (entry % 4 == 0) MATRIX_DIAGONAL_DENOMINATOR else 1
                entry % 4 == 0 -> 1 // the diagonal: entries 0, 4 and 8
                else -> 0
            }
        }
    }

    /** The curve a probe step sends (flat (Pin, Pout) pairs). */
    fun curve(step: Step): FloatArray = when (step) {
        Step.Curve -> floatArrayOf(0f, CURVE_LEVEL, 1f, CURVE_LEVEL)
        Step.Matrix -> floatArrayOf(0f, MATRIX_LEVEL, 1f, 1f)
    }

    /** Whether [r] reports that the device applied [step]'s settings (else its frame says nothing). */
    fun reportsStep(step: Step, r: CaptureReport): Boolean {
        if (r.awbMode != DeviceSupport.CONTROL_AWB_MODE_OFF) return false
        if (r.colorCorrectionMode != ProtectionGuard.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX) return false
        if (r.tonemapMode != DeviceSupport.TONEMAP_MODE_CONTRAST_CURVE) return false
        val curves = r.curves ?: return false
        val want = curve(step)
        for (c in curves) {
            if (c.size < 4 || c.size % 2 != 0) return false
            // Every reported point lies on the sent curve (a device may resample it).
            for (i in 0 until c.size / 2) {
                val x = c[2 * i]
                val y = want[1] + (want[3] - want[1]) * x
                if (!(kotlin.math.abs(c[2 * i + 1] - y) <= 1e-3f)) return false
            }
        }
        if (step == Step.Matrix) {
            // Every reported entry is the near-zero transform's (within a HAL's rounding: at
            // most 1/128 from it, far from the identity and from any auto-mode matrix).
            val t = r.transform ?: return false
            if (t.size != 18) return false
            val want = transform(Step.Matrix, IntArray(18))
            for (e in 0 until 9) {
                if (t[2 * e + 1] == 0) return false
                val got = t[2 * e].toDouble() / t[2 * e + 1]
                val w = want[2 * e].toDouble() / want[2 * e + 1]
                if (!(kotlin.math.abs(got - w) <= 1.0 / 128)) return false
            }
        }
        return true
    }

    /**
     * The level of a flat frame: the mean luma of the ±[FLAT_WINDOW] window that holds the
     * most samples, when it holds at least [FLAT_SHARE] of them; `null` when the frame shows
     * detail (or carries fewer than [MIN_SAMPLES] samples).
     */
    fun flatLevel(luma: ByteArray): Int? {
        if (luma.size < MIN_SAMPLES) return null
        val hist = IntArray(256)
        for (v in luma) hist[v.toInt() and 255]++
        var best = -1
        var bestCount = -1
        for (centre in 0 until 256) {
            var n = 0
            for (v in maxOf(0, centre - FLAT_WINDOW)..minOf(255, centre + FLAT_WINDOW)) n += hist[v]
            if (n > bestCount) { best = centre; bestCount = n }
        }
        if (bestCount < FLAT_SHARE * luma.size) return null
        // The level: the window's mean, rounded (the first window of the most samples).
        var sum = 0L
        for (v in maxOf(0, best - FLAT_WINDOW)..minOf(255, best + FLAT_WINDOW)) sum += v.toLong() * hist[v]
        return ((2 * sum + bestCount) / (2 * bestCount)).toInt()
    }

    /**
     * What [Step.Curve]'s frame (level [curveLevel] or `null`: not flat) and [Step.Matrix]'s
     * ([matrixLevel]) say: `null` when the pixels follow, else why not.
     */
    fun verdict(curveLevel: Int?, matrixLevel: Int?): String? = when {
        curveLevel == null ->
            "a frame sent with a constant tone curve showed scene detail: the device does not apply the requested TONEMAP_CURVE to its pixels"
        matrixLevel == null ->
            "a frame sent with a near-zero COLOR_CORRECTION_TRANSFORM showed scene detail: the device does not apply the requested transform to its pixels"
        matrixLevel - curveLevel < MIN_STEP ->
            "the probe's curve levels ${CURVE_LEVEL} and ${MATRIX_LEVEL} came out as luma $curveLevel and $matrixLevel: the device's pixels do not follow the requested curve"
        else -> null
    }

    /** Pixels between luma samples along each axis of a probe frame's Y plane (a 320 x 240 frame gives 4,800 samples). */
    const val SAMPLE_STEP = 4

    /**
     * Luma samples of a YUV image's Y plane ([buffer] from its position, [rowStride] and
     * [pixelStride] in bytes, as `Image.Plane` and CameraX's `PlaneProxy` give them): every
     * [step]-th pixel of every [step]-th row of a [width] x [height] image. Reads absolute
     * positions only; a plane shorter than its strides say gives fewer samples.
     */
    fun lumaOfPlane(buffer: java.nio.ByteBuffer, width: Int, height: Int, rowStride: Int, pixelStride: Int, step: Int = SAMPLE_STEP): ByteArray {
        require(width >= 0 && height >= 0 && rowStride >= 1 && pixelStride >= 1 && step >= 1) {
            "bad plane geometry: $width x $height, row stride $rowStride, pixel stride $pixelStride, step $step"
        }
        val out = java.io.ByteArrayOutputStream((width / step + 1) * (height / step + 1))
        val base = buffer.position()
        for (y in 0 until height step step) for (x in 0 until width step step) {
            val i = base.toLong() + y.toLong() * rowStride + x.toLong() * pixelStride
            if (i < buffer.limit()) out.write(buffer.get(i.toInt()).toInt())
        }
        return out.toByteArray()
    }
}
