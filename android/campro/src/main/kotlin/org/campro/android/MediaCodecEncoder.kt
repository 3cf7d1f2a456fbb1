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
 * The stream is tagged as the camera's `YUV_420_888` is: full range, BT.601 matrix, SDR video
 * transfer (`KEY_COLOR_RANGE`/`STANDARD`/`TRANSFER`), so players do not read it as limited
 * range (crushed blacks, clipped whites). The codec is chosen for the size first: HEVC falls
 * back to H.264 when the device has no HEVC encoder for [width] x [height] ([mime] says which
 * was used); neither is an [IOException] before anything is written. A codec or muxer that
 * fails to configure releases everything it took (the thread, the muxer, the `.part` file).
 *
 * Threads: [encode] on the frame thread (it copies the borrowed frame: a few milliseconds);
 * [finish] and [abandon] on any one thread (the camera runs them off the frame thread: the
 * end of stream may wait for the codec); the codec's callbacks on this encoder's own thread.
 * Android only: compiled against the framework in CI, run on phones.
 */
class MediaCodecEncoder(
    private val output: File,
    private val width: Int,
    private val height: Int,
    /** Clockwise degrees a player turns the video (`MediaMuxer.setOrientationHint`). */
    orientationHint: Int,
    private val options: RecordingOptions = RecordingOptions(),
    /** Whether this device has an encoder of a MIME type for a size (default: `MediaCodecList`; tests script it). */
    supports: (mime: String, width: Int, height: Int) -> Boolean = ::deviceEncodes,
) : VideoEncoder<Image> {
    /** The codec used: [RecordingOptions.mime], or H.264 where HEVC is not available at this size. */
    val mime: String = org.campro.Records.chooseVideoMime(options.mime, width, height, supports)
        ?: throw IOException("this device has no H.264 or HEVC encoder for $width x $height")

    private val part = partOf(output)
    private val thread: HandlerThread
    private val codec: MediaCodec
    private val muxer: MediaMuxer
    private val freeInputs = LinkedBlockingQueue<Int>()
    private val lock = Any()

    /** Set on the encoder thread under [lock]. */
    private var videoTrack = -1
    private var metadataTrack = -1
    private var muxing = false

    private val ended = CountDownLatch(1)

    /** Why the recording failed (`null`: it has not); the frames after it are refused. */
    @Volatile
    var failure: String? = null
        private set
    private var lastUs = 0L

    init {
        if (output.exists() && !options.overwrite) throw IOException("$output exists: pass RecordingOptions(overwrite = true) to replace it")
        part.delete()
        var t: HandlerThread? = null
        var m: MediaMuxer? = null
        var c: MediaCodec? = null
        try {
            t = HandlerThread("campro-encoder").apply { start() }
            m = MediaMuxer(part.path, MediaMuxer.OutputFormat.MUXER_OUTPUT_MPEG_4)
            m.setOrientationHint(((orientationHint % 360) + 360) % 360)
            c = MediaCodec.createEncoderByType(mime)
            c.setCallback(callback(), Handler(t.looper))
            c.configure(format(mime, width, height, options.bitRate), null, null, MediaCodec.CONFIGURE_FLAG_ENCODE)
        } catch (e: Exception) {
            runCatching { c?.release() }
            runCatching { m?.release() }
            t?.quitSafely()
            part.delete()
            throw IOException("the $mime encoder for $width x $height could not start: ${e.message}", e)
        }
        // Every field the callbacks use is set before the codec starts calling them.
        thread = t
        muxer = m
        codec = c
        try {
            c.start()
        } catch (e: Exception) {
            release()
            part.delete()
            throw IOException("the $mime encoder for $width x $height could not start: ${e.message}", e)
        }
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
            // The size the codec's own layout spans (its buffer, padding and alignment
            // included), not a packed 4:2:0 size: a codec with aligned rows reads all of it.
            val size = codec.getInputBuffer(index)?.capacity() ?: (width * height * 3 / 2)
            codec.queueInputBuffer(index, 0, size, presentationUs, 0)
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

    internal companion object {
        const val END_TIMEOUT_MS = 5000L

        /** The encoder's format: flexible YUV in, the camera's colour tags, 0.2 bits a pixel at 30 fps unless [bitRate] is set. */
        fun format(mime: String, width: Int, height: Int, bitRate: Int): MediaFormat =
            MediaFormat.createVideoFormat(mime, width, height).apply {
                setInteger(MediaFormat.KEY_COLOR_FORMAT, MediaCodecInfo.CodecCapabilities.COLOR_FormatYUV420Flexible)
                setInteger(MediaFormat.KEY_BIT_RATE, if (bitRate > 0) bitRate else (0.2 * width * height * 30).toInt())
                setInteger(MediaFormat.KEY_FRAME_RATE, 30)
                setInteger(MediaFormat.KEY_I_FRAME_INTERVAL, 1)
                // Camera2's YUV_420_888 is JFIF: full range, BT.601 matrix; sRGB-like SDR transfer.
                setInteger(MediaFormat.KEY_COLOR_RANGE, MediaFormat.COLOR_RANGE_FULL)
                setInteger(MediaFormat.KEY_COLOR_STANDARD, MediaFormat.COLOR_STANDARD_BT601_PAL)
                setInteger(MediaFormat.KEY_COLOR_TRANSFER, MediaFormat.COLOR_TRANSFER_SDR_VIDEO)
            }

        /** Whether `MediaCodecList` has an encoder of [mime] for [width] x [height]. */
        fun deviceEncodes(mime: String, width: Int, height: Int): Boolean =
            android.media.MediaCodecList(android.media.MediaCodecList.REGULAR_CODECS).codecInfos.any { info ->
                info.isEncoder && info.supportedTypes.any { it.equals(mime, ignoreCase = true) } &&
                    runCatching { info.getCapabilitiesForType(mime).videoCapabilities?.isSizeSupported(width, height) == true }.getOrDefault(false)
            }
    }
}
