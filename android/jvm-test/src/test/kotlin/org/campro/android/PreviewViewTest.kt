package org.campro.android

import android.app.Activity
import android.view.Surface
import org.campro.Orientation
import org.junit.Assert.assertArrayEquals
import org.junit.Test
import org.junit.runner.RunWith
import org.robolectric.Robolectric
import org.robolectric.RobolectricTestRunner
import org.robolectric.Shadows.shadowOf
import org.robolectric.annotation.Config
import org.robolectric.shadows.ShadowDisplay

/** [CamProPreviewView] in a window: the matrix it gives its texture follows the display. */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34])
class PreviewViewTest {
    private fun values(view: CamProPreviewView) = FloatArray(9).also { view.textureTransform().getValues(it) }

    /**
     * Landscape to reverse landscape changes no configuration (the activity is not told):
     * only the display listener sees it. The matrix must be the hand-checked fit for the new
     * turn (`Orientation.fitTransform`, tested against hand-derived cases in CaptureLogicTest).
     */
    @Test
    fun aHalfTurnOfTheDisplayTurnsThePreview() {
        val display = ShadowDisplay.getDefaultDisplay()
        shadowOf(display).setRotation(Surface.ROTATION_90)
        val activity = Robolectric.buildActivity(Activity::class.java).setup().get()
        val view = CamProPreviewView(activity)
        activity.setContentView(view)
        view.configure(1280, 720, 90, front = false)
        shadowOf(android.os.Looper.getMainLooper()).idle()
        // Display at 90: a back sensor at 90 shows unturned.
        assertArrayEquals(Orientation.fitTransform(1280, 720, view.width, view.height, Orientation.previewRotation(90, 90, false), false), values(view), 1e-4f)
        val (w, h) = view.width to view.height
        shadowOf(display).setRotation(Surface.ROTATION_270)
        shadowOf(android.os.Looper.getMainLooper()).idle()
        assertArrayEquals("the view kept its size: only the display turned", intArrayOf(w, h), intArrayOf(view.width, view.height))
        assertArrayEquals(Orientation.fitTransform(1280, 720, w, h, Orientation.previewRotation(90, 270, false), false), values(view), 1e-4f)
    }

    /** A front camera's preview is mirrored unless the app asks otherwise. */
    @Test
    fun aFrontPreviewIsMirroredOnlyWhenAsked() {
        val activity = Robolectric.buildActivity(Activity::class.java).setup().get()
        val view = CamProPreviewView(activity)
        activity.setContentView(view)
        shadowOf(android.os.Looper.getMainLooper()).idle()
        view.configure(640, 480, 270, front = true)
        assertArrayEquals(Orientation.fitTransform(640, 480, view.width, view.height, Orientation.previewRotation(270, 0, true), true), values(view), 1e-4f)
        view.configure(640, 480, 270, front = true, mirror = false)
        assertArrayEquals(Orientation.fitTransform(640, 480, view.width, view.height, Orientation.previewRotation(270, 0, true), false), values(view), 1e-4f)
    }
}
