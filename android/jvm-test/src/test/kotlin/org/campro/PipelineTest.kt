package org.campro

import org.campro.Fixtures.FakeCamera
import org.campro.Fixtures.QueueExecutor
import org.campro.Fixtures.with
import org.junit.After
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertTrue
import org.junit.Test
import java.util.concurrent.CountDownLatch
import java.util.concurrent.Executor
import java.util.concurrent.Executors
import java.util.concurrent.TimeUnit

/** CamProPipeline on scripted camera sequences: every path a phone can take, on the host JVM. */
class PipelineTest {
    private val session = Fixtures.session()
    private val cam = FakeCamera()
    private val app = QueueExecutor()
    private val shown = mutableListOf<Int>()
    private val closed = mutableListOf<Int>()
    private val states = mutableListOf<ProtectionState>()

    private fun pipeline(perFrame: Boolean = true, depth: Int = 4, queue: Int = 4, trust: Boolean = false) =
        CamProPipeline<Int>(session, cam, app, perFrame, depth, queue, trust, deliver = { shown += it }, drop = { closed += it }, onState = { states += it })

    @After
    fun close() = session.close()

    private fun names() = states.map { it.javaClass.simpleName }

    /** A started pipeline whose first metering result converged: probing the device's pixels. */
    private fun probing(): CamProPipeline<Int> {
        val p = pipeline()
        p.start(Fixtures.supported())
        p.onMeteringResult(Fixtures.converged())
        assertTrue(p.isProbing)
        return p
    }

    /** A probe frame at [ts] whose result reports the probe's settings and whose luma is [luma]. */
    private fun probeFrame(p: CamProPipeline<Int>, ts: Long, luma: (Int) -> Int) {
        p.onProbeResult(ts, cam.honouredProbe())
        p.onProbeFrame(ts, ByteArray(4800) { luma(it).toByte() })
    }

    /** A metering result, then the pixel probe answered as an honest device would. */
    private fun meter(p: CamProPipeline<Int>, m: MeteringReport, camera: FakeCamera = cam) {
        p.onMeteringResult(m)
        Fixtures.answerProbes(p, camera)
    }

    @Test
    fun openMeterProtectViolateRecover() {
        val p = pipeline()
        assertTrue(p.state is ProtectionState.Stopped)
        p.start(Fixtures.supported())
        assertEquals(listOf("meter"), cam.calls)
        // AWB still searching: the transform is not taken yet.
        p.onMeteringResult(MeteringReport(1, 1, intArrayOf(1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), Fixtures.GAINS))
        assertEquals(1L, p.unconvergedMeteringResults)
        assertEquals(listOf("meter"), cam.calls)
        meter(p, Fixtures.converged())
        assertEquals(listOf("meter", "protect+meter3/30"), cam.calls)
        assertEquals(ProtectionState.Verifying, p.state)
        // What was sent is the session's conversion of the device's own transform.
        CamProSession.fromJson(Fixtures.params()).use { ref ->
            ref.updateFromTransform(Fixtures.PHONE)
            assertTrue(ref.transform.contentEquals(cam.lastTransform!!))
            assertTrue(ref.curvesForRequest().zip(cam.lastCurves!!).all { (a, b) -> a.contentEquals(b) })
        }
        assertTrue(Fixtures.GAINS.contentEquals(cam.lastGains!!))

        val ok = cam.honoured()
        p.onFrame(1000, 1)
        p.onProtectedResult(1000, ok)
        p.onFrame(2000, 2)
        p.onProtectedResult(2000, ok.with(curves = List(3) { floatArrayOf(0f, 0f, 1f, 1f) })) // this frame's curve ignored
        p.onProtectedResult(3000, ok)
        p.onFrame(3000, 3)
        assertTrue("nothing reaches the app before its executor runs", shown.isEmpty())
        app.runAll()
        assertEquals(listOf(1, 3), shown)
        assertEquals(listOf(2), closed)
        assertEquals(listOf("Verifying", "Protected", "Violated", "Protected"), names())
    }

    @Test
    fun withoutPerFrameControlMeteringIsPhased() {
        val p = pipeline(perFrame = false)
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        assertEquals(listOf("meter", "protect"), cam.calls)
        // A late auto-mode result changes nothing while protecting.
        meter(p, Fixtures.converged(gains = floatArrayOf(1.5f, 1f, 1f, 2f)))
        assertEquals(listOf("meter", "protect"), cam.calls)
        p.onProtectedResult(1, cam.honoured())
        assertEquals(ProtectionState.Protected, p.state)
        p.remeter()
        assertEquals(ProtectionState.Verifying, p.state)
        p.onFrame(5, 5)
        meter(p, Fixtures.converged(gains = floatArrayOf(1.5f, 1f, 1f, 2f)))
        assertEquals(listOf("meter", "protect", "meter", "protect"), cam.calls)
        app.runAll()
        assertEquals(listOf(5), closed)
        assertTrue(shown.isEmpty())
    }

    @Test
    fun interleavedMeteringRebuildsOnlyWhenTheLightMoves() {
        val p = pipeline()
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        p.onProtectedResult(1, cam.honoured())
        meter(p, Fixtures.converged()) // same light: no new request, still Protected
        assertEquals(2, cam.calls.size)
        assertEquals(ProtectionState.Protected, p.state)
        meter(p, Fixtures.converged(gains = floatArrayOf(1.5f, 1f, 1f, 2f)))
        assertEquals(3, cam.calls.size)
        assertEquals("a new request verifies again", ProtectionState.Verifying, p.state)
    }

    @Test
    fun disconnectMidStreamDropsEverythingAndLateResultsChangeNothing() {
        val p = pipeline()
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        val ok = cam.honoured()
        p.onProtectedResult(1, ok)
        p.onFrame(2, 2)
        p.onCameraStopped("the camera was disconnected")
        p.onProtectedResult(2, ok) // a result that was in flight
        p.onFrame(3, 3)
        p.onProtectedResult(3, ok)
        app.runAll()
        assertTrue(shown.isEmpty())
        assertEquals(listOf(2, 3), closed)
        assertEquals(ProtectionState.Stopped("the camera was disconnected", org.campro.Problem.CameraClosed), p.state)
    }

    @Test
    fun aFailingCameraStopsClosed() {
        val p = pipeline()
        p.start(Fixtures.supported())
        cam.failWith = IllegalStateException("CameraDevice was already closed")
        meter(p, Fixtures.converged())
        val s = p.state
        assertTrue("$s", s is ProtectionState.Stopped && s.reason.contains("already closed"))
        assertTrue(cam.calls.contains("halt"))
        p.onFrame(1, 1)
        app.runAll()
        assertEquals(listOf(1), closed)
    }

    @Test
    fun neverStartedIsStoppedAndDropsFrames() {
        // What the app has when the camera permission is refused: the pipeline never starts.
        val p = pipeline()
        p.onFrame(1, 1)
        p.onProtectedResult(1, CaptureReport(0, 0, 0, IntArray(18), null))
        app.runAll()
        assertTrue(p.state is ProtectionState.Stopped)
        assertEquals(listOf(1), closed)
        assertTrue(cam.calls.isEmpty())
    }

    @Test
    fun deviceWithoutManualPostProcessing() {
        // No CONTRAST_CURVE at all: Unsupported, final, nothing captured.
        val none = DeviceSupport.check(intArrayOf(0), intArrayOf(1, 2), 64, intArrayOf(0, 1))
        val p = pipeline()
        p.start(none)
        val s = p.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("MANUAL_POST_PROCESSING"))
        assertEquals(listOf("halt"), cam.calls)
        meter(p, Fixtures.converged())
        assertEquals(listOf("halt"), cam.calls)
        // CONTRAST_CURVE listed without the capability: nothing promises the values are applied as sent.
        val listed = DeviceSupport.check(intArrayOf(0), intArrayOf(0, 1, 2), 64, intArrayOf(0, 1))
        assertTrue("$listed", listed is DeviceSupport.Result.Unsupported && listed.reasons.single().contains("MANUAL_POST_PROCESSING"))
    }

    @Test
    fun curveBudgetsOf20_32_64Points() {
        val bounds = mutableListOf<Double>()
        for (n in listOf(20, 32, 64)) {
            Fixtures.session(n).use { s ->
                val c = FakeCamera()
                val p = CamProPipeline<Int>(s, c, app, true, 4, 4, deliver = {}, drop = {})
                p.start(Fixtures.supported(n))
                meter(p, Fixtures.converged(), c)
                val pts = c.lastCurves!!.maxOf { it.size } / 2
                assertTrue("$n points allowed, $pts sent", pts in 2..n)
                assertEquals(ProtectionState.Protected, p.onProtectedResult(1, c.honoured()).let { p.state })
                bounds += s.boundLsb
            }
        }
        // Fewer points cannot follow the curve as closely: the stated bound grows, and the
        // 64-point curve holds the desktop pipeline within a quarter LSB.
        println("curve bound at 20/32/64 points: $bounds LSB")
        assertTrue("$bounds", bounds[0] >= bounds[1] && bounds[1] >= bounds[2] && bounds[2] < 0.25)
    }

    @Test
    fun gainsAreReadBack() {
        val p = pipeline()
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        val ok = cam.honoured()
        p.onProtectedResult(1, ok.with(gains = floatArrayOf(1f, 1f, 1f, 1f)))
        val s = p.state
        assertTrue("$s", s is ProtectionState.Violated && s.reason.contains("gain R"))
        p.onProtectedResult(2, ok.with(gains = floatArrayOf(2.0f * 1.001f, 1f, 1f, 1.6f))) // within 0.2%
        assertEquals(ProtectionState.Protected, p.state)
        p.onProtectedResult(3, ok.with(gains = null))
        assertTrue(p.state is ProtectionState.Violated)
    }

    @Test
    fun aDeviceThatNeverReportsTheTransformEndsUnsupported() {
        val p = pipeline()
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        val ok = cam.honoured()
        repeat(p.guard.missingKeyLimit - 1) { p.onProtectedResult(it.toLong(), ok.with(transform = null)) }
        assertTrue(p.state is ProtectionState.Violated)
        p.onProtectedResult(99, ok.with(transform = null))
        val s = p.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("COLOR_CORRECTION_TRANSFORM"))
        p.onProtectedResult(100, ok)
        assertTrue("final", p.state is ProtectionState.Unsupported)
        // And in auto mode: no transform in metering results.
        val q = pipeline()
        q.start(Fixtures.supported())
        repeat(q.meteringKeyLimit) { q.onMeteringResult(MeteringReport(1, 2, null, Fixtures.GAINS)) }
        assertTrue(q.state is ProtectionState.Unsupported)
    }

    @Test
    fun trustNeverCoversMissingModes() {
        val p = pipeline(trust = true)
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        val ok = cam.honoured()
        assertEquals(ProtectionState.Protected, p.onProtectedResult(1, ok.with(transform = null, curves = null, gains = null)).let { p.state })
        for (r in listOf(ok.with(awbMode = null), ok.with(colorCorrectionMode = null), ok.with(tonemapMode = null))) {
            p.onProtectedResult(2, r)
            assertTrue("${p.state}", p.state is ProtectionState.Violated)
        }
    }

    @Test
    fun resultsLeadingFramesByThePipelineDepthLoseNoGoodFrame() {
        val depth = 8
        val p = pipeline(depth = depth, queue = 6)
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        val ok = cam.honoured()
        for (t in 1L..depth) p.onProtectedResult(t, ok) // results first, as a deep pipeline gives them
        for (t in 1L..depth) p.onFrame(t, t.toInt())
        app.runAll()
        assertEquals((1..depth).toList(), shown)
        assertTrue(closed.isEmpty())
        // The previous sizing (queue depth - 1 verdicts) lost the oldest three of these.
        val g = FrameGate<Int>(p.guard, 5, 5, Executor { it.run() }, deliver = {}, drop = {})
        for (t in 1L..depth) g.onResult(t, ok)
        for (t in 1L..depth) g.onFrame(t, t.toInt())
        assertEquals(5L, g.delivered)
    }

    @Test
    fun twoFramesWithOneTimestampAreBothClosedAndNeitherShown() {
        val p = pipeline()
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        val ok = cam.honoured()
        val shownHere = mutableListOf<Int>()
        val closedHere = mutableListOf<Int>()
        val g = FrameGate<Int>(p.guard, 4, 8, Executor { it.run() }, deliver = { shownHere += it }, drop = { closedHere += it })
        g.onFrame(7, 70)
        g.onFrame(7, 71) // a HAL that stamps two frames alike
        g.onResult(7, ok)
        g.onFrame(8, 80)
        g.onResult(8, ok)
        assertEquals(listOf(80), shownHere)
        assertEquals(listOf(70, 71), closedHere)
    }

    @Test
    fun deliveryRunsOnTheAppExecutorOutsideTheGateLock() {
        val appThread = Executors.newSingleThreadExecutor()
        val entered = CountDownLatch(1)
        val release = CountDownLatch(1)
        val seen = mutableListOf<Int>()
        val p = CamProPipeline<Int>(session, cam, appThread, true, 4, 4, deliver = { entered.countDown(); release.await(5, TimeUnit.SECONDS); synchronized(seen) { seen += it } }, drop = {})
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        val ok = cam.honoured()
        p.onFrame(1, 1)
        p.onProtectedResult(1, ok)
        assertTrue(entered.await(5, TimeUnit.SECONDS))
        // The consumer is still busy with frame 1; the camera thread is not blocked by it.
        val t0 = System.nanoTime()
        p.onFrame(2, 2)
        p.onProtectedResult(2, ok)
        assertTrue("camera thread waited on the consumer", System.nanoTime() - t0 < 2_000_000_000L)
        release.countDown()
        appThread.shutdown()
        assertTrue(appThread.awaitTermination(5, TimeUnit.SECONDS))
        assertEquals(listOf(1, 2), seen)
    }

    @Test
    fun aShutDownAppExecutorGetsNoFrameAndLeaksNone() {
        val appThread = Executors.newSingleThreadExecutor()
        appThread.shutdown()
        val p = CamProPipeline<Int>(session, cam, appThread, true, 4, 4, deliver = { shown += it }, drop = { closed += it })
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        p.onFrame(1, 1)
        p.onProtectedResult(1, cam.honoured())
        // The verified frame could not be handed over: it is closed, counted as dropped.
        assertEquals(listOf(1), closed)
        assertTrue(shown.isEmpty())
        assertEquals(0L, p.gate.delivered)
        assertEquals(1L, p.gate.dropped)
    }

    @Test
    fun theProbeSendsAConstantCurveThenANearZeroTransformBeforeAnyProtectedRequest() {
        val p = pipeline(perFrame = false)
        p.start(Fixtures.supported())
        p.onMeteringResult(Fixtures.converged())
        assertEquals(listOf("meter"), cam.calls)
        assertTrue(p.isProbing)
        val (t1, c1, g1) = cam.probes.single()
        assertTrue("CamPro's own transform", t1.contentEquals(session.transform))
        assertTrue(floatArrayOf(0f, 0.25f, 1f, 0.25f).contentEquals(c1))
        assertTrue(Fixtures.GAINS.contentEquals(g1))
        // A frame still made with the metering settings (latency) says nothing.
        p.onProbeResult(1, CaptureReport(1, 1, 2, Fixtures.PHONE, List(3) { floatArrayOf(0f, 0f, 1f, 1f) }, Fixtures.GAINS))
        p.onProbeFrame(1, ByteArray(4800) { (it % 200).toByte() })
        assertEquals(1, cam.probes.size)
        // The curve step's flat frame (its result reports the probe) moves on to the matrix step.
        p.onProbeFrame(2, ByteArray(4800) { 64 })
        p.onProbeResult(2, cam.honouredProbe())
        val (t2, c2, _) = cam.probes[1]
        // The near-zero matrix: 1/256 on the diagonal, zeros elsewhere (invertible).
        assertTrue((0 until 9).all { e -> if (e % 4 == 0) t2[2 * e] == 1 && t2[2 * e + 1] == 256 else t2[2 * e] == 0 })
        assertTrue(floatArrayOf(0f, 0.5f, 1f, 1f).contentEquals(c2))
        assertEquals(ProtectionState.Verifying, p.state)
        p.onProbeResult(3, cam.honouredProbe())
        p.onProbeFrame(3, ByteArray(4800) { 128.toByte() })
        assertEquals(listOf("meter", "protect"), cam.calls)
        assertFalse(p.isProbing)
        // Metering again (the light changed) probes again: a mode switch may have come with it.
        p.remeter()
        p.onMeteringResult(Fixtures.converged())
        assertEquals(listOf("meter", "protect", "meter"), cam.calls)
        assertEquals(3, cam.probes.size)
        Fixtures.answerProbes(p, cam)
        assertEquals(listOf("meter", "protect", "meter", "protect"), cam.calls)
    }

    @Test
    fun aDeviceThatEchoesTheCurveButAppliesItsOwnIsUnsupported() {
        val p = probing()
        // The result reports the constant curve; the pixels show the scene.
        probeFrame(p, 5) { it * 7 % 256 }
        val s = p.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("TONEMAP_CURVE"))
        assertTrue(cam.calls.none { it.startsWith("protect") })
        assertEquals("halt", cam.calls.last())
    }

    @Test
    fun aDeviceThatIgnoresTheTransformIsUnsupported() {
        val p = probing()
        probeFrame(p, 5) { 64 }
        // Zero transform sent and reported; the frame shows the scene through the curve.
        probeFrame(p, 6) { 128 + it % 100 }
        val s = p.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("COLOR_CORRECTION_TRANSFORM"))
        assertTrue(cam.calls.none { it.startsWith("protect") })
    }

    @Test
    fun aDeviceWhoseProbeLevelsDoNotStepIsUnsupported() {
        // A flat scene through a device that applies neither: the same level twice.
        val p = probing()
        for (ts in 5L..6L) probeFrame(p, ts) { 90 }
        val s = p.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("luma 90 and 90"))
    }

    @Test
    fun aProbeThatNeverSeesItsSettingsGivesUp() {
        val p = probing()
        for (ts in 1L..CamProPipeline.PROBE_FRAME_LIMIT.toLong()) {
            p.onProbeFrame(ts, ByteArray(4800) { 64 }) // its result never comes (or another timestamp base)
            assertEquals(ProtectionState.Verifying, p.state)
        }
        p.onProbeFrame(1000, ByteArray(4800) { 64 })
        val s = p.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("no probe frame"))
    }

    @Test
    fun flatLevelsByHand() {
        // 98 of 100 samples within 2 codes of 64 (62..66), two outliers: flat at 64.
        val a = ByteArray(100) { if (it < 49) 63 else if (it < 98) 65 else 200.toByte() }
        assertEquals(64, PixelProbe.flatLevel(a))
        // 97 of 100: not flat.
        val b = ByteArray(100) { if (it < 97) 64 else 10 }
        assertEquals(null, PixelProbe.flatLevel(b))
        // Too few samples to say.
        assertEquals(null, PixelProbe.flatLevel(ByteArray(PixelProbe.MIN_SAMPLES - 1) { 64 }))
        // Verdicts: the step is measured between the two levels.
        assertEquals(null, PixelProbe.verdict(64, 128))
        assertEquals(null, PixelProbe.verdict(70, 70 + PixelProbe.MIN_STEP))
        assertTrue(PixelProbe.verdict(70, 70 + PixelProbe.MIN_STEP - 1)!!.contains("do not follow"))
        // Luma of RGB: BT.601 weights, rounded: (299 * 255 + 500) / 1000 = 76.
        assertTrue(byteArrayOf(76, 150.toByte(), 29).contentEquals(org.campro.hal.lumaOfRgb(byteArrayOf(-1, 0, 0, 0, -1, 0, 0, 0, -1))))
        // A Y plane with row padding and 2-byte pixels, sampled every 2nd pixel of every 2nd row.
        val plane = java.nio.ByteBuffer.wrap(ByteArray(4 * 10) { it.toByte() }) // 4 rows of 10 bytes: 4 pixels of stride 2 + 2 padding
        val luma = PixelProbe.lumaOfPlane(plane, 4, 4, 10, 2, 2)
        assertTrue(luma.contentToString(), byteArrayOf(0, 4, 20, 24).contentEquals(luma))
        // Resampled probe curves still count (points on the sent line); others do not.
        val nearZero = intArrayOf(1, 256, 0, 1, 0, 1, 0, 1, 1, 256, 0, 1, 0, 1, 0, 1, 1, 256)
        assertTrue(nearZero.contentEquals(PixelProbe.transform(PixelProbe.Step.Matrix, Fixtures.PHONE)))
        val r = CaptureReport(0, 0, 0, nearZero, List(3) { floatArrayOf(0f, 0.5f, 0.5f, 0.75f, 1f, 1f) }, null)
        assertTrue(PixelProbe.reportsStep(PixelProbe.Step.Matrix, r))
        assertFalse(PixelProbe.reportsStep(PixelProbe.Step.Curve, r))
        assertFalse(PixelProbe.reportsStep(PixelProbe.Step.Matrix, CaptureReport(0, 0, 0, Fixtures.PHONE, r.curves, null)))
        // A HAL's Q10 rounding of the near-zero matrix still counts; the identity (what a HAL
        // that refused the matrix applies) does not.
        val q10 = intArrayOf(4, 1024, 0, 1, 0, 1, 0, 1, 4, 1024, 0, 1, 0, 1, 0, 1, 4, 1024)
        assertTrue(PixelProbe.reportsStep(PixelProbe.Step.Matrix, CaptureReport(0, 0, 0, q10, r.curves, null)))
        val identity = intArrayOf(1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1)
        assertFalse(PixelProbe.reportsStep(PixelProbe.Step.Matrix, CaptureReport(0, 0, 0, identity, r.curves, null)))
    }

    @Test
    fun streamSizesComeFromTheListByHand() {
        val listed = listOf(4032 to 3024, 1920 to 1080, 1280 to 720, 1440 to 1080, 1280 to 960, 640 to 480, 320 to 240)
        // 16:9 within 1280 x 720: 1280 x 720 (1920 x 1080 is over the bound).
        assertEquals(1280 to 720, StreamSize.choose(listed, 1280, 720))
        // 4:3 within 1600 x 1200: 1440 x 1080, the largest 4:3 size that fits (1280 x 960, 640 x 480 are smaller).
        assertEquals(1440 to 1080, StreamSize.choose(listed, 1600, 1200))
        // No 16:9 size within 1000 x 563: the largest that fits, 640 x 480.
        assertEquals(640 to 480, StreamSize.choose(listed, 1000, 563))
        // Nothing fits 100 x 100: the smallest listed.
        assertEquals(320 to 240, StreamSize.choose(listed, 100, 100))
        assertEquals(null, StreamSize.choose(emptyList(), 1280, 720))
        assertEquals(null, StreamSize.choose(listOf(0 to 0, -1 to 5), 1280, 720))
    }

    /** A pipeline whose frames are luma levels (negative: a frame with scene detail), re-probing every [reprobe] protected results. */
    private fun levelPipeline(reprobe: Int = 5) = CamProPipeline<Int>(
        session, cam, app, true, 4, 6, deliver = { shown += it }, drop = { closed += it }, onState = { states += it },
        lumaOf = { f -> if (f < 0) ByteArray(4800) { (it % 200).toByte() } else ByteArray(4800) { f.toByte() } },
        reprobeInterval = reprobe,
    )

    /** What a device reports for a probe step's frame. */
    private fun probeReport(step: PixelProbe.Step) =
        CaptureReport(0, 0, 0, PixelProbe.transform(step, session.transform), List(3) { PixelProbe.curve(step) }, Fixtures.GAINS)

    /** A protected pipeline past [n] verified frames (value 7) from [ts]; returns the next timestamp. */
    private fun protectedFrames(p: CamProPipeline<Int>, ts: Long, n: Int): Long {
        var t = ts
        repeat(n) { p.onFrame(t, 7); p.onProtectedResult(t, cam.honoured()); t++ }
        app.runAll()
        return t
    }

    @Test
    fun theBurstReprobesTheProtectedStreamEveryIntervalWithoutClosingThePreview() {
        val p = levelPipeline()
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        assertEquals("protect+meter3/30", cam.calls.last())
        var ts = protectedFrames(p, 1000, 4)
        assertEquals(ProtectionState.Protected, p.state)
        ts = protectedFrames(p, ts, 1) // the fifth result: the next burst carries the probe
        assertEquals("protect+meter3/30+probe2", cam.calls.last())
        // The probe's frames come to the protected stream: read, dropped, never shown.
        for ((step, level) in listOf(PixelProbe.Step.Curve to 64, PixelProbe.Step.Matrix to 128)) {
            p.onProbeCaptureStarted(ts)
            p.onFrame(ts, level)
            p.onProbeResult(ts, probeReport(step))
            ts++
        }
        app.runAll()
        assertEquals(1L, p.reprobes)
        assertEquals("back to the plain burst", "protect+meter3/30", cam.calls.last())
        assertTrue(64 in closed && 128 in closed && 64 !in shown && 128 !in shown)
        assertEquals(ProtectionState.Protected, p.state)
        assertEquals("the re-probe never closed the preview", listOf("Verifying", "Protected"), names())
        protectedFrames(p, ts, 2)
        assertEquals(listOf(7), shown.distinct())
    }

    @Test
    fun aReprobeThatSeesTheSceneThroughTheConstantCurveRefusesTheCamera() {
        val p = levelPipeline()
        p.start(Fixtures.supported())
        meter(p, Fixtures.converged())
        var ts = protectedFrames(p, 1000, 5)
        // A mode switch: the device now applies its own curve while reporting the request.
        p.onProbeCaptureStarted(ts)
        p.onFrame(ts, -1)
        p.onProbeResult(ts, probeReport(PixelProbe.Step.Curve))
        val s = p.state
        assertTrue("$s", s is ProtectionState.Unsupported && s.reason.contains("pixel probe") && s.reason.contains("TONEMAP_CURVE") && s.problem == Problem.PixelProbe)
        assertEquals("halt", cam.calls.last())
        ts++
        p.onFrame(ts, 7)
        p.onProtectedResult(ts, cam.honoured())
        app.runAll()
        assertEquals("nothing after the refusal", 5, shown.size)
    }

    @Test
    fun blackProbeFramesStopTheCameraAndTheProbeGoesOnUntilRealFramesCome() {
        val p = probing()
        probeFrame(p, 5) { 0 } // the privacy toggle: black whatever the curve
        val s = p.state
        assertTrue("$s", s is ProtectionState.Stopped && s.reason.contains("black frames") && s.problem == Problem.PrivacyToggle)
        assertTrue("still probing, not refused", p.isProbing)
        probeFrame(p, 6) { 16 } // limited-range black
        assertTrue(p.state is ProtectionState.Stopped)
        probeFrame(p, 7) { 64 }
        probeFrame(p, 8) { 128 }
        assertEquals(listOf("meter", "protect+meter3/30"), cam.calls)
        assertEquals(ProtectionState.Verifying, p.state)
    }

    @Test
    fun lostBuffersMatchTheirTimestampsInEitherOrder() {
        val lost = mutableListOf<Long>()
        val b = LostBuffers { lost += it }
        b.started(1, 100)
        b.lost(1) // the usual order
        b.lost(2) // lost before its capture started
        assertEquals(listOf(100L), lost)
        b.started(2, 200)
        b.started(3, 300)
        assertEquals(listOf(100L, 200L), lost)
        b.lost(4)
        b.lost(4) // twice: once reported
        b.started(4, 400)
        b.started(4, 401)
        assertEquals(listOf(100L, 200L, 400L), lost)
    }

    @Test
    fun meteringAdaptsItsRunAndIntervalByHand() {
        val c = CamProController(session)
        assertEquals(3 to 30, c.meteringRun to c.meteringInterval)
        // A run without CONVERGED doubles the run; the interval keeps four runs.
        assertTrue(c.runEnded(converged = false, rebuilt = false))
        assertEquals(6 to 30, c.meteringRun to c.meteringInterval)
        assertTrue(c.runEnded(converged = false, rebuilt = false))
        assertEquals(12 to 48, c.meteringRun to c.meteringInterval)
        assertTrue(c.runEnded(converged = false, rebuilt = false)) // 24 is the longest run
        assertEquals(24 to 96, c.meteringRun to c.meteringInterval)
        assertFalse(c.runEnded(converged = false, rebuilt = false))
        // Three converged runs without a rebuild double the interval, up to 240.
        assertFalse(c.runEnded(converged = true, rebuilt = false))
        assertFalse(c.runEnded(converged = true, rebuilt = false))
        assertTrue(c.runEnded(converged = true, rebuilt = false))
        assertEquals(24 to 192, c.meteringRun to c.meteringInterval)
        repeat(3) { c.runEnded(converged = true, rebuilt = false) }
        assertEquals(240, c.meteringInterval)
        // A rebuild brings it back to the base (at least four runs).
        assertTrue(c.runEnded(converged = true, rebuilt = true))
        assertEquals(96, c.meteringInterval)
        c.resetPlan()
        assertEquals(3 to 30, c.meteringRun to c.meteringInterval)
    }

    @Test
    fun gainsWithinTheBandNeverRebuildAndADriftRebuildsOnce() {
        val c = CamProController(session)
        assertTrue(c.onMeteringResult(Fixtures.PHONE, Fixtures.GAINS)) // the first
        // +-1.9% around what was sent: inside the 2% band.
        for (f in listOf(1.019f, 0.981f, 1.01f, 0.99f)) assertFalse(c.onMeteringResult(Fixtures.PHONE, FloatArray(4) { Fixtures.GAINS[it] * f }))
        // A drift past 2% of the sent value rebuilds, and the band moves with it.
        assertTrue(c.onMeteringResult(Fixtures.PHONE, FloatArray(4) { Fixtures.GAINS[it] * 1.021f }))
        assertFalse(c.onMeteringResult(Fixtures.PHONE, FloatArray(4) { Fixtures.GAINS[it] * 1.035f }))
        assertEquals(2L, c.rebuilds)
    }

    @Test
    fun theImageQueueFollowsThePipelineDepth() {
        assertEquals(6, CamProPipeline.imageQueueDepth(4))
        assertEquals(10, CamProPipeline.imageQueueDepth(8))
        assertEquals(4, CamProPipeline.imageQueueDepth(1))
        assertEquals(16, CamProPipeline.imageQueueDepth(100))
    }

    @Test
    fun gridsByHand() {
        assertEquals(DeviceGrid.MatrixBits(10), DeviceGrid.parse("q10"))
        assertEquals(DeviceGrid.CurvePoints(33), DeviceGrid.parse("lut33"))
        assertEquals(listOf(null, null, null, null), listOf("q0", "lut1", "Q10", "x").map { DeviceGrid.parse(it) })
        assertEquals(setOf(DeviceGrid.MatrixBits(7), DeviceGrid.CurvePoints(64)), DeviceGrid.parseList("q7,lut64,bad"))
        // 1.3 and -0.27 rounded to 1/1024: 1331/1024 and -276/1024 (-0.26953); on the grid, within half a step.
        val want = IntArray(18) { i -> if (i % 2 == 1) 100 else if (i == 0) 130 else if (i == 2) -27 else 0 }
        val q10 = IntArray(18) { i -> if (i % 2 == 1) 1024 else if (i == 0) 1331 else if (i == 2) -276 else 0 }
        assertTrue(DeviceGrid.matrixOnGrid(want, q10, 10))
        assertFalse("not on a 1/128 grid", DeviceGrid.matrixOnGrid(want, q10, 7))
        val off = q10.copyOf().also { it[0] = 1333 } // on the grid but 1.5 steps away
        assertFalse(DeviceGrid.matrixOnGrid(want, off, 10))
        // y = x^2 at 5 points, resampled at 3: (0, 0), (0.5, 0.25 on the chords), (1, 1).
        val curve = floatArrayOf(0f, 0f, 0.25f, 0.0625f, 0.5f, 0.25f, 0.75f, 0.5625f, 1f, 1f)
        assertTrue(DeviceGrid.curveOnGrid(curve, 0, curve.size, floatArrayOf(0f, 0f, 0.5f, 0.25f, 1f, 1f), 3))
        assertFalse("a point off the curve", DeviceGrid.curveOnGrid(curve, 0, curve.size, floatArrayOf(0f, 0f, 0.5f, 0.3f, 1f, 1f), 3))
        assertFalse("not evenly spaced", DeviceGrid.curveOnGrid(curve, 0, curve.size, floatArrayOf(0f, 0f, 0.25f, 0.0625f, 1f, 1f), 3))
        assertTrue(DeviceGrid.curveExact(curve, 0, curve.size, curve.copyOf()))
    }
}
