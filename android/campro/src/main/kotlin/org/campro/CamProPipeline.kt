package org.campro

import java.util.concurrent.Executor

/** What one auto-mode (metering) result reported: `null` where a key is absent. */
class MeteringReport(
    /** `CONTROL_AWB_MODE`. */
    val awbMode: Int?,
    /** `CONTROL_AWB_STATE`: the device's white balance is usable once CONVERGED (2) or LOCKED (3). */
    val awbState: Int?,
    /** `COLOR_CORRECTION_TRANSFORM`: 18 ints (numerator, denominator pairs). */
    val transform: IntArray?,
    /** `COLOR_CORRECTION_GAINS` as (R, G_even, G_odd, B). */
    val gains: FloatArray?,
    /** `LOGICAL_MULTI_CAMERA_ACTIVE_PHYSICAL_ID` (`null`: not a logical camera). */
    val physicalId: String? = null,
)

/**
 * What [CamProPipeline] asks of the camera. The Android glue implements it on a
 * `CameraCaptureSession` ([org.campro.android.CamProCamera2]) or on CameraX's
 * `Camera2CameraControl` ([org.campro.android.CamProCameraX]); tests script it. A call that
 * fails (the camera was disconnected, the session closed) throws; the pipeline then stops.
 */
interface CameraRequests {
    /** Repeat auto-mode (AWB on) frames that go to no consumer; their results are metering results. */
    fun meter()

    /**
     * Repeat protected frames with these values (AWB off, TRANSFORM_MATRIX, CONTRAST_CURVE).
     * With [interleaveMetering], the repeating burst of [meteringInterval] frames begins with
     * [meteringRun] auto-mode metering frames (a run: AWB converges only after its first)
     * is an auto-mode metering frame (needs per-frame control: `SYNC_MAX_LATENCY_PER_FRAME_CONTROL`).
     */
    fun protect(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray, interleaveMetering: Boolean, meteringInterval: Int, meteringRun: Int)

    /**
     * Repeat probe frames ([PixelProbe]) with these values (AWB off, TRANSFORM_MATRIX,
     * CONTRAST_CURVE) to the small metering stream, never to the app's: their results go
     * to [CamProPipeline.onProbeResult] and their luma to [CamProPipeline.onProbeFrame].
     */
    fun probe(transform: IntArray, curve: FloatArray, gains: FloatArray)

    /** Stop repeating: nothing more is captured. Must not throw. */
    fun halt()
}

/**
 * CamPro's camera loop, free of Android types: metering, protected requests, the per-frame
 * gate and the state an app shows. The Android glue turns callbacks into these calls and
 * [CameraRequests] into requests; every decision is here, tested on the host JVM.
 *
 * The loop: [start] meters in auto mode until AWB has CONVERGED (or LOCKED), takes the
 * device's transform and gains from that result, proves from pixels that the device applies
 * the transform and curve it is sent ([PixelProbe]: once a start and physical camera;
 * a device whose pixels do not follow is Unsupported), sends CamPro's values
 * ([CameraRequests.protect]) and is `Verifying` until a protected result reads back. On a device with per-frame control
 * the repeating burst keeps a run of metering frames in [CamProController.meteringInterval] and the
 * values follow the light; otherwise (AUTO/OFF switches may land frames late) metering runs
 * again only on [remeter], with the preview closed meanwhile.
 *
 * Every frame waits in a [FrameGate] for its own result; only frames whose result verified
 * reach [deliver], on [appExecutor]. State changes reach [onState] on [appExecutor] too, in
 * order. Any exception from the camera ([CameraRequests]) or from native code stops the loop
 * closed: `Stopped(reason)`, every waiting frame dropped.
 */
class CamProPipeline<T>(
    val session: CamProSession,
    private val camera: CameraRequests,
    /** The app's executor: frames and states are delivered there. */
    private val appExecutor: Executor,
    /** Whether the device applies settings per frame (`SYNC_MAX_LATENCY == PER_FRAME_CONTROL`). */
    val perFrameControl: Boolean,
    /** Frames a result may lead its image by (`REQUEST_PIPELINE_MAX_DEPTH`, >= 1). */
    pipelineDepth: Int,
    /** Frames the image queue holds (>= 2): up to this many less one wait for results. */
    imageQueueDepth: Int,
    /** See [ProtectionGuard.trustMissingKeys]: accepting it risks unprotected frames. */
    trustMissingKeys: Boolean = false,
    /** Called on [appExecutor] with each verified frame; it owns (and closes) the frame. */
    deliver: (T) -> Unit,
    /** Called with each frame that must not reach the app (an Image is closed here). */
    private val drop: (T) -> Unit,
    /** Called on [appExecutor] with each new state. */
    private val onState: (ProtectionState) -> Unit = {},
    /** Metering results in a row without transform or gains after which the device is Unsupported. */
    val meteringKeyLimit: Int = 30,
    /**
     * Largest deviation of the reported values from the ideal camera the app accepts, 8-bit
     * LSB ([ProtectionGuard.maxDeviationLsb]). The default 0.5 refuses a HAL that rounds the
     * matrix to 1/1024 (about 4.7 LSB for `campro-omega-0.5`); raise it only for a preset
     * evaluated with that device's rounding (`campro convert --capture-result`).
     */
    maxDeviationLsb: Double = 0.5,
) {
    init {
        require(pipelineDepth >= 1) { "pipelineDepth must be >= 1, got $pipelineDepth" }
        require(imageQueueDepth >= 2) { "imageQueueDepth must be >= 2, got $imageQueueDepth" }
        require(meteringKeyLimit >= 1) { "meteringKeyLimit must be >= 1, got $meteringKeyLimit" }
    }

    /** The fail-closed state. */
    val guard = ProtectionGuard(session, maxDeviationLsb = maxDeviationLsb, trustMissingKeys = trustMissingKeys)

    /** When to rebuild and with which gains. */
    val controller = CamProController(session)

    /** The per-frame gate; verdicts sized for results that lead their images by the pipeline depth (and one more). */
    val gate = FrameGate(guard, maxWaitingFrames = imageQueueDepth - 1, maxPendingVerdicts = pipelineDepth + 1, executor = appExecutor, deliver = deliver, drop = drop)

    // The loop's state below is guarded by this object's lock (`@Synchronized` methods and
    // `synchronized(this)`); `running` is also read without it, by [onFrame] on the image
    // thread, so it is volatile: a frame arriving after [stop] sees `false` and is dropped
    // (the gate would refuse it too: the guard is stopped first).
    private var metering = false
    @Volatile
    private var running = false
    /** The physical camera of the metering result the current values come from (logical cameras). */
    private var meteredPhysicalId: String? = null
    private var meteringMissing = 0
    private var lastState: ProtectionState? = null

    /** The probe phase under way (`null`: none). */
    private var probing: PixelProbe.Step? = null
    /** [PixelProbe.Step.Curve]'s flat level, once seen. */
    private var probeCurveLevel: Int? = null
    /** Physical cameras (`null`: the camera itself) whose pixels the probe has shown to follow, since [start]. */
    private val probedIds = HashSet<String?>()
    /** Probe frames' luma and results' verdicts ("shows the step's settings") waiting for each other, by timestamp. */
    private val probeFrames = LinkedHashMap<Long, ByteArray>()
    private val probeResults = LinkedHashMap<Long, Boolean>()
    /** Probe frames of the current step so far. */
    private var probeFramesSeen = 0

    init {
        guard.stopped("not started")
    }

    /** Metering results ignored because AWB had not converged yet. */
    var unconvergedMeteringResults = 0L
        private set

    /** The current state. */
    val state: ProtectionState get() = guard.state

    /** Whether the loop is metering in auto mode (CameraX routes results by this: no per-request tags). */
    val isMetering: Boolean @Synchronized get() = metering && running

    /** Whether the loop is probing the device's pixels ([PixelProbe]; CameraX routes frames and results by this). */
    val isProbing: Boolean @Synchronized get() = probing != null && running

    /** Whether frames may reach the app now. */
    val framesAllowed: Boolean get() = guard.framesAllowed

    /**
     * Starts with the camera's [support] (from [DeviceSupport.check]): an unsupported camera
     * is final and nothing is captured; otherwise metering begins. Call once the capture
     * session is configured.
     */
    @Synchronized
    fun start(support: DeviceSupport.Result) {
        when (support) {
            is DeviceSupport.Result.Unsupported -> {
                guard.unsupported(support.reasons.joinToString("; "))
                running = false
                gate.stop()
                camera.halt()
            }
            is DeviceSupport.Result.Supported -> guarded {
                session.setMaxCurvePoints(support.maxCurvePoints)
                running = true
                probedIds.clear()
                beginMetering()
            }
        }
        publish()
    }

    /** Meters again (devices without per-frame control: the light changed); closed meanwhile. */
    @Synchronized
    fun remeter() {
        if (!running) return
        guarded { beginMetering() }
        publish()
    }

    /** An auto-mode result arrived. */
    @Synchronized
    fun onMeteringResult(m: MeteringReport) {
        if (!running || probing != null || !(metering || perFrameControl)) return
        // Only a result of an auto-mode frame carries the device's own transform: one made
        // with CamPro's settings (a late switch) would compose CamPro onto itself.
        if (m.awbMode != AWB_MODE_AUTO) {
            unconvergedMeteringResults++
            return
        }
        val converged = m.awbState == AWB_STATE_CONVERGED || m.awbState == AWB_STATE_LOCKED
        if (m.awbState != null && !converged) {
            unconvergedMeteringResults++
            return
        }
        val transform = m.transform
        val gains = m.gains
        if (transform == null || gains == null || m.awbState == null) {
            if (++meteringMissing >= meteringKeyLimit) {
                val what = when {
                    transform == null -> "COLOR_CORRECTION_TRANSFORM"
                    gains == null -> "COLOR_CORRECTION_GAINS"
                    else -> "CONTROL_AWB_STATE"
                }
                guard.unsupported("the device reports no $what in auto mode ($meteringMissing results): CamPro's values cannot follow it")
                running = false
                gate.stop()
                camera.halt()
                publish()
            }
            return
        }
        meteringMissing = 0
        guarded {
            val rebuild = controller.onMeteringResult(transform, gains)
            // Values computed for one physical sensor are never sent for another.
            val switched = m.physicalId != meteredPhysicalId
            meteredPhysicalId = m.physicalId
            if (rebuild || metering || switched) {
                if (meteredPhysicalId in probedIds) sendProtected() else beginProbe(PixelProbe.Step.Curve)
            }
        }
        publish()
    }

    /** A probe frame's result arrived ([timestampNs]: its `SENSOR_TIMESTAMP`). */
    @Synchronized
    fun onProbeResult(timestampNs: Long, report: CaptureReport) {
        val step = probing ?: return
        if (!running) return
        probeResults[timestampNs] = PixelProbe.reportsStep(step, report)
        trim(probeResults)
        guarded { judgeProbe(timestampNs) }
        publish()
    }

    /** A probe frame arrived: its image's timestamp and luma samples (a YUV image's Y plane, subsampled). */
    @Synchronized
    fun onProbeFrame(timestampNs: Long, luma: ByteArray) {
        if (probing == null || !running) return
        probeFrames[timestampNs] = luma
        trim(probeFrames)
        guarded {
            if (++probeFramesSeen > PROBE_FRAME_LIMIT) {
                failProbe("no probe frame in $PROBE_FRAME_LIMIT matched a result that shows the probe's settings (its image timestamps are not SENSOR_TIMESTAMP, or the settings never applied)")
            } else {
                judgeProbe(timestampNs)
            }
        }
        publish()
    }

    private fun <V> trim(m: LinkedHashMap<Long, V>) {
        while (m.size > PROBE_PENDING) m.remove(m.keys.first())
    }

    /** Judges the probe frame at [ts] once both its luma and its result are here. */
    private fun judgeProbe(ts: Long) {
        val step = probing ?: return
        val shows = probeResults[ts] ?: return
        val luma = probeFrames.remove(ts) ?: return
        probeResults.remove(ts)
        if (!shows) return // earlier settings (latency): this frame says nothing
        val level = PixelProbe.flatLevel(luma)
        when (step) {
            PixelProbe.Step.Curve -> {
                if (level == null) return failProbe(PixelProbe.verdict(null, null)!!)
                probeCurveLevel = level
                beginProbe(PixelProbe.Step.Matrix)
            }
            PixelProbe.Step.Matrix -> {
                val why = PixelProbe.verdict(probeCurveLevel, level)
                if (why != null) return failProbe(why)
                probing = null
                probedIds += meteredPhysicalId
                sendProtected()
            }
        }
    }

    private fun failProbe(why: String) {
        probing = null
        running = false
        guard.unsupported("pixel probe: $why")
        gate.stop()
        camera.halt()
    }

    /**
     * A protected frame's result arrived ([timestampNs]: its `SENSOR_TIMESTAMP`). A logical
     * camera that moved to another physical sensor fails the check (its values were computed
     * for the other one) and metering starts again.
     */
    fun onProtectedResult(timestampNs: Long, report: CaptureReport) {
        guarded { gate.onResult(timestampNs, report) }
        synchronized(this) {
            if (running && !metering && guard.physicalCameraChanged) guarded { beginMetering() }
        }
        publish()
    }

    /** A protected frame arrived (its image's timestamp, equal to the result's `SENSOR_TIMESTAMP`). */
    fun onFrame(timestampNs: Long, frame: T) {
        if (!running) return drop(frame)
        gate.onFrame(timestampNs, frame)
    }

    /**
     * The camera will never deliver the protected frame at [timestampNs] (Camera2's
     * `onCaptureBufferLost`, its timestamp from `onCaptureStarted`): see [FrameGate.onFrameLost].
     */
    fun onFrameLost(timestampNs: Long) = gate.onFrameLost(timestampNs)

    /** The camera failed, was disconnected or closed: closed, nothing waiting survives. */
    @Synchronized
    fun onCameraStopped(reason: String) {
        running = false
        probing = null
        guard.stopped(reason)
        gate.clear()
        publish()
    }

    /** The app stops (pause, close): stops the camera's requests and closes the gate. */
    @Synchronized
    fun stop(reason: String = "stopped by the app") {
        running = false
        probing = null
        try {
            camera.halt()
        } catch (e: RuntimeException) {
            // halt must not throw; if it does the camera is going away anyway.
        }
        guard.stopped(reason)
        gate.clear()
        publish()
    }

    private fun beginProbe(step: PixelProbe.Step) {
        metering = false
        probing = step
        probeFrames.clear()
        probeResults.clear()
        probeFramesSeen = 0
        guard.requestChanged()
        gate.clear()
        camera.probe(PixelProbe.transform(step, session.transform), PixelProbe.curve(step), controller.gains.copyOf())
    }

    private fun beginMetering() {
        probing = null
        metering = true
        guard.requestChanged()
        gate.clear()
        camera.meter()
    }

    private fun sendProtected() {
        // The values come from a metering result; never send an empty curve.
        check(session.curvePoints >= 2) { "no CamPro values yet: the session has not been updated from a metering result" }
        metering = false
        val gains = controller.gains.copyOf()
        guard.requestChanged(gains, meteredPhysicalId)
        gate.clear()
        camera.protect(session.transform.copyOf(), session.curvesForRequest(), gains, perFrameControl, controller.meteringInterval, controller.meteringRun)
    }

    /** Runs [body]; any exception stops the loop closed with its message. */
    private inline fun guarded(body: () -> Unit) {
        try {
            body()
        } catch (e: Exception) {
            running = false
            guard.stopped("stopped: ${e.javaClass.simpleName}: ${e.message}")
            gate.clear()
            try {
                camera.halt()
            } catch (ignored: RuntimeException) {
            }
        }
    }

    /** Hands the state to the app when it changed (on its executor, in order). */
    private fun publish() {
        val s = guard.state
        synchronized(this) {
            if (s == lastState) return
            lastState = s
        }
        try {
            appExecutor.execute { onState(s) }
        } catch (e: java.util.concurrent.RejectedExecutionException) {
            // The app's executor is shut down: nobody is left to tell; the state still holds.
        }
    }

    companion object {
        /** `CameraMetadata.CONTROL_AWB_MODE_AUTO`. */
        const val AWB_MODE_AUTO = 1
        /** `CameraMetadata.CONTROL_AWB_STATE_CONVERGED`. */
        const val AWB_STATE_CONVERGED = 2
        /** `CameraMetadata.CONTROL_AWB_STATE_LOCKED`. */
        const val AWB_STATE_LOCKED = 3
        /** Probe frames of one step after which a probe that saw no frame with its settings gives up: Unsupported. */
        const val PROBE_FRAME_LIMIT = 60
        /** Probe frames (and results) waiting for each other, at most. */
        const val PROBE_PENDING = 16
        /** `CameraMetadata.SYNC_MAX_LATENCY_PER_FRAME_CONTROL`. */
        const val SYNC_MAX_LATENCY_PER_FRAME_CONTROL = 0
    }
}
