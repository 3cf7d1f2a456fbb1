package org.campro.sample

import android.Manifest
import android.content.pm.PackageManager
import android.hardware.camera2.CameraManager
import android.view.View
import org.campro.ProtectionState
import org.campro.android.CameraScript
import org.campro.android.CameraScript.FakeImage
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertNull
import org.junit.Assert.assertTrue
import org.junit.Test
import org.junit.runner.RunWith
import org.robolectric.Robolectric
import org.robolectric.RobolectricTestRunner
import org.robolectric.RuntimeEnvironment
import org.robolectric.Shadows.shadowOf
import org.robolectric.annotation.Config

/**
 * The sample app under Robolectric on a scripted camera: the unsupported-device screen,
 * the permission asked once, and the showcase (preview covered until Protected, photo and
 * video only while Protected, a photo of a verified frame, pause and resume).
 */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34], application = PresetAssetsApp::class)
class MainActivityTest {
    private val app = RuntimeEnvironment.getApplication()
    private val manager = app.getSystemService(CameraManager::class.java)

    @Test
    fun aDeviceCamProCannotProtectGetsItsOwnScreenAndNoCamera() {
        shadowOf(manager).addCamera("0", CameraScript.chars(supported = false))
        val act = Robolectric.buildActivity(MainActivity::class.java).setup().get()
        assertEquals(View.VISIBLE, act.unsupportedView.visibility)
        assertTrue(act.unsupportedView.text.toString(), act.unsupportedView.text.contains("camera 0: ") && act.unsupportedView.text.contains("CONTRAST_CURVE"))
        assertEquals(View.GONE, act.preview.visibility)
        assertNull("no permission asked, nothing opened", shadowOf(act).lastRequestedPermission)
        assertNull(act.camera)
    }

    @Test
    fun refusedPermissionShowsTheStateAndIsNotAskedAgainOnResume() {
        shadowOf(manager).addCamera("0", CameraScript.chars())
        val controller = Robolectric.buildActivity(MainActivity::class.java).setup()
        val act = controller.get()
        val asked = shadowOf(act).lastRequestedPermission
        assertEquals(listOf(Manifest.permission.CAMERA), asked.requestedPermissions.toList())
        act.onRequestPermissionsResult(asked.requestCode, asked.requestedPermissions, intArrayOf(PackageManager.PERMISSION_DENIED))
        assertTrue(act.statusView.text.toString(), act.statusView.text.contains("refused"))
        assertFalse(act.photoButton.isEnabled || act.recordButton.isEnabled)
        assertNull(act.camera)
        controller.pause().resume()
        assertTrue("asked once", shadowOf(act).lastRequestedPermission === asked)
    }

    @Test
    fun theShowcaseTakesAPhotoOfAVerifiedFrameAndFollowsTheLifecycle() {
        shadowOf(manager).addCamera("0", CameraScript.chars())
        shadowOf(app).grantPermissions(Manifest.permission.CAMERA)
        val controller = Robolectric.buildActivity(MainActivity::class.java).setup()
        val act = controller.get()
        val cam = act.camera
        assertNotNull("permission granted: the camera opens with the activity", cam)
        CameraScript.settle(cam!!)
        assertTrue(act.statusView.text.toString(), act.statusView.text.startsWith("campro-omega-0.5: Verifying"))
        assertFalse("no photo or video before Protected", act.photoButton.isEnabled || act.recordButton.isEnabled)
        assertEquals(View.VISIBLE, act.preview.cover.visibility)

        CameraScript.protect(cam, 1000)
        assertEquals(ProtectionState.Protected, cam.state.value)
        assertTrue(act.photoButton.isEnabled && act.recordButton.isEnabled)
        assertEquals(View.GONE, act.preview.cover.visibility)

        act.photoButton.performClick()
        CameraScript.onCamera(cam) { cam.glue!!.pipeline.onFrame(2000, FakeImage(64, 48, 2000, ArrayList())) }
        CameraScript.verify(cam, 2000)
        Thread.sleep(200) // the JPEG is encoded on campro-still
        CameraScript.settle(cam)
        assertTrue(act.statusView.text.toString(), act.statusView.text.contains("photo saved"))
        val photos = (act.getExternalFilesDir(null) ?: act.filesDir).listFiles { f -> f.name.endsWith(".jpg") }!!
        assertEquals(1, photos.size)

        // In the background: closed, nothing to press; back: verifying again.
        controller.pause().stop()
        CameraScript.settle(cam)
        assertTrue(act.statusView.text.toString(), act.statusView.text.contains("Stopped(reason=paused"))
        assertFalse(act.photoButton.isEnabled)
        assertEquals(View.VISIBLE, act.preview.cover.visibility)
        controller.start().resume()
        CameraScript.settle(cam)
        assertEquals(ProtectionState.Verifying, cam.state.value)
        controller.pause().stop().destroy()
        CameraScript.settle(cam)
        assertEquals(ProtectionState.Stopped("closed by the app", org.campro.Problem.CameraClosed), cam.state.value)
    }
}
