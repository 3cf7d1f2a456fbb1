package org.campro.android

import android.media.Image
import android.media.MediaCodec
import android.media.MediaCodecInfo
import android.media.MediaFormat
import android.media.MediaMuxer
import android.os.Handler
import android.os.HandlerThread
import org.campro.RecordingSummary
import org.campro.VideoEncoder
import org.campro.Yuv
import java.io.File
import java.io.IOException
import java.nio.ByteBuffer
import java.util.concurrent.CountDownLatch
import java.util.concurrent.LinkedBlockingQueue
import java.util.concurrent.TimeUnit

/** What a recording is written as. */
data class RecordingOptions(
    /** `MediaFormat.MIMETYPE_VIDEO_AVC` (H.264) or `MIMETYPE_VIDEO_HEVC`. */
    val mime: String = MediaFormat.MIMETYPE_VIDEO_AVC,
    /** Bits a second; 0: 0.2 bits a pixel at 30 fps (about 5.5 Mbit/s at 720p). */
    val bitRate: Int = 0,
    /** Replace [output] if it exists (otherwise starting fails and nothing is touched). */
    val overwrite: Boolean = false,
) {
    init {
        require(mime == MediaFormat.MIMETYPE_VIDEO_AVC || mime == MediaFormat.MIMETYPE_VIDEO_HEVC) { "mime must be video/avc or video/hevc, got $mime" }
        require(bitRate >= 0) { "bitRate must be >= 0, got $bitRate" }
    }
}

/**
 * A protected recording's encoder: each verified `YUV_420_888` frame is copied into an input
 * image of an H.264/HEVC `MediaCodec` (flexible YUV) with its presentation time, and the
 * encoded stream goes into an MP4 through `MediaMuxer`. [RecordingSummary] is written as the
 * MP4's one-sample metadata track ([RecordingSummary.METADATA_MIME]).
 *
 * The file is written beside [output] as `.NAME.part` and moved onto [output] when finished,
 * so a crash never leaves a half-written file under the app's name; an existing [output] is
 * replaced only with [RecordingOptions.overwrite]. Frames are copied (a CPU copy, about
 * 1.4 MB a 720p frame) because one verified image feeds the preview too; the encoder never
 * sees a frame the gate did not pass.
 *
 * Threads: [encode], [finish] and [abandon] on the frame thread; the codec's callbacks on
 * this encoder's own thread. Android only: compiled against the framework in CI, run on phones.
 */
class MediaCodecEncoder(
    private val output: File,
    private val width: Int,
    private val height: Int,
    /** Clockwise degrees a player turns the video (`MediaMuxer.setOrientationHint`). */
    orientationHint: Int,
    private val options: RecordingOptions = RecordingOptions(),
) : VideoEncoder<Image> {
    private val part = partOf(output)
    private val thread = HandlerThread("campro-encoder").apply { start() }
    private val codec: MediaCodec
    private val muxer: MediaMuxer
    private val freeInputs = LinkedBlockingQueue<Int>()
    private val lock = Any()

    /** Set on the encoder thread under [lock]. */
    private var videoTrack = -1
    private var metadataTrack = -1
    private var muxing = false

    private val ended = CountDownLatch(1)

    @Volatile
    private var failure: String? = null
    private var lastUs = 0L

    init {
        if (output.exists() && !options.overwrite) throw IOException("$output exists: pass RecordingOptions(overwrite = true) to replace it")
        part.delete()
        muxer = MediaMuxer(part.path, MediaMuxer.OutputFormat.MUXER_OUTPUT_MPEG_4)
        muxer.setOrientationHint(((orientationHint % 360) + 360) % 360)
        codec = MediaCodec.createEncoderByType(options.mime)
        val bitRate = if (options.bitRate > 0) options.bitRate else (0.2 * width * height * 30).toInt()
        val format = MediaFormat.createVideoFormat(options.mime, width, height).apply {
            setInteger(MediaFormat.KEY_COLOR_FORMAT, MediaCodecInfo.CodecCapabilities.COLOR_FormatYUV420Flexible)
            setInteger(MediaFormat.KEY_BIT_RATE, bitRate)
            setInteger(MediaFormat.KEY_FRAME_RATE, 30)
            setInteger(MediaFormat.KEY_I_FRAME_INTERVAL, 1)
        }
        codec.setCallback(callback(), Handler(thread.looper))
        codec.configure(format, null, null, MediaCodec.CONFIGURE_FLAG_ENCODE)
        codec.start()
    }

    private fun callback() = object : MediaCodec.Callback() {
        override fun onInputBufferAvailable(c: MediaCodec, index: Int) {
            freeInputs.add(index)
        }

        override fun onOutputFormatChanged(c: MediaCodec, format: MediaFormat) {
            // A callback must never throw on this thread (an uncaught exception ends the app):
            // every failure is recorded and ends the recording instead.
            try {
                synchronized(lock) {
                    if (released) return
                    if (muxing) return fail("the encoder changed its output format mid-stream")
                    videoTrack = muxer.addTrack(format)
                    metadataTrack = muxer.addTrack(MediaFormat().apply { setString(MediaFormat.KEY_MIME, RecordingSummary.METADATA_MIME) })
                    muxer.start()
                    muxing = true
                }
            } catch (e: RuntimeException) {
                fail("the muxer could not start: ${e.message}")
            }
        }

        override fun onOutputBufferAvailable(c: MediaCodec, index: Int, info: MediaCodec.BufferInfo) {
            try {
                synchronized(lock) {
                    if (released) return
                    val config = info.flags and MediaCodec.BUFFER_FLAG_CODEC_CONFIG != 0
                    if (!config && info.size > 0 && muxing) muxer.writeSampleData(videoTrack, c.getOutputBuffer(index)!!, info)
                }
                c.releaseOutputBuffer(index, false)
            } catch (e: RuntimeException) {
                fail("muxing failed: ${e.message}")
            }
            if (info.flags and MediaCodec.BUFFER_FLAG_END_OF_STREAM != 0) ended.countDown()
        }

        override fun onError(c: MediaCodec, e: MediaCodec.CodecException) = fail("the encoder failed: ${e.diagnosticInfo}")
    }

    private fun fail(why: String) {
        if (failure == null) failure = why
        ended.countDown()
    }

    override fun encode(frame: Image, presentationUs: Long): Boolean {
        if (failure != null) return false
        val index = freeInputs.poll() ?: return false
        return try {
            val dst = codec.getInputImage(index) ?: throw IllegalStateException("no input image")
            copyYuv(frame, dst)
            codec.queueInputBuffer(index, 0, width * height * 3 / 2, presentationUs, 0)
            lastUs = presentationUs
            true
        } catch (e: RuntimeException) {
            fail("the frame could not be queued: ${e.message}")
            false
        }
    }

    /** Copies the three planes of a YUV 4:2:0 image into the codec's input image, whatever the strides of each. */
    private fun copyYuv(src: Image, dst: Image) {
        val s = src.planes
        val d = dst.planes
        for (p in 0 until 3) {
            val cols = if (p == 0) width else (width + 1) / 2
            val rows = if (p == 0) height else (height + 1) / 2
            Yuv.copyPlane(s[p].buffer, s[p].rowStride, s[p].pixelStride, d[p].buffer, d[p].rowStride, d[p].pixelStride, cols, rows)
        }
    }

    override fun finish(summary: RecordingSummary) {
        try {
            val index = freeInputs.poll(END_TIMEOUT_MS, TimeUnit.MILLISECONDS) ?: throw IOException("the encoder took no end-of-stream buffer")
            codec.queueInputBuffer(index, 0, 0, lastUs, MediaCodec.BUFFER_FLAG_END_OF_STREAM)
            if (!ended.await(END_TIMEOUT_MS, TimeUnit.MILLISECONDS)) throw IOException("the encoder did not finish within $END_TIMEOUT_MS ms")
            failure?.let { throw IOException(it) }
            synchronized(lock) {
                val json = summary.toJson().toByteArray()
                val info = MediaCodec.BufferInfo().apply { set(0, json.size, lastUs, 0) }
                muxer.writeSampleData(metadataTrack, ByteBuffer.wrap(json), info)
                muxer.stop()
                muxing = false
            }
            release()
            moveIntoPlace(part, output, options.overwrite)
        } catch (e: Exception) {
            release()
            part.delete()
            throw IOException("recording to $output failed: ${e.message}", e)
        }
    }

    override fun abandon() {
        release()
        part.delete()
    }

    /** Set under [lock]: callbacks that come after the release do nothing. */
    private var released = false

    private fun release() {
        synchronized(lock) {
            if (released) return
            released = true
        }
        runCatching { codec.stop() }
        runCatching { codec.release() }
        runCatching { muxer.release() }
        thread.quitSafely()
    }

    private companion object {
        const val END_TIMEOUT_MS = 5000L
    }
}
