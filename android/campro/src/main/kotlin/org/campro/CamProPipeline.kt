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

/** One probe request ([PixelProbe]) of a repeating burst: its transform and its curve (all three channels); the gains are the protected request's. */
class ProbeRequest(val transform: IntArray, val curve: FloatArray)

/**
 * The repeating burst of a camera with per-frame control: protected frames first, then
 * [probes] (a periodic re-probe: each a frame to the protected stream that never reaches the
 * app), then [meteringRun] auto-mode metering frames to no consumer; [length] frames in all.
 */
class Burst(val length: Int, val meteringRun: Int, val probes: List<ProbeRequest> = emptyList()) {
    init {
        require(meteringRun >= 1 && length > meteringRun + probes.size) { "a burst of $length frames cannot hold $meteringRun metering and ${probes.size} probe frames and a protected one" }
    }

    /** Protected frames of the burst. */
    val protectedFrames: Int get() = length - meteringRun - probes.size
}

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
     * Repeat protected frames with these values (AWB off, TRANSFORM_MATRIX, CONTRAST_CURVE):
     * alone when [burst] is `null`, else as the repeating [Burst] (needs per-frame control:
     * `SYNC_MAX_LATENCY_PER_FRAME_CONTROL`), whose probe frames carry these [gains] too.
     */
    fun protect(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray, burst: Burst?)

    /**
     * Repeat probe frames ([PixelProbe]) with these values (AWB off, TRANSFORM_MATRIX,
     * CONTRAST_CURVE) to the protected stream (the app's size and format; a stream whose
     * pixels cannot be read, PRIVATE, gets a readable stream of the same size): their
     * results go to [CamProPipeline.onProbeResult], their frames to [CamProPipeline.onFrame]
     * (or their luma to [CamProPipeline.onProbeFrame]), and none reaches the app.
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
 * device's transform and gains from that result, proves from the protected stream's pixels
 * that the device applies the transform and curve it is sent ([PixelProbe]: at every start
 * and physical camera; a device whose pixels do not follow is Unsupported; black frames are
 * Stopped until real ones come), sends CamPro's values ([CameraRequests.protect]) and is
 * `Verifying` until a protected result reads back. On a device with per-frame control the
 * repeating [Burst] ends with a run of metering frames (adaptive: [CamProController]) and
 * the values follow the light, and every [reprobeInterval] protected results the burst also
 * carries the probe's frames (a mode switch mid-session is caught within that interval);
 * otherwise (AUTO/OFF switches may land frames late) metering and the probe run again only
 * on [remeter], with the preview closed meanwhile.
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
    /** Frames the image queue holds (>= 2): up to this many less one wait for results ([imageQueueDepth] gives it from the pipeline depth). */
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
    /**
     * The luma samples of a protected-stream frame ([PixelProbe.lumaOfPlane] of its Y plane),
     * read before the frame is dropped; `null` when the stream's pixels cannot be read (a
     * PRIVATE stream: the glue then probes a readable stream and calls [onProbeFrame]).
     */
    private val lumaOf: ((T) -> ByteArray)? = null,
    /**
     * Protected results between re-probes in the burst's slots (per-frame control only; >= 1):
     * 90 is 3 s at 30 fps, two hidden frames more in every 90. A device that stops following
     * mid-session (a mode switch) shows unprotected frames until the next re-probe.
     */
    val reprobeInterval: Int = 90,
    /** The grids a device may put the values on ([ProtectionGuard.deviceGrids]; `null`: the session's measured ones). */
    deviceGrids: Set<DeviceGrid>? = null,
) {
    init {
        require(pipelineDepth >= 1) { "pipelineDepth must be >= 1, got $pipelineDepth" }
        require(imageQueueDepth >= 2) { "imageQueueDepth must be >= 2, got $imageQueueDepth" }
        require(meteringKeyLimit >= 1) { "meteringKeyLimit must be >= 1, got $meteringKeyLimit" }
        require(reprobeInterval >= 1) { "reprobeInterval must be >= 1, got $reprobeInterval" }
    }

    /** The fail-closed state. */
    val guard = ProtectionGuard(session, maxDeviationLsb = maxDeviationLsb, trustMissingKeys = trustMissingKeys, deviceGrids = deviceGrids)

    /** When to rebuild and with which gains; the metering plan. */
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
    /** Probe levels seen, by step ([PixelProbe.flatLevel]); for the phased probe and the re-probe in the burst alike. */
    private val probeLevels = HashMap<PixelProbe.Step, Int>()
    /** Physical cameras (`null`: the camera itself) whose pixels the probe has shown to follow, since [start]. */
    private val probedIds = HashSet<String?>()
    /** Probe frames' luma and results' steps (the step its settings show; `null`: none) waiting for each other, by timestamp. */
    private val probeFrames = LinkedHashMap<Long, ByteArray>()
    private val probeResults = LinkedHashMap<Long, PixelProbe.Step?>()
    /** Sensor timestamps of probe captures started in the burst's slots ([onProbeCaptureStarted]): their frames are probe frames. */
    private val probeStarts = LinkedHashSet<Long>()
    /** Probe frames of the current step so far. */
    private var probeFramesSeen = 0
    /** Whether the burst carries the probe's frames now (a re-probe). */
    private var reprobing = false
    /** Protected results since the last probe passed (or since the re-probe began). */
    private var resultsSinceProbe = 0
    /** The current metering run: whether it has begun, saw a CONVERGED result, rebuilt the request. */
    private var inRun = false
    private var runConverged = false
    private var runRebuilt = false
    /** Whether the probe saw black frames (the state is Stopped until real frames come). */
    private var black = false

    init {
        guard.stopped("not started")
    }

    /** Metering results ignored because AWB had not converged yet. */
    var unconvergedMeteringResults = 0L
        private set

    /** Re-probes that passed in the burst's slots. */
    @Volatile
    var reprobes = 0L
        private set

    /** The current state. */
    val state: ProtectionState get() = guard.state

    /** Whether the loop is metering in auto mode (CameraX routes results by this: no per-request tags). */
    val isMetering: Boolean @Synchronized get() = metering && running

    /** Whether the loop is probing the device's pixels in its own phase ([PixelProbe]; CameraX routes results by this). */
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
                controller.resetPlan()
                beginMetering()
            }
        }
        publish()
    }

    /** Meters and probes again (devices without per-frame control: the light changed); closed meanwhile. */
    @Synchronized
    fun remeter() {
        if (!running) return
        probedIds.clear()
        guarded { beginMetering() }
        publish()
    }

    /** An auto-mode result arrived. */
    @Synchronized
    fun onMeteringResult(m: MeteringReport) {
        if (!running || probing != null || !(metering || perFrameControl)) return
        if (!metering && !inRun) {
            inRun = true
            runConverged = false
            runRebuilt = false
        }
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
                guard.unsupported("the device reports no $what in auto mode ($meteringMissing results): CamPro's values cannot follow it", Problem.MissingKey)
                running = false
                gate.stop()
                camera.halt()
                publish()
            }
            return
        }
        meteringMissing = 0
        runConverged = true
        guarded {
            val rebuild = controller.onMeteringResult(transform, gains)
            // Values computed for one physical sensor are never sent for another.
            val switched = m.physicalId != meteredPhysicalId
            meteredPhysicalId = m.physicalId
            if (rebuild || metering || switched) {
                runRebuilt = true
                if (meteredPhysicalId in probedIds) sendProtected() else beginProbe(PixelProbe.Step.Curve)
            }
        }
        publish()
    }

    /**
     * A probe capture of the burst's slots started at sensor time [timestampNs] (Camera2's
     * `onCaptureStarted` for a probe request): the protected stream's frame of that time is a
     * probe frame, read and dropped, never shown.
     */
    @Synchronized
    fun onProbeCaptureStarted(timestampNs: Long) {
        if (!running) return
        probeStarts += timestampNs
        while (probeStarts.size > PROBE_PENDING) probeStarts.remove(probeStarts.first())
    }

    /** A probe frame's result arrived ([timestampNs]: its `SENSOR_TIMESTAMP`). */
    @Synchronized
    fun onProbeResult(timestampNs: Long, report: CaptureReport) {
        if (!running) return
        // Its frame, if it reached the gate (its start was not seen first), is never shown.
        gate.reject(timestampNs)
        val step = probing
        if (step == null && !reprobing) return
        probeResults[timestampNs] = if (step != null) step.takeIf { PixelProbe.reportsStep(it, report) } else PixelProbe.Step.values().firstOrNull { PixelProbe.reportsStep(it, report) }
        trim(probeResults)
        guarded { judgeProbe(timestampNs) }
        publish()
    }

    /** A probe frame arrived: its image's timestamp and luma samples (a YUV image's Y plane, subsampled). */
    @Synchronized
    fun onProbeFrame(timestampNs: Long, luma: ByteArray) {
        if ((probing == null && !reprobing) || !running) return
        probeFrames[timestampNs] = luma
        trim(probeFrames)
        guarded {
            if (probing != null && ++probeFramesSeen > PROBE_FRAME_LIMIT) {
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
        if (!probeResults.containsKey(ts)) return
        val luma = probeFrames.remove(ts) ?: return
        val step = probeResults.remove(ts) ?: return // earlier settings (latency): this frame says nothing
        val level = PixelProbe.flatLevel(luma)
        if (level == null) {
            return failProbe(if (step == PixelProbe.Step.Curve) PixelProbe.verdict(null, null)!! else PixelProbe.verdict(0, null)!!)
        }
        if (level <= PixelProbe.BLACK_MAX) {
            // Black (neither step's level is that dark on a device that renders: about 64 and
            // 128): the privacy toggle or a stopped sensor. Closed, not final: the probe goes
            // on from its first step until real frames come.
            if (!black) guard.stopped("the camera delivers black frames (the camera privacy toggle is on, or the sensor stopped): waiting for real frames", Problem.PrivacyToggle)
            black = true
            probeLevels.clear()
            probeFramesSeen = 0
            if (probing == PixelProbe.Step.Matrix) beginProbe(PixelProbe.Step.Curve)
            return
        }
        probeLevels[step] = level
        val curveLevel = probeLevels[PixelProbe.Step.Curve]
        val matrixLevel = probeLevels[PixelProbe.Step.Matrix]
        if (probing != null && step == PixelProbe.Step.Curve && matrixLevel == null) return beginProbe(PixelProbe.Step.Matrix, fresh = false)
        if (curveLevel == null || matrixLevel == null) return
        val why = PixelProbe.verdict(curveLevel, matrixLevel)
        if (why != null) return failProbe(why)
        black = false
        probing = null
        probedIds += meteredPhysicalId
        resultsSinceProbe = 0
        probeLevels.clear()
        if (reprobing) {
            reprobing = false
            reprobes++
            if (guard.state is ProtectionState.Stopped) sendProtected() else sendBurst()
        } else {
            sendProtected()
        }
    }

    private fun failProbe(why: String) {
        probing = null
        reprobing = false
        running = false
        guard.unsupported("pixel probe: $why", Problem.PixelProbe)
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
            if (running && !metering && probing == null) guarded {
                if (guard.physicalCameraChanged) return@guarded beginMetering()
                if (inRun) {
                    inRun = false
                    if (perFrameControl && controller.runEnded(runConverged, runRebuilt) && !reprobing) sendBurst()
                }
                if (perFrameControl && ++resultsSinceProbe >= reprobeInterval) {
                    if (!reprobing) {
                        reprobing = true
                        resultsSinceProbe = 0
                        probeLevels.clear()
                        sendBurst()
                    } else if (resultsSinceProbe >= REPROBE_LIMIT * reprobeInterval) {
                        failProbe("no probe frame of the burst matched a result that shows the probe's settings in ${REPROBE_LIMIT * reprobeInterval} protected results")
                    }
                }
            }
        }
        publish()
    }

    /**
     * A frame of the protected stream arrived (its image's timestamp, equal to the result's
     * `SENSOR_TIMESTAMP`). While the probe runs in its own phase every frame is a probe frame;
     * in the burst, the frames of probe captures ([onProbeCaptureStarted]) are: their luma
     * goes to the probe and the frame is dropped, never shown.
     */
    fun onFrame(timestampNs: Long, frame: T) {
        if (!running) return drop(frame)
        val probe = synchronized(this) { probing != null || probeStarts.remove(timestampNs) }
        if (!probe) return gate.onFrame(timestampNs, frame)
        val luma = try {
            lumaOf?.invoke(frame)
        } catch (e: RuntimeException) {
            ByteArray(0) // an unreadable frame: not flat, the probe fails closed
        } finally {
            drop(frame)
        }
        if (luma != null) onProbeFrame(timestampNs, luma)
    }

    /**
     * The camera will never deliver the protected frame at [timestampNs] (Camera2's
     * `onCaptureBufferLost`, its timestamp from `onCaptureStarted`: [LostBuffers]): see [FrameGate.onFrameLost].
     */
    fun onFrameLost(timestampNs: Long) = gate.onFrameLost(timestampNs)

    /** The camera failed, was disconnected or closed ([problem]: what kind): closed, nothing waiting survives. */
    @Synchronized
    fun onCameraStopped(reason: String, problem: Problem = Problem.CameraClosed) {
        running = false
        probing = null
        reprobing = false
        guard.stopped(reason, problem)
        gate.clear()
        publish()
    }

    /** The app stops (pause, close): stops the camera's requests and closes the gate. */
    @Synchronized
    fun stop(reason: String = "stopped by the app") {
        running = false
        probing = null
        reprobing = false
        try {
            camera.halt()
        } catch (e: RuntimeException) {
            // halt must not throw; if it does the camera is going away anyway.
        }
        guard.stopped(reason)
        gate.clear()
        publish()
    }

    /** Begins a phase of the probe ([fresh]: from its first step, forgetting earlier levels). */
    private fun beginProbe(step: PixelProbe.Step, fresh: Boolean = true) {
        metering = false
        reprobing = false
        probing = step
        if (fresh) probeLevels.clear()
        probeFrames.clear()
        probeResults.clear()
        probeStarts.clear()
        probeFramesSeen = 0
        if (!black) guard.requestChanged()
        gate.clear()
        camera.probe(PixelProbe.transform(step, session.transform), PixelProbe.curve(step), controller.gains.copyOf())
    }

    private fun beginMetering() {
        probing = null
        reprobing = false
        metering = true
        inRun = false
        guard.requestChanged()
        gate.clear()
        camera.meter()
    }

    /** Sends new values: nothing is protected until a result of them verifies. */
    private fun sendProtected() {
        // The values come from a metering result; never send an empty curve.
        check(session.curvePoints >= 2) { "no CamPro values yet: the session has not been updated from a metering result" }
        metering = false
        black = false
        guard.requestChanged(controller.gains.copyOf(), meteredPhysicalId)
        gate.clear()
        sendBurst()
    }

    /**
     * Sends the current values again with the current burst (the metering plan changed, or a
     * re-probe begins or ends): the values are the same, so the verdicts stand.
     */
    private fun sendBurst() {
        val burst = if (!perFrameControl) null else Burst(
            controller.meteringInterval, controller.meteringRun,
            if (!reprobing) emptyList() else PROBE_STEPS.map { ProbeRequest(PixelProbe.transform(it, session.transform), PixelProbe.curve(it)) },
        )
        camera.protect(session.transform.copyOf(), session.curvesForRequest(), controller.gains.copyOf(), burst)
    }

    /** Runs [body]; any exception stops the loop closed with its message. */
    private inline fun guarded(body: () -> Unit) {
        try {
            body()
        } catch (e: Exception) {
            running = false
            guard.stopped("stopped: ${e.javaClass.simpleName}: ${e.message}", Problem.Other)
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
        /** Re-probe intervals without a judged probe frame after which the re-probe gives up: Unsupported. */
        const val REPROBE_LIMIT = 4
        /** `CameraMetadata.SYNC_MAX_LATENCY_PER_FRAME_CONTROL`. */
        const val SYNC_MAX_LATENCY_PER_FRAME_CONTROL = 0
        /** The probe's steps, in the order the phased probe runs them. */
        private val PROBE_STEPS = listOf(PixelProbe.Step.Curve, PixelProbe.Step.Matrix)

        /**
         * Frames the protected stream's image queue must hold for a camera whose results
         * may lead or trail their images by [pipelineDepth] (`REQUEST_PIPELINE_MAX_DEPTH`):
         * that many wait for their results, one is with the app, one arrives (4..16).
         */
        @JvmStatic
        fun imageQueueDepth(pipelineDepth: Int): Int = (pipelineDepth + 2).coerceIn(4, 16)
    }
}

/**
 * Matches Camera2's lost-buffer callbacks to sensor timestamps: `onCaptureBufferLost` names a
 * frame number, and may come before that capture's `onCaptureStarted`, which gives the
 * timestamp. Either order reaches [onLost] once with the timestamp. Plain Kotlin; the glue
 * calls it on the camera thread (synchronized all the same: CameraX may call from others).
 */
class LostBuffers(private val onLost: (Long) -> Unit) {
    /** Started captures not yet matched, by frame number: their timestamps. */
    private val started = object : LinkedHashMap<Long, Long>() {
        override fun removeEldestEntry(eldest: MutableMap.MutableEntry<Long, Long>?) = size > KEPT
    }
    /** Frame numbers whose buffer was lost before their capture started. */
    private val lostEarly = object : LinkedHashSet<Long>() {}

    /** `onCaptureStarted` of a protected capture. */
    fun started(frameNumber: Long, timestampNs: Long) {
        val lost = synchronized(this) {
            if (lostEarly.remove(frameNumber)) true else {
                started[frameNumber] = timestampNs
                false
            }
        }
        if (lost) onLost(timestampNs)
    }

    /** `onCaptureBufferLost` of a protected capture's buffer. */
    fun lost(frameNumber: Long) {
        val ts = synchronized(this) {
            started.remove(frameNumber) ?: run {
                lostEarly += frameNumber
                while (lostEarly.size > KEPT) lostEarly.remove(lostEarly.first())
                null
            }
        }
        if (ts != null) onLost(ts)
    }

    private companion object {
        /** Captures remembered: more than any pipeline holds in flight. */
        const val KEPT = 64
    }
}
