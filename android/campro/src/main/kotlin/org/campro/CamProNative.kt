package org.campro

/**
 * The native functions of `libcampro_jni.so` (Rust crate `jni-bridge`). Use them through
 * [CamProSession], which owns the handle and the output arrays.
 *
 * Handles are opaque integers, never addresses: a closed or foreign handle throws
 * [IllegalStateException]; bad arguments throw [IllegalArgumentException] naming the
 * argument and the rule; an internal error in the native code arrives as a
 * [RuntimeException] starting with "campro internal error" and never crashes the process.
 */
object CamProNative {
    /** Index of the report slots every update fills (see `jni-bridge/src/lib.rs`, `report`). */
    const val REPORT_RECOMPUTED = 0
    const val REPORT_BOUND = 1
    const val REPORT_MATRIX_MAX_ABS = 2
    const val REPORT_CURVE_MAX_ABS = 3
    const val REPORT_CURVE_LIPSCHITZ = 4
    const val REPORT_SCALE = 5
    /** The most (Pin, Pout) points of a channel. */
    const val REPORT_CURVE_POINTS = 6
    const val REPORT_CURVE_SIMPLIFIED = 7
    /** Points of the red channel's curve; green and blue follow. */
    const val REPORT_CURVE_POINTS_RED = 8
    const val REPORT_LEN = 11

    /** Index of the readback comparison slots. */
    const val READBACK_MATRIX_MAX_ABS = 0
    const val READBACK_CURVE_MAX_ABS = 1
    const val READBACK_BOUND = 2
    const val READBACK_LEN = 3

    /** Whether the native library is loaded (by [loadLibrary], [load] or [ensureLoaded]). */
    @Volatile
    var isLoaded = false
        private set

    /** Loads `libcampro_jni.so` from the APK (Android) or `java.library.path`, once. */
    @Synchronized
    fun loadLibrary() {
        if (isLoaded) return
        System.loadLibrary("campro_jni")
        isLoaded = true
    }

    /** Loads the library from an absolute path (host tests), once. */
    @Synchronized
    fun load(path: String) {
        if (isLoaded) return
        System.load(path)
        isLoaded = true
    }

    /**
     * Loads the library unless it is loaded: every [CamProSession] factory calls it, so an
     * app never has to (and a missing library is an `UnsatisfiedLinkError` naming it, at
     * the first session, not a crash at the first native call).
     */
    fun ensureLoaded() {
        if (!isLoaded) loadLibrary()
    }

    @JvmStatic external fun create(paramsJson: String?, maxCurvePoints: Int, maxDenominator: Int, skipTolerance: Double): Long
    @JvmStatic external fun createFromBytes(paramsJson: ByteArray?, maxCurvePoints: Int, maxDenominator: Int, skipTolerance: Double): Long
    /** [assetManager] is an `android.content.res.AssetManager`; Android only. */
    @JvmStatic external fun createFromAsset(assetManager: Any?, path: String?, maxCurvePoints: Int, maxDenominator: Int, skipTolerance: Double): Long
    @JvmStatic external fun close(handle: Long)
    @JvmStatic external fun liveHandles(): Int
    /** Whether the session's parameter set is protective (a protection rating within the threshold, `campro::Params::protective`). */
    @JvmStatic external fun protective(handle: Long): Boolean

    /** The grids a HAL may put the values on with the set's protection measured to hold, comma-separated (`q10,lut64`; `campro::Params::device_grids`). */
    @JvmStatic external fun deviceGrids(handle: Long): String
    @JvmStatic external fun setMaxCurvePoints(handle: Long, n: Int)
    @JvmStatic external fun setDngCalibration(handle: Long, illuminant1: Int, forwardMatrix1: IntArray?, illuminant2: Int, forwardMatrix2: IntArray?)
    @JvmStatic external fun updateFromTransform(handle: Long, deviceTransform: IntArray?, outTransform: IntArray?, outCurve: FloatArray?, outReport: DoubleArray?): Boolean
    @JvmStatic external fun updateFromColorTemperature(handle: Long, kelvin: Double, outTransform: IntArray?, outCurve: FloatArray?, outReport: DoubleArray?): Boolean
    /**
     * One channel (0 red, 1 green, 2 blue) of a result against the request: the requested
     * curve is [requestedCount] floats of [requestedCurve] from [requestedOffset] (a session's
     * packed curves), the reported one the first [reportedCount] floats of [reportedCurve].
     */
    @JvmStatic external fun readback(
        requestedTransform: IntArray?, requestedCurve: FloatArray?, requestedOffset: Int, requestedCount: Int,
        reportedTransform: IntArray?, reportedCurve: FloatArray?, reportedCount: Int,
        channel: Int, out: DoubleArray?,
    )

    /**
     * A verified `YUV_420_888` frame's planes (as `Image.getPlanes()` gives them, copied) as a
     * JPEG whose only metadata is EXIF [exifOrientation] (1..8); [quality] 1..100.
     */
    @JvmStatic external fun encodeJpegYuv(
        width: Int, height: Int,
        y: ByteArray?, yRowStride: Int,
        u: ByteArray?, v: ByteArray?, uvRowStride: Int, uvPixelStride: Int,
        exifOrientation: Int, quality: Int,
    ): ByteArray

    /** Interleaved 8-bit RGB as a JPEG whose only metadata is EXIF [exifOrientation] (1..8). */
    @JvmStatic external fun encodeJpegRgb(width: Int, height: Int, rgb: ByteArray?, exifOrientation: Int, quality: Int): ByteArray

    /**
     * The record (`NAME.campro.json`) of a phone's protected output: see [RecordContext];
     * [jpegQuality] 0 when the output is not a JPEG.
     */
    @JvmStatic external fun record(
        presetJson: ByteArray?, given: String?, presetSha256: String?, cameraId: String?,
        transform: IntArray?, curvePoints: Int, gains: FloatArray?,
        conversionBoundLsb: Double, worstDeviationLsb: Double, maxDeviationLsb: Double,
        jpegQuality: Int, metadata: String?, outputName: String?, outputSha256: String?, outputBytes: Long,
    ): String
}
