package org.campro

import java.nio.ByteBuffer

/** Copies between the planes of YUV 4:2:0 images (`Image.Plane`s), whatever their strides. */
object Yuv {
    /**
     * Copies [rows] rows of [cols] samples from [src] to [dst], each plane addressed from its
     * buffer's position with its own row and pixel stride (bytes). Rows of pixel stride 1
     * are copied whole; other strides sample by sample (chroma of semi-planar images: a
     * quarter of the pixels). Positions and limits of the buffers are left as they were.
     */
    fun copyPlane(
        src: ByteBuffer, srcRowStride: Int, srcPixelStride: Int,
        dst: ByteBuffer, dstRowStride: Int, dstPixelStride: Int,
        cols: Int, rows: Int,
    ) {
        require(cols > 0 && rows > 0) { "cols and rows must be positive, got $cols x $rows" }
        require(srcPixelStride >= 1 && dstPixelStride >= 1) { "pixel strides must be >= 1, got $srcPixelStride and $dstPixelStride" }
        require(srcRowStride >= (cols - 1) * srcPixelStride + 1) { "source row stride $srcRowStride cannot hold $cols samples at pixel stride $srcPixelStride" }
        require(dstRowStride >= (cols - 1) * dstPixelStride + 1) { "destination row stride $dstRowStride cannot hold $cols samples at pixel stride $dstPixelStride" }
        val s0 = src.position()
        val d0 = dst.position()
        val span = (rows - 1).toLong()
        require(s0 + span * srcRowStride + (cols - 1).toLong() * srcPixelStride < src.limit()) { "the source plane is too small for $cols x $rows" }
        require(d0 + span * dstRowStride + (cols - 1).toLong() * dstPixelStride < dst.limit()) { "the destination plane is too small for $cols x $rows" }
        if (srcPixelStride == 1 && dstPixelStride == 1) {
            val s = src.duplicate()
            val d = dst.duplicate()
            for (r in 0 until rows) {
                s.limit(s0 + r * srcRowStride + cols).position(s0 + r * srcRowStride)
                d.position(d0 + r * dstRowStride)
                d.put(s)
            }
        } else {
            for (r in 0 until rows) {
                var si = s0 + r * srcRowStride
                var di = d0 + r * dstRowStride
                for (c in 0 until cols) {
                    dst.put(di, src.get(si))
                    si += srcPixelStride
                    di += dstPixelStride
                }
            }
        }
    }

    /** A plane's samples as a tightly packed array ([cols] x [rows]), for the still encoder. */
    fun packPlane(src: ByteBuffer, rowStride: Int, pixelStride: Int, cols: Int, rows: Int): ByteArray {
        val out = ByteArray(cols * rows)
        copyPlane(src, rowStride, pixelStride, ByteBuffer.wrap(out), cols, 1, cols, rows)
        return out
    }
}
