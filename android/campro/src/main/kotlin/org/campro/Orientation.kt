package org.campro

/**
 * How a camera buffer is turned for the screen and for a still, from plain values
 * (`SENSOR_ORIENTATION`, the display's rotation or the device's physical orientation,
 * `LENS_FACING`), so the rules are host-tested.
 *
 * Degrees are clockwise and multiples of 90 (anything else is refused by name).
 */
object Orientation {
    private fun quarter(name: String, deg: Int): Int {
        require(deg % 90 == 0) { "$name must be a multiple of 90 degrees, got $deg" }
        return ((deg % 360) + 360) % 360
    }

    /**
     * Clockwise turn that shows the buffer upright on a display rotated by
     * [displayRotation] (`Display.getRotation()` in degrees): back cameras
     * `sensor - display`, front cameras `sensor + display` (the image is then mirrored).
     */
    fun previewRotation(sensorOrientation: Int, displayRotation: Int, frontFacing: Boolean): Int {
        val s = quarter("sensorOrientation", sensorOrientation)
        val d = quarter("displayRotation", displayRotation)
        return if (frontFacing) (s + d) % 360 else (s - d + 360) % 360
    }

    /**
     * Clockwise turn a viewer must give a still's stored pixels, from the device's physical
     * orientation ([deviceOrientation], `OrientationEventListener` rounded to 90): Camera2's
     * `JPEG_ORIENTATION` rule, back `sensor + device`, front `sensor - device`. Stills are
     * not mirrored (as the camera's own JPEGs).
     */
    fun stillRotation(sensorOrientation: Int, deviceOrientation: Int, frontFacing: Boolean): Int {
        val s = quarter("sensorOrientation", sensorOrientation)
        val d = quarter("deviceOrientation", deviceOrientation)
        return if (frontFacing) (s - d + 360) % 360 else (s + d) % 360
    }

    /**
     * The EXIF `Orientation` value for a clockwise turn: 0 -> 1, 90 -> 6, 180 -> 3, 270 -> 8;
     * with [mirror] (a front camera's still shown as the preview showed it: turned, then
     * mirrored left-right) 0 -> 2, 90 -> 5 (transpose), 180 -> 4, 270 -> 7 (transverse).
     */
    @JvmOverloads
    fun exifOrientation(rotation: Int, mirror: Boolean = false): Int = when (quarter("rotation", rotation)) {
        0 -> if (mirror) 2 else 1
        90 -> if (mirror) 5 else 6
        180 -> if (mirror) 4 else 3
        else -> if (mirror) 7 else 8
    }

    /** `OrientationEventListener.ORIENTATION_UNKNOWN`: the device lies flat, or the sensor has no reading. */
    const val UNKNOWN = -1

    /** Degrees past the half-way mark (45) a reading must go before the device counts as turned to the next quarter. */
    const val HYSTERESIS = 15

    /**
     * The device's physical orientation, a multiple of 90, from an `OrientationEventListener`
     * reading ([degrees], 0..359 clockwise, or [UNKNOWN]) and the [previous] one: the reading's
     * nearest quarter, except that [previous] holds until the reading is more than
     * 45 + [HYSTERESIS] degrees from it (a phone held near 45 does not flip back and forth).
     * Apps locked to portrait get stills and videos turned as the device is held, which the
     * display's rotation (always 0 there) cannot tell.
     */
    fun deviceOrientation(degrees: Int, previous: Int): Int {
        val prev = quarter("previous", previous)
        if (degrees == UNKNOWN) return prev
        require(degrees in 0..359) { "degrees must be 0..359 or UNKNOWN, got $degrees" }
        val away = minOf((degrees - prev + 360) % 360, (prev - degrees + 360) % 360)
        if (away <= 45 + HYSTERESIS) return prev
        return ((degrees + 45) / 90 % 4) * 90
    }

    /**
     * The transform a `TextureView` needs (`Matrix.setValues`: a, b, c, d, e, f, 0, 0, 1 with
     * x' = a x + b y + c, y' = d x + e y + f) to show a [bufferWidth] x [bufferHeight] buffer,
     * which the view stretches over its [viewWidth] x [viewHeight] pixels, turned by
     * [rotation] (clockwise), mirrored left-right when [mirror], and fitted whole in the view,
     * centred (aspect kept, bars where the shapes differ).
     */
    fun fitTransform(bufferWidth: Int, bufferHeight: Int, viewWidth: Int, viewHeight: Int, rotation: Int, mirror: Boolean): FloatArray {
        require(bufferWidth > 0 && bufferHeight > 0) { "buffer size must be positive, got $bufferWidth x $bufferHeight" }
        require(viewWidth > 0 && viewHeight > 0) { "view size must be positive, got $viewWidth x $viewHeight" }
        val r = quarter("rotation", rotation)
        val turned = r == 90 || r == 270
        val bw = (if (turned) bufferHeight else bufferWidth).toDouble()
        val bh = (if (turned) bufferWidth else bufferHeight).toDouble()
        val s = minOf(viewWidth / bw, viewHeight / bh)
        val dw = bw * s
        val dh = bh * s
        val ox = (viewWidth - dw) / 2
        val oy = (viewHeight - dh) / 2
        // Normalised buffer (u, v) -> normalised upright (p, q) = A (u, v) + t, clockwise turns.
        var a = doubleArrayOf(1.0, 0.0, 0.0, 1.0)
        var t = doubleArrayOf(0.0, 0.0)
        when (r) {
            90 -> { a = doubleArrayOf(0.0, -1.0, 1.0, 0.0); t = doubleArrayOf(1.0, 0.0) } // (1 - v, u)
            180 -> { a = doubleArrayOf(-1.0, 0.0, 0.0, -1.0); t = doubleArrayOf(1.0, 1.0) } // (1 - u, 1 - v)
            270 -> { a = doubleArrayOf(0.0, 1.0, -1.0, 0.0); t = doubleArrayOf(0.0, 1.0) } // (v, 1 - u)
        }
        if (mirror) { a = doubleArrayOf(-a[0], -a[1], a[2], a[3]); t = doubleArrayOf(1 - t[0], t[1]) }
        // View (x, y) = (u W, v H) in; out (ox + p dw, oy + q dh).
        val w = viewWidth.toDouble()
        val h = viewHeight.toDouble()
        return floatArrayOf(
            (dw * a[0] / w).toFloat(), (dw * a[1] / h).toFloat(), (ox + dw * t[0]).toFloat(),
            (dh * a[2] / w).toFloat(), (dh * a[3] / h).toFloat(), (oy + dh * t[1]).toFloat(),
            0f, 0f, 1f,
        )
    }
}
