package org.campro

/**
 * A CamPro parameter set deployed on one Camera2 camera: load it once, call an update
 * per frame (or per auto-mode metering result), send [transform] and [curve] when an
 * update returns `true`. Close it (or use `use {}`) to free the native state.
 *
 * Per update nothing is allocated: the native side writes into this object's arrays.
 * Thread safety: every method is synchronized on the session, so one session may be
 * shared between the camera callback thread and the UI; the arrays are only consistent
 * when read under `synchronized(session)` or from the thread that called the update.
 */
class CamProSession private constructor(
    private var handle: Long,
    maxCurvePoints: Int,
) : AutoCloseable {
    /** `COLOR_CORRECTION_TRANSFORM` to send: nine (numerator, denominator) pairs, row-major. */
    val transform = IntArray(18)

    /**
     * `TONEMAP_CURVE` to send, packed: channel c (0 red, 1 green, 2 blue) from [curveOffset]
     * with [curvePoints] `(c)` (Pin, Pout) pairs. A parameter set with one curve has the same
     * three; a version 2 set has its own per channel.
     */
    var curve = FloatArray(3 * 2 * maxCurvePoints)
        private set

    /** What the last update achieved; slots are `CamProNative.REPORT_*`. */
    val report = DoubleArray(CamProNative.REPORT_LEN)

    /** The device's `TONEMAP_MAX_CURVE_POINTS` this session fits the curve to. */
    var maxCurvePoints = maxCurvePoints
        private set

    /** The most (Pin, Pout) points of any channel in [curve]. */
    val curvePoints: Int get() = report[CamProNative.REPORT_CURVE_POINTS].toInt()

    /** (Pin, Pout) points of [channel] (0 red, 1 green, 2 blue) in [curve]. */
    fun curvePoints(channel: Int): Int = report[CamProNative.REPORT_CURVE_POINTS_RED + channel].toInt()

    /** Where [channel]'s pairs start in [curve]. */
    fun curveOffset(channel: Int): Int = 2 * maxCurvePoints * channel

    /** Guaranteed bound on |device - desktop pipeline| for the last update, output units (1 = full scale). */
    val bound: Double get() = report[CamProNative.REPORT_BOUND]

    /** [bound] in 8-bit LSB. */
    val boundLsb: Double get() = bound * 255.0

    val isClosed: Boolean @Synchronized get() = handle == 0L

    /**
     * Whether the parameter set protects faces: its provenance holds a protection rating
     * whose worst measured top-1 is within `campro::provenance::PROTECTIVE_TOP1` (15%).
     * Hand-made sets (`identity`, `srgb-passthrough`, `color-inversion`) and JSON without the
     * rating are not: a camera with them reads [ProtectionState.Applied], never Protected.
     */
    val protective: Boolean @Synchronized get() = CamProNative.protective(live())

    /**
     * The grids a phone's HAL may put this set's values on with its protection measured to
     * hold there (the preset's `protection.device_grids.held`; docs/android.md, "Grids"):
     * none for a set that is not protective.
     */
    val deviceGrids: Set<DeviceGrid> @Synchronized get() = DeviceGrid.parseList(CamProNative.deviceGrids(live()))

    /** One frame from the device's own `COLOR_CORRECTION_TRANSFORM` (18 ints, as `ColorSpaceTransform.copyElements` gives). Returns whether the values changed. */
    @Synchronized
    fun updateFromTransform(deviceTransform: IntArray): Boolean =
        CamProNative.updateFromTransform(live(), deviceTransform, transform, curve, report)

    /** One frame from a colour temperature in kelvin (needs [setDngCalibration] or a parameter set with `ct_calibration`). */
    @Synchronized
    fun updateFromColorTemperature(kelvin: Double): Boolean =
        CamProNative.updateFromColorTemperature(live(), kelvin, transform, curve, report)

    /** The device's `TONEMAP_MAX_CURVE_POINTS`; the next update recomputes. */
    @Synchronized
    fun setMaxCurvePoints(n: Int) {
        CamProNative.setMaxCurvePoints(live(), n)
        if (n != maxCurvePoints) {
            curve = FloatArray(3 * 2 * n)
            maxCurvePoints = n
        }
    }

    /** `SENSOR_REFERENCE_ILLUMINANT1/2` and `SENSOR_FORWARD_MATRIX1/2` (18 ints each). */
    @Synchronized
    fun setDngCalibration(illuminant1: Int, forwardMatrix1: IntArray, illuminant2: Int, forwardMatrix2: IntArray) =
        CamProNative.setDngCalibration(live(), illuminant1, forwardMatrix1, illuminant2, forwardMatrix2)

    /** The red, green and blue curves with exactly their pairs, as `TonemapCurve`'s constructor wants them (allocates; call when an update returned `true`). */
    @Synchronized
    fun curvesForRequest(): Array<FloatArray> =
        Array(3) { c -> curve.copyOfRange(curveOffset(c), curveOffset(c) + 2 * curvePoints(c)) }

    /** Frees the native state; further calls throw [IllegalStateException]. Idempotent. */
    @Synchronized
    override fun close() {
        if (handle != 0L) {
            val h = handle
            handle = 0L
            CamProNative.close(h)
        }
    }

    private fun live(): Long {
        check(handle != 0L) { "CamProSession is closed" }
        return handle
    }

    companion object {
        /** Android guarantees at least 64 curve points where CONTRAST_CURVE exists. */
        const val DEFAULT_MAX_CURVE_POINTS = 64
        /** Denominator bound of the rationals (2^16: entry error <= 7.6e-6). */
        const val DEFAULT_MAX_DENOMINATOR = 65536
        /** Extra error a skipped update may cost: a quarter of an 8-bit LSB. */
        const val DEFAULT_SKIP_TOLERANCE = 0.25 / 255.0

        fun fromJson(
            json: String,
            maxCurvePoints: Int = DEFAULT_MAX_CURVE_POINTS,
            maxDenominator: Int = DEFAULT_MAX_DENOMINATOR,
            skipTolerance: Double = DEFAULT_SKIP_TOLERANCE,
        ) = CamProSession(CamProNative.ensureLoaded().let { CamProNative.create(json, maxCurvePoints, maxDenominator, skipTolerance) }, maxCurvePoints)

        fun fromBytes(
            json: ByteArray,
            maxCurvePoints: Int = DEFAULT_MAX_CURVE_POINTS,
            maxDenominator: Int = DEFAULT_MAX_DENOMINATOR,
            skipTolerance: Double = DEFAULT_SKIP_TOLERANCE,
        ) = CamProSession(CamProNative.ensureLoaded().let { CamProNative.createFromBytes(json, maxCurvePoints, maxDenominator, skipTolerance) }, maxCurvePoints)

        /** [assetManager]: an `android.content.res.AssetManager` (Android only). */
        fun fromAsset(
            assetManager: Any,
            path: String,
            maxCurvePoints: Int = DEFAULT_MAX_CURVE_POINTS,
            maxDenominator: Int = DEFAULT_MAX_DENOMINATOR,
            skipTolerance: Double = DEFAULT_SKIP_TOLERANCE,
        ) = CamProSession(CamProNative.ensureLoaded().let { CamProNative.createFromAsset(assetManager, path, maxCurvePoints, maxDenominator, skipTolerance) }, maxCurvePoints)
    }
}
