package org.campro.android

import android.graphics.ImageFormat
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CaptureResult
import android.hardware.camera2.params.ColorSpaceTransform
import android.hardware.camera2.params.RggbChannelVector
import android.hardware.camera2.params.TonemapCurve
import android.media.Image
import android.os.Looper
import android.util.Size
import org.campro.Fixtures
import org.campro.PixelProbe
import org.robolectric.Shadows.shadowOf
import org.robolectric.shadow.api.Shadow
import org.robolectric.shadows.ShadowCameraCharacteristics
import org.robolectric.shadows.StreamConfigurationMapBuilder
import java.nio.ByteBuffer

/** Scripts a [CamProCamera] on Robolectric's camera service as an honest HAL would (shared by the Android tests). */
object CameraScript {
    /** A camera CamPro supports, back-facing, sensor at 90, listing YUV 1280 x 720 and 640 x 480. */
    fun chars(supported: Boolean = true, facing: Int = CameraCharacteristics.LENS_FACING_BACK): CameraCharacteristics {
        val c = ShadowCameraCharacteristics.newCameraCharacteristics()
        val s = Shadow.extract<ShadowCameraCharacteristics>(c)
        s.set(CameraCharacteristics.REQUEST_AVAILABLE_CAPABILITIES, if (supported) intArrayOf(0, 2) else intArrayOf(0))
        s.set(CameraCharacteristics.TONEMAP_AVAILABLE_TONE_MAP_MODES, if (supported) intArrayOf(0, 1, 2) else intArrayOf(1, 2))
        s.set(CameraCharacteristics.TONEMAP_MAX_CURVE_POINTS, 64)
        s.set(CameraCharacteristics.CONTROL_AWB_AVAILABLE_MODES, intArrayOf(0, 1))
        // Settings apply 2 frames late: protected frames repeat alone (Robolectric's session takes repeating requests, not bursts).
        s.set(CameraCharacteristics.SYNC_MAX_LATENCY, 2)
        s.set(CameraCharacteristics.REQUEST_PIPELINE_MAX_DEPTH, 4.toByte())
        s.set(CameraCharacteristics.LENS_FACING, facing)
        s.set(CameraCharacteristics.SENSOR_ORIENTATION, 90)
        s.set(
            CameraCharacteristics.SCALER_STREAM_CONFIGURATION_MAP,
            StreamConfigurationMapBuilder.newBuilder()
                .addOutputSize(ImageFormat.YUV_420_888, Size(1280, 720))
                .addOutputSize(ImageFormat.YUV_420_888, Size(640, 480))
                .build(),
        )
        return c
    }

    /** Runs what the camera, frame and main threads have queued, until all are idle. */
    fun settle(c: CamProCamera) {
        repeat(4) {
            for (l in listOf(c.cameraLooper, c.frameLooper)) {
                // A closed camera's threads have quit (or are quitting): nothing to run there.
                if (l != null && l.thread.isAlive) runCatching { shadowOf(l).idle() }
            }
            shadowOf(Looper.getMainLooper()).idle()
        }
    }

    fun result(vararg values: Pair<CaptureResult.Key<*>, Any>) = scriptedResult(*values)

    /** Meters, answers the pixel probe and verifies one protected result at [ts], as an honest HAL (on the camera thread). */
    fun protect(c: CamProCamera, ts: Long) {
        val g = c.glue!!
        onCamera(c) {
            g.onResult(
                CamProCamera2.METERING,
                result(
                    CaptureResult.CONTROL_AWB_MODE to 1, CaptureResult.CONTROL_AWB_STATE to 2,
                    CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(Fixtures.PHONE),
                    CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
                ),
            )
            for ((i, step) in PixelProbe.Step.values().withIndex()) {
                val curve = PixelProbe.curve(step)
                g.onResult(CamProCamera2.PROBE, honoured(g, 100L + i, PixelProbe.transform(step, g.session.transform), arrayOf(curve, curve, curve)))
                g.pipeline.onProbeFrame(100L + i, ByteArray(4800) { Fixtures.probeLevel(curve).toByte() })
            }
        }
        verify(c, ts)
    }

    fun honoured(g: CamProCamera2, ts: Long, transform: IntArray = g.session.transform.copyOf(), curves: Array<FloatArray> = g.session.curvesForRequest()) = result(
        CaptureResult.CONTROL_AWB_MODE to 0, CaptureResult.COLOR_CORRECTION_MODE to 0, CaptureResult.TONEMAP_MODE to 0,
        CaptureResult.COLOR_CORRECTION_TRANSFORM to ColorSpaceTransform(transform),
        CaptureResult.TONEMAP_CURVE to TonemapCurve(curves[0], curves[1], curves[2]),
        CaptureResult.COLOR_CORRECTION_GAINS to RggbChannelVector(2f, 1f, 1f, 1.6f),
        CaptureResult.SENSOR_TIMESTAMP to ts,
    )

    fun verify(c: CamProCamera, ts: Long) {
        val g = c.glue!!
        onCamera(c) { g.onResult(CamProCamera2.PROTECTED, honoured(g, ts)) }
    }

    fun onCamera(c: CamProCamera, body: () -> Unit) {
        android.os.Handler(c.cameraLooper!!).post(body)
        settle(c)
    }

    /** A YUV 4:2:0 frame of flat 8 x 8 blocks (I420 planes), closed through [closed]. */
    /**
     * A `YUV_420_888` image over [planes] (buffer, row stride, pixel stride each), as a camera
     * or a codec hands them out; [onClose] runs on close.
     */
    open class YuvImage(
        private val w: Int,
        private val h: Int,
        private val ts: Long,
        private val planes: () -> List<Triple<ByteBuffer, Int, Int>>,
        private val onClose: () -> Unit = {},
    ) : Image() {
        override fun getFormat() = ImageFormat.YUV_420_888
        override fun getWidth() = w
        override fun getHeight() = h
        override fun getTimestamp() = ts
        override fun getTransform() = 0
        override fun getScalingMode() = 0
        override fun getPlanes(): Array<Plane> = planes().map { (b, row, px) ->
            object : Plane() {
                override fun getRowStride() = row
                override fun getPixelStride() = px
                override fun getBuffer(): ByteBuffer = b.duplicate()
            }
        }.toTypedArray()
        override fun close() = onClose()
    }

    /** A YUV 4:2:0 frame of flat 8 x 8 blocks (I420 planes), its timestamp added to [closed] on close. */
    class FakeImage(w: Int, h: Int, ts: Long, closed: MutableList<Long>) :
        YuvImage(w, h, ts, { emptyList() }, { closed += ts }) {
        val y = ByteArray(w * h) { k -> (40 + 13 * ((k % w) / 8 + 3 * ((k / w) / 8))).toByte() }
        val u = ByteArray(w * h / 4) { k -> (90 + 11 * ((k % (w / 2)) / 4)).toByte() }
        val v = ByteArray(w * h / 4) { k -> (170 - 9 * ((k / (w / 2)) / 4)).toByte() }
        private val planeList = listOf(Triple(ByteBuffer.wrap(y), w, 1), Triple(ByteBuffer.wrap(u), w / 2, 1), Triple(ByteBuffer.wrap(v), w / 2, 1))
        override fun getPlanes(): Array<Plane> = YuvImage(width, height, timestamp, { planeList }).planes
    }
}
