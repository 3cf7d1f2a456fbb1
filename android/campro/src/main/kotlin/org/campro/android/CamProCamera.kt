package org.campro.android

import android.Manifest
import android.content.Context
import android.content.pm.PackageManager
import android.graphics.ImageFormat
import android.hardware.HardwareBuffer
import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraDevice
import android.hardware.camera2.CameraManager
import android.hardware.camera2.params.SessionConfiguration
import android.media.Image
import android.os.Handler
import android.os.HandlerThread
import android.os.Looper
import android.view.Surface
import android.view.WindowManager
import androidx.lifecycle.DefaultLifecycleObserver
import androidx.lifecycle.LifecycleOwner
import kotlinx.coroutines.flow.MutableStateFlow
import kotlinx.coroutines.flow.StateFlow
import kotlinx.coroutines.flow.asStateFlow
import org.campro.CamProNative
import org.campro.CamProSession
import org.campro.RecordContext
import org.campro.Records
import org.campro.DeviceSupport
import org.campro.FrameRouter
import org.campro.LatestFrame
import org.campro.Problem
import org.campro.Orientation
import org.campro.ProtectedRecording
import org.campro.applied
import org.campro.ProtectionState
import org.campro.RecordingSummary
import org.campro.StillCapture
import org.campro.StillResult
import org.campro.Yuv
import java.io.File
import java.io.IOException
import java.util.concurrent.CopyOnWriteArrayList
import java.util.concurrent.Executor
import java.util.concurrent.Executors
import java.util.concurrent.RejectedExecutionException

/** How a recording ended: the file and what it holds, or why there is none. */
sealed class RecordingResult {
    /** The MP4, what it holds, and its record beside it (`NAME.campro.json`). */
    class Saved(val file: File, val summary: RecordingSummary, val record: File) : RecordingResult()
    data class Failed(val reason: String) : RecordingResult()
}

/**
 * A recording under way ([CamProCamera.startRecording]). It ends on [stop] or when the camera
 * closes (the owner stopped, another app took the camera); either way the recording's
 * `onEnded` runs once, on the main thread, with the finished file or why there is none.
 */
class ActiveRecording internal constructor(
    /** The file being written (it appears there only once finished). */
    val output: File,
    internal val recording: ProtectedRecording<Image>,
    internal val overwrite: Boolean,
    internal val onEnded: (RecordingResult) -> Unit,
    private val stopper: (ActiveRecording, String) -> Unit,
) {
    /** Ends the recording. */
    fun stop() = stopper(this, "stopped by the app")

    /** Frames written so far. */
    val framesWritten: Long get() = recording.framesWritten
}

/**
 * A protected camera that owns its lifecycle ([CamPro.open]): opened while its owner is
 * started, closed when it stops, reopened when the camera becomes available again (another
 * app in multi-window took it, or camera access priorities changed).
 *
 * One protected `YUV_420_888` stream feeds everything: each frame waits in the gate for its
 * own `CaptureResult` to verify, then goes to stills and a recording (which copy it) and to
 * the preview (which shows it): [org.campro.FrameRouter]. No surface of the app is ever a
 * capture target, so no consumer can see a frame the gate did not pass.
 *
 * Threads and ownership: camera calls and the fields below marked "camera thread" run on
 * `campro-camera`; frames, states and the recording's copies on `campro-frames`; the preview's
 * writes on `campro-preview` (latest frame only: a stalled view drops preview frames, nothing
 * else); JPEG encoding and recordings' ends on `campro-background`; callbacks and the view on
 * the main thread. [state] may be read anywhere.
 */
class CamProCamera internal constructor(
    private val context: Context,
    private val owner: LifecycleOwner,
    val lens: Lens,
    val preset: Preset,
    val options: CamProOptions,
) : AutoCloseable {
    private val manager: CameraManager = context.getSystemService(CameraManager::class.java)
        ?: throw IllegalStateException("this device has no CameraManager")
    private val cameraThread = HandlerThread("campro-camera").apply { start() }
    private val cameraHandler = Handler(cameraThread.looper)
    private val cameraExecutor = Executor { if (!cameraHandler.post(it)) throw RejectedExecutionException("the camera is closed") }
    private val frameThread = HandlerThread("campro-frames").apply { start() }
    private val frameHandler = Handler(frameThread.looper)
    private val frameExecutor = Executor { if (!frameHandler.post(it)) throw RejectedExecutionException("the camera is closed") }
    /** Stills' encoding and recordings' ends: work that may wait, off the frame thread. */
    private val backgroundExecutor = Executors.newSingleThreadExecutor { r -> Thread(r, "campro-background") }

    /** The preview's own thread: `ImageWriter.queueInputImage` may block there, never on the frame thread that feeds recordings and stills. */
    private val previewExecutor = Executors.newSingleThreadExecutor { r -> Thread(r, "campro-preview") }

    /** The preview's latest-frame slot (`null`: no preview); replaced on the main thread, read on the frame thread. */
    @Volatile
    private var previewSlot: LatestFrame<Image>? = null
    private val main = Handler(Looper.getMainLooper())

    private val mutableState = MutableStateFlow<ProtectionState>(ProtectionState.Stopped("not started: the lifecycle owner has not started", Problem.CameraClosed))

    /** The protection state: frames reach the preview, recordings and stills only while [ProtectionState.Protected] (or [ProtectionState.Applied] for a preset opened with `allowUnprotective`). */
    val state: StateFlow<ProtectionState> = mutableState.asStateFlow()

    private val listeners = CopyOnWriteArrayList<Pair<Executor, (ProtectionState) -> Unit>>()

    /** Verified frames, in order: stills, the recording, the preview. */
    private val router = FrameRouter<Image> { it.close() }

    private val stills = StillCapture<Image, Pair<ImageSnapshot, RecordContext?>>({ image -> ImageSnapshot.of(image) to recordContext() }, backgroundExecutor)

    /** The preset's bytes for records, set when the camera opens (camera thread). */
    @Volatile
    private var presetBytes: ByteArray? = null

    // Camera thread.
    private var wanted = false

    /** Times the camera went away since it last protected; availability reopens it only below [REOPEN_LIMIT]. */
    private var lostInARow = 0
    private var device: CameraDevice? = null

    /** The running Camera2 glue (camera thread writes; the frame thread reads the gate's count). */
    @Volatile
    private var campro: CamProCamera2? = null

    /** The camera opened last (camera thread writes; records read it on other threads). */
    @Volatile
    private var cameraId: String? = null

    /** The open stream: size, sensor orientation, facing (written on the camera thread). */
    @Volatile
    private var stream: Stream? = null

    private class Stream(val width: Int, val height: Int, val sensorOrientation: Int, val front: Boolean)

    // Main thread.
    private var preview: CamProPreviewView? = null

    @Volatile
    private var closed = false

    /** [Orientation.deviceOrientation] of the last accelerometer reading (`null`: none yet, or no sensor). Main thread writes. */
    @Volatile
    internal var sensedOrientation: Int? = null

    /** Readings while the owner is started (main thread). */
    private val orientationListener = object : android.view.OrientationEventListener(context) {
        override fun onOrientationChanged(degrees: Int) {
            if (degrees != ORIENTATION_UNKNOWN) sensedOrientation = Orientation.deviceOrientation(degrees, sensedOrientation ?: 0)
        }
    }

    private val lifecycleObserver = object : DefaultLifecycleObserver {
        override fun onStart(owner: LifecycleOwner) {
            if (orientationListener.canDetectOrientation()) orientationListener.enable()
            onCamera { wanted = true; lostInARow = 0; openCamera() }
        }

        override fun onStop(owner: LifecycleOwner) {
            orientationListener.disable()
            onCamera { wanted = false; closeCamera("paused: the app is not in the foreground") }
        }
        override fun onDestroy(owner: LifecycleOwner) = close()
    }

    private val availability = object : CameraManager.AvailabilityCallback() {
        override fun onCameraAvailable(id: String) {
            if (id == cameraId || cameraId == null) reopen()
        }

        override fun onCameraAccessPrioritiesChanged() = reopen()

        /** A camera that keeps failing is not reopened for ever: the owner's next start tries again. */
        private fun reopen() {
            if (lostInARow < REOPEN_LIMIT) openCamera()
        }
    }

    init {
        router.stills = stills
        manager.registerAvailabilityCallback(availability, cameraHandler)
        owner.lifecycle.addObserver(lifecycleObserver)
    }

    /**
     * Adds [listener], called on [executor] with the current state now and every change after,
     * in order (the current state is queued under the same lock as every change, so a change
     * racing with this call never reaches the listener before the state it replaced).
     */
    fun addStateListener(executor: Executor, listener: (ProtectionState) -> Unit) {
        synchronized(listeners) {
            listeners += executor to listener
            val now = mutableState.value
            executor.execute { listener(now) }
        }
    }

    fun removeStateListener(listener: (ProtectionState) -> Unit) {
        listeners.removeAll { it.second === listener }
    }

    /**
     * Shows the protected stream in [view] (`null`: no preview). Main thread. The view gets
     * only frames the gate passed, and covers itself unless Protected.
     */
    fun setPreview(view: CamProPreviewView?) {
        checkMain()
        preview = view
        val v = view
        val slot = if (v == null) null else LatestFrame<Image>(previewExecutor, { image -> v.render(image) }, { it.close() })
        previewSlot?.close()
        previewSlot = slot
        router.preview = if (slot == null) null else { image -> slot.offer(image) }
        v?.showState(mutableState.value)
        stream?.let { s -> v?.configure(s.width, s.height, s.sensorOrientation, s.front, s.front && options.mirrorFrontPreview) }
    }

    /**
     * Records verified frames into [output] (MP4, H.264 or HEVC, no audio), from now until
     * [ActiveRecording.stop] or the camera closes (the owner stopped, the camera was taken):
     * the file is then finished with what it holds and the frames the gate dropped.
     * [onEnded] runs once on the main thread when it ends. Throws [IllegalStateException]
     * when the camera is not open or a recording runs, and [IOException] when [output]
     * exists without [RecordingOptions.overwrite] or the encoder cannot start.
     */
    fun startRecording(
        output: File,
        recordingOptions: RecordingOptions = RecordingOptions(),
        deviceOrientation: Int? = null,
        onEnded: (RecordingResult) -> Unit = {},
    ): ActiveRecording {
        // Under the lock closeCamera takes: a recording either starts before the camera closes
        // (and closing ends it) or finds it closed; it never runs on into the next session.
        synchronized(recordingLock) {
            val c = campro ?: throw IllegalStateException("the camera is not open (state: ${mutableState.value})")
            val s = stream ?: throw IllegalStateException("the camera is not open")
            check(active == null) { "a recording is under way" }
            val recordFile = Records.pathOf(output)
            if (recordFile.exists() && !recordingOptions.overwrite) throw IOException("$recordFile exists: pass RecordingOptions(overwrite = true) to replace it")
            val rotation = Orientation.stillRotation(s.sensorOrientation, deviceOrientation ?: currentDeviceOrientation(), s.front)
            val encoder = MediaCodecEncoder(output, s.width, s.height, rotation, recordingOptions)
            val rec = ProtectedRecording(encoder, Image::getTimestamp) { c.pipeline.gate.dropped }
            val a = ActiveRecording(output, rec, recordingOptions.overwrite, onEnded, ::stopRecording)
            active = a
            router.recording = rec
            return a
        }
    }

    /** Guards the pair (the open camera, the recording under way) between [startRecording] and [closeCamera]. */
    private val recordingLock = Any()

    /**
     * Meters the light again now (the scene changed: indoors to outdoors): on a camera with
     * per-frame control metering also runs in every burst, adaptively; on one without, only
     * here, with the preview closed meanwhile. The pixel probe runs again too. Any thread.
     */
    fun remeter() {
        try {
            cameraHandler.post { campro?.pipeline?.remeter() }
        } catch (e: RuntimeException) {
            // Closed: nothing to meter.
        }
    }

    /** The recording under way, if any. */
    @Volatile
    private var active: ActiveRecording? = null

    /**
     * Ends [a]: detached on the frame thread (after the frames already queued), finished on
     * the background thread (the encoder's end of stream may wait for the codec: never on the
     * frame thread, which feeds the preview and stills), then reported on the main thread; once.
     */
    private fun stopRecording(a: ActiveRecording, reason: String) {
        val ctx = recordContext() // now, while the camera's values are there
        val task = Runnable {
            if (!a.recording.isActive) return@Runnable
            if (router.recording === a.recording) router.recording = null
            try {
                backgroundExecutor.execute { finishRecording(a, reason, ctx) }
            } catch (e: RejectedExecutionException) {
                finishRecording(a, reason, ctx)
            }
        }
        try {
            frameExecutor.execute(task)
        } catch (e: RejectedExecutionException) {
            task.run()
        }
    }

    /** Finishes [a]'s file and record, then reports on the main thread (background thread). */
    private fun finishRecording(a: ActiveRecording, reason: String, ctx: RecordContext?) {
        run {
            if (active === a) active = null
            val result = try {
                val summary = a.recording.stop(reason)
                when {
                    summary.frames == 0L -> RecordingResult.Failed("no verified frame was recorded ($reason)")
                    ctx == null -> {
                        a.output.delete() // a protected output always has its record
                        RecordingResult.Failed("the camera closed before the recording's values could be recorded")
                    }
                    else -> {
                        val recordFile = Records.pathOf(a.output)
                        try {
                            writeAtomically(recordFile, ctx.json(a.output, 0, RECORD_METADATA_VIDEO).toByteArray(), a.overwrite)
                        } catch (e: Exception) {
                            a.output.delete()
                            throw IOException("its record could not be written: ${e.message}", e)
                        }
                        RecordingResult.Saved(a.output, summary, recordFile)
                    }
                }
            } catch (e: IOException) {
                RecordingResult.Failed(e.message ?: "the recording failed")
            }
            main.post { a.onEnded(result) }
        }
    }

    /**
     * Takes the next verified frame as a JPEG into [output] (written atomically; an existing
     * file is replaced only with [overwrite]). Its only metadata is the EXIF orientation, from
     * [deviceOrientation] (degrees the device is turned clockwise, e.g. from an
     * `OrientationEventListener`; default: the display's rotation). [callback] runs on the
     * main thread: the file's bytes, or why there is none (no verified frame within
     * [CamProOptions.stillTimeoutMs], the camera closed, the file exists).
     */
    fun takePicture(output: File, overwrite: Boolean = false, deviceOrientation: Int? = null, callback: (StillResult) -> Unit) {
        val s = stream
        val recordFile = Records.pathOf(output)
        val refused = when {
            s == null -> "the camera is not open (state: ${mutableState.value})"
            output.exists() && !overwrite -> "$output exists: pass overwrite = true to replace it"
            recordFile.exists() && !overwrite -> "$recordFile exists: pass overwrite = true to replace it"
            else -> null
        }
        if (refused != null || s == null) {
            main.post { callback(StillResult.Failed(refused ?: "the camera is not open")) }
            return
        }
        val exif = Orientation.exifOrientation(
            Orientation.stillRotation(s.sensorOrientation, deviceOrientation ?: currentDeviceOrientation(), s.front),
            mirror = s.front && options.mirrorFrontStills,
        )
        val quality = options.jpegQuality
        val request = stills.request({ (snap, ctx) -> saveStill(snap, ctx, output, recordFile, exif, quality, overwrite) }) { r ->
            main.post { callback(r) }
        }
        main.postDelayed({
            stills.cancel(request, "no verified frame within ${options.stillTimeoutMs} ms (state: ${mutableState.value})")
        }, options.stillTimeoutMs)
    }

    /**
     * Encodes [snap], writes it to [output] and its record to [recordFile] (each through a
     * temporary file), on the still thread. A record that cannot be made takes the photo
     * with it: a protected output always has its record.
     */
    private fun saveStill(snap: ImageSnapshot, ctx: RecordContext?, output: File, recordFile: File, exif: Int, quality: Int, overwrite: Boolean): StillResult {
        ctx ?: return StillResult.Failed("the camera closed before the still's values could be recorded")
        val jpeg = snap.jpeg(exif, quality)
        return try {
            writeAtomically(output, jpeg, overwrite)
            writeAtomically(recordFile, ctx.json(output, quality, RECORD_METADATA_STILL).toByteArray(), overwrite)
            StillResult.Taken(jpeg, snap.timestampNs, recordFile)
        } catch (e: Exception) {
            output.delete()
            StillResult.Failed("the still could not be written: ${e.message}")
        }
    }

    /** Stops everything and releases the camera and the threads. Idempotent; any thread. */
    override fun close() {
        synchronized(this) {
            if (closed) return
            closed = true
        }
        manager.unregisterAvailabilityCallback(availability)
        onMain {
            owner.lifecycle.removeObserver(lifecycleObserver)
            orientationListener.disable()
        }
        try {
            cameraHandler.post {
                wanted = false
                closeCamera("closed by the app")
                // After the frame thread has run what closeCamera queued (the reader's close, the last state).
                frameHandler.post { frameThread.quitSafely() }
                backgroundExecutor.shutdown()
                previewSlot?.close()
                previewExecutor.shutdown()
                cameraThread.quitSafely()
            }
        } catch (e: RuntimeException) {
            // The threads are gone already.
        }
    }

    /** What a record says of the camera now (`null` when it is not open): any thread. */
    private fun recordContext(): RecordContext? {
        val c = campro ?: return null
        val bytes = presetBytes ?: return null
        val id = cameraId ?: return null
        val session = c.session
        return synchronized(session) {
            if (session.isClosed) return null
            RecordContext(
                bytes, preset.given, id, session.transform.copyOf(), session.curvePoints,
                c.pipeline.controller.gains.copyOf(), session.boundLsb,
                c.pipeline.guard.worstDeviationLsb, c.pipeline.guard.maxDeviationLsb,
            )
        }
    }

    // ------------------------------------------------------------------------------------
    // Camera thread

    private fun onCamera(body: () -> Unit) {
        if (!closed) cameraHandler.post(body)
    }

    private fun openCamera() {
        if (!wanted || closed || campro != null) return
        try {
            val ids = manager.cameraIdList.map { it to manager.getCameraCharacteristics(it).get(CameraCharacteristics.LENS_FACING) }
            val id = CamPro.pick(ids, lens) ?: return publish(ProtectionState.Unsupported("this device has no $lens", Problem.DeviceCapability))
            cameraId = id
            val chars = manager.getCameraCharacteristics(id)
            val support = chars.camproSupport()
            if (support is DeviceSupport.Result.Unsupported) return publish(ProtectionState.Unsupported(support.reasons.joinToString("; "), Problem.DeviceCapability))
            if (context.checkSelfPermission(Manifest.permission.CAMERA) != PackageManager.PERMISSION_GRANTED) {
                return publish(ProtectionState.Stopped("the camera permission is not granted", Problem.Permission))
            }
            val size = chars.camproStreamSize(ImageFormat.YUV_420_888, options.maxWidth, options.maxHeight)
                ?: return publish(ProtectionState.Unsupported("the camera lists no YUV_420_888 size", Problem.DeviceCapability))
            val bytes = preset.bytes(context)
            val session = CamProSession.fromBytes(bytes, (support as DeviceSupport.Result.Supported).maxCurvePoints)
            if (!session.protective && !options.allowUnprotective) {
                session.close()
                return publish(
                    ProtectionState.Unsupported(
                        "the preset ${preset.given} does not protect faces (no protection rating in its provenance): open it with CamProOptions(allowUnprotective = true) to apply it anyway; the camera then reads Applied, never Protected",
                        Problem.Preset,
                    ),
                )
            }
            val grids = options.deviceGrids?.mapNotNull { org.campro.DeviceGrid.parse(it) }?.toSet()
            val held = session.deviceGrids
            val unmeasured = grids.orEmpty() - held
            if (unmeasured.isNotEmpty()) {
                session.close()
                return publish(
                    ProtectionState.Unsupported(
                        "CamProOptions.deviceGrids ${unmeasured.joinToString()}: the preset ${preset.given} was not measured to protect on ${if (unmeasured.size == 1) "that grid" else "those grids"} (it holds: ${held.joinToString().ifEmpty { "none" }}; docs/android.md, Grids)",
                        Problem.Preset,
                    ),
                )
            }
            presetBytes = bytes
            val c = try {
                CamProCamera2(
                    session, chars, cameraHandler, frameExecutor, size.width, size.height,
                    deliver = router::deliver,
                    onState = ::publish,
                    trustMissingKeys = options.trustMissingKeys,
                    maxDeviationLsb = options.maxDeviationLsb,
                    deviceGrids = grids,
                    format = ImageFormat.YUV_420_888,
                    usage = HardwareBuffer.USAGE_CPU_READ_OFTEN or HardwareBuffer.USAGE_GPU_SAMPLED_IMAGE,
                )
            } catch (e: RuntimeException) {
                session.close()
                throw e
            }
            campro = c
            val s = Stream(size.width, size.height, chars.get(CameraCharacteristics.SENSOR_ORIENTATION) ?: 0, chars.get(CameraCharacteristics.LENS_FACING) == CameraCharacteristics.LENS_FACING_FRONT)
            stream = s
            main.post { preview?.configure(s.width, s.height, s.sensorOrientation, s.front, s.front && options.mirrorFrontPreview) }
            manager.openCamera(id, cameraExecutor, object : CameraDevice.StateCallback() {
                override fun onOpened(d: CameraDevice) {
                    if (campro !== c) return d.close() // closed or reopened meanwhile: not ours any more
                    device = d
                    createSession(d, c)
                }

                override fun onDisconnected(d: CameraDevice) =
                    lost(c, d, "the camera was taken by another app or disconnected; CamPro reopens it when it is free")

                override fun onError(d: CameraDevice, error: Int) = lost(c, d, errorReason(error))
            })
        } catch (e: Exception) {
            // CameraAccessException, SecurityException, IllegalArgumentException, native errors.
            closeCamera("cannot open the camera: ${e.message}")
        }
    }

    private fun createSession(d: CameraDevice, c: CamProCamera2) {
        try {
            d.createCaptureSession(
                SessionConfiguration(
                    SessionConfiguration.SESSION_REGULAR, c.outputs(), cameraExecutor,
                    object : CameraCaptureSession.StateCallback() {
                        override fun onConfigured(s: CameraCaptureSession) = c.onConfigured(d, s)
                        override fun onConfigureFailed(s: CameraCaptureSession) = lost(c, d, "the capture session could not be configured")
                        override fun onClosed(s: CameraCaptureSession) = c.onCameraStopped("the capture session closed")
                    },
                ),
            )
        } catch (e: Exception) {
            lost(c, d, "cannot create the capture session: ${e.message}")
        }
    }

    /** The camera went away (taken, disconnected, failed): closed until it is available again. */
    private fun lost(c: CamProCamera2, d: CameraDevice, reason: String) {
        c.onCameraStopped(reason)
        if (campro !== c) return d.close()
        lostInARow++
        closeCamera(
            if (lostInARow < REOPEN_LIMIT) reason
            else "$reason ($lostInARow times without protecting in between: not reopened until the app starts again)",
        )
    }

    /** Closes the camera, stops a recording and fails waiting stills with [reason]; the state becomes Stopped. */
    private fun closeCamera(reason: String) {
        val c: CamProCamera2?
        synchronized(recordingLock) {
            active?.let { stopRecording(it, reason) } // first: its record needs the camera's values
            c = campro
            campro = null
            stream = null
        }
        // The requests stop, then the device (and its session) closes, then the readers: a
        // reader closed under a running session makes the HAL drop buffers into a dead queue.
        c?.pipeline?.stop(reason)
        device?.close()
        device = null
        c?.close()
        c?.session?.close()
        stills.fail(reason)
        // Queued behind the pipeline's own last state on the frame thread, so this one is final.
        try {
            frameExecutor.execute { publish(ProtectionState.Stopped(reason, Problem.CameraClosed)) }
        } catch (e: RejectedExecutionException) {
            publish(ProtectionState.Stopped(reason, Problem.CameraClosed))
        }
    }

    private fun errorReason(error: Int): String = when (error) {
        CameraDevice.StateCallback.ERROR_CAMERA_IN_USE -> "the camera is in use by another app"
        CameraDevice.StateCallback.ERROR_MAX_CAMERAS_IN_USE -> "too many cameras are open"
        CameraDevice.StateCallback.ERROR_CAMERA_DISABLED -> "the camera is disabled by a device policy"
        CameraDevice.StateCallback.ERROR_CAMERA_DEVICE -> "the camera device failed"
        CameraDevice.StateCallback.ERROR_CAMERA_SERVICE -> "the camera service failed"
        else -> "camera error $error"
    }

    // ------------------------------------------------------------------------------------
    // Any thread

    private fun publish(s: ProtectionState) {
        if (s.applied) cameraHandler.post { lostInARow = 0 }
        synchronized(listeners) {
            if (mutableState.value == s && s !is ProtectionState.Stopped) return
            mutableState.value = s
            for ((executor, listener) in listeners) {
                try {
                    executor.execute { listener(s) }
                } catch (e: RejectedExecutionException) {
                    // The app's executor is shut down: it no longer listens.
                }
            }
        }
        main.post { preview?.showState(s) }
    }

    private fun onMain(body: () -> Unit) {
        if (Looper.myLooper() == Looper.getMainLooper()) body() else main.post(body)
    }

    private fun checkMain() = check(Looper.myLooper() == Looper.getMainLooper()) { "call on the main thread" }

    /** The device's physical orientation as the display's rotation implies it (a portrait-locked app should pass its own). */
    /**
     * The device's physical orientation (degrees clockwise, a multiple of 90): from the
     * accelerometer while the owner is started (an app locked to portrait still gets stills
     * and videos turned as the phone is held), else from the display's rotation.
     */
    internal fun currentDeviceOrientation(): Int = sensedOrientation ?: deviceOrientationFromDisplay()

    private fun deviceOrientationFromDisplay(): Int {
        @Suppress("DEPRECATION")
        val rotation = context.getSystemService(WindowManager::class.java)?.defaultDisplay?.rotation ?: Surface.ROTATION_0
        return when (rotation) {
            Surface.ROTATION_90 -> 270
            Surface.ROTATION_180 -> 180
            Surface.ROTATION_270 -> 90
            else -> 0
        }
    }

    private companion object {
        /** Losses in a row after which the camera is left closed until the owner starts again. */
        const val REOPEN_LIMIT = 3

        /** What a still carries of metadata (the record's `metadata`): its EXIF orientation alone. */
        const val RECORD_METADATA_STILL = "orientation"

        /** What a recording carries: the orientation hint and CamPro's summary track. */
        const val RECORD_METADATA_VIDEO = "orientation+summary"
    }

    // ------------------------------------------------------------------------------------
    // Internal, for tests

    /** The Camera2 glue while the camera is open (tests feed it scripted results). */
    internal val glue: CamProCamera2? get() = campro

    /** The camera thread's looper and the frame thread's (tests idle them). */
    internal val cameraLooper: Looper? get() = cameraThread.looper
    internal val frameLooper: Looper? get() = frameThread.looper
}

/** A verified frame's planes, copied tightly packed (I420) for the still encoder. */
internal class ImageSnapshot(
    val width: Int,
    val height: Int,
    val timestampNs: Long,
    private val y: ByteArray,
    private val u: ByteArray,
    private val v: ByteArray,
) {
    /** The JPEG: [exifOrientation] is its only metadata. */
    fun jpeg(exifOrientation: Int, quality: Int): ByteArray {
        val cw = (width + 1) / 2
        return CamProNative.encodeJpegYuv(width, height, y, width, u, v, cw, 1, exifOrientation, quality)
    }

    companion object {
        fun of(image: Image): ImageSnapshot {
            val p = image.planes
            val (w, h) = image.width to image.height
            val (cw, ch) = (w + 1) / 2 to (h + 1) / 2
            return ImageSnapshot(
                w, h, image.timestamp,
                Yuv.packPlane(p[0].buffer, p[0].rowStride, p[0].pixelStride, w, h),
                Yuv.packPlane(p[1].buffer, p[1].rowStride, p[1].pixelStride, cw, ch),
                Yuv.packPlane(p[2].buffer, p[2].rowStride, p[2].pixelStride, cw, ch),
            )
        }
    }
}
