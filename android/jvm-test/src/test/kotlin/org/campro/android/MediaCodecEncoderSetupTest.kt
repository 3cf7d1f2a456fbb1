package org.campro.android

import android.media.MediaFormat
import org.junit.After
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Before
import org.junit.Test
import org.junit.runner.RunWith
import org.robolectric.RobolectricTestRunner
import org.robolectric.annotation.Config
import org.robolectric.shadows.ShadowMediaCodec
import java.io.File
import java.io.IOException
import java.nio.file.Files

/** [MediaCodecEncoder]'s set-up: the codec chosen for the size, the stream's colour tags, a failed start that leaves nothing. */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34])
class MediaCodecEncoderSetupTest {
    private val dir: File = Files.createTempDirectory("campro-encoder-setup").toFile()

    @Before
    fun codec() {
        ShadowMediaCodec.addEncoder(MediaFormat.MIMETYPE_VIDEO_AVC, ShadowMediaCodec.CodecConfig(192, 192) { input, output -> output.put(input) })
    }

    @After
    fun cleanUp() {
        ShadowMediaCodec.clearCodecs()
        dir.deleteRecursively()
    }

    @Test
    fun hevcFallsBackToH264AndTheStreamCarriesTheCamerasColourTags() {
        val out = File(dir, "clip.mp4")
        val enc = MediaCodecEncoder(out, 16, 8, 0, RecordingOptions(mime = MediaFormat.MIMETYPE_VIDEO_HEVC)) { mime, _, _ -> mime == MediaFormat.MIMETYPE_VIDEO_AVC }
        assertEquals(MediaFormat.MIMETYPE_VIDEO_AVC, enc.mime)
        enc.abandon()
        val f = MediaCodecEncoder.format(MediaFormat.MIMETYPE_VIDEO_AVC, 1280, 720, 0)
        assertEquals(MediaFormat.COLOR_RANGE_FULL, f.getInteger(MediaFormat.KEY_COLOR_RANGE))
        assertEquals(MediaFormat.COLOR_STANDARD_BT601_PAL, f.getInteger(MediaFormat.KEY_COLOR_STANDARD))
        assertEquals(MediaFormat.COLOR_TRANSFER_SDR_VIDEO, f.getInteger(MediaFormat.KEY_COLOR_TRANSFER))
        assertEquals((0.2 * 1280 * 720 * 30).toInt(), f.getInteger(MediaFormat.KEY_BIT_RATE))
    }

    @Test
    fun noEncoderForTheSizeOrAFailedConfigureLeavesNothing() {
        val out = File(dir, "clip.mp4")
        val none = runCatching { MediaCodecEncoder(out, 16, 8, 0) { _, _, _ -> false } }.exceptionOrNull()
        assertTrue("$none", none is IOException && none.message!!.contains("no H.264 or HEVC encoder for 16 x 8"))
        // The encoder's set-up fails half-way (the muxer cannot open its part file): what it took is released.
        val failed = runCatching { MediaCodecEncoder(File(dir, "missing/clip.mp4"), 16, 8, 0) { _, _, _ -> true } }.exceptionOrNull()
        assertTrue("$failed", failed is IOException && failed.message!!.contains("could not start"))
        assertEquals(emptyList<String>(), dir.list()!!.toList())
        assertTrue("no encoder thread left", Thread.getAllStackTraces().keys.none { it.name == "campro-encoder" && it.isAlive })
    }
}
