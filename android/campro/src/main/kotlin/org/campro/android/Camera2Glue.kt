package org.campro.android

// The Android-typed half of the library: Camera2 metadata read into plain values, CamPro's
// values written into requests, and CamProCamera2, which runs CamProPipeline on a
// CameraDevice. Every decision is made in org.campro.CamProPipeline, ProtectionGuard,
// FrameGate, CamProController, DeviceSupport (plain Kotlin, tested on the host JVM) or in
// the Rust core; android/jvm-test runs this file under Robolectric.

import android.content.res.AssetManager
import android.graphics.ImageFormat
import android.hardware.HardwareBuffer
import android.hardware.camera2.CameraAccessException
import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraDevice
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.TotalCaptureResult
import android.hardware.camera2.params.ColorSpaceTransform
import android.hardware.camera2.params.OutputConfiguration
import android.hardware.camera2.params.RggbChannelVector
import android.hardware.camera2.params.TonemapCurve
import android.media.Image
import android.media.ImageReader
import android.os.Handler
import org.campro.CamProPipeline
import org.campro.CamProSession
import org.campro.CameraRequests
import org.campro.CaptureReport
import org.campro.DeviceSupport
import org.campro.MeteringReport
import org.campro.PixelProbe
import org.campro.ProtectionState
import java.util.concurrent.Executor

/** The luma samples of a YUV image's Y plane ([PixelProbe.lumaOfPlane]): what the pixel probe reads. */
fun lumaOfImage(image: Image): ByteArray {
    val y = image.planes[0]
    return PixelProbe.lumaOfPlane(y.buffer, image.width, image.height, y.rowStride, y.pixelStride)
}

/** Whether this camera can run CamPro, with the reasons when not. */
fun CameraCharacteristics.camproSupport(): DeviceSupport.Result = DeviceSupport.check(
    capabilities = get(CameraCharacteristics.REQUEST_AVAILABLE_CAPABILITIES),
    toneMapModes = get(CameraCharacteristics.TONEMAP_AVAILABLE_TONE_MAP_MODES),
    maxCurvePoints = get(CameraCharacteristics.TONEMAP_MAX_CURVE_POINTS),
    awbModes = get(CameraCharacteristics.CONTROL_AWB_AVAILABLE_MODES),
    syncMaxLatency = get(CameraCharacteristics.SYNC_MAX_LATENCY),
)

/** Whether settings apply on the very frame that asks for them (`SYNC_MAX_LATENCY_PER_FRAME_CONTROL`). */
fun CameraCharacteristics.hasPerFrameControl(): Boolean =
    get(CameraCharacteristics.SYNC_MAX_LATENCY) == CamProPipeline.SYNC_MAX_LATENCY_PER_FRAME_CONTROL

/**
 * The protected stream's size for [format] from the camera's `StreamConfigurationMap`
 * ([org.campro.StreamSize.choose]: the wanted aspect ratio, the largest within
 * [maxWidth] x [maxHeight]); `null` when the camera lists no size for the format.
 */
fun CameraCharacteristics.camproStreamSize(format: Int, maxWidth: Int = 1280, maxHeight: Int = 720): android.util.Size? {
    val listed = get(CameraCharacteristics.SCALER_STREAM_CONFIGURATION_MAP)?.getOutputSizes(format) ?: return null
    return org.campro.StreamSize.choose(listed.map { it.width to it.height }, maxWidth, maxHeight)?.let { (w, h) -> android.util.Size(w, h) }
}

/** `REQUEST_PIPELINE_MAX_DEPTH` (frames a result may lead its image by); 8 when absent. */
fun CameraCharacteristics.pipelineDepth(): Int =
    (get(CameraCharacteristics.REQUEST_PIPELINE_MAX_DEPTH)?.toInt() ?: 8).coerceAtLeast(1)

private fun ColorSpaceTransform.toInts(): IntArray = IntArray(18).also { copyElements(it, 0) }

private fun RggbChannelVector.toFloats(): FloatArray = floatArrayOf(red, greenEven, greenOdd, blue)

/**
 * What this result reports about CamPro's stages, for [org.campro.ProtectionGuard]: the
 * three modes, the transform, the three curves and the gains, `null` where a key is absent.
 */
fun CaptureResult.camproReport(): CaptureReport = CaptureReport(
    physicalId = activePhysicalId(),
    awbMode = get(CaptureResult.CONTROL_AWB_MODE),
    colorCorrectionMode = get(CaptureResult.COLOR_CORRECTION_MODE),
    tonemapMode = get(CaptureResult.TONEMAP_MODE),
    transform = get(CaptureResult.COLOR_CORRECTION_TRANSFORM)?.toInts(),
    curves = get(CaptureResult.TONEMAP_CURVE)?.let { c ->
        listOf(TonemapCurve.CHANNEL_RED, TonemapCurve.CHANNEL_GREEN, TonemapCurve.CHANNEL_BLUE).map { ch ->
            FloatArray(2 * c.getPointCount(ch)).also { c.copyColorCurve(ch, it, 0) }
        }
    },
    gains = get(CaptureResult.COLOR_CORRECTION_GAINS)?.toFloats(),
)

/** `LOGICAL_MULTI_CAMERA_ACTIVE_PHYSICAL_ID` (API 29): the physical sensor of a logical camera's frame; `null` otherwise. */
fun CaptureResult.activePhysicalId(): String? =
    if (android.os.Build.VERSION.SDK_INT >= 29) get(CaptureResult.LOGICAL_MULTI_CAMERA_ACTIVE_PHYSICAL_ID) else null

/** What this auto-mode result reports for metering: AWB mode and state, transform, gains. */
fun CaptureResult.meteringReport(): MeteringReport = MeteringReport(
    physicalId = activePhysicalId(),
    awbMode = get(CaptureResult.CONTROL_AWB_MODE),
    awbState = get(CaptureResult.CONTROL_AWB_STATE),
    transform = get(CaptureResult.COLOR_CORRECTION_TRANSFORM)?.toInts(),
    gains = get(CaptureResult.COLOR_CORRECTION_GAINS)?.toFloats(),
)

/**
 * CamPro's values as request settings: AWB off (Camera2 ignores TRANSFORM_MATRIX otherwise),
 * the [gains] measured in auto mode, the [transform] (18 ints) and the [curves] (red, green,
 * blue: flat (Pin, Pout) pairs, at least two each). One list serves a
 * `CaptureRequest.Builder` ([applyCamPro]) and CameraX's `CaptureRequestOptions`.
 */
fun camproSettings(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray): List<Pair<CaptureRequest.Key<*>, Any>> {
    require(transform.size == 18) { "transform must have 18 ints, got ${transform.size}" }
    require(curves.size == 3) { "curves must hold red, green and blue, got ${curves.size}" }
    for ((c, curve) in curves.withIndex()) {
        require(curve.size >= 4 && curve.size % 2 == 0) { "curves[$c] must hold at least two (Pin, Pout) pairs, got ${curve.size} floats" }
    }
    require(gains.size == 4) { "gains must have 4 elements (R, G_even, G_odd, B), got ${gains.size}" }
    return listOf(
        CaptureRequest.CONTROL_AWB_MODE to CaptureRequest.CONTROL_AWB_MODE_OFF,
        CaptureRequest.COLOR_CORRECTION_MODE to CaptureRequest.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX,
        CaptureRequest.COLOR_CORRECTION_GAINS to RggbChannelVector(gains[0], gains[1], gains[2], gains[3]),
        CaptureRequest.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(transform),
        CaptureRequest.TONEMAP_MODE to CaptureRequest.TONEMAP_MODE_CONTRAST_CURVE,
        CaptureRequest.TONEMAP_CURVE to TonemapCurve(curves[0], curves[1], curves[2]),
        // The HAL's face detector would put face rectangles and landmarks into every result:
        // metadata about the faces the picture hides.
        CaptureRequest.STATISTICS_FACE_DETECT_MODE to CaptureRequest.STATISTICS_FACE_DETECT_MODE_OFF,
    )
}

@Suppress("UNCHECKED_CAST")
private fun CaptureRequest.Builder.setAny(key: CaptureRequest.Key<*>, value: Any) = set(key as CaptureRequest.Key<Any>, value)

/** Sets CamPro's values ([camproSettings]) on a request. */
fun CaptureRequest.Builder.applyCamPro(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray) {
    for ((k, v) in camproSettings(transform, curves, gains)) setAny(k, v)
}

/** A session from a parameter file in the APK's assets, read natively (NDK AAssetManager). */
fun openCamProAsset(
    assets: AssetManager,
    path: String,
    maxCurvePoints: Int,
    skipTolerance: Double = CamProSession.DEFAULT_SKIP_TOLERANCE,
): CamProSession = CamProSession.fromAsset(assets, path, maxCurvePoints, CamProSession.DEFAULT_MAX_DENOMINATOR, skipTolerance)

/**
 * CamPro on a Camera2 camera, fail closed per frame, the screen included.
 *
 * Protected frames go only to [frames], an `ImageReader` this class owns; each image waits
 * in the pipeline's [org.campro.FrameGate] until its own `CaptureResult` verified, and only
 * then reaches [deliver] on [appExecutor] (render it with `ImageWriter.queueInputImage` onto
 * a `SurfaceView`, or with GL; the consumer closes it). Metering frames (auto mode) go to a
 * small reader that drops them unread. The pixel probe's frames ([org.campro.PixelProbe]) go
 * to the protected stream itself when its format is `YUV_420_888` (read, then dropped: never
 * delivered), else to a `YUV_420_888` reader of the same size (a PRIVATE stream's pixels
 * cannot be read; a HAL that splits passes by stream size treats both alike, one that splits
 * them by format is not seen). No display surface is ever a capture target: a
 * `TextureView`/`SurfaceView` fed straight by the camera would show frames before their
 * results are checked, and is not fail-closed.
 *
 * Use: configure a session with [outputs], then call [onConfigured] from its
 * `StateCallback.onConfigured`; forward `CameraDevice.StateCallback.onDisconnected` and
 * `onError` to [onCameraStopped]; [close] when done. All camera calls run on [cameraHandler]'s
 * thread. States reach [onState] on [appExecutor].
 */
class CamProCamera2(
    val session: CamProSession,
    characteristics: CameraCharacteristics,
    /** The camera thread: requests, results and image callbacks run here. */
    private val cameraHandler: Handler,
    /** The app's executor: frames and states are delivered there, in order (the main thread's, or one thread). */
    private val appExecutor: Executor,
    /** Frame size of the protected stream. */
    width: Int,
    height: Int,
    /** Called on [appExecutor] with each verified image; it must close it (ImageWriter.queueInputImage does). */
    deliver: (Image) -> Unit,
    /** Called on [appExecutor] with each new state. */
    onState: (ProtectionState) -> Unit = {},
    /** See [org.campro.ProtectionGuard.trustMissingKeys]: accepting it risks unprotected frames. */
    trustMissingKeys: Boolean = false,
    /** See [org.campro.CamProPipeline]'s `maxDeviationLsb` (8-bit LSB). */
    maxDeviationLsb: Double = 0.5,
    /** See [org.campro.ProtectionGuard.deviceGrids] (`null`: the preset's measured grids). */
    deviceGrids: Set<org.campro.DeviceGrid>? = null,
    /** The protected stream's format: PRIVATE for the screen (zero-copy to ImageWriter), YUV_420_888 to read pixels. */
    format: Int = ImageFormat.PRIVATE,
    /** Its usage flags (API 29): GPU sampling and composition for the screen. */
    usage: Long = HardwareBuffer.USAGE_GPU_SAMPLED_IMAGE or HardwareBuffer.USAGE_COMPOSER_OVERLAY,
) : AutoCloseable {
    /** Whether and why CamPro can run on this camera. */
    val support: DeviceSupport.Result = characteristics.camproSupport()

    /** Images the protected reader holds: frames wait there for their results, as many as the camera's pipeline depth asks. */
    val queueDepth: Int = CamProPipeline.imageQueueDepth(characteristics.pipelineDepth())

    /** Protected frames, gated before anyone sees them: private, so no caller can read around the gate. */
    private val frames: ImageReader = ImageReader.newInstance(width, height, format, queueDepth, usage)

    /** Whether the protected stream's pixels can be read (YUV_420_888): the probe then runs on it. */
    private val readable = format == ImageFormat.YUV_420_888

    /** The probe's stream when the protected one cannot be read: same size, YUV_420_888 (`null` otherwise). */
    private val probeReader: ImageReader? = if (readable) null else ImageReader.newInstance(width, height, ImageFormat.YUV_420_888, 2)

    /** Where probe requests go: the protected stream when readable, else the probe's own (internal: tests check it). */
    internal val probeSurface: android.view.Surface get() = probeReader?.surface ?: frames.surface

    /** The protected stream's surface (internal: tests compare targets). */
    internal val protectedSurface: android.view.Surface get() = frames.surface

    private val meteringReader: ImageReader = ImageReader.newInstance(METERING_WIDTH, METERING_HEIGHT, ImageFormat.YUV_420_888, 2)

    @Volatile
    private var device: CameraDevice? = null

    @Volatile
    private var captureSession: CameraCaptureSession? = null

    private val requests = object : CameraRequests {
        override fun meter() {
            val s = captureSession ?: error("no capture session")
            s.setRepeatingRequest(meteringRequest(), callback, cameraHandler)
        }

        override fun protect(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray, burst: org.campro.Burst?) {
            val s = captureSession ?: error("no capture session")
            val d = device ?: error("no camera device")
            val protected = d.createCaptureRequest(CameraDevice.TEMPLATE_PREVIEW).apply {
                addTarget(frames.surface)
                applyCamPro(transform, curves, gains)
                setTag(PROTECTED)
            }.build()
            if (burst != null) {
                val metering = meteringRequest()
                val probes = burst.probes.map { probeRequest(it.transform, it.curve, gains) }
                s.setRepeatingBurst(List(burst.protectedFrames) { protected } + probes + List(burst.meteringRun) { metering }, callback, cameraHandler)
            } else {
                s.setRepeatingRequest(protected, callback, cameraHandler)
            }
        }

        override fun probe(transform: IntArray, curve: FloatArray, gains: FloatArray) {
            val s = captureSession ?: error("no capture session")
            s.setRepeatingRequest(probeRequest(transform, curve, gains), callback, cameraHandler)
        }

        override fun halt() {
            try {
                captureSession?.stopRepeating()
            } catch (e: CameraAccessException) {
                // Disconnected: nothing repeats any more.
            } catch (e: IllegalStateException) {
                // The session is closed: nothing repeats any more.
            }
        }
    }

    /** A probe request ([org.campro.PixelProbe]) to the probe's stream: the protected one when readable. */
    private fun probeRequest(transform: IntArray, curve: FloatArray, gains: FloatArray): CaptureRequest =
        (device ?: error("no camera device")).createCaptureRequest(CameraDevice.TEMPLATE_PREVIEW).apply {
            addTarget(probeSurface)
            applyCamPro(transform, arrayOf(curve, curve, curve), gains)
            setTag(PROBE)
        }.build()

    /** The loop: states, gate and metering. */
    val pipeline = CamProPipeline<Image>(
        session, requests, appExecutor,
        perFrameControl = characteristics.hasPerFrameControl(),
        pipelineDepth = characteristics.pipelineDepth(),
        imageQueueDepth = queueDepth,
        trustMissingKeys = trustMissingKeys,
        deliver = deliver,
        drop = { it.close() },
        onState = onState,
        maxDeviationLsb = maxDeviationLsb,
        deviceGrids = deviceGrids,
        lumaOf = if (readable) { image -> lumaOfImage(image) } else null,
    )

    /** Lost protected buffers matched to their sensor timestamps, in either callback order. */
    private val lostBuffers = org.campro.LostBuffers { ts -> pipeline.onFrameLost(ts) }

    init {
        frames.setOnImageAvailableListener({ r -> acquire(r) }, cameraHandler)
        meteringReader.setOnImageAvailableListener({ r -> drain(r) }, cameraHandler)
        probeReader?.setOnImageAvailableListener({ r -> drainProbe(r) }, cameraHandler)
    }

    /**
     * The surfaces to configure the capture session with: protected frames and metering,
     * their images stamped with `SENSOR_TIMESTAMP` (API 33+): with the default base, a
     * reader whose usage looks like a display's gets choreographer-synced or readout
     * timestamps, which match no result, and the gate would show nothing.
     */
    fun outputs(): List<OutputConfiguration> =
        listOfNotNull(frames.surface, meteringReader.surface, probeReader?.surface).map { OutputConfiguration(it) }.onEach { o ->
            if (android.os.Build.VERSION.SDK_INT >= 33) o.setTimestampBase(OutputConfiguration.TIMESTAMP_BASE_SENSOR)
        }

    /** The capture session is configured: metering starts (or Unsupported, final). */
    fun onConfigured(device: CameraDevice, session: CameraCaptureSession) {
        this.device = device
        this.captureSession = session
        pipeline.start(support)
    }

    /** The camera was disconnected, failed, or its session closed: closed until started again. */
    fun onCameraStopped(reason: String) {
        captureSession = null
        device = null
        pipeline.onCameraStopped(reason)
    }

    /** Whether the protected reader is closed (internal: tests check the close ordering). */
    @Volatile
    internal var framesClosed = false
        private set

    /**
     * Stops requests and releases the readers; the camera device is the app's to close.
     * Verified images may still wait in [appExecutor] for [deliver]: closing their reader
     * now would invalidate them under the consumer (`ImageWriter.queueInputImage` throws on
     * a closed image). So the protected reader is closed by a task queued on [appExecutor]
     * behind those deliveries; the gate delivers nothing new once the pipeline stopped. An
     * executor that no longer takes tasks (shut down) gets the reader closed at once: its
     * deliveries never run.
     */
    override fun close() {
        pipeline.stop()
        captureSession = null
        device = null
        meteringReader.close()
        probeReader?.close()
        val closeFrames = Runnable {
            framesClosed = true
            frames.close()
        }
        try {
            appExecutor.execute(closeFrames)
        } catch (e: java.util.concurrent.RejectedExecutionException) {
            closeFrames.run()
        }
    }

    private val callback = object : CameraCaptureSession.CaptureCallback() {
        override fun onCaptureStarted(s: CameraCaptureSession, request: CaptureRequest, timestamp: Long, frameNumber: Long) =
            onStarted(request.tag, timestamp, frameNumber)

        override fun onCaptureCompleted(s: CameraCaptureSession, request: CaptureRequest, result: TotalCaptureResult) =
            onResult(request.tag, result)

        override fun onCaptureBufferLost(s: CameraCaptureSession, request: CaptureRequest, target: android.view.Surface, frameNumber: Long) =
            onBufferLost(request.tag, frameNumber, target == frames.surface)
    }

    /** A capture started at sensor time [timestamp] (internal: tests call it). */
    internal fun onStarted(tag: Any?, timestamp: Long, frameNumber: Long) {
        when (tag) {
            PROTECTED -> lostBuffers.started(frameNumber, timestamp)
            PROBE -> if (readable) pipeline.onProbeCaptureStarted(timestamp)
        }
    }

    /**
     * A capture's buffer for [toFrames] (the protected reader) was lost (internal: tests
     * call it): the app holds every image of the stream, or the HAL dropped the buffer.
     * Its result must not count as one whose frame never matched ([CamProPipeline.onFrameLost]).
     */
    internal fun onBufferLost(tag: Any?, frameNumber: Long, toFrames: Boolean) {
        if (tag == PROTECTED && toFrames) lostBuffers.lost(frameNumber)
    }

    /** One completed capture, routed by its request's tag (internal: tests feed scripted results). */
    internal fun onResult(tag: Any?, result: CaptureResult) {
        when (tag) {
            METERING -> pipeline.onMeteringResult(result.meteringReport())
            // A result without a timestamp matches no frame: its frame is dropped.
            PROTECTED -> pipeline.onProtectedResult(result.get(CaptureResult.SENSOR_TIMESTAMP) ?: Long.MIN_VALUE, result.camproReport())
            PROBE -> pipeline.onProbeResult(result.get(CaptureResult.SENSOR_TIMESTAMP) ?: Long.MIN_VALUE, result.camproReport())
        }
    }

    /** Takes every image the reader holds (one callback may stand for several images). */
    private fun acquire(r: ImageReader) {
        while (true) {
            val image = try {
                r.acquireNextImage()
            } catch (e: IllegalStateException) {
                null // more images acquired than the queue holds: the gate drops them as results come
            } ?: return
            pipeline.onFrame(image.timestamp, image)
        }
    }

    /** Metering frames are dropped unread. */
    private fun drain(r: ImageReader) {
        try {
            r.acquireLatestImage()?.close()
        } catch (e: IllegalStateException) {
            // closed reader
        }
    }

    /** The probe's own stream (a PRIVATE protected stream): each frame's luma goes to the probe. */
    private fun drainProbe(r: ImageReader) {
        try {
            r.acquireLatestImage()?.use { image -> pipeline.onProbeFrame(image.timestamp, lumaOfImage(image)) }
        } catch (e: IllegalStateException) {
            // closed reader
        }
    }

    private fun meteringRequest(): CaptureRequest = (device ?: error("no camera device")).createCaptureRequest(CameraDevice.TEMPLATE_PREVIEW).apply {
        addTarget(meteringReader.surface)
        set(CaptureRequest.CONTROL_AWB_MODE, CaptureRequest.CONTROL_AWB_MODE_AUTO)
        setTag(METERING)
    }.build()

    companion object {
        const val METERING_WIDTH = 320
        const val METERING_HEIGHT = 240
        internal const val METERING = "campro-metering"
        internal const val PROTECTED = "campro-protected"
        internal const val PROBE = "campro-probe"
    }
}
