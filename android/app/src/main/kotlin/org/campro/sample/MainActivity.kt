package org.campro.sample

// The sample camera app: Camera2 preview with CamPro on/off, the parameter set chosen
// from the bundled params/, and a status line. Android-only plumbing; the decisions
// (support, when to rebuild, readback deviation) live in org.campro.* and the Rust core.

import android.Manifest
import android.app.Activity
import android.content.pm.PackageManager
import android.graphics.ImageFormat
import android.graphics.SurfaceTexture
import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraDevice
import android.hardware.camera2.CameraManager
import android.hardware.camera2.CaptureRequest
import android.hardware.camera2.TotalCaptureResult
import android.hardware.camera2.params.OutputConfiguration
import android.hardware.camera2.params.SessionConfiguration
import android.media.ImageReader
import android.os.Bundle
import android.os.Handler
import android.os.HandlerThread
import android.view.Surface
import android.view.TextureView
import android.view.View
import android.widget.AdapterView
import android.widget.ArrayAdapter
import android.widget.Spinner
import android.widget.Switch
import android.widget.TextView
import org.campro.CamProController
import org.campro.CamProNative
import org.campro.DeviceSupport
import org.campro.ProtectionGuard
import org.campro.ProtectionState
import org.campro.android.applyCamPro
import org.campro.android.camproReport
import org.campro.android.camproSupport
import org.campro.android.colorTransformInto
import org.campro.android.gainsInto
import org.campro.android.openCamProAsset
import java.util.concurrent.Executor

class MainActivity : Activity() {
    private lateinit var preview: TextureView
    private lateinit var statusView: TextView
    private lateinit var toggle: Switch
    private lateinit var spinner: Spinner

    private val cameraThread = HandlerThread("campro-camera").apply { start() }
    private val camera = Handler(cameraThread.looper)
    private val cameraExecutor = Executor { camera.post(it) }

    // Everything below is touched only on the camera thread.
    private var device: CameraDevice? = null
    private var captureSession: CameraCaptureSession? = null
    private var meteringReader: ImageReader? = null
    private var previewSurface: Surface? = null
    private var support: DeviceSupport.Result? = null
    private var controller: CamProController? = null
    private var guard: ProtectionGuard? = null
    private var description = ""
    private var enabled = true
    private var paramFile = ""
    private var results = 0L
    private val transformBuf = IntArray(18)
    private val gainsBuf = FloatArray(4)

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        setContentView(R.layout.activity_main)
        CamProNative.loadLibrary()
        preview = findViewById(R.id.preview)
        statusView = findViewById(R.id.status)
        toggle = findViewById(R.id.campro_switch)
        spinner = findViewById(R.id.params_spinner)

        val files = (assets.list("params") ?: emptyArray()).filter { it.endsWith(".json") }.sorted()
        spinner.adapter = ArrayAdapter(this, android.R.layout.simple_spinner_dropdown_item, files)
        // The recommended learnt preset by default.
        spinner.setSelection(maxOf(0, files.indexOf("campro-omega-0.5.json")))
        paramFile = files.getOrElse(spinner.selectedItemPosition) { "" }
        spinner.onItemSelectedListener = object : AdapterView.OnItemSelectedListener {
            override fun onItemSelected(parent: AdapterView<*>?, view: View?, position: Int, id: Long) {
                val f = files[position]
                camera.post { paramFile = f; reconfigure() }
            }
            override fun onNothingSelected(parent: AdapterView<*>?) {}
        }
        toggle.setOnCheckedChangeListener { _, on -> camera.post { enabled = on; reconfigure() } }
    }

    override fun onResume() {
        super.onResume()
        if (checkSelfPermission(Manifest.permission.CAMERA) != PackageManager.PERMISSION_GRANTED) {
            requestPermissions(arrayOf(Manifest.permission.CAMERA), 1)
            return
        }
        if (preview.isAvailable) camera.post { openCamera() } else preview.surfaceTextureListener = object : TextureView.SurfaceTextureListener {
            override fun onSurfaceTextureAvailable(s: SurfaceTexture, w: Int, h: Int) { camera.post { openCamera() } }
            override fun onSurfaceTextureSizeChanged(s: SurfaceTexture, w: Int, h: Int) {}
            override fun onSurfaceTextureDestroyed(s: SurfaceTexture) = true
            override fun onSurfaceTextureUpdated(s: SurfaceTexture) {}
        }
    }

    override fun onRequestPermissionsResult(requestCode: Int, permissions: Array<out String>, grantResults: IntArray) {
        if (grantResults.firstOrNull() == PackageManager.PERMISSION_GRANTED) recreate() else showStatus("CamPro needs the camera permission")
    }

    override fun onPause() {
        camera.post { closeCamera() }
        super.onPause()
    }

    override fun onDestroy() {
        cameraThread.quitSafely()
        super.onDestroy()
    }

    private fun showStatus(text: String) = runOnUiThread { statusView.text = text }

    private fun openCamera() {
        if (device != null) return
        val manager = getSystemService(CameraManager::class.java)
        val id = manager.cameraIdList.firstOrNull {
            manager.getCameraCharacteristics(it).get(CameraCharacteristics.LENS_FACING) == CameraCharacteristics.LENS_FACING_BACK
        } ?: manager.cameraIdList.firstOrNull() ?: return showStatus("no camera")
        support = manager.getCameraCharacteristics(id).camproSupport()
        try {
            manager.openCamera(id, cameraExecutor, object : CameraDevice.StateCallback() {
                override fun onOpened(d: CameraDevice) { device = d; createSession() }
                override fun onDisconnected(d: CameraDevice) { d.close(); device = null }
                override fun onError(d: CameraDevice, error: Int) { d.close(); device = null; showStatus("camera error $error") }
            })
        } catch (e: SecurityException) {
            showStatus("camera permission missing")
        }
    }

    private fun closeCamera() {
        controller?.session?.close()
        controller = null
        guard = null
        showPreview(false)
        captureSession?.close(); captureSession = null
        device?.close(); device = null
        meteringReader?.close(); meteringReader = null
        previewSurface?.release(); previewSurface = null
    }

    private fun createSession() {
        val d = device ?: return
        val texture = preview.surfaceTexture ?: return
        texture.setDefaultBufferSize(1280, 720)
        val surface = Surface(texture).also { previewSurface = it }
        // Metering frames (auto white balance) go only here and are dropped unread.
        val reader = ImageReader.newInstance(320, 240, ImageFormat.YUV_420_888, 2).also { meteringReader = it }
        reader.setOnImageAvailableListener({ r -> r.acquireLatestImage()?.close() }, camera)
        val outputs = listOf(OutputConfiguration(surface), OutputConfiguration(reader.surface))
        d.createCaptureSession(SessionConfiguration(SessionConfiguration.SESSION_REGULAR, outputs, cameraExecutor, object : CameraCaptureSession.StateCallback() {
            override fun onConfigured(s: CameraCaptureSession) { captureSession = s; reconfigure() }
            override fun onConfigureFailed(s: CameraCaptureSession) = showStatus("capture session failed")
        }))
    }

    /** The preview is shown only while the guard says Protected (or CamPro is off): blank otherwise. */
    private fun showPreview(on: Boolean) = runOnUiThread { preview.visibility = if (on) View.VISIBLE else View.INVISIBLE }

    /** CamPro switched, parameter set changed, or the session (re)started. */
    private fun reconfigure() {
        val s = captureSession ?: return
        controller?.session?.close()
        controller = null
        guard = null
        showPreview(false)
        if (!enabled) {
            val req = device!!.createCaptureRequest(CameraDevice.TEMPLATE_PREVIEW).apply { addTarget(previewSurface!!) }
            s.setRepeatingRequest(req.build(), null, camera)
            showPreview(true)
            return showStatus("CamPro off: unprotected preview")
        }
        description = try {
            org.json.JSONObject(assets.open("params/$paramFile").bufferedReader().use { it.readText() }).optString("description")
        } catch (e: Exception) {
            ""
        }
        when (val sup = support) {
            is DeviceSupport.Result.Unsupported -> {
                s.stopRepeating() // never show unprotected frames while CamPro is on
                showStatus("${ProtectionState.Unsupported(sup.reasons.joinToString("; "))}")
            }
            is DeviceSupport.Result.Supported -> try {
                val session = openCamProAsset(assets, "params/$paramFile", sup.maxCurvePoints)
                controller = CamProController(session)
                guard = ProtectionGuard(session)
                // Until the first metering result, only metering frames run: the preview stays dark.
                s.setRepeatingRequest(meteringRequest(), captureCallback, camera)
                showStatus("CamPro: metering" + (sup.note?.let { " ($it)" } ?: ""))
            } catch (e: RuntimeException) {
                s.stopRepeating()
                showStatus("CamPro: cannot load $paramFile: ${e.message}")
            }
            null -> showStatus("camera characteristics not read yet")
        }
    }

    private fun meteringRequest(): CaptureRequest = device!!.createCaptureRequest(CameraDevice.TEMPLATE_PREVIEW).apply {
        addTarget(meteringReader!!.surface)
        set(CaptureRequest.CONTROL_AWB_MODE, CaptureRequest.CONTROL_AWB_MODE_AUTO)
        setTag(METERING)
    }.build()

    /** The repeating burst: one metering frame, then protected preview frames. */
    private fun rebuildBurst() {
        val ctl = controller ?: return
        val protected = device!!.createCaptureRequest(CameraDevice.TEMPLATE_PREVIEW).apply {
            addTarget(previewSurface!!)
            applyCamPro(ctl.session, ctl.gains)
            setTag(PROTECTED)
        }.build()
        val burst = listOf(meteringRequest()) + List(ctl.meteringInterval - 1) { protected }
        guard?.requestChanged() // new values: closed until a result of them verifies
        showPreview(false)
        captureSession?.setRepeatingBurst(burst, captureCallback, camera)
    }

    private val captureCallback = object : CameraCaptureSession.CaptureCallback() {
        override fun onCaptureCompleted(session: CameraCaptureSession, request: CaptureRequest, result: TotalCaptureResult) {
            val ctl = controller ?: return
            try {
                when (request.tag) {
                    METERING -> if (result.colorTransformInto(transformBuf) && result.gainsInto(gainsBuf)) {
                        if (ctl.onMeteringResult(transformBuf, gainsBuf)) rebuildBurst()
                    }
                    PROTECTED -> {
                        val g = guard ?: return
                        val before = g.framesAllowed
                        g.onProtectedResult(result.camproReport())
                        if (g.framesAllowed != before) showPreview(g.framesAllowed)
                    }
                }
            } catch (e: RuntimeException) {
                // A device reporting values campro rejects: stop rather than show unprotected frames.
                session.stopRepeating()
                showStatus("CamPro stopped: ${e.message}")
                return
            }
            if (++results % 15 == 0L) showStatus("$paramFile: $description\n${guard?.state}; ${ctl.status()}")
        }
    }

    private companion object {
        const val METERING = "campro-metering"
        const val PROTECTED = "campro-protected"
    }
}
