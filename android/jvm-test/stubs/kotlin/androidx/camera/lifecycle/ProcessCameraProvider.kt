package androidx.camera.lifecycle

import androidx.camera.core.Camera
import androidx.camera.core.CameraSelector
import androidx.camera.core.UseCase
import androidx.lifecycle.LifecycleOwner

/** Stub of ProcessCameraProvider (CameraX 1.4): the calls the library makes, open so tests can record them. */
open class ProcessCameraProvider protected constructor() {
    open fun bindToLifecycle(lifecycleOwner: LifecycleOwner, cameraSelector: CameraSelector, vararg useCases: UseCase): Camera =
        throw UnsupportedOperationException("stub")

    open fun isBound(useCase: UseCase): Boolean = throw UnsupportedOperationException("stub")

    open fun unbind(vararg useCases: UseCase): Unit = throw UnsupportedOperationException("stub")

    open fun unbindAll(): Unit = throw UnsupportedOperationException("stub")
}
