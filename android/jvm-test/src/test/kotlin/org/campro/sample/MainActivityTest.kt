package org.campro.sample

import android.Manifest
import android.content.pm.PackageManager
import android.view.View
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertTrue
import org.junit.Test
import org.junit.runner.RunWith
import org.robolectric.Robolectric
import org.robolectric.RobolectricTestRunner
import org.robolectric.Shadows.shadowOf
import org.robolectric.annotation.Config

/** The sample app under Robolectric: permission refused, no request loop, nothing shown. */
@RunWith(RobolectricTestRunner::class)
@Config(sdk = [34])
class MainActivityTest {
    @Test
    fun refusedPermissionShowsTheStateAndIsNotAskedAgainOnResume() {
        val controller = Robolectric.buildActivity(MainActivity::class.java).setup()
        val act = controller.get()
        val asked = shadowOf(act).lastRequestedPermission
        assertEquals(listOf(Manifest.permission.CAMERA), asked.requestedPermissions.toList())
        act.onRequestPermissionsResult(asked.requestCode, asked.requestedPermissions, intArrayOf(PackageManager.PERMISSION_DENIED))
        assertTrue(act.statusView.text.toString(), act.statusView.text.contains("refused"))
        assertFalse("the switch shows the real state", act.toggle.isChecked)
        assertEquals(View.INVISIBLE, act.preview.visibility)
        // Back to the foreground: no second request (the old onResume asked again and recreate()d).
        controller.pause().resume()
        assertTrue(shadowOf(act).lastRequestedPermission === asked)
        assertTrue(act.statusView.text.toString(), act.statusView.text.contains("camera permission"))
        assertEquals(View.INVISIBLE, act.preview.visibility)
    }
}
