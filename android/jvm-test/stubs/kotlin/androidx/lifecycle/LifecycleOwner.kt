package androidx.lifecycle

/** Stub of androidx.lifecycle.LifecycleOwner: the library passes it through to CameraX and calls nothing on it. */
interface LifecycleOwner
