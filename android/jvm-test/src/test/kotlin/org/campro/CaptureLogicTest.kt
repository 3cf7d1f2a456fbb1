package org.campro

import org.junit.Assert.assertArrayEquals
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Test
import java.nio.ByteBuffer

/** The capture API's plain rules: turns, the preview's fit, YUV plane copies, stills' life cycle. */
class CaptureLogicTest {
    private fun assertMatrix(want: DoubleArray, got: FloatArray) {
        for (i in want.indices) assertEquals("entry $i of ${got.toList()}", want[i], got[i].toDouble(), 1e-4)
    }

    @Test
    fun turnsFollowCamera2Rules() {
        // Back camera, sensor at 90 (most phones): upright in portrait, level when the display turns.
        assertEquals(90, Orientation.previewRotation(90, 0, false))
        assertEquals(0, Orientation.previewRotation(90, 90, false))
        assertEquals(180, Orientation.previewRotation(90, 270, false))
        // Front camera, sensor at 270.
        assertEquals(270, Orientation.previewRotation(270, 0, true))
        assertEquals(0, Orientation.previewRotation(270, 90, true))
        // Stills: JPEG_ORIENTATION's rule (back sensor + device, front sensor - device).
        assertEquals(90, Orientation.stillRotation(90, 0, false))
        assertEquals(180, Orientation.stillRotation(90, 90, false))
        assertEquals(0, Orientation.stillRotation(90, 270, false))
        assertEquals(180, Orientation.stillRotation(270, 90, true))
        assertEquals(listOf(1, 6, 3, 8, 8), listOf(0, 90, 180, 270, -90).map { Orientation.exifOrientation(it) })
        // Mirrored (a front still as the preview showed it): turned, then flipped left-right.
        assertEquals(listOf(2, 5, 4, 7), listOf(0, 90, 180, 270).map { Orientation.exifOrientation(it, mirror = true) })
        // The physical orientation: the nearest quarter, held within 60 degrees of the last one.
        assertEquals(0, Orientation.deviceOrientation(50, 0)) // past 45, within the hysteresis
        assertEquals(90, Orientation.deviceOrientation(61, 0))
        assertEquals(90, Orientation.deviceOrientation(31, 90)) // 59 away from 90: held
        assertEquals(0, Orientation.deviceOrientation(29, 90))
        assertEquals(270, Orientation.deviceOrientation(280, 0))
        assertEquals(0, Orientation.deviceOrientation(350, 270)) // 80 away: the nearest quarter, 0
        assertEquals(180, Orientation.deviceOrientation(Orientation.UNKNOWN, 180)) // flat: unchanged
        assertTrue(runCatching { Orientation.deviceOrientation(360, 0) }.isFailure)
        val e = runCatching { Orientation.exifOrientation(45) }.exceptionOrNull()
        assertTrue("$e", e is IllegalArgumentException && e.message!!.startsWith("rotation must be a multiple of 90"))
    }

    /** Hand-derived: a 1280 x 720 back-camera buffer turned 90 in a 1080 x 1920 portrait view fills it; its top-left lands top-right. */
    @Test
    fun portraitPreviewOfALandscapeSensorFillsTheView() {
        val m = Orientation.fitTransform(1280, 720, 1080, 1920, 90, false)
        // x' = 1080 - 0.5625 y, y' = (1920 / 1080) x.
        assertMatrix(doubleArrayOf(0.0, -0.5625, 1080.0, 1920.0 / 1080, 0.0, 0.0, 0.0, 0.0, 1.0), m)
    }

    /** Hand-derived: unturned, mirrored, letterboxed in a square view (bars of 218.75 above and below). */
    @Test
    fun mirroredPreviewIsLetterboxedAndCentred() {
        val m = Orientation.fitTransform(1280, 720, 1000, 1000, 0, true)
        // Shown 1000 x 562.5 at y = 218.75; x' = 1000 - x, y' = 218.75 + 0.5625 y.
        assertMatrix(doubleArrayOf(-1.0, 0.0, 1000.0, 0.0, 0.5625, 218.75, 0.0, 0.0, 1.0), m)
    }

    /** Hand-derived: a front camera at 270 in portrait, mirrored: buffer (u, v) shows at (1 - v, 1 - u). */
    @Test
    fun frontCameraAt270IsTurnedThenMirrored() {
        val m = Orientation.fitTransform(640, 480, 480, 640, 270, true)
        assertMatrix(doubleArrayOf(0.0, -0.75, 480.0, -640.0 / 480, 0.0, 640.0, 0.0, 0.0, 1.0), m)
    }

    /** A planar plane with padded rows, copied into a semi-planar one (pixel stride 2) and packed back, is unchanged. */
    @Test
    fun planeCopiesHonourEveryStride() {
        val cols = 5
        val rows = 3
        val src = ByteBuffer.allocate(8 * rows)
        for (r in 0 until rows) for (c in 0 until cols) src.put(r * 8 + c, (10 * r + c).toByte())
        val interleaved = ByteBuffer.allocate(12 * rows)
        for (i in 0 until interleaved.capacity()) interleaved.put(i, 99.toByte())
        Yuv.copyPlane(src, 8, 1, interleaved, 12, 2, cols, rows)
        for (r in 0 until rows) for (c in 0 until cols) {
            assertEquals((10 * r + c).toByte(), interleaved.get(r * 12 + 2 * c))
            assertEquals("the other plane's bytes are left alone", 99.toByte(), interleaved.get(r * 12 + 2 * c + 1))
        }
        val packed = Yuv.packPlane(interleaved, 12, 2, cols, rows)
        assertArrayEquals(ByteArray(cols * rows) { (10 * (it / cols) + it % cols).toByte() }, packed)
        assertEquals("positions are left as they were", 0, src.position())
        // A plane read from its buffer's position (a semi-planar image's second plane starts one byte in).
        interleaved.position(1)
        assertArrayEquals(ByteArray(cols * rows) { 99 }, Yuv.packPlane(interleaved, 12, 2, cols, rows))
        val e = runCatching { Yuv.copyPlane(src, 8, 1, ByteBuffer.allocate(10), 5, 1, cols, rows) }.exceptionOrNull()
        assertTrue("$e", e is IllegalArgumentException && e.message!!.contains("destination plane is too small"))
    }

    @Test
    fun stillsTakeOnlyFramesAfterTheirRequestAndEndOnce() {
        val direct = java.util.concurrent.Executor { it.run() }
        val snapshots = ArrayList<Int>()
        val stills = StillCapture<Int, Int>({ snapshots += it; it }, direct)
        stills.onFrame(1) // nobody asked: not even copied
        assertEquals(emptyList<Int>(), snapshots)
        val results = ArrayList<StillResult>()
        val a = stills.request({ f -> StillResult.Taken(byteArrayOf(f.toByte()), f.toLong()) }) { results += it }
        stills.request({ throw java.io.IOException("disk full") }) { results += it }
        stills.onFrame(2)
        assertEquals("one copy for both requests", listOf(2), snapshots)
        assertEquals(2L, (results[0] as StillResult.Taken).timestampNs)
        assertEquals("the still failed: disk full", (results[1] as StillResult.Failed).reason)
        assertTrue("a finished request cannot be cancelled", !stills.cancel(a, "late"))
        val c = stills.request({ StillResult.Failed("never made") }) { results += it }
        assertTrue(stills.cancel(c, "timed out"))
        stills.request({ StillResult.Failed("never made") }) { results += it }
        stills.fail("the camera closed")
        stills.onFrame(3)
        assertEquals(listOf("timed out", "the camera closed"), results.drop(2).map { (it as StillResult.Failed).reason })
        assertEquals(0, stills.waiting)
    }

    @Test
    fun theRouterLendsFramesThenHandsThemToThePreviewOrClosesThem() {
        val events = ArrayList<String>()
        val router = FrameRouter<Int> { events += "close $it" }
        router.deliver(1)
        router.preview = { events += "show $it" }
        val rec = ProtectedRecording(object : VideoEncoder<Int> {
            override fun encode(frame: Int, presentationUs: Long): Boolean { events += "encode $frame@$presentationUs"; return true }
            override fun finish(summary: RecordingSummary) {}
            override fun abandon() {}
        }, { it * 1000L }, { 0L })
        router.recording = rec
        router.deliver(2)
        router.deliver(5)
        assertEquals(listOf("close 1", "encode 2@0", "show 2", "encode 5@3", "show 5"), events)
        assertEquals(3L, router.routed)
    }

    @Test
    fun theSummaryIsOneLineOfJson() {
        val s = RecordingSummary(3, 10, 0, 1, 5_000, 70_000, "the camera said \"stop\"\n")
        assertEquals(
            "{\"campro_recording\":1,\"frames\":3,\"frames_failed_check\":10,\"frames_encoder_busy\":0,\"frames_out_of_order\":1," +
                "\"first_timestamp_ns\":5000,\"last_timestamp_ns\":70000,\"ended_because\":\"the camera said \\\"stop\\\"\\u000a\"}",
            s.toJson(),
        )
        assertEquals(65L, s.durationUs)
    }

    /**
     * A preview that never gives a buffer back (a hidden view: `queueInputImage` blocks for
     * good) holds its own thread only: the frame thread goes on, every frame reaches the
     * recording and the still, and the preview keeps at most one frame waiting.
     */
    @Test
    fun aStalledPreviewNeverStallsRecordingOrStills() {
        val stuck = java.util.concurrent.CountDownLatch(1)
        val previewThread = java.util.concurrent.Executors.newSingleThreadExecutor()
        val shown = java.util.concurrent.atomic.AtomicInteger()
        val closed = java.util.Collections.synchronizedList(ArrayList<Int>())
        try {
            val slot = LatestFrame<Int>(previewThread, { f -> shown.incrementAndGet(); stuck.await(); closed += f }, { closed += it })
            val router = FrameRouter<Int> { closed += it }
            router.preview = slot::offer
            val recorded = ArrayList<Int>()
            val encoder = object : VideoEncoder<Int> {
                override fun encode(frame: Int, presentationUs: Long): Boolean { recorded += frame; return true }
                override fun finish(summary: RecordingSummary) {}
                override fun abandon() {}
            }
            router.recording = ProtectedRecording(encoder, { it * 33_333_333L }, { 0L })
            val stills = StillCapture<Int, Int>({ it }, java.util.concurrent.Executor { it.run() })
            router.stills = stills
            val results = ArrayList<StillResult>()
            // The frame thread (this one) delivers 100 frames; a still is asked for at frame 50.
            for (f in 1..100) {
                if (f == 50) stills.request({ n -> StillResult.Taken(byteArrayOf(n.toByte()), n.toLong()) }) { results += it }
                router.deliver(f)
            }
            assertEquals((1..100).toList(), recorded)
            assertEquals(listOf(50L), results.map { (it as StillResult.Taken).timestampNs })
            // The preview took one frame and is stuck in it; at most one waits; the rest were replaced and closed.
            val deadline = System.nanoTime() + 5_000_000_000L
            while (shown.get() == 0 && System.nanoTime() < deadline) Thread.sleep(5)
            assertEquals(1, shown.get())
            assertTrue("${slot.replaced}", slot.replaced in 98L..99L)
            assertEquals(slot.replaced.toInt(), closed.size)
            slot.close()
            assertEquals("the waiting frame closed with the slot", 99, closed.size)
            stuck.countDown()
        } finally {
            previewThread.shutdown()
            assertTrue(previewThread.awaitTermination(5, java.util.concurrent.TimeUnit.SECONDS))
        }
        assertEquals("every frame closed once", (1..100).toList(), closed.sorted())
    }
}
