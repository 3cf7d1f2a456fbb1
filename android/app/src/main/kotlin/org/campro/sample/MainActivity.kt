package org.campro.sample

// The sample camera app: CamPro on a Camera2 camera, fail closed per frame on screen too.
// The camera writes protected frames only into CamProCamera2's ImageReader; each frame is
// shown (ImageWriter onto a SurfaceView) only after its own CaptureResult verified. No
// display surface is ever a capture target. The "CamPro" switch shows the real state: it is
// on while frames are protected, and turning CamPro off closes the camera (this app never
// shows unprotected frames). Android-only plumbing: the decisions live in org.campro.* and
// the Rust core; views are built in code (no resources to compile).

import android.Manifest
import android.graphics.ImageFormat
import android.app.Activity
import android.content.pm.PackageManager
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraDevice
import android.hardware.camera2.CameraManager
import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.params.SessionConfiguration
import android.media.Image
import android.media.ImageWriter
import android.os.Bundle
import android.os.Handler
import android.os.HandlerThread
import android.view.SurfaceHolder
import android.view.SurfaceView
import android.view.View
import android.widget.AdapterView
import android.widget.ArrayAdapter
import android.widget.LinearLayout
import android.widget.Spinner
import android.widget.Switch
import android.widget.TextView
import org.campro.ProtectionState
import org.campro.android.CamProCamera2
import org.campro.android.camproStreamSize
import org.campro.android.camproSupport
import org.campro.android.openCamProAsset
import java.util.concurrent.Executor

class MainActivity : Activity() {
    internal lateinit var preview: SurfaceView
    internal lateinit var statusView: TextView
    internal lateinit var toggle: Switch
    private lateinit var spinner: Spinner

    private val cameraThread = HandlerThread("campro-camera").apply { start() }
    private val camera = Handler(cameraThread.looper)
    private val cameraExecutor = Executor { camera.post(it) }

    // Touched only on the camera thread.
    private var device: CameraDevice? = null
    private var campro: CamProCamera2? = null
    private var paramFile = ""
    private var wantCamPro = true

    // Touched only on the main thread.
    private var writer: ImageWriter? = null
    private var permissionAsked = false
    private var updatingSwitch = false

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        preview = SurfaceView(this)
        statusView = TextView(this).apply { setPadding(16, 16, 16, 16); textSize = 12f }
        toggle = Switch(this).apply { text = "CamPro" }
        spinner = Spinner(this)
        val bar = LinearLayout(this).apply {
            orientation = LinearLayout.HORIZONTAL
            addView(toggle)
            addView(spinner, LinearLayout.LayoutParams(0, LinearLayout.LayoutParams.WRAP_CONTENT, 1f))
        }
        setContentView(
            LinearLayout(this).apply {
                orientation = LinearLayout.VERTICAL
                addView(preview, LinearLayout.LayoutParams(LinearLayout.LayoutParams.MATCH_PARENT, 0, 1f))
                addView(bar)
                addView(statusView)
            },
        )
        preview.visibility = View.INVISIBLE

        val files = (assets.list("params") ?: emptyArray()).filter { it.endsWith(".json") }.sorted()
        spinner.adapter = ArrayAdapter(this, android.R.layout.simple_spinner_dropdown_item, files)
        // The recommended learnt preset by default.
        spinner.setSelection(maxOf(0, files.indexOf("campro-omega-0.5.json")))
        paramFile = files.getOrElse(spinner.selectedItemPosition) { "" }
        spinner.onItemSelectedListener = object : AdapterView.OnItemSelectedListener {
            override fun onItemSelected(parent: AdapterView<*>?, view: View?, position: Int, id: Long) {
                val f = files[position]
                camera.post { if (f != paramFile) { paramFile = f; restartCamera() } }
            }
            override fun onNothingSelected(parent: AdapterView<*>?) {}
        }
        toggle.setOnCheckedChangeListener { _, on ->
            if (updatingSwitch) return@setOnCheckedChangeListener
            camera.post { wantCamPro = on; restartCamera() }
        }
        preview.holder.addCallback(object : SurfaceHolder.Callback {
            override fun surfaceCreated(holder: SurfaceHolder) {}
            override fun surfaceChanged(holder: SurfaceHolder, format: Int, width: Int, height: Int) {
                writer?.close()
                writer = ImageWriter.newInstance(holder.surface, 2)
            }
            override fun surfaceDestroyed(holder: SurfaceHolder) {
                writer?.close()
                writer = null
            }
        })
    }

    override fun onResume() {
        super.onResume()
        when {
            checkSelfPermission(Manifest.permission.CAMERA) == PackageManager.PERMISSION_GRANTED -> camera.post { openCamera() }
            // Asked once per activity: no request/recreate loop from onResume.
            !permissionAsked -> { permissionAsked = true; requestPermissions(arrayOf(Manifest.permission.CAMERA), REQUEST_CAMERA) }
            else -> show(ProtectionState.Stopped("CamPro needs the camera permission (Settings > Apps > CamPro)"))
        }
    }

    override fun onRequestPermissionsResult(requestCode: Int, permissions: Array<out String>, grantResults: IntArray) {
        if (requestCode != REQUEST_CAMERA) return
        if (grantResults.firstOrNull() == PackageManager.PERMISSION_GRANTED) {
            camera.post { openCamera() }
        } else {
            show(ProtectionState.Stopped("the camera permission was refused: nothing is captured"))
        }
    }

    override fun onPause() {
        camera.post { closeCamera() }
        super.onPause()
    }

    override fun onDestroy() {
        cameraThread.quitSafely()
        super.onDestroy()
    }

    /** The state on screen: frames only while Protected; the switch shows whether CamPro runs. */
    private fun show(state: ProtectionState) {
        preview.visibility = if (state == ProtectionState.Protected) View.VISIBLE else View.INVISIBLE
        updatingSwitch = true
        toggle.isChecked = state == ProtectionState.Protected || state == ProtectionState.Verifying
        updatingSwitch = false
        statusView.text = "$paramFile: $state"
    }

    /** A verified frame: onto the screen (ImageWriter takes it and closes it), else closed. */
    private fun render(image: Image) {
        val w = writer
        if (w == null) {
            image.close()
            return
        }
        try {
            w.queueInputImage(image)
        } catch (e: RuntimeException) {
            image.close()
            show(ProtectionState.Stopped("display failed: ${e.message}"))
        }
    }

    private fun openCamera() {
        // One camera at a time: `campro` is set here, on this thread, before the (asynchronous)
        // open; `device` only once it opened, so it alone would let the permission grant and
        // the onResume that follows it open twice.
        if (device != null || campro != null) return
        if (!wantCamPro) return runOnUiThread { show(ProtectionState.Stopped("CamPro is off: the camera is closed")) }
        try {
            val manager = getSystemService(CameraManager::class.java)
            val id = manager.cameraIdList.firstOrNull {
                manager.getCameraCharacteristics(it).get(CameraCharacteristics.LENS_FACING) == CameraCharacteristics.LENS_FACING_BACK
            } ?: manager.cameraIdList.firstOrNull() ?: return runOnUiThread { show(ProtectionState.Unsupported("no camera")) }
            val chars = manager.getCameraCharacteristics(id)
            val support = chars.camproSupport()
            val maxPoints = (support as? org.campro.DeviceSupport.Result.Supported)?.maxCurvePoints ?: 64
            val size = chars.camproStreamSize(ImageFormat.PRIVATE)
                ?: return runOnUiThread { show(ProtectionState.Unsupported("the camera lists no size for a private stream")) }
            val session = openCamProAsset(assets, "params/$paramFile", maxPoints)
            val c = CamProCamera2(
                session, chars, camera, mainExecutor, size.width, size.height,
                deliver = ::render,
                onState = ::show,
            )
            campro = c
            manager.openCamera(id, cameraExecutor, object : CameraDevice.StateCallback() {
                override fun onOpened(d: CameraDevice) {
                    // Opened after the app paused or switched presets: not ours any more.
                    if (campro !== c) return d.close()
                    device = d
                    createSession(d, c)
                }
                override fun onDisconnected(d: CameraDevice) {
                    c.onCameraStopped("the camera was disconnected")
                    d.close()
                    if (device === d) device = null
                }
                override fun onError(d: CameraDevice, error: Int) {
                    c.onCameraStopped("camera error $error")
                    d.close()
                    if (device === d) device = null
                }
            })
        } catch (e: Exception) {
            // CameraAccessException, SecurityException, IllegalArgumentException, native errors:
            // nothing was shown, and nothing will be.
            closeCamera()
            runOnUiThread { show(ProtectionState.Stopped("cannot open the camera: ${e.message}")) }
        }
    }

    private fun createSession(d: CameraDevice, c: CamProCamera2) {
        try {
            d.createCaptureSession(
                SessionConfiguration(SessionConfiguration.SESSION_REGULAR, c.outputs(), cameraExecutor, object : CameraCaptureSession.StateCallback() {
                    override fun onConfigured(s: CameraCaptureSession) = c.onConfigured(d, s)
                    override fun onConfigureFailed(s: CameraCaptureSession) = c.onCameraStopped("the capture session could not be configured")
                    override fun onClosed(s: CameraCaptureSession) = c.onCameraStopped("the capture session closed")
                }),
            )
        } catch (e: Exception) {
            c.onCameraStopped("cannot create the capture session: ${e.message}")
        }
    }

    private fun closeCamera() {
        campro?.let { it.close(); it.session.close() }
        campro = null
        device?.close()
        device = null
    }

    private fun restartCamera() {
        closeCamera()
        openCamera()
    }

    private companion object {
        const val REQUEST_CAMERA = 1
    }
}
