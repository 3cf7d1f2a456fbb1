package org.campro.android

// The entry point: a protected camera in a few lines.
//
//     val check = CamPro.checkDevice(context)            // before showing the feature
//     val camera = CamPro.open(context, lifecycleOwner)  // back camera, the recommended preset
//     camera.setPreview(findViewById<CamProPreviewView>(R.id.preview))
//     lifecycleScope.launch { camera.state.collect { showState(it) } }
//     camera.takePicture(File(filesDir, "photo.jpg")) { result -> ... }
//     val recording = camera.startRecording(File(filesDir, "clip.mp4")); ...; recording.stop()
//
// CamPro owns the camera: it opens it when the owner starts, closes it when the owner
// stops, reopens it when another app (multi-window) gives it back, and never lets a frame
// reach the preview, a recording or a still before its own CaptureResult verified.

import android.content.Context
import android.hardware.camera2.CameraCharacteristics
import android.hardware.camera2.CameraManager
import androidx.lifecycle.LifecycleOwner
import org.campro.CamProSession
import org.campro.DeviceSupport

/** Which camera to protect. */
sealed class Lens {
    /** The first camera facing away from the user. */
    object Back : Lens() {
        override fun toString() = "back camera"
    }

    /** The first camera facing the user (the preview is mirrored, stills are not). */
    object Front : Lens() {
        override fun toString() = "front camera"
    }

    /** A camera by its Camera2 id. */
    data class Id(val cameraId: String) : Lens()
}

/** A CamPro parameter set: a bundled preset by name, or JSON the app holds. */
sealed class Preset {
    /** A preset bundled in the library's assets (`campro/params/NAME.json`), e.g. [RECOMMENDED]. */
    data class Named(val name: String) : Preset()

    /** A parameter set's JSON (from `campro convert`, a training, or the app's own assets). */
    class Json(val json: String) : Preset()

    /**
     * Whether the parameter set protects faces ([org.campro.CamProSession.protective]: a
     * protection rating in its provenance within the threshold). The bundled presets all
     * do; a camera with one that does not opens only with [CamProOptions.allowUnprotective]
     * and then reads [org.campro.ProtectionState.Applied], never Protected.
     */
    fun protective(context: Context): Boolean =
        org.campro.CamProSession.fromBytes(bytes(context)).use { it.protective }

    /** What names it in a record: the bundled preset's name, or "app JSON". */
    internal val given: String get() = when (this) {
        is Named -> name
        is Json -> "app JSON"
    }

    /** The parameter file's bytes (a bundled preset read with a byte cap). */
    internal fun bytes(context: Context): ByteArray = when (this) {
        is Named -> {
            require(name.matches(Regex("[A-Za-z0-9._-]{1,64}")) && !name.startsWith(".")) { "preset name '$name' is not a bundled preset's name" }
            val stream = try {
                context.assets.open("$ASSET_DIR/$name.json")
            } catch (e: java.io.FileNotFoundException) {
                throw IllegalArgumentException("no bundled preset '$name' (assets/$ASSET_DIR/$name.json)")
            }
            // Read with the core's limit for a parameter file (InputStream.readNBytes is API 33; minSdk is 29).
            stream.use { input ->
                val out = java.io.ByteArrayOutputStream()
                val buf = ByteArray(64 shl 10)
                while (true) {
                    val n = input.read(buf)
                    if (n < 0) break
                    out.write(buf, 0, n)
                    require(out.size() <= MAX_JSON_BYTES) { "preset '$name' is over $MAX_JSON_BYTES bytes" }
                }
                out.toByteArray()
            }
        }
        is Json -> json.toByteArray(Charsets.UTF_8)
    }

    companion object {
        /** The preset the README recommends. */
        @JvmField
        val RECOMMENDED = Named("campro-omega-0.5")

        /** Where the library's assets keep the bundled presets. */
        const val ASSET_DIR = "campro/params"

        /** Largest parameter file read, bytes (`campro::params::MAX_JSON_BYTES`). */
        const val MAX_JSON_BYTES = 4 shl 20
    }
}

/** What [CamPro.open] may change; the defaults suit a phone's preview and 720p video. */
data class CamProOptions @JvmOverloads constructor(
    /** Largest protected stream size; the camera's largest size of the sensor's shape within it is used. */
    val maxWidth: Int = 1280,
    val maxHeight: Int = 720,
    /** Milliseconds a still request waits for a verified frame before failing. */
    val stillTimeoutMs: Long = 3000,
    /** JPEG quality of stills, 1..100. */
    val jpegQuality: Int = 95,
    /** See [org.campro.ProtectionGuard.trustMissingKeys]: accepting it risks unprotected frames. */
    val trustMissingKeys: Boolean = false,
    /**
     * Open a preset that does not protect faces ([Preset.protective] false: `identity`, an
     * app's JSON without a protection rating). Without it such a camera ends
     * [org.campro.ProtectionState.Unsupported]; with it, it reads
     * [org.campro.ProtectionState.Applied], never Protected, and faces are NOT hidden.
     */
    val allowUnprotective: Boolean = false,
    /**
     * Largest deviation, in 8-bit LSB, of what the camera reports it applied from what was
     * sent ([org.campro.ProtectionGuard.maxDeviationLsb]). 0.5 (the default) refuses a HAL
     * that rounds the matrix to 1/1024; raise it only to a bound the preset was measured to
     * protect at on that device's grid (docs/android.md, "Grids").
     */
    val maxDeviationLsb: Double = 0.5,
    /**
     * The grids a HAL may put the preset's values on (`q10`: matrix entries to 10 fractional
     * bits; `lut64`: curves resampled to 64 points): each must be one the preset was measured
     * to protect on (`protection.device_grids.held`; docs/android.md, "Grids"), else the camera
     * is Unsupported naming it. `null` (the default): every grid the preset holds; empty: none
     * (values as sent, within [maxDeviationLsb]).
     */
    val deviceGrids: Set<String>? = null,
    /** Mirror a front camera's preview left-right, as a mirror shows the user (the default). */
    val mirrorFrontPreview: Boolean = true,
    /**
     * Store a front camera's stills mirrored, as the preview showed them (EXIF orientation
     * 2, 4, 5 or 7: the pixels stay the sensor's; viewers mirror). Off by default, as the
     * camera's own JPEGs. Recordings are never mirrored (an MP4 has no mirror flag).
     */
    val mirrorFrontStills: Boolean = false,
) {
    init {
        deviceGrids?.forEach { require(org.campro.DeviceGrid.parse(it) != null) { "deviceGrids: $it is not a grid (qB with B 1..24, or lutN with N 2..4096)" } }
        require(maxDeviationLsb.isFinite() && maxDeviationLsb >= 0.0) { "maxDeviationLsb must be finite and >= 0, got $maxDeviationLsb" }
        require(maxWidth > 0 && maxHeight > 0) { "maxWidth and maxHeight must be positive, got $maxWidth x $maxHeight" }
        require(stillTimeoutMs > 0) { "stillTimeoutMs must be positive, got $stillTimeoutMs" }
        require(jpegQuality in 1..100) { "jpegQuality must be 1..100, got $jpegQuality" }
    }
}

/** One camera as [CamPro.checkDevice] sees it. */
data class CameraCheck(
    val cameraId: String,
    /** `LENS_FACING`: 0 front, 1 back, 2 external; `null` when not reported. */
    val facing: Int?,
    /** Whether and why CamPro can run on it. */
    val support: DeviceSupport.Result,
    /** Settings apply on the frame that asks for them (`SYNC_MAX_LATENCY_PER_FRAME_CONTROL`): metering can run beside protection. */
    val perFrameControl: Boolean,
    /** `TONEMAP_MAX_CURVE_POINTS` (`null`: not reported). */
    val curvePoints: Int?,
) {
    val supported: Boolean get() = support is DeviceSupport.Result.Supported
}

/** What [CamPro.checkDevice] found: every camera, and whether any can be protected. */
data class DeviceCheck(val cameras: List<CameraCheck>, val error: String? = null) {
    /** Whether some camera can run CamPro. */
    val supported: Boolean get() = cameras.any { it.supported }

    /** Whether the camera [lens] picks can run CamPro. */
    fun supports(lens: Lens): Boolean = CamPro.pick(cameras.map { it.cameraId to it.facing }, lens)?.let { id -> cameras.first { it.cameraId == id }.supported } == true

    /** One sentence for the app's "not available" screen. */
    fun summary(): String = when {
        error != null -> "the cameras cannot be read: $error"
        cameras.isEmpty() -> "this device has no camera"
        supported -> "CamPro can protect: " + cameras.filter { it.supported }.joinToString { "camera ${it.cameraId}" }
        else -> "no camera can run CamPro: " + cameras.joinToString("; ") { c ->
            "camera ${c.cameraId}: " + (c.support as DeviceSupport.Result.Unsupported).reasons.joinToString(", ")
        }
    }
}

/** Opens protected cameras and checks devices. */
object CamPro {
    /**
     * Every camera of the device and whether CamPro can run on it, from its characteristics
     * alone (opens nothing, needs no permission): use it before offering the feature.
     */
    @JvmStatic
    fun checkDevice(context: Context): DeviceCheck {
        val manager = context.getSystemService(CameraManager::class.java) ?: return DeviceCheck(emptyList(), "no CameraManager")
        return try {
            DeviceCheck(
                manager.cameraIdList.map { id ->
                    val c = manager.getCameraCharacteristics(id)
                    CameraCheck(
                        cameraId = id,
                        facing = c.get(CameraCharacteristics.LENS_FACING),
                        support = c.camproSupport(),
                        perFrameControl = c.hasPerFrameControl(),
                        curvePoints = c.get(CameraCharacteristics.TONEMAP_MAX_CURVE_POINTS),
                    )
                },
            )
        } catch (e: Exception) {
            // CameraAccessException (camera service down), IllegalArgumentException (a camera went away).
            DeviceCheck(emptyList(), e.message ?: e.javaClass.simpleName)
        }
    }

    /**
     * A protected camera tied to [owner]'s lifecycle: opened while the owner is started,
     * closed when it stops or is destroyed. Nothing is opened before the owner starts, and
     * the camera permission must be granted by then (else the state says so: Stopped).
     * Call on the main thread; [CamProCamera.close] ends it early.
     */
    @JvmStatic
    @JvmOverloads
    fun open(
        context: Context,
        owner: LifecycleOwner,
        lens: Lens = Lens.Back,
        preset: Preset = Preset.RECOMMENDED,
        options: CamProOptions = CamProOptions(),
    ): CamProCamera = CamProCamera(context.applicationContext ?: context, owner, lens, preset, options)

    /** The camera id [lens] picks among (id, `LENS_FACING`) pairs; `null` when none. */
    internal fun pick(cameras: List<Pair<String, Int?>>, lens: Lens): String? = when (lens) {
        is Lens.Id -> cameras.firstOrNull { it.first == lens.cameraId }?.first
        Lens.Back -> cameras.firstOrNull { it.second == CameraCharacteristics.LENS_FACING_BACK }?.first
        Lens.Front -> cameras.firstOrNull { it.second == CameraCharacteristics.LENS_FACING_FRONT }?.first
    }
}
