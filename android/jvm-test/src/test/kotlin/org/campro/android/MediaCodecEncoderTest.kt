package org.campro.android

import android.graphics.ImageFormat
import android.media.Image
import android.media.MediaCodec
import android.media.MediaFormat
import org.campro.RecordingSummary
import org.junit.After
import org.junit.Assert.assertArrayEquals
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertTrue
import org.junit.Before
import org.junit.Test
import org.junit.runner.RunWith
import org.robolectric.RobolectricTestRunner
import org.robolectric.annotation.Config
import org.robolectric.annotation.Implementation
import org.robolectric.annotation.Implements
import org.robolectric.shadows.ShadowMediaCodec
import java.io.File
import java.io.IOException
import java.nio.ByteBuffer
import java.nio.file.Files

/**
 * Robolectric's `MediaCodec` is a passthrough encoder (input bytes become output bytes) and
 * its `MediaMuxer` writes the samples as they come; it has no `getInputImage`, which
 * [ImageCodecShadow] adds: an I420 view of the input buffer, as a flexible-YUV encoder gives.
 * So [MediaCodecEncoder]'s own logic runs for real (input buffers taken and refused, the
 * planes copied whatever their strides, the muxer started on the format, end of stream,
 * the summary sample, the move into place); the file holds the raw frames and the summary.
 * What this cannot show: a real encoder's output, and the MP4 container (a phone, or
 * `hal.CaptureOnHalTest` through ffmpeg for the frames' path).
 */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34], shadows = [MediaCodecEncoderTest.ImageCodecShadow::class])
class MediaCodecEncoderTest {
    /** `MediaCodec.getInputImage` over the shadow's input buffer: planar Y, U, V of [w] x [h]. */
    @Implements(MediaCodec::class)
    class ImageCodecShadow : ShadowMediaCodec() {
        @Implementation
        fun getInputImage(index: Int): Image {
            val buf = getBuffer(true, index)
            return PlanarImage(buf, w, h)
        }
    }

    /** I420 planes over [buf] (a codec's input buffer). */
    private class PlanarImage(buf: ByteBuffer, w: Int, h: Int) : CameraScript.YuvImage(w, h, 0, {
        fun slice(from: Int, to: Int): ByteBuffer = buf.duplicate().also { it.limit(to).position(from) }.slice()
        listOf(Triple(slice(0, w * h), w, 1), Triple(slice(w * h, w * h * 5 / 4), w / 2, 1), Triple(slice(w * h * 5 / 4, w * h * 3 / 2), w / 2, 1))
    })

    /** A camera frame as NV21 (V and U interleaved, pixel stride 2) with rows padded to [stride]. */
    private class Nv21Frame(val y: ByteArray, val u: ByteArray, val v: ByteArray, w: Int, h: Int, stride: Int) : CameraScript.YuvImage(w, h, 0, {
        val yBuf = ByteBuffer.allocate(stride * h).also { b -> for (r in 0 until h) for (c in 0 until w) b.put(r * stride + c, y[r * w + c]) }
        val vu = ByteBuffer.allocate(stride * h / 2).also { b ->
            for (r in 0 until h / 2) for (c in 0 until w / 2) { b.put(r * stride + 2 * c, v[r * w / 2 + c]); b.put(r * stride + 2 * c + 1, u[r * w / 2 + c]) }
        }
        listOf(Triple(yBuf, stride, 1), Triple(vu.duplicate().also { it.position(1) }.slice(), stride, 2), Triple(vu, stride, 2))
    })

    private val dir: File = Files.createTempDirectory("campro-encoder").toFile()

    @Before
    fun codec() {
        ShadowMediaCodec.addEncoder(
            MediaFormat.MIMETYPE_VIDEO_AVC,
            ShadowMediaCodec.CodecConfig(w * h * 3 / 2, w * h * 3 / 2) { input, output -> output.put(input) },
        )
    }

    @After
    fun cleanUp() {
        ShadowMediaCodec.clearCodecs()
        dir.deleteRecursively()
    }

    private fun frame(k: Int) = Nv21Frame(
        ByteArray(w * h) { (it * 7 + k).toByte() },
        ByteArray(w * h / 4) { (100 + it + k).toByte() },
        ByteArray(w * h / 4) { (200 - it - k).toByte() },
        w, h, stride = 24,
    )

    /** Encodes [n] frames, waiting for a free input buffer each time (the encoder refuses when none is free). */
    private fun encode(enc: MediaCodecEncoder, frames: List<Nv21Frame>): Int {
        var refused = 0
        for ((k, f) in frames.withIndex()) {
            var tries = 0
            while (!enc.encode(f, 33_333L * k)) {
                refused++
                check(++tries < 500) { "no input buffer came free (${enc.failure})" }
                Thread.sleep(2)
            }
        }
        return refused
    }

    @Test
    fun framesAndTheSummaryReachTheFileInOrderAndTheFileMovesIntoPlace() {
        val out = File(dir, "clip.mp4")
        val enc = MediaCodecEncoder(out, w, h, orientationHint = 90, supports = any)
        val frames = (0 until 5).map { frame(it) }
        encode(enc, frames)
        assertFalse("nothing under the app's name before the end", out.exists())
        val summary = RecordingSummary(5, 2, 0, 0, 1_000, 134_333_000, "stopped by the app")
        enc.finish(summary)
        assertTrue(out.isFile)
        assertFalse("no part file left", File(dir, ".clip.mp4.part").exists())
        val bytes = out.readBytes()
        val size = w * h * 3 / 2
        val json = summary.toJson().toByteArray()
        assertEquals(frames.size * size + json.size, bytes.size)
        for ((k, f) in frames.withIndex()) {
            // The encoder got I420: the NV21 frame's planes, each copied across its strides.
            assertArrayEquals("frame $k", f.y + f.u + f.v, bytes.copyOfRange(k * size, (k + 1) * size))
        }
        assertArrayEquals("the summary sample comes last", json, bytes.copyOfRange(frames.size * size, bytes.size))
    }

    @Test
    fun anExistingFileIsNotReplacedWithoutOverwrite() {
        val out = File(dir, "clip.mp4").also { it.writeText("mine") }
        val e = runCatching { MediaCodecEncoder(out, w, h, 0, supports = any) }.exceptionOrNull()
        assertTrue("$e", e is IOException && e.message!!.contains("overwrite"))
        assertEquals("mine", out.readText())
        val enc = MediaCodecEncoder(out, w, h, 0, RecordingOptions(overwrite = true), any)
        encode(enc, listOf(frame(0)))
        enc.finish(RecordingSummary(1, 0, 0, 0, 5, 5, "stopped by the app"))
        assertEquals(w * h * 3 / 2 + RecordingSummary(1, 0, 0, 0, 5, 5, "stopped by the app").toJson().length, out.readBytes().size)
    }

    @Test
    fun anAbandonedRecordingLeavesNothing() {
        val out = File(dir, "clip.mp4")
        val enc = MediaCodecEncoder(out, w, h, 0, supports = any)
        enc.abandon()
        assertFalse(out.exists())
        assertEquals(emptyList<String>(), dir.list()!!.toList())
    }

    private companion object {
        /** Every codec at every size (Robolectric's MediaCodecList lists none). */
        val any: (String, Int, Int) -> Boolean = { _, _, _ -> true }

        /** The test's frame size (even, small). */
        const val w = 16
        const val h = 8
    }
}
