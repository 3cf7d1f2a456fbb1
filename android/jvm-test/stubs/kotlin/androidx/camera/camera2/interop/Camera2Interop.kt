package androidx.camera.camera2.interop

import android.hardware.camera2.CameraCaptureSession
import android.hardware.camera2.CaptureRequest
import androidx.camera.core.CameraControl
import androidx.camera.core.ExtendableBuilder
import androidx.camera.core.ImageAnalysis
import com.google.common.util.concurrent.ListenableFuture

/** Stub of the experimental marker (CameraX 1.4). */
@RequiresOptIn
@Retention(AnnotationRetention.BINARY)
annotation class ExperimentalCamera2Interop

/** Stub of CaptureRequestOptions: the options, readable as in CameraX. */
class CaptureRequestOptions private constructor(private val options: Map<CaptureRequest.Key<*>, Any?>) {
    @Suppress("UNCHECKED_CAST")
    fun <T> getCaptureRequestOption(key: CaptureRequest.Key<T>): T? = options[key] as T?

    class Builder {
        private val options = LinkedHashMap<CaptureRequest.Key<*>, Any?>()
        fun <T> setCaptureRequestOption(key: CaptureRequest.Key<T>, value: T): Builder = apply { options[key] = value }
        fun build(): CaptureRequestOptions = CaptureRequestOptions(LinkedHashMap(options))
    }
}

/** Stub of Camera2CameraControl: open so tests can record or fail calls. */
open class Camera2CameraControl protected constructor() {
    open fun setCaptureRequestOptions(options: CaptureRequestOptions): ListenableFuture<Void?> = throw UnsupportedOperationException("stub")
    open fun clearCaptureRequestOptions(): ListenableFuture<Void?> = throw UnsupportedOperationException("stub")

    companion object {
        /** The stub's way for tests to answer: a [CameraControl] that is also a Camera2CameraControl. */
        @JvmStatic
        fun from(control: CameraControl): Camera2CameraControl = control as? Camera2CameraControl ?: throw UnsupportedOperationException("stub")
    }
}

/** Stub of Camera2Interop. */
object Camera2Interop {
    class Extender<T>(private val builder: ExtendableBuilder<T>) {
        fun setSessionCaptureCallback(callback: CameraCaptureSession.CaptureCallback): Extender<T> = apply {
            (builder as? ImageAnalysis.Builder)?.sessionCaptureCallback = callback
        }

        fun setSessionStateCallback(callback: CameraCaptureSession.StateCallback): Extender<T> = apply {
            (builder as? ImageAnalysis.Builder)?.sessionStateCallback = callback
        }
    }
}

/** Stub of Camera2CameraInfo: the Camera2 id behind a CameraX camera. */
open class Camera2CameraInfo protected constructor() {
    open val cameraId: String get() = throw UnsupportedOperationException("stub")

    companion object {
        /** The stub's way for tests to answer [from]: a [androidx.camera.core.CameraInfo] that is also a Camera2CameraInfo. */
        @JvmStatic
        fun from(info: androidx.camera.core.CameraInfo): Camera2CameraInfo = info as? Camera2CameraInfo ?: throw UnsupportedOperationException("stub")
    }
}
