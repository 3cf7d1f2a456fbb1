package org.campro

/**
 * The protected stream's size, chosen from what the camera lists for the format
 * (`StreamConfigurationMap.getOutputSizes`) instead of a size the device may not have (a
 * size it does not list fails the session's configuration, or is silently replaced).
 *
 * Rule: among the listed sizes no larger than [maxWidth] x [maxHeight] (in either
 * orientation of the listing: sensors list landscape sizes), those closest to the wanted
 * aspect ratio `maxWidth / maxHeight` (within 1%), then the largest area; when none is that
 * close, the largest area of any aspect within the bound; when none fits the bound, the
 * smallest listed size. `null` only when nothing is listed.
 */
object StreamSize {
    fun choose(listed: List<Pair<Int, Int>>, maxWidth: Int, maxHeight: Int): Pair<Int, Int>? {
        require(maxWidth >= 1 && maxHeight >= 1) { "the bound must be positive, got $maxWidth x $maxHeight" }
        val sizes = listed.filter { (w, h) -> w >= 1 && h >= 1 }
        if (sizes.isEmpty()) return null
        val fits = sizes.filter { (w, h) -> w <= maxWidth && h <= maxHeight }
        if (fits.isEmpty()) return sizes.minByOrNull { (w, h) -> w.toLong() * h }
        val want = maxWidth.toDouble() / maxHeight
        val aspect = fits.filter { (w, h) -> kotlin.math.abs(w.toDouble() / h / want - 1.0) <= 0.01 }
        return (aspect.ifEmpty { fits }).maxByOrNull { (w, h) -> w.toLong() * h }
    }
}
