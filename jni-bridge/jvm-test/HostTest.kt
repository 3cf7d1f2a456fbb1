// Host JVM test of libcampro_jni.so through the real Kotlin wrapper (org.campro.*).
// Run by jni-bridge/tests/jvm_host.rs:  java -cp host-test.jar HostTestKt <lib.so> <cases.txt> <soakUpdates>
// Prints "PASS name", "FAIL name: why" and "TIMING key=value"; exits 1 on any failure.

import org.campro.CamProController
import org.campro.Problem
import org.campro.CamProNative
import org.campro.CamProSession
import org.campro.CaptureReport
import org.campro.DeviceSupport
import org.campro.FrameGate
import org.campro.ProtectionGuard
import org.campro.ProtectionState
import org.campro.TestHooks
import java.io.File
import java.util.concurrent.atomic.AtomicInteger
import kotlin.concurrent.thread

var failures = 0

fun check(name: String, body: () -> Unit) {
    try {
        body()
        println("PASS $name")
    } catch (e: Throwable) {
        failures++
        println("FAIL $name: $e")
    }
}

fun expect(cond: Boolean, msg: () -> String) {
    if (!cond) throw AssertionError(msg())
}

inline fun <reified T : Throwable> throws(contains: String, body: () -> Unit) {
    try {
        body()
    } catch (e: Throwable) {
        expect(e is T) { "expected ${T::class.simpleName}, got $e" }
        expect(e.message?.contains(contains) == true) { "message '${e.message}' lacks '$contains'" }
        return
    }
    throw AssertionError("expected ${T::class.simpleName} containing '$contains', nothing thrown")
}

/** One expected conversion, written by the Rust core. */
class Case(val name: String) {
    var params = ""
    var maxPoints = 64
    var maxDen = 65536
    var device: IntArray? = null
    var dng: Triple<Int, IntArray, Pair<Int, IntArray>>? = null
    var ct = 0.0
    var transform = IntArray(18)
    val curves = Array(3) { FloatArray(0) }
    var report = DoubleArray(0)
}

fun readCases(path: String): List<Case> {
    val cases = mutableListOf<Case>()
    var c: Case? = null
    for (line in File(path).readLines()) {
        val t = line.trim().split(Regex("\\s+"))
        if (t.isEmpty() || t[0].isEmpty()) continue
        val ints = { from: Int, n: Int -> IntArray(n) { t[from + it].toInt() } }
        when (t[0]) {
            "case" -> c = Case(t[1]).also { cases += it }
            "params" -> c!!.params = t[1]
            "opts" -> { c!!.maxPoints = t[1].toInt(); c.maxDen = t[2].toInt() }
            "device" -> c!!.device = ints(1, 18)
            "dng" -> { c!!.dng = Triple(t[1].toInt(), ints(2, 18), Pair(t[20].toInt(), ints(21, 18))); c.ct = t[39].toDouble() }
            "transform" -> c!!.transform = ints(1, 18)
            "curve" -> c!!.curves[t[1].toInt()] = FloatArray(t.size - 2) { java.lang.Float.intBitsToFloat(t[2 + it].toInt()) }
            "report" -> c!!.report = DoubleArray(t.size - 1) { java.lang.Double.longBitsToDouble(t[1 + it].toLong()) }
            else -> error("bad cases line: $line")
        }
    }
    return cases
}

fun update(s: CamProSession, c: Case): Boolean {
    val d = c.dng
    return if (d != null) {
        s.setDngCalibration(d.first, d.second, d.third.first, d.third.second)
        s.updateFromColorTemperature(c.ct)
    } else {
        s.updateFromTransform(c.device!!)
    }
}

fun valuesEqualTheCore(cases: List<Case>) {
    for (c in cases) {
        check("values ${c.name}") {
            CamProSession.fromBytes(File(c.params).readBytes(), c.maxPoints, c.maxDen, 0.0).use { s ->
                expect(update(s, c)) { "first update must recompute" }
                expect(s.transform.contentEquals(c.transform)) { "transform ${s.transform.toList()} != ${c.transform.toList()}" }
                for ((ch, sent) in s.curvesForRequest().withIndex()) {
                    val want = c.curves[ch]
                    expect(sent.size == want.size) { "curve $ch size ${sent.size} != ${want.size}" }
                    for (i in sent.indices) expect(sent[i].toRawBits() == want[i].toRawBits()) { "curve $ch [$i] ${sent[i]} != ${want[i]}" }
                }
                for (k in 1 until CamProNative.REPORT_LEN) {
                    expect(s.report[k].toRawBits() == c.report[k].toRawBits()) { "report[$k] ${s.report[k]} != ${c.report[k]}" }
                }
                expect(s.report[CamProNative.REPORT_RECOMPUTED] == 1.0) { "recomputed flag" }
                // Same inputs again: nothing to do, same values.
                expect(!update(s, c)) { "unchanged inputs must not recompute" }
                expect(s.transform.contentEquals(c.transform) && s.report[CamProNative.REPORT_RECOMPUTED] == 0.0) { "values kept" }
            }
        }
    }
}

val ID = intArrayOf(1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1)
val PHONE = intArrayOf(178, 100, -62, 100, -16, 100, -28, 100, 162, 100, -34, 100, 2, 100, -71, 100, 169, 100)

fun badInput(paramsJson: String) {
    check("malformed JSON names the problem") {
        throws<IllegalArgumentException>("params") { CamProSession.fromJson("{not json") }
        throws<IllegalArgumentException>("ccm") { CamProSession.fromJson(paramsJson.replace("\"ccm\"", "\"ccm_typo\"")) }
        throws<IllegalArgumentException>("paramsJson: must not be null") { CamProNative.create(null, 64, 65536, 0.0) }
        throws<IllegalArgumentException>("not UTF-8") { CamProSession.fromBytes(byteArrayOf(0xff.toByte(), 0xfe.toByte())) }
    }
    check("bad options name the option") {
        throws<IllegalArgumentException>("skip_tolerance") { CamProSession.fromJson(paramsJson, skipTolerance = Double.NaN) }
        throws<IllegalArgumentException>("maxCurvePoints") { CamProSession.fromJson(paramsJson, maxCurvePoints = 0) }
        throws<IllegalArgumentException>("max_curve_points") { CamProSession.fromJson(paramsJson, maxCurvePoints = 1) }
        throws<IllegalArgumentException>("maxDenominator") { CamProSession.fromJson(paramsJson, maxDenominator = -5) }
    }
    CamProSession.fromJson(paramsJson).use { s ->
        val t = IntArray(18); val c = FloatArray(3 * 128); val r = DoubleArray(CamProNative.REPORT_LEN)
        val h = handleOf(s)
        check("wrong array sizes and nulls name the array") {
            throws<IllegalArgumentException>("deviceTransform: must have 18 elements, got 9") { s.updateFromTransform(IntArray(9)) }
            throws<IllegalArgumentException>("outTransform: must have exactly 18 elements, got 17") { CamProNative.updateFromTransform(h, ID, IntArray(17), c, r) }
            throws<IllegalArgumentException>("outCurve: must have at least 384 elements, got 10") { CamProNative.updateFromTransform(h, ID, t, FloatArray(10), r) }
            throws<IllegalArgumentException>("outReport: must have at least 11 elements, got 2") { CamProNative.updateFromTransform(h, ID, t, c, DoubleArray(2)) }
            throws<IllegalArgumentException>("deviceTransform: must not be null") { CamProNative.updateFromTransform(h, null, t, c, r) }
            throws<IllegalArgumentException>("outCurve: must not be null") { CamProNative.updateFromTransform(h, ID, t, null, r) }
        }
        check("bad numbers are named") {
            val zeroDen = ID.copyOf().also { it[3] = 0 }
            throws<IllegalArgumentException>("deviceTransform.colorCorrectionTransform[3]") { s.updateFromTransform(zeroDen) }
            throws<IllegalArgumentException>("ct_kelvin") { s.setDngCalibration(17, ID, 21, ID); s.updateFromColorTemperature(Double.NaN) }
            throws<IllegalArgumentException>("illuminant1") { s.setDngCalibration(99, ID, 21, ID) }
            throws<IllegalArgumentException>("forwardMatrix2: must have 18 elements") { s.setDngCalibration(17, ID, 21, IntArray(3)) }
            val huge = ID.copyOf().also { it[0] = Int.MAX_VALUE }
            throws<IllegalArgumentException>("device_ccm[0][0]") { s.updateFromTransform(huge) }
        }
        check("a rejected update leaves the session usable") {
            expect(s.updateFromTransform(PHONE)) { "recomputes" }
            expect(s.bound < 0.5 / 255) { "bound ${s.bound}" }
        }
    }
    check("colour temperature without a calibration is a state error") {
        CamProSession.fromJson(paramsJson).use { s -> throws<IllegalStateException>("ct_calibration") { s.updateFromColorTemperature(5000.0) } }
    }
    check("closed and foreign handles throw IllegalStateException") {
        val s = CamProSession.fromJson(paramsJson)
        val h = handleOf(s)
        s.close()
        s.close() // idempotent in the wrapper
        throws<IllegalStateException>("closed") { s.updateFromTransform(ID) }
        throws<IllegalStateException>("is closed or was never issued") { CamProNative.updateFromTransform(h, ID, IntArray(18), FloatArray(128), DoubleArray(8)) }
        throws<IllegalStateException>("is closed or was never issued") { CamProNative.close(h) }
        throws<IllegalStateException>("is closed or was never issued") { CamProNative.updateFromTransform(12345L, ID, IntArray(18), FloatArray(128), DoubleArray(8)) }
        throws<IllegalStateException>("is closed or was never issued") { CamProNative.setMaxCurvePoints(-1L, 64) }
    }
    check("assets exist only on Android") {
        throws<IllegalStateException>("only on Android") { CamProNative.createFromAsset(Any(), "params/identity.json", 64, 65536, 0.0) }
        throws<IllegalArgumentException>("assetManager: must not be null") { CamProNative.createFromAsset(null, "x", 64, 65536, 0.0) }
    }
    check("a native panic arrives as RuntimeException and the library keeps working") {
        throws<RuntimeException>("campro internal error: self-test panic: boom") { TestHooks.selfTestPanic("boom") }
        CamProSession.fromJson(paramsJson).use { s -> expect(s.updateFromTransform(PHONE)) { "works after a panic" } }
    }
}

fun handleOf(s: CamProSession): Long {
    val f = CamProSession::class.java.getDeclaredField("handle")
    f.isAccessible = true
    return f.getLong(s)
}

fun readbackAndController(paramsJson: String) {
    check("readback of an exact device is zero; of a deviating one, positive") {
        CamProSession.fromJson(paramsJson).use { s ->
            s.updateFromTransform(PHONE)
            val ctl = CamProController(s)
            expect(ctl.onProtectedResult(s.transform, s.curvesForRequest().toList()) == 0.0) { "exact readback" }
            val off = s.transform.copyOf().also { it[0] = it[0] + 1 }
            val b = ctl.onProtectedResult(off, s.curvesForRequest().toList())
            expect(b > 0.0 && ctl.worstReadbackBound == b) { "deviation $b" }
            throws<IllegalArgumentException>("reportedCurves") { ctl.onProtectedResult(s.transform, listOf(FloatArray(4))) }
            throws<IllegalArgumentException>("reported.tonemapCurve.red") { ctl.onProtectedResult(s.transform, List(3) { FloatArray(3) }) }
        }
    }
    check("controller: rebuild on first result, on a moved transform or moved gains, not otherwise") {
        CamProSession.fromJson(paramsJson).use { s ->
            val ctl = CamProController(s, baseInterval = 12)
            val g = floatArrayOf(2.0f, 1.0f, 1.0f, 1.6f)
            expect(ctl.onMeteringResult(PHONE, g)) { "first" }
            expect(!ctl.onMeteringResult(PHONE, g)) { "same" }
            expect(!ctl.onMeteringResult(PHONE, floatArrayOf(2.0001f, 1.0f, 1.0f, 1.6f))) { "gain moved 5e-5 relative" }
            expect(!ctl.onMeteringResult(PHONE, floatArrayOf(2.03f, 1.0f, 1.0f, 1.6f))) { "gain moved 1.5%: inside the 2% band" }
            expect(ctl.onMeteringResult(PHONE, floatArrayOf(2.1f, 1.0f, 1.0f, 1.6f))) { "gain moved 5%" }
            val moved = PHONE.copyOf().also { it[0] = 150 }
            expect(ctl.onMeteringResult(moved, floatArrayOf(2.1f, 1.0f, 1.0f, 1.6f))) { "transform moved" }
            expect(ctl.rebuilds == 3L && ctl.meteringResults == 6L) { "counts ${ctl.rebuilds}/${ctl.meteringResults}" }
            // A run of 3 metering frames (the default) in a burst of 12; a run without CONVERGED doubles it.
            expect(ctl.meteringRun == 3 && ctl.meteringInterval == 12) { "plan ${ctl.meteringRun}/${ctl.meteringInterval}" }
            expect(ctl.runEnded(converged = false, rebuilt = false) && ctl.meteringRun == 6 && ctl.meteringInterval == 24) { "grown ${ctl.meteringRun}/${ctl.meteringInterval}" }
            expect(ctl.status().startsWith("CamPro on")) { ctl.status() }
            throws<IllegalArgumentException>("gains[2]") { ctl.onMeteringResult(PHONE, floatArrayOf(1f, 1f, Float.NaN, 1f)) }
            throws<IllegalArgumentException>("baseInterval") { CamProController(s, baseInterval = 3) }
        }
    }
    check("device support follows Camera2's rules") {
        val ok = DeviceSupport.check(intArrayOf(0, 2), intArrayOf(0, 1, 2), 64, intArrayOf(0, 1))
        expect(ok == DeviceSupport.Result.Supported(64, null)) { "$ok" }
        val few = DeviceSupport.check(intArrayOf(0, 2), intArrayOf(0, 1, 2), 32, intArrayOf(0, 1))
        expect(few is DeviceSupport.Result.Supported && few.note!!.contains("32")) { "$few" }
        val none = DeviceSupport.check(intArrayOf(0), intArrayOf(1, 2), null, intArrayOf(1))
        expect(none is DeviceSupport.Result.Unsupported && none.reasons.size == 3) { "$none" }
        expect((none as DeviceSupport.Result.Unsupported).reasons[0].contains("MANUAL_POST_PROCESSING")) { "$none" }
    }
    check("setMaxCurvePoints refits the curve to the new budget") {
        CamProSession.fromJson(paramsJson).use { s ->
            s.updateFromTransform(PHONE)
            s.setMaxCurvePoints(8)
            expect(s.updateFromTransform(PHONE)) { "recompute after a budget change" }
            expect(s.curvePoints <= 8 && s.curve.size == 3 * 16) { "points ${s.curvePoints}" }
            throws<IllegalArgumentException>("maxCurvePoints") { s.setMaxCurvePoints(1) }
        }
    }
}

fun threads(paramsJson: String) {
    check("one session shared by 4 threads; 4 sessions in parallel") {
        CamProSession.fromJson(paramsJson, skipTolerance = 0.0).use { shared ->
            shared.updateFromTransform(PHONE)
            val want = shared.transform.copyOf()
            val bad = AtomicInteger()
            val ts = (0 until 4).map { k ->
                thread {
                    CamProSession.fromJson(paramsJson, skipTolerance = 0.0).use { own ->
                        val m = PHONE.copyOf()
                        for (i in 0 until 20000) {
                            m[0] = 170 + (i + k) % 16
                            own.updateFromTransform(m)
                            synchronized(shared) {
                                shared.updateFromTransform(if (i % 2 == 0) PHONE else m)
                                if (i % 2 == 0 && !shared.transform.contentEquals(want)) bad.incrementAndGet()
                            }
                        }
                    }
                }
            }
            ts.forEach { it.join() }
            expect(bad.get() == 0) { "${bad.get()} inconsistent reads" }
        }
    }
}

fun rssKb(): Long = File("/proc/self/status").readLines().first { it.startsWith("VmRSS:") }.split(Regex("\\s+"))[1].toLong()

fun median(v: LongArray): Long = v.sorted()[v.size / 2]

fun soak(paramsJson: String, updates: Int) {
    check("$updates updates: no leak, no slow-down") {
        val liveBefore = CamProNative.liveHandles()
        CamProSession.fromJson(paramsJson).use { s ->
            val a = PHONE
            val b = PHONE.copyOf().also { it[0] = 171; it[8] = 160 }
            // Warm up the JIT, then take the baseline.
            for (i in 0 until 50000) s.updateFromTransform(if (i % 2 == 0) a else b)
            System.gc()
            val rss0 = rssKb()
            val batch = 10000
            val batches = updates / batch
            val skipNs = LongArray(batches)
            var recomputes = 0L
            for (k in 0 until batches) {
                // Steady scene: the skip path (what most frames cost).
                val t0 = System.nanoTime()
                for (i in 0 until batch) if (s.updateFromTransform(a)) recomputes++
                skipNs[k] = (System.nanoTime() - t0) / batch
            }
            val recompNs = LongArray(batches / 10)
            for (k in recompNs.indices) {
                // The scene flips every frame: a full recompute each time.
                val t0 = System.nanoTime()
                for (i in 0 until batch) s.updateFromTransform(if (i % 2 == 0) a else b)
                recompNs[k] = (System.nanoTime() - t0) / batch
            }
            System.gc()
            val rss1 = rssKb()
            val q = maxOf(1, batches / 10)
            val early = median(skipNs.copyOfRange(0, q))
            val late = median(skipNs.copyOfRange(batches - q, batches))
            println("TIMING skip_update_median_ns=${median(skipNs)}")
            println("TIMING recompute_update_median_ns=${median(recompNs)}")
            println("TIMING skip_early_ns=$early skip_late_ns=$late")
            println("TIMING rss_growth_kb=${rss1 - rss0}")
            expect(recomputes <= 1) { "a steady scene recomputed $recomputes times" }
            // Generous: a leak or per-call growth shows as a multiple, not a few percent.
            expect(late <= 3 * early + 2000) { "slowed down: ${early}ns -> ${late}ns per update" }
            expect(rss1 - rss0 < 64 * 1024) { "RSS grew ${rss1 - rss0} kB over $updates updates" }
        }
        for (i in 0 until 2000) CamProSession.fromJson(paramsJson).use { it.updateFromTransform(PHONE) }
        expect(CamProNative.liveHandles() == liveBefore) { "handles leaked: ${CamProNative.liveHandles()} live, $liveBefore before" }
    }
}

/** A result that honours the request: modes as asked, the sent transform and curve on all channels. */
fun honoured(s: CamProSession): CaptureReport {
    return CaptureReport(0, 0, 0, s.transform.copyOf(), s.curvesForRequest().toList())
}

fun CaptureReport.with(
    awbMode: Int? = this.awbMode,
    colorCorrectionMode: Int? = this.colorCorrectionMode,
    tonemapMode: Int? = this.tonemapMode,
    transform: IntArray? = this.transform,
    curves: List<FloatArray>? = this.curves,
) = CaptureReport(awbMode, colorCorrectionMode, tonemapMode, transform, curves)

fun violated(st: ProtectionState, needle: String) = st is ProtectionState.Violated && st.reason.contains(needle)

fun failClosed(paramsJson: String) {
    check("fail closed: a device that honours the request is Protected after its first result") {
        CamProSession.fromJson(paramsJson).use { s ->
            s.updateFromTransform(PHONE)
            val g = ProtectionGuard(s)
            expect(g.state == ProtectionState.Verifying && !g.framesAllowed) { "starts Verifying, closed" }
            expect(g.onProtectedResult(honoured(s)) == ProtectionState.Protected && g.framesAllowed) { "${g.state}" }
            // A device that reports the curve with more points (here 2n - 1: every sent point and
            // each segment's midpoint) applies the same curve: still Protected.
            val c = s.curvesForRequest()[0]
            val dense = FloatArray(2 * (2 * (c.size / 2) - 1))
            var k = 0
            for (i in 0 until c.size / 2) {
                if (i > 0) { dense[k++] = (c[2 * i - 2] + c[2 * i]) / 2; dense[k++] = (c[2 * i - 1] + c[2 * i + 1]) / 2 }
                dense[k++] = c[2 * i]; dense[k++] = c[2 * i + 1]
            }
            expect(g.onProtectedResult(honoured(s).with(curves = listOf(dense, dense, dense))) == ProtectionState.Protected) { "${g.state}" }
        }
    }
    check("fail closed: an ignored transform, an ignored curve, AWB back on, wrong modes are violations") {
        CamProSession.fromJson(paramsJson).use { s ->
            s.updateFromTransform(PHONE)
            val g = ProtectionGuard(s)
            val ok = honoured(s)
            // The device kept its own transform (what auto mode reported) instead of CamPro's.
            expect(violated(g.onProtectedResult(ok.with(transform = PHONE)), "transform differs")) { "${g.state}" }
            expect(!g.framesAllowed) { "closed" }
            val line = floatArrayOf(0f, 0f, 1f, 1f)
            expect(violated(g.onProtectedResult(ok.with(curves = listOf(line, line, line))), "curve differs")) { "${g.state}" }
            // One channel only ignored is enough.
            val (r, gr, _) = s.curvesForRequest()
            expect(violated(g.onProtectedResult(ok.with(curves = listOf(r, gr, line))), "channel B")) { "${g.state}" }
            expect(violated(g.onProtectedResult(ok.with(awbMode = 1)), "auto white balance is on")) { "${g.state}" }
            expect(violated(g.onProtectedResult(ok.with(colorCorrectionMode = 1)), "instead of TRANSFORM_MATRIX")) { "${g.state}" }
            expect(violated(g.onProtectedResult(ok.with(tonemapMode = 2)), "instead of CONTRAST_CURVE")) { "${g.state}" }
            expect(violated(g.onProtectedResult(ok.with(transform = IntArray(5))), "not 18")) { "${g.state}" }
            expect(violated(g.onProtectedResult(ok.with(transform = IntArray(18))), "do not read back")) { "${g.state}" }
        }
    }
    check("fail closed: missing keys are violations unless the app trusts the device") {
        CamProSession.fromJson(paramsJson).use { s ->
            s.updateFromTransform(PHONE)
            val ok = honoured(s)
            val strict = ProtectionGuard(s)
            expect(violated(strict.onProtectedResult(ok.with(transform = null)), "does not report COLOR_CORRECTION_TRANSFORM")) { "${strict.state}" }
            expect(violated(strict.onProtectedResult(ok.with(curves = null)), "does not report TONEMAP_CURVE")) { "${strict.state}" }
            expect(violated(strict.onProtectedResult(ok.with(awbMode = null)), "CONTROL_AWB_MODE")) { "${strict.state}" }
            val trusting = ProtectionGuard(s, trustMissingKeys = true)
            expect(trusting.onProtectedResult(ok.with(transform = null, curves = null)) == ProtectionState.Protected) { "${trusting.state}" }
            // Trust covers absent keys, never wrong ones.
            expect(violated(trusting.onProtectedResult(ok.with(transform = null, awbMode = 1)), "auto white balance")) { "${trusting.state}" }
        }
    }
    check("fail closed: a change mid-stream and back; a new request verifies again; unsupported is final") {
        CamProSession.fromJson(paramsJson).use { s ->
            s.updateFromTransform(PHONE)
            val g = ProtectionGuard(s)
            val seq = listOf(honoured(s), honoured(s), honoured(s).with(awbMode = 1), honoured(s).with(transform = PHONE), honoured(s))
            val states = seq.map { g.onProtectedResult(it).javaClass.simpleName }
            expect(states == listOf("Protected", "Protected", "Violated", "Violated", "Protected")) { "$states" }
            g.requestChanged()
            expect(g.state == ProtectionState.Verifying && !g.framesAllowed) { "${g.state}" }
            g.unsupported("no CONTRAST_CURVE")
            expect(g.onProtectedResult(honoured(s)) == ProtectionState.Unsupported("no CONTRAST_CURVE", Problem.DeviceCapability)) { "${g.state}" }
            g.requestChanged()
            expect(g.state is ProtectionState.Unsupported) { "${g.state}" }
        }
    }
    check("fail closed: each frame waits for its own result; unverified frames never reach the app") {
        CamProSession.fromJson(paramsJson).use { s ->
            s.updateFromTransform(PHONE)
            val got = mutableListOf<Int>()
            val closed = mutableListOf<Int>()
            val gate = FrameGate<Int>(ProtectionGuard(s), maxWaitingFrames = 2, maxPendingVerdicts = 2, executor = { it.run() }, deliver = { got += it }, drop = { closed += it })
            gate.onFrame(100, 1)
            expect(got.isEmpty()) { "held until its result" }
            gate.onResult(100, honoured(s))
            gate.onFrame(200, 2)
            gate.onResult(200, honoured(s).with(awbMode = 1)) // this very frame was not protected
            gate.onResult(300, honoured(s)) // result before its frame
            gate.onFrame(300, 3)
            gate.onFrame(400, 4); gate.onFrame(500, 5); gate.onFrame(600, 6) // results never come
            gate.clear()
            expect(got == listOf(1, 3)) { "delivered $got" }
            expect(closed == listOf(2, 4, 5, 6)) { "dropped $closed" }
            expect(gate.delivered == 2L && gate.dropped == 4L) { "${gate.delivered}/${gate.dropped}" }
        }
    }
}

fun main(args: Array<String>) {
    val cases = readCases(args[1])
    val soakUpdates = args[2].toInt()
    val paramsJson = File(cases.first().params).readText()
    // The library loads itself (from java.library.path, as from an APK) at the first session.
    expect(!CamProNative.isLoaded) { "loaded before any session" }
    CamProSession.fromJson(paramsJson).close()
    expect(CamProNative.isLoaded) { "a session did not load libcampro_jni" }
    CamProNative.load(args[0]) // a no-op now
    valuesEqualTheCore(cases)
    badInput(paramsJson)
    readbackAndController(paramsJson)
    failClosed(paramsJson)
    threads(paramsJson)
    soak(paramsJson, soakUpdates)
    println(if (failures == 0) "ALL PASSED (${cases.size} value cases)" else "$failures FAILED")
    System.exit(if (failures == 0) 0 else 1)
}
