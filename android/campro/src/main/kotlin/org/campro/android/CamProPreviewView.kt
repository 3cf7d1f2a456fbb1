package org.campro.android

import android.content.Context
import android.graphics.Color
import android.graphics.ImageFormat
import android.graphics.Matrix
import android.graphics.SurfaceTexture
import android.media.Image
import android.media.ImageWriter
import android.util.AttributeSet
import android.view.Surface
import android.view.TextureView
import android.view.View
import android.widget.FrameLayout
import org.campro.Orientation
import org.campro.ProtectionState
import org.campro.applied

/**
 * The protected camera's preview: shows only frames whose own `CaptureResult` verified
 * (they reach [render] through the camera's gate, and nothing else writes to its surface),
 * fitted whole into the view (aspect kept), turned for the display's rotation and mirrored
 * for a front camera.
 *
 * While the state is not [ProtectionState.Protected] (or [ProtectionState.Applied], opted in) an opaque cover hides the picture
 * (show the state yourself: `CamProCamera.state`). The surface is never recreated for a
 * state change: the cover is the only thing that moves, so the preview comes back on the
 * first verified frame without a flash or a new buffer queue.
 *
 * Threads: [render] runs on the camera's preview thread; everything else on the main thread.
 * The writer reference is shared between them under [lock], never held across a call into it.
 */
class CamProPreviewView @JvmOverloads constructor(
    context: Context,
    attrs: AttributeSet? = null,
) : FrameLayout(context, attrs) {
    private val texture = TextureView(context)

    /** Covers the picture unless Protected (opaque black). */
    internal val cover = View(context).apply { setBackgroundColor(Color.BLACK) }

    private val lock = Any()

    /** Writes verified frames onto the texture's surface; `null` while there is no surface. Guarded by [lock]. */
    private var writer: ImageWriter? = null
    private var surface: Surface? = null

    /** Frames shown and frames closed unshown (no surface yet, or the writer refused them). */
    @Volatile
    var framesShown = 0L
        private set

    @Volatile
    var framesDropped = 0L
        private set

    // Main thread only.
    private var bufferWidth = 0
    private var bufferHeight = 0
    private var sensorOrientation = 0
    private var frontFacing = false
    private var mirrored = false

    /** The state the cover shows (main thread). */
    var state: ProtectionState = ProtectionState.Stopped("no camera", org.campro.Problem.CameraClosed)
        private set

    init {
        addView(texture, LayoutParams(LayoutParams.MATCH_PARENT, LayoutParams.MATCH_PARENT))
        addView(cover, LayoutParams(LayoutParams.MATCH_PARENT, LayoutParams.MATCH_PARENT))
        texture.surfaceTextureListener = object : TextureView.SurfaceTextureListener {
            override fun onSurfaceTextureAvailable(st: SurfaceTexture, width: Int, height: Int) {
                attach(st)
                applyTransform()
            }

            override fun onSurfaceTextureSizeChanged(st: SurfaceTexture, width: Int, height: Int) = applyTransform()

            override fun onSurfaceTextureDestroyed(st: SurfaceTexture): Boolean {
                detach()
                return true
            }

            override fun onSurfaceTextureUpdated(st: SurfaceTexture) {}
        }
    }

    /** The protection state: the picture shows only while Protected (main thread). */
    fun showState(s: ProtectionState) {
        state = s
        cover.visibility = if (s.applied) View.GONE else View.VISIBLE
    }

    /**
     * The stream this view shows: its buffer size, `SENSOR_ORIENTATION`, whether the camera
     * faces the user, and whether to mirror it (a front camera's preview, as a mirror shows
     * the user; `CamProOptions.mirrorFrontPreview`). Main thread; the camera calls it when it opens.
     */
    @JvmOverloads
    fun configure(width: Int, height: Int, sensorOrientationDegrees: Int, front: Boolean, mirror: Boolean = front) {
        require(width > 0 && height > 0) { "stream size must be positive, got $width x $height" }
        val changed = width != bufferWidth || height != bufferHeight
        bufferWidth = width
        bufferHeight = height
        sensorOrientation = sensorOrientationDegrees
        frontFacing = front
        mirrored = mirror
        if (changed) texture.surfaceTexture?.let { detach(); attach(it) }
        applyTransform()
    }

    /**
     * One verified frame (the camera's preview thread, never the frame thread: the camera
     * hands frames over through a latest-frame slot, [org.campro.LatestFrame]): queued onto
     * the surface, which then owns and closes it; closed here when there is no surface.
     * `queueInputImage` blocks while the writer has no free buffer (a hidden or stopped
     * view), so it runs outside [lock]: tearing the view down meanwhile closes the writer
     * under the call, which then throws and the frame is closed, and the main thread never
     * waits for it.
     */
    fun render(image: Image) {
        val w = synchronized(lock) { writer }
        if (w != null) {
            try {
                w.queueInputImage(image)
                framesShown++
                return
            } catch (e: RuntimeException) {
                // The surface went away under us (IllegalStateException) or the format was refused.
            }
        }
        framesDropped++
        image.close()
    }

    private fun attach(st: SurfaceTexture) {
        if (bufferWidth > 0) st.setDefaultBufferSize(bufferWidth, bufferHeight)
        val s = Surface(st)
        val w = try {
            ImageWriter.newInstance(s, WRITER_IMAGES, ImageFormat.YUV_420_888)
        } catch (e: RuntimeException) {
            null // no writer, no picture: frames are closed unshown (fail closed)
        }
        synchronized(lock) {
            surface = s
            writer = w
        }
    }

    private fun detach() {
        synchronized(lock) {
            writer?.close()
            writer = null
            surface?.release()
            surface = null
        }
    }

    /** The texture's matrix for the current sizes and rotation (main thread). */
    private fun applyTransform() {
        if (bufferWidth == 0 || width == 0 || height == 0) return
        val rotation = Orientation.previewRotation(sensorOrientation, displayRotationDegrees(), frontFacing)
        texture.setTransform(Matrix().apply { setValues(Orientation.fitTransform(bufferWidth, bufferHeight, width, height, rotation, mirrored)) })
    }

    private fun displayRotationDegrees(): Int = when (display?.rotation ?: Surface.ROTATION_0) {
        Surface.ROTATION_90 -> 90
        Surface.ROTATION_180 -> 180
        Surface.ROTATION_270 -> 270
        else -> 0
    }

    /**
     * A turn from landscape to reverse landscape (180 degrees) changes no configuration, so
     * only the display says so: the picture would show upside down until the next resize.
     */
    private val displayListener = object : android.hardware.display.DisplayManager.DisplayListener {
        override fun onDisplayAdded(displayId: Int) {}
        override fun onDisplayRemoved(displayId: Int) {}
        override fun onDisplayChanged(displayId: Int) {
            if (displayId == display?.displayId) applyTransform()
        }
    }

    override fun onAttachedToWindow() {
        super.onAttachedToWindow()
        context.getSystemService(android.hardware.display.DisplayManager::class.java)?.registerDisplayListener(displayListener, handler)
        applyTransform()
    }

    override fun onDetachedFromWindow() {
        context.getSystemService(android.hardware.display.DisplayManager::class.java)?.unregisterDisplayListener(displayListener)
        super.onDetachedFromWindow()
    }

    /** The texture's current matrix (internal: tests read what the view applies). */
    internal fun textureTransform(): Matrix = texture.getTransform(null)

    override fun onConfigurationChanged(newConfig: android.content.res.Configuration?) {
        super.onConfigurationChanged(newConfig)
        applyTransform() // the display turned under an activity that handles rotation itself
    }

    override fun onSizeChanged(w: Int, h: Int, oldw: Int, oldh: Int) {
        super.onSizeChanged(w, h, oldw, oldh)
        applyTransform()
    }

    private companion object {
        /** Buffers between the writer and the texture: one shown, one queued. */
        const val WRITER_IMAGES = 2
    }
}
