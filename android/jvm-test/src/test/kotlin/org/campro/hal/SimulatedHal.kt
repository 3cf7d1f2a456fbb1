package org.campro.hal

import org.campro.Burst
import org.campro.CamProNative
import org.campro.LostBuffers
import org.campro.CamProPipeline
import org.campro.CameraRequests
import org.campro.CaptureReport
import org.campro.MeteringReport

/**
 * The core's emulator and desktop pipeline, for the simulated camera (`jni-bridge`, built
 * with its `test-exports` feature; never in an app's library).
 */
object HalNative {
    /**
     * What a device applying [transform], the curves in [curve] (channel c's `counts[c]`
     * floats from `c * stride`) and [gains] makes of linear sensor RGB [raw]: 8-bit codes.
     */
    @JvmStatic external fun emulate(transform: IntArray, curve: FloatArray, stride: Int, counts: IntArray, gains: FloatArray, raw: FloatArray, out: ByteArray)

    /** What the desktop pipeline of [handle]'s parameters makes of the scene the device renders with [deviceTransform] and [gains]. */
    @JvmStatic external fun desktop(handle: Long, deviceTransform: IntArray, gains: FloatArray, raw: FloatArray, out: ByteArray)
}

/**
 * How one simulated HAL departs from a camera that applies every request at once and
 * reports exactly what it applied; each is a latitude the Camera2 documentation gives or
 * a fault seen on shipping devices.
 */
data class Behaviour(
    val name: String,
    /** Frames until a request's settings apply (`SYNC_MAX_LATENCY`; 0: per-frame control). */
    val latency: Int = 0,
    /** Matrix entries applied (and reported) rounded to 1/[matrixStep] (0: exact). */
    val matrixStep: Int = 0,
    /** The curve applied (and reported) resampled to this many evenly spaced points (0: as sent). */
    val curvePoints: Int = 0,
    /** `image.timestamp` minus `SENSOR_TIMESTAMP` on the protected stream (a display or readout timestamp base). */
    val imageTimestampOffsetNs: Long = 0,
    /** Results arrive this many frames after their image (at least; see [resultDelayMax]). */
    val resultDelay: Int = 0,
    /** Results arrive up to this many frames after their image, varying frame to frame (at most [resultDelay] when smaller). */
    val resultDelayMax: Int = 0,
    /** `REQUEST_PIPELINE_MAX_DEPTH` the camera reports (0: 4 more than the largest result delay). */
    val pipelineMaxDepth: Int = 0,
    /** The results of each pair of frames arrive swapped. */
    val swapResults: Boolean = false,
    /** Every n-th result never arrives (0: none lost). */
    val loseResultEvery: Int = 0,
    /** Reports the requested transform and curve while applying its own default curve (on the protected stream; the small metering stream stays honest). */
    val echo: Boolean = false,
    /** From this frame on the HAL echoes ([echo]): a mode switch (HDR, low-light binning) mid-session (-1: never). */
    val echoFrom: Int = -1,
    /**
     * Frames from [faultFrom] until [faultUntil] are made with the device's automatic settings
     * whatever was asked, and their results say so (a passing fault, e.g. a 3A override: the
     * HAL recovers).
     */
    val faultFrom: Int = -1,
    val faultUntil: Int = -1,
    /** Reports the requested transform while applying the sensor's own (auto-mode) one. */
    val ignoreTransform: Boolean = false,
    /** A singular requested transform is refused: the identity is applied and reported instead (some HALs). */
    val singularToIdentity: Boolean = false,
    /** The scene is one flat colour (a covered lens, a blank wall). */
    val flatScene: Boolean = false,
    /** The frame from which a logical camera streams from its second physical sensor (-1: never). */
    val physicalSwitchAt: Int = -1,
    /** The frame from which the light changes: the first sensor's auto transform becomes the third one given (-1: never). */
    val lightChangeAt: Int = -1,
    /** The frame at which the camera is disconnected (-1: never). */
    val disconnectAt: Int = -1,
    /** AUTO frames after a switch into AUTO before AWB reports CONVERGED. */
    val awbSettleFrames: Int = 0,
    /** Results leave out `CONTROL_AWB_STATE`. */
    val awbStateAbsent: Boolean = false,
    /** `CONTROL_AWB_STATE` reported for a frame made with AWB off (a conforming HAL says INACTIVE, 0). */
    val offFrameAwbState: Int = 0,
    /** Frames in this range are black whatever the settings (the camera privacy toggle), their results as usual. */
    val blackFrames: IntRange = IntRange.EMPTY,
    /** Every output code moves by up to this much (noise or dither after the curve; deterministic), rounded. */
    val noiseCodes: Double = 0.0,
    /** Metering results report gains off by up to this relative amount, frame to frame (AWB jitter). */
    val gainJitter: Double = 0.0,
    /** `onCaptureBufferLost` comes before that capture's `onCaptureStarted`. */
    val bufferLostBeforeStart: Boolean = false,
) {
    /** The largest result delay. */
    val maxDelay: Int get() = maxOf(resultDelay, resultDelayMax)

    /** `REQUEST_PIPELINE_MAX_DEPTH` as the camera reports it. */
    val pipelineDepth: Int get() = if (pipelineMaxDepth > 0) pipelineMaxDepth else 4 + maxDelay
}

/**
 * One frame as the app would receive it: its index, its pixels and the pixels CamPro
 * promises; after a light change also [before], the protected output under the old light
 * (frames still made with the values metered before the change).
 */
class SimFrame(
    val index: Int,
    val pixels: ByteArray,
    val expected: ByteArray,
    val before: ByteArray? = null,
    /** The image's timestamp, nanoseconds (the sensor's, unless the HAL offsets it). */
    val timestampNs: Long = 0,
    private val onClose: () -> Unit = {},
) : AutoCloseable {
    private var closed = false

    /** Gives its buffer back to the stream (an `Image.close()`); twice is a test failure. */
    override fun close() {
        check(!closed) { "frame $index closed twice" }
        closed = true
        onClose()
    }
}

/**
 * A simulated Camera2 device: requests in, frames and results out, the pixels of each frame
 * computed by the core's emulator from the settings the device *applied* to it (not the
 * request), on a fixed scene of linear sensor colours. It drives a [CamProPipeline] as the
 * Android glue does: protected frames to `onFrame`, their results to `onProtectedResult`,
 * auto-mode results to `onMeteringResult`.
 */
class SimulatedHal(
    private val b: Behaviour,
    /** Linear sensor RGB of the scene, 3 floats a pixel. */
    private val scene: FloatArray,
    /** The physical sensors' auto-mode transforms (a logical camera switches from the first to the second; the third is the first's after a light change). */
    private val sensors: List<IntArray>,
    private val autoGains: FloatArray,
    /** A handle of CamProNative with the same parameters as the pipeline's session (the reference). */
    private val reference: Long,
    /** Buffers of the protected stream (the `ImageReader`'s maxImages): with all of them open, a frame's buffer is lost. */
    private val bufferPool: Int = 6,
) : CameraRequests {
    /** Protected frames handed to the pipeline and not closed yet. */
    private var open = 0

    /** Protected frames whose buffer was lost (every buffer was open). */
    var lostFrames = 0
        private set

    private sealed class Req {
        object Auto : Req()
        /** CamPro-style settings: a protected request, or a probe ([probe]) when [probe] is set. */
        class Protect(val transform: IntArray, val curves: List<FloatArray>, val gains: FloatArray, val probe: Boolean = false) : Req()
    }

    private var repeating: List<Req> = emptyList()
    private var cursor = 0
    /** Requests submitted for the frames so far, newest last: frame i applies entry i - latency. */
    private val submitted = ArrayList<Req?>()
    private var autoRun = 0
    /** Results not yet delivered: (frame due, frame of origin, delivery). */
    private val pendingResults = ArrayList<Triple<Int, Int, () -> Unit>>()

    override fun meter() { setRepeating(listOf(Req.Auto)) }

    override fun protect(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray, burst: Burst?) {
        val p = Req.Protect(transform.copyOf(), curves.map { it.copyOf() }, gains.copyOf())
        setRepeating(
            if (burst == null) listOf(p) else List<Req>(burst.protectedFrames) { p } +
                burst.probes.map { Req.Protect(it.transform.copyOf(), List(3) { _ -> it.curve.copyOf() }, gains.copyOf(), probe = true) } +
                List(burst.meteringRun) { Req.Auto },
        )
    }

    override fun probe(transform: IntArray, curve: FloatArray, gains: FloatArray) {
        setRepeating(listOf(Req.Protect(transform.copyOf(), List(3) { curve.copyOf() }, gains.copyOf(), probe = true)))
    }

    override fun halt() { setRepeating(emptyList()) }

    private fun setRepeating(r: List<Req>) { repeating = r; cursor = 0 }

    /** The sRGB-like curve a device applies when not asked for CamPro's (33 points of x^(1/2.2)). */
    private val defaultCurve = FloatArray(66).also { c ->
        for (i in 0..32) { val x = i / 32f; c[2 * i] = x; c[2 * i + 1] = Math.pow(x.toDouble(), 1 / 2.2).toFloat() }
    }

    private fun resample(curve: FloatArray, n: Int): FloatArray {
        val out = FloatArray(2 * n)
        for (i in 0 until n) {
            val x = i / (n - 1f)
            var k = 0
            while (k < curve.size / 2 - 2 && curve[2 * (k + 1)] < x) k++
            val (x0, y0, x1, y1) = listOf(curve[2 * k], curve[2 * k + 1], curve[2 * k + 2], curve[2 * k + 3])
            out[2 * i] = x
            out[2 * i + 1] = if (x1 > x0) y0 + (y1 - y0) * ((x - x0) / (x1 - x0)).coerceIn(0f, 1f) else y1
        }
        return out
    }

    private fun rounded(t: IntArray, step: Int): IntArray = IntArray(18).also { o ->
        for (i in 0 until 9) {
            o[2 * i] = Math.round(t[2 * i].toDouble() / t[2 * i + 1] * step).toInt()
            o[2 * i + 1] = step
        }
    }

    /** The frame being made (for [blackFrames] and the noise pattern). */
    private var frameNow = 0

    private fun render(transform: IntArray, curves: List<FloatArray>, gains: FloatArray): ByteArray {
        if (frameNow in b.blackFrames) return ByteArray(scene.size)
        val stride = curves.maxOf { it.size }
        val packed = FloatArray(3 * stride)
        for ((c, curve) in curves.withIndex()) curve.copyInto(packed, c * stride)
        val counts = IntArray(3) { curves[it].size }
        val out = ByteArray(scene.size).also { HalNative.emulate(transform, packed, stride, counts, gains, scene, it) }
        if (b.noiseCodes > 0) {
            val rng = java.util.Random(frameNow.toLong())
            for (k in out.indices) out[k] = ((out[k].toInt() and 255) + Math.round((2 * rng.nextDouble() - 1) * b.noiseCodes).toInt()).coerceIn(0, 255).toByte()
        }
        return out
    }

    /** The gains a metering result reports: the true ones, jittered by [Behaviour.gainJitter]. */
    private fun meteredGains(i: Int): FloatArray =
        if (b.gainJitter == 0.0) autoGains.copyOf() else java.util.Random(31L * i).let { r -> FloatArray(4) { (autoGains[it] * (1 + (2 * r.nextDouble() - 1) * b.gainJitter)).toFloat() } }

    /** Lost protected buffers as the Camera2 glue matches them (either callback order). */
    private var lostBuffers: LostBuffers? = null

    /** Runs [frames] frames into [p]; returns the frames that reached the app (through [delivered]). */
    fun run(frames: Int, p: CamProPipeline<SimFrame>, onFrame: (Int) -> Unit = {}) {
        lostBuffers = LostBuffers { ts -> p.onFrameLost(ts) }
        for (i in 0 until frames) {
            frameNow = i
            if (i == b.disconnectAt) {
                p.onCameraStopped("the camera was disconnected")
                repeating = emptyList()
            }
            deliverResults(i)
            if (repeating.isEmpty()) {
                // Nothing repeats: no frame (its slot stays, so frame i still applies entry i - latency).
                submitted += null
                onFrame(i)
                continue
            }
            val tagged = repeating[cursor % repeating.size]
            cursor++
            submitted += tagged
            val applied = if (i in b.faultFrom until b.faultUntil) Req.Auto else submitted.getOrNull(i - b.latency) ?: Req.Auto
            val sensor = if (b.physicalSwitchAt in 0..i) 1 else 0
            val relit = sensor == 0 && b.lightChangeAt in 0..i
            val device = if (relit) sensors[2] else sensors[sensor]
            val physicalId = sensor.toString()
            val ts = 1_000_000_000L + i * 33_333_333L
            // What CamPro promises for this frame: the desktop pipeline under the gains it was made with.
            val madeWith = (applied as? Req.Protect)?.gains ?: autoGains
            val expected = ByteArray(scene.size).also { HalNative.desktop(reference, device, madeWith, scene, it) }
            val before = if (relit) ByteArray(scene.size).also { HalNative.desktop(reference, sensors[0], madeWith, scene, it) } else null
            when (applied) {
                is Req.Auto -> {
                    autoRun++
                    val state = when {
                        autoRun == 1 -> 0 // INACTIVE: the mode just switched
                        autoRun <= 1 + b.awbSettleFrames -> 1 // SEARCHING
                        else -> CamProPipeline.AWB_STATE_CONVERGED
                    }
                    val pixels = render(device, List(3) { defaultCurve }, autoGains)
                    if (tagged is Req.Protect) {
                        // A protected (or probe) request whose frame still carries auto settings: its result says so.
                        val report = CaptureReport(1, 1, 2, device.copyOf(), List(3) { defaultCurve.copyOf() }, autoGains.copyOf(), physicalId)
                        deliver(p, tagged, i, ts, report, pixels, expected, before)
                    } else {
                        val reported = if (b.awbStateAbsent) null else state
                        val gains = meteredGains(i)
                        schedule(i) { p.onMeteringResult(MeteringReport(1, reported, device.copyOf(), gains, physicalId)) }
                    }
                }
                is Req.Protect -> {
                    autoRun = 0
                    val t = when {
                        b.ignoreTransform -> device
                        b.singularToIdentity && singular(applied.transform) -> IDENTITY
                        b.matrixStep > 0 -> rounded(applied.transform, b.matrixStep)
                        else -> applied.transform
                    }
                    val echoing = b.echo || b.echoFrom in 0..i
                    val c = when {
                        echoing -> List(3) { defaultCurve }
                        b.curvePoints > 0 -> applied.curves.map { resample(it, b.curvePoints) }
                        else -> applied.curves
                    }
                    val pixels = render(t, c, applied.gains)
                    val reportedCurves = if (echoing) applied.curves else c
                    val reportedTransform = if (echoing || b.ignoreTransform) applied.transform else t
                    val report = CaptureReport(0, 0, 0, reportedTransform.copyOf(), reportedCurves.map { it.copyOf() }, applied.gains.copyOf(), physicalId)
                    if (tagged is Req.Protect) {
                        deliver(p, tagged, i, ts, report, pixels, expected, before)
                    } else {
                        // A metering request whose frame still carries protected settings: AWB reads OFF.
                        val reported = if (b.awbStateAbsent) null else b.offFrameAwbState
                        schedule(i) { p.onMeteringResult(MeteringReport(0, reported, t.copyOf(), applied.gains.copyOf(), physicalId)) }
                    }
                }
            }
            onFrame(i)
        }
        deliverResults(Int.MAX_VALUE)
    }

    /** Whether the rational transform (18 ints) has determinant 0. */
    private fun singular(t: IntArray): Boolean {
        val m = DoubleArray(9) { t[2 * it].toDouble() / t[2 * it + 1] }
        val det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6])
        return det == 0.0
    }

    /** The identity as a Camera2 rational transform. */
    private val IDENTITY = IntArray(18) { i -> if (i % 2 == 1) 1 else if ((i / 2) % 4 == 0) 1 else 0 }

    /**
     * A frame of a protected or probe request, with its result, to the protected stream (the
     * glue sends the probe there: [CameraRequests.probe]); a probe capture's start is told
     * first, as Camera2's `onCaptureStarted` comes before its image.
     */
    private fun deliver(p: CamProPipeline<SimFrame>, tagged: Req.Protect, i: Int, ts: Long, report: CaptureReport, pixels: ByteArray, expected: ByteArray, before: ByteArray?) {
        val lost = lostBuffers!!
        if (tagged.probe) {
            schedule(i) { p.onProbeResult(ts, report) }
            p.onProbeCaptureStarted(ts)
        } else {
            schedule(i) { p.onProtectedResult(ts, report) }
            if (!(b.bufferLostBeforeStart && open >= bufferPool)) lost.started(i.toLong(), ts)
        }
        if (open >= bufferPool) {
            // No free buffer: the frame is lost, and Camera2 says so (onCaptureBufferLost).
            lostFrames++
            if (!tagged.probe) {
                lost.lost(i.toLong())
                if (b.bufferLostBeforeStart) lost.started(i.toLong(), ts)
            }
            return
        }
        open++
        val imageTs = ts + b.imageTimestampOffsetNs
        p.onFrame(imageTs, SimFrame(i, pixels, expected, before, imageTs) { open-- })
    }

    private fun schedule(frame: Int, result: () -> Unit) {
        if (b.loseResultEvery > 0 && frame % b.loseResultEvery == b.loseResultEvery - 1) return
        // Swapped: each even frame's result waits for the next frame's and comes after it.
        val delay = if (b.resultDelayMax > b.resultDelay) b.resultDelay + frame % (b.resultDelayMax - b.resultDelay + 1) else b.resultDelay
        val at = frame + delay + if (b.swapResults && frame % 2 == 0) 1 else 0
        pendingResults += Triple(at, frame, result)
    }

    private fun deliverResults(upTo: Int) {
        val due = pendingResults.filter { it.first <= upTo }
        pendingResults.removeAll(due)
        val order = if (b.swapResults) compareBy<Triple<Int, Int, () -> Unit>>({ it.first }, { -it.second }) else compareBy({ it.first }, { it.second })
        due.sortedWith(order).forEach { it.third() }
    }

    companion object {
        /** A reference handle for [HalNative.desktop] with the parameters [json]. */
        fun reference(json: String): Long = CamProNative.create(json, 64, 65536, 0.0)
    }
}

/** What a YUV stream's Y plane carries for interleaved 8-bit RGB: BT.601 luma (0..255), rounded. */
fun lumaOfRgb(rgb: ByteArray): ByteArray = ByteArray(rgb.size / 3) { k ->
    val i = 3 * k
    ((299 * (rgb[i].toInt() and 255) + 587 * (rgb[i + 1].toInt() and 255) + 114 * (rgb[i + 2].toInt() and 255) + 500) / 1000).toByte()
}
