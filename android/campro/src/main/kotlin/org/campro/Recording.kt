package org.campro

/**
 * Where a protected recording's frames go: an H.264/HEVC encoder and an MP4 muxer on a phone
 * ([org.campro.android.MediaCodecEncoder]); a lossless ffmpeg encoder in the JVM tests.
 * Called on one thread (the frame thread), in order.
 */
interface VideoEncoder<T> {
    /**
     * One verified frame at [presentationUs] (microseconds from the recording's first frame,
     * strictly increasing). The encoder *borrows* the frame: it copies what it needs before
     * returning and never closes it. Returns `false` when it could not take the frame (no
     * input buffer free): the frame is counted as dropped, never queued for later.
     */
    fun encode(frame: T, presentationUs: Long): Boolean

    /** Ends the file with [summary] written into it (the MP4's metadata track; a comment tag in tests). */
    fun finish(summary: RecordingSummary)

    /** Abandons the file (nothing was recorded, or the recording failed): it is deleted, never left half-written. */
    fun abandon()
}

/**
 * What a finished recording holds and what it left out, written into the file itself.
 *
 * [framesFailedCheck] counts the frames the camera made while recording that the per-frame
 * gate dropped (their result did not verify, never came, or came too late): they are not in
 * the file, and the gaps they leave are real time (the timestamps are the sensor's).
 */
data class RecordingSummary(
    /** Frames in the file. */
    val frames: Long,
    /** Frames dropped by the gate while recording (never written). */
    val framesFailedCheck: Long,
    /** Verified frames the encoder could not take (no input buffer), not written. */
    val framesEncoderBusy: Long,
    /** Verified frames whose sensor timestamp did not increase, not written. */
    val framesOutOfOrder: Long,
    /** Sensor timestamp of the first and last frame written, nanoseconds (0 when none). */
    val firstTimestampNs: Long,
    val lastTimestampNs: Long,
    /** Why the recording ended: "stopped by the app", or the state that ended it. */
    val endedBecause: String,
) {
    /** Presentation time of the last frame, microseconds. */
    val durationUs: Long get() = if (frames == 0L) 0L else (lastTimestampNs - firstTimestampNs) / 1000

    /** One line of JSON, as the file carries it. */
    fun toJson(): String = buildString {
        append("{\"campro_recording\":1")
        append(",\"frames\":").append(frames)
        append(",\"frames_failed_check\":").append(framesFailedCheck)
        append(",\"frames_encoder_busy\":").append(framesEncoderBusy)
        append(",\"frames_out_of_order\":").append(framesOutOfOrder)
        append(",\"first_timestamp_ns\":").append(firstTimestampNs)
        append(",\"last_timestamp_ns\":").append(lastTimestampNs)
        append(",\"ended_because\":\"").append(jsonEscape(endedBecause)).append("\"}")
    }

    companion object {
        /** The MIME type of the MP4 metadata track that carries [toJson]. */
        const val METADATA_MIME = "application/x-campro-recording"

        private fun jsonEscape(s: String) = buildString {
            for (c in s) when {
                c == '"' -> append("\\\"")
                c == '\\' -> append("\\\\")
                c < ' ' -> append("\\u%04x".format(c.code))
                else -> append(c)
            }
        }
    }
}

/**
 * A recording of verified frames only. Feed it every frame the pipeline delivers
 * ([onFrame]: only frames whose own result verified ever arrive there) and it writes them
 * with their sensor timestamps, made relative to the first frame, to [encoder]; frames the
 * gate dropped meanwhile are counted from [gateDropped] (the pipeline's `gate.dropped`), so
 * the file says how many were left out.
 *
 * Timestamps: a frame whose sensor timestamp is not after the last one written is not
 * written (an encoder and MP4 need increasing times; such a frame is a HAL fault) and is
 * counted. Threads: every method is synchronized; frames come from one thread in order.
 */
class ProtectedRecording<T>(
    private val encoder: VideoEncoder<T>,
    /** The frame's sensor timestamp, nanoseconds (`Image.getTimestamp()`). */
    private val timestampNs: (T) -> Long,
    /** The gate's running count of dropped frames. */
    private val gateDropped: () -> Long,
) {
    private val droppedAtStart = gateDropped()
    private var frames = 0L
    private var busy = 0L
    private var outOfOrder = 0L
    private var first = 0L
    private var last = Long.MIN_VALUE
    private var summary: RecordingSummary? = null

    /** Whether the recording still takes frames. */
    val isActive: Boolean @Synchronized get() = summary == null

    /** Frames written so far. */
    val framesWritten: Long @Synchronized get() = frames

    /** Borrows one verified frame (the caller keeps ownership and closes it). */
    @Synchronized
    fun onFrame(frame: T) {
        if (summary != null) return
        val ts = timestampNs(frame)
        if (frames > 0 && ts <= last) {
            outOfOrder++
            return
        }
        val pts = if (frames == 0L) 0L else (ts - first) / 1000
        if (!encoder.encode(frame, pts)) {
            busy++
            return
        }
        if (frames == 0L) first = ts
        last = ts
        frames++
    }

    /**
     * Ends the recording ([reason] is written into the file): the file is finished, or
     * abandoned (deleted) when no frame was written. Idempotent: returns the first summary.
     */
    @Synchronized
    fun stop(reason: String = "stopped by the app"): RecordingSummary {
        summary?.let { return it }
        val s = RecordingSummary(
            frames = frames,
            framesFailedCheck = gateDropped() - droppedAtStart,
            framesEncoderBusy = busy,
            framesOutOfOrder = outOfOrder,
            firstTimestampNs = if (frames == 0L) 0L else first,
            lastTimestampNs = if (frames == 0L) 0L else last,
            endedBecause = reason,
        )
        summary = s
        if (frames == 0L) encoder.abandon() else encoder.finish(s)
        return s
    }
}

/**
 * What a protected output's record (`NAME.campro.json`, `campro::record`) says of the camera
 * that made it, captured while the camera runs (its native state may be gone when the file
 * is finished): the preset's bytes and SHA-256, the values sent, the bounds. [json] builds
 * the record natively, by the same rules `campro check --record` reads it with.
 */
class RecordContext(
    private val presetJson: ByteArray,
    /** What named the preset (a bundled preset's name, or "app JSON"). */
    val given: String,
    val cameraId: String,
    private val transform: IntArray,
    private val curvePoints: Int,
    private val gains: FloatArray,
    /** The last update's stated bound, 8-bit LSB. */
    private val conversionBoundLsb: Double,
    private val worstDeviationLsb: Double,
    private val maxDeviationLsb: Double,
) {
    /** The record of [output] ([jpegQuality] 0: not a JPEG; [metadata]: what it carries). */
    fun json(output: java.io.File, jpegQuality: Int, metadata: String): String = CamProNative.record(
        presetJson, given, Records.sha256(presetJson), cameraId, transform, curvePoints, gains,
        conversionBoundLsb, worstDeviationLsb, maxDeviationLsb, jpegQuality, metadata,
        output.name, Records.sha256(output), output.length(),
    )
}

/** Where records lie and the hashes they hold. */
object Records {
    /** `MediaFormat.MIMETYPE_VIDEO_AVC` and `MIMETYPE_VIDEO_HEVC`. */
    const val AVC = "video/avc"
    const val HEVC = "video/hevc"

    /**
     * The video codec to record with: [wanted] when the device encodes it at [width] x
     * [height] ([supports]), else H.264 for HEVC (the one every Android device must encode);
     * `null` when neither is available at that size.
     */
    fun chooseVideoMime(wanted: String, width: Int, height: Int, supports: (String, Int, Int) -> Boolean): String? = when {
        supports(wanted, width, height) -> wanted
        wanted == HEVC && supports(AVC, width, height) -> AVC
        else -> null
    }

    /** The record of [output]: its name with `.campro.json` appended, beside it. */
    fun pathOf(output: java.io.File) = java.io.File(output.path + ".campro.json")

    /** SHA-256 of [bytes], lowercase hex. */
    fun sha256(bytes: ByteArray): String = hex(java.security.MessageDigest.getInstance("SHA-256").digest(bytes))

    /** SHA-256 of a file's bytes, streamed, lowercase hex. */
    fun sha256(file: java.io.File): String {
        val md = java.security.MessageDigest.getInstance("SHA-256")
        file.inputStream().use { input ->
            val buf = ByteArray(1 shl 16)
            while (true) {
                val n = input.read(buf)
                if (n < 0) break
                md.update(buf, 0, n)
            }
        }
        return hex(md.digest())
    }

    private fun hex(d: ByteArray) = d.joinToString("") { "%02x".format(it.toInt() and 255) }
}
