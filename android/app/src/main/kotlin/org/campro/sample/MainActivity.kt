package org.campro.sample

// The sample camera app: a protected camera in a few lines of CamPro.open. The preview shows
// only frames whose own CaptureResult verified (CamProPreviewView covers itself otherwise);
// photos and videos are made of the same verified frames, never of the camera's own JPEG or
// an unchecked stream. A device CamPro cannot protect gets a screen that says why, and no
// camera. Views are built in code (no resources to compile).

import android.Manifest
import android.content.pm.PackageManager
import android.os.Bundle
import android.view.View
import android.widget.AdapterView
import android.widget.ArrayAdapter
import android.widget.Button
import android.widget.LinearLayout
import android.widget.Spinner
import android.widget.TextView
import androidx.activity.ComponentActivity
import org.campro.ProtectionState
import org.campro.StillResult
import org.campro.android.ActiveRecording
import org.campro.android.CamPro
import org.campro.android.CamProCamera
import org.campro.android.CamProPreviewView
import org.campro.android.Lens
import org.campro.android.Preset
import org.campro.android.RecordingResult
import java.io.File
import java.text.SimpleDateFormat
import java.util.Date
import java.util.Locale

class MainActivity : ComponentActivity() {
    internal lateinit var preview: CamProPreviewView
    internal lateinit var statusView: TextView
    internal lateinit var photoButton: Button
    internal lateinit var recordButton: Button

    /** The "not available" screen: shown instead of the camera when no camera can be protected. */
    internal lateinit var unsupportedView: TextView

    /** The protected camera (main thread). */
    internal var camera: CamProCamera? = null
    private var recording: ActiveRecording? = null
    private var preset: Preset.Named = Preset.RECOMMENDED
    private var permissionAsked = false
    private var state: ProtectionState = ProtectionState.Stopped("not started")
    private var lastMessage = ""

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        preview = CamProPreviewView(this)
        statusView = TextView(this).apply { setPadding(16, 16, 16, 16); textSize = 12f }
        unsupportedView = TextView(this).apply { setPadding(32, 32, 32, 32); textSize = 16f; visibility = View.GONE }
        photoButton = Button(this).apply { text = "Photo"; setOnClickListener { takePhoto() } }
        recordButton = Button(this).apply { text = "Record"; setOnClickListener { toggleRecording() } }
        val spinner = Spinner(this)
        val bar = LinearLayout(this).apply {
            orientation = LinearLayout.HORIZONTAL
            addView(photoButton)
            addView(recordButton)
            addView(spinner, LinearLayout.LayoutParams(0, LinearLayout.LayoutParams.WRAP_CONTENT, 1f))
        }
        setContentView(
            LinearLayout(this).apply {
                orientation = LinearLayout.VERTICAL
                addView(unsupportedView)
                addView(preview, LinearLayout.LayoutParams(LinearLayout.LayoutParams.MATCH_PARENT, 0, 1f))
                addView(bar)
                addView(statusView)
            },
        )

        // Checked before anything opens: a device CamPro cannot protect never shows a camera.
        val check = CamPro.checkDevice(this)
        if (!check.supports(Lens.Back)) {
            unsupportedView.text = "CamPro cannot protect this device's back camera.\n\n${check.summary()}"
            unsupportedView.visibility = View.VISIBLE
            preview.visibility = View.GONE
            bar.visibility = View.GONE
            statusView.visibility = View.GONE
            return
        }

        val presets = (assets.list(Preset.ASSET_DIR) ?: emptyArray()).filter { it.endsWith(".json") }.map { it.removeSuffix(".json") }.sorted()
        spinner.adapter = ArrayAdapter(this, android.R.layout.simple_spinner_dropdown_item, presets)
        spinner.setSelection(maxOf(0, presets.indexOf(Preset.RECOMMENDED.name)))
        spinner.onItemSelectedListener = object : AdapterView.OnItemSelectedListener {
            override fun onItemSelected(parent: AdapterView<*>?, view: View?, position: Int, id: Long) {
                val p = Preset.Named(presets[position])
                if (p != preset) { preset = p; if (camera != null) reopen() }
            }
            override fun onNothingSelected(parent: AdapterView<*>?) {}
        }
        show(state)
        when {
            checkSelfPermission(Manifest.permission.CAMERA) == PackageManager.PERMISSION_GRANTED -> reopen()
            // Asked once per activity: no request/recreate loop.
            !permissionAsked -> { permissionAsked = true; requestPermissions(arrayOf(Manifest.permission.CAMERA), REQUEST_CAMERA) }
        }
    }

    override fun onRequestPermissionsResult(requestCode: Int, permissions: Array<out String>, grantResults: IntArray) {
        if (requestCode != REQUEST_CAMERA) return
        if (grantResults.firstOrNull() == PackageManager.PERMISSION_GRANTED) {
            reopen()
        } else {
            show(ProtectionState.Stopped("the camera permission was refused: nothing is captured (Settings > Apps > CamPro)"))
        }
    }

    /** Opens the camera with the chosen preset, tied to this activity's lifecycle. */
    private fun reopen() {
        recording?.stop()
        camera?.close()
        camera = CamPro.open(this, this, Lens.Back, preset).also { c ->
            c.setPreview(preview)
            c.addStateListener(mainExecutor, ::show)
        }
    }

    /** The state on screen; photo and video only while Protected (the library refuses otherwise too). */
    private fun show(s: ProtectionState) {
        state = s
        photoButton.isEnabled = s == ProtectionState.Protected
        recordButton.isEnabled = s == ProtectionState.Protected || recording != null
        recordButton.text = if (recording != null) "Stop" else "Record"
        statusView.text = "${preset.name}: $s" + if (lastMessage.isEmpty()) "" else "\n$lastMessage"
    }

    private fun message(m: String) {
        lastMessage = m
        show(state)
    }

    private fun outputFile(ext: String): File {
        val dir = getExternalFilesDir(null) ?: filesDir
        return File(dir, "campro-" + SimpleDateFormat("yyyyMMdd-HHmmss-SSS", Locale.ROOT).format(Date()) + ".$ext")
    }

    private fun takePhoto() {
        val c = camera ?: return
        c.takePicture(outputFile("jpg")) { r ->
            message(
                when (r) {
                    is StillResult.Taken -> "photo saved (${r.jpeg.size / 1024} KiB)"
                    is StillResult.Failed -> "no photo: ${r.reason}"
                },
            )
        }
    }

    private fun toggleRecording() {
        val r = recording
        if (r != null) return r.stop()
        val c = camera ?: return
        val file = outputFile("mp4")
        recording = try {
            c.startRecording(file, onEnded = { result ->
                recording = null
                message(
                    when (result) {
                        is RecordingResult.Saved -> "video saved: ${result.summary.frames} frames, ${result.summary.framesFailedCheck} left out by the check"
                        is RecordingResult.Failed -> "no video: ${result.reason}"
                    },
                )
            })
        } catch (e: Exception) {
            message("cannot record: ${e.message}")
            null
        }
        show(state)
    }

    private companion object {
        const val REQUEST_CAMERA = 1
    }
}
