package org.campro.hal

import org.campro.CamProNative
import org.campro.CamProPipeline
import org.campro.Fixtures
import org.campro.FrameRouter
import org.campro.Orientation
import org.campro.ProtectedRecording
import org.campro.ProtectionState
import org.campro.RecordingSummary
import org.campro.StillCapture
import org.campro.StillResult
import org.campro.VideoEncoder
import org.junit.Assert.assertArrayEquals
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Test
import java.io.ByteArrayInputStream
import java.io.File
import java.nio.file.Files
import java.nio.file.attribute.FileTime
import java.util.concurrent.TimeUnit
import javax.imageio.ImageIO

/**
 * Recording, stills and the preview on the simulated camera, through the library's own
 * routing ([FrameRouter], [ProtectedRecording], [StillCapture]): what ends up in the file,
 * the JPEG and on screen is compared, pixel for pixel, with the desktop pipeline's output
 * for the scene. The HAL falls back to its automatic settings for frames 50 to 59 (and its
 * results say so): those frames must be missing from everything, and counted.
 *
 * The encoder here is ffmpeg's lossless H.264 (RGB, `-qp 0`) fed with each frame's sensor
 * timestamp, so the file can be held to the pipeline's bound exactly; on a phone
 * `MediaCodecEncoder` encodes the same frames lossily (compression removes detail, it adds
 * none). ffmpeg is Debian's (`.ci/run` installs it).
 */
class CaptureOnHalTest {
    /** Lossless H.264 in MP4 through ffmpeg; each frame's file carries its timestamp as its mtime (ns). */
    private class FfmpegEncoder(private val out: File, private val w: Int, private val h: Int) : VideoEncoder<SimFrame> {
        val dir: File = Files.createTempDirectory("campro-rec").toFile()
        var n = 0
        var finished: RecordingSummary? = null
        var abandoned = false

        override fun encode(frame: SimFrame, presentationUs: Long): Boolean {
            val f = File(dir, "f%06d.ppm".format(n++))
            f.outputStream().use { o ->
                o.write("P6 $w $h 255\n".toByteArray())
                o.write(frame.pixels)
            }
            // ffmpeg's image2 demuxer reads the time from the mtime (ts_from_file=2, ns).
            Files.setLastModifiedTime(f.toPath(), FileTime.from(1_000_000_000L + presentationUs * 1000, TimeUnit.NANOSECONDS))
            return true
        }

        override fun finish(summary: RecordingSummary) {
            finished = summary
            run(
                "ffmpeg", "-v", "error", "-y", "-f", "image2", "-ts_from_file", "2", "-i", "${dir.path}/f%06d.ppm",
                "-fps_mode", "passthrough", "-c:v", "libx264rgb", "-qp", "0", "-pix_fmt", "rgb24",
                "-video_track_timescale", "1000000", "-metadata", "comment=${summary.toJson()}", out.path,
            )
            dir.deleteRecursively()
        }

        override fun abandon() {
            abandoned = true
            dir.deleteRecursively()
        }
    }

    private val side = 128
    private val block = 8

    /** The 256-colour scene as 16 x 16 flat blocks of 8 x 8 pixels (JPEG's blocks: a still is then held to 2 codes). */
    private val scene = FloatArray(3 * side * side).also { s ->
        val colours = FloatArray(3 * 256)
        var k = 0
        for (r in 0 until 6) for (g in 0 until 6) for (b in 0 until 6) {
            if (k >= 216) break
            colours[3 * k] = r / 5f * 0.45f; colours[3 * k + 1] = g / 5f * 0.9f; colours[3 * k + 2] = b / 5f * 0.55f; k++
        }
        while (k < 256) { val v = (k - 216) / 40f; colours[3 * k] = 0.45f * v; colours[3 * k + 1] = 0.8f * v; colours[3 * k + 2] = 0.5f * v; k++ }
        for (y in 0 until side) for (x in 0 until side) {
            val c = (y / block) * (side / block) + x / block
            for (ch in 0 until 3) s[3 * (y * side + x) + ch] = colours[3 * c + ch]
        }
    }

    private fun maxDiff(a: ByteArray, b: ByteArray): Int = a.indices.maxOf { kotlin.math.abs((a[it].toInt() and 255) - (b[it].toInt() and 255)) }

    @Test
    fun recordingStillAndPreviewHoldOnlyVerifiedFramesWithinTheBound() {
        Fixtures.load()
        val session = Fixtures.session()
        val reference = SimulatedHal.reference(Fixtures.params())
        val file = File.createTempFile("campro-recording", ".mp4").also { it.delete() }
        try {
            val hal = SimulatedHal(Behaviour("fault 50..60", faultFrom = 50, faultUntil = 60), scene, listOf(Fixtures.PHONE), Fixtures.GAINS, reference)
            val router = FrameRouter<SimFrame> { it.close() }
            val bound = 2 // the pipeline's bound (under 0.5 LSB) plus 8-bit rounding, as HalScenariosTest
            val previewed = ArrayList<Int>()
            var previewWorst = 0
            router.preview = { f -> previewed += f.index; previewWorst = maxOf(previewWorst, maxDiff(f.pixels, f.expected)); f.close() }
            val recorded = ArrayList<SimFrame>() // what the file must hold, in order
            val ff = FfmpegEncoder(file, side, side)
            val spy = object : VideoEncoder<SimFrame> {
                override fun encode(frame: SimFrame, presentationUs: Long): Boolean { recorded += frame; return ff.encode(frame, presentationUs) }
                override fun finish(summary: RecordingSummary) = ff.finish(summary)
                override fun abandon() = ff.abandon()
            }
            val direct = java.util.concurrent.Executor { it.run() }
            val stills = ArrayList<StillResult>()
            var stillFrame: SimFrame? = null
            val stillCapture = StillCapture<SimFrame, Pair<SimFrame, ByteArray>>(
                snapshot = { f -> stillFrame = f; f to f.pixels.copyOf() },
                background = direct,
            )
            router.stills = stillCapture
            lateinit var p: CamProPipeline<SimFrame>
            p = CamProPipeline(
                session, hal, direct, perFrameControl = true, pipelineDepth = 4, imageQueueDepth = 6,
                deliver = router::deliver, drop = { it.close() }, lumaOf = { lumaOfRgb(it.pixels) },
            )
            val recording = ProtectedRecording(spy, { it.timestampNs }, { p.gate.dropped })
            router.recording = recording
            p.start(Fixtures.supported())
            val droppedBefore = p.gate.dropped
            hal.run(120, p) { i -> if (i == 100) stillCapture.request({ (f, px) -> StillResult.Taken(CamProNative.encodeJpegRgb(side, side, px, Orientation.exifOrientation(90), 100), f.timestampNs) }) { stills += it } }
            assertEquals(ProtectionState.Protected, p.state)
            val summary = recording.stop()

            // Nothing from the faulty frames reached any consumer, and they are counted.
            val faulty = 50 until 60
            assertTrue("preview got a faulty frame: $previewed", previewed.none { it in faulty })
            assertTrue(recorded.none { it.index in faulty })
            assertTrue("the gate dropped ${summary.framesFailedCheck} frames", summary.framesFailedCheck >= faulty.count())
            assertEquals(p.gate.dropped - droppedBefore, summary.framesFailedCheck)
            assertTrue("preview frames off by $previewWorst", previewWorst <= bound)
            assertEquals(previewed, recorded.map { it.index })
            assertTrue(recorded.size >= 80)

            // The file: every frame decodes to the protected pipeline's output, times as the sensor's.
            assertEquals(recorded.size.toLong(), summary.frames)
            val raw = exec("ffmpeg", "-v", "error", "-i", file.path, "-fps_mode", "passthrough", "-f", "rawvideo", "-pix_fmt", "rgb24", "-")
            val frameBytes = 3 * side * side
            assertEquals(recorded.size * frameBytes, raw.size)
            var worst = 0
            for ((k, f) in recorded.withIndex()) {
                val decoded = raw.copyOfRange(k * frameBytes, (k + 1) * frameBytes)
                assertArrayEquals("frame ${f.index}: the file holds other pixels than the camera delivered", f.pixels, decoded)
                worst = maxOf(worst, maxDiff(decoded, f.expected))
            }
            assertTrue("recorded frames off by $worst LSB", worst <= bound)
            // Decoded frames come in presentation order: their times must increase as decoded.
            val pts = String(exec("ffprobe", "-v", "error", "-select_streams", "v", "-show_entries", "frame=pts", "-of", "csv=p=0", file.path))
                .lines().filter { it.isNotBlank() }.map { it.trim().trimEnd(',').toLong() }
            assertTrue("presentation times increase: $pts", pts.zipWithNext().all { (a, b) -> b > a })
            val want = recorded.map { (it.timestampNs - recorded[0].timestampNs) / 1000 }
            assertEquals(want.size, pts.size)
            for ((a, b) in want.zip(pts)) assertTrue("pts $b, sensor $a", kotlin.math.abs(a - b) <= 1)
            assertTrue("the gap of the dropped frames is real time", (1 until want.size).any { want[it] - want[it - 1] > 300_000 })
            val comment = String(exec("ffprobe", "-v", "error", "-show_entries", "format_tags=comment", "-of", "default=nw=1:nk=1", file.path)).trim()
            assertTrue(comment, comment.contains("\"frames\":${summary.frames}") && comment.contains("\"frames_failed_check\":${summary.framesFailedCheck}"))

            // The still: the first verified frame after the request, within 2 codes of it at quality 100.
            assertEquals(1, stills.size)
            val taken = stills[0] as StillResult.Taken
            val sf = stillFrame!!
            assertTrue(sf.index >= 100)
            assertEquals(sf.timestampNs, taken.timestampNs)
            val img = ImageIO.read(ByteArrayInputStream(taken.jpeg))
            assertEquals(side, img.width)
            var stillWorst = 0
            for (y in 0 until side) for (x in 0 until side) {
                val rgb = img.getRGB(x, y)
                val k = 3 * (y * side + x)
                for ((ch, v) in listOf((rgb shr 16) and 255, (rgb shr 8) and 255, rgb and 255).withIndex()) {
                    stillWorst = maxOf(stillWorst, kotlin.math.abs(v - (sf.expected[k + ch].toInt() and 255)))
                }
            }
            assertTrue("still off by $stillWorst LSB", stillWorst <= bound + 2)
            println("capture on the simulated HAL: ${summary.frames} frames recorded (worst $worst LSB), ${summary.framesFailedCheck} dropped by the gate, still worst $stillWorst LSB, preview worst $previewWorst LSB")
        } finally {
            file.delete()
            CamProNative.close(reference)
            session.close()
        }
    }

    @Test
    fun aRecordingWithNoVerifiedFrameLeavesNoFile() {
        val ff = FfmpegEncoder(File("unused.mp4"), 2, 2)
        val r = ProtectedRecording(ff, { it.timestampNs }, { 7L })
        val s = r.stop("the camera stopped")
        assertEquals(0L, s.frames)
        assertTrue(ff.abandoned)
        assertEquals(s, r.stop())
        assertTrue(!File("unused.mp4").exists())
    }

    @Test
    fun framesWhoseTimestampDoesNotIncreaseAreNotWritten() {
        val times = ArrayList<Long>()
        val enc = object : VideoEncoder<SimFrame> {
            override fun encode(frame: SimFrame, presentationUs: Long): Boolean { times += presentationUs; return frame.index != 3 }
            override fun finish(summary: RecordingSummary) {}
            override fun abandon() {}
        }
        val r = ProtectedRecording(enc, { it.timestampNs }, { 0L })
        for ((i, ts) in listOf(1_000_000L, 2_000_000L, 2_000_000L, 3_000_000L, 1_500_000L, 4_000_000L).withIndex()) {
            r.onFrame(SimFrame(i, ByteArray(0), ByteArray(0), timestampNs = ts))
        }
        val s = r.stop()
        // Frame 2 repeats a time, frame 4 goes back: neither reaches the encoder; frame 3 was refused (busy).
        assertEquals(listOf(0L, 1000L, 2000L, 3000L), times)
        assertEquals(3L, s.frames)
        assertEquals(2L, s.framesOutOfOrder)
        assertEquals(1L, s.framesEncoderBusy)
        assertEquals(4_000_000L, s.lastTimestampNs)
        assertEquals(3000L, s.durationUs)
    }

    companion object {
        fun exec(vararg cmd: String): ByteArray {
            val p = ProcessBuilder(*cmd).redirectError(ProcessBuilder.Redirect.INHERIT).start()
            val out = p.inputStream.readBytes()
            check(p.waitFor() == 0) { "${cmd.joinToString(" ")} failed" }
            return out
        }

        fun run(vararg cmd: String) {
            exec(*cmd)
        }
    }
}
