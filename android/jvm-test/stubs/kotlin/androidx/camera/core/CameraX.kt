package androidx.camera.core

import java.util.concurrent.Executor

/** Stub of androidx.camera.core.CameraControl (CameraX 1.4). */
interface CameraControl {
    /** Stub of CameraControl.OperationCanceledException: a newer call superseded this one, or the camera is not active. */
    class OperationCanceledException(message: String) : Exception(message)
}

/** Stub of androidx.camera.core.CameraInfo. */
interface CameraInfo

/** Stub of androidx.camera.core.Camera: what bindToLifecycle returns. */
interface Camera {
    val cameraControl: CameraControl
    val cameraInfo: CameraInfo
}

/** Stub of androidx.camera.core.UseCase. */
abstract class UseCase

/** Stub of androidx.camera.core.CameraSelector: which camera to bind (by lens facing). */
class CameraSelector private constructor(val lensFacing: Int) {
    companion object {
        const val LENS_FACING_FRONT = 0
        const val LENS_FACING_BACK = 1
        @JvmField val DEFAULT_BACK_CAMERA = CameraSelector(LENS_FACING_BACK)
        @JvmField val DEFAULT_FRONT_CAMERA = CameraSelector(LENS_FACING_FRONT)
    }
}

/** Stub of androidx.camera.core.ImageInfo. */
interface ImageInfo {
    val timestamp: Long
}

/** Stub of androidx.camera.core.ImageProxy. */
interface ImageProxy : AutoCloseable {
    val imageInfo: ImageInfo
    val width: Int
    val height: Int
    val planes: Array<PlaneProxy>
    override fun close()

    /** Stub of androidx.camera.core.ImageProxy.PlaneProxy. */
    interface PlaneProxy {
        val rowStride: Int
        val pixelStride: Int
        val buffer: java.nio.ByteBuffer
    }
}

/** Stub of androidx.camera.core.ExtendableBuilder. */
interface ExtendableBuilder<T> {
    fun build(): T
}

/** Stub of androidx.camera.core.ImageAnalysis. */
class ImageAnalysis private constructor(val builder: Builder) : UseCase() {
    fun interface Analyzer {
        fun analyze(image: ImageProxy)
    }

    fun setAnalyzer(executor: Executor, analyzer: Analyzer) {
        builder.analyzer = analyzer
    }

    class Builder : ExtendableBuilder<ImageAnalysis> {
        var queueDepth = 6
        var backpressure = STRATEGY_KEEP_ONLY_LATEST
        var analyzer: Analyzer? = null
        /** What Camera2Interop.Extender set (the stub's way to reach it). */
        var sessionCaptureCallback: android.hardware.camera2.CameraCaptureSession.CaptureCallback? = null
        var sessionStateCallback: android.hardware.camera2.CameraCaptureSession.StateCallback? = null

        fun setImageQueueDepth(depth: Int): Builder = apply { queueDepth = depth }
        fun setBackpressureStrategy(strategy: Int): Builder = apply { backpressure = strategy }
        override fun build(): ImageAnalysis = ImageAnalysis(this)
    }

    companion object {
        const val STRATEGY_KEEP_ONLY_LATEST = 0
        const val STRATEGY_BLOCK_PRODUCER = 1
    }
}
