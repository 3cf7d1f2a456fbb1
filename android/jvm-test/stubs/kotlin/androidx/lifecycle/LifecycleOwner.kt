package androidx.lifecycle

// Stubs of androidx.lifecycle (lifecycle-common 2.8, Kotlin sources): the declarations the
// library uses, with their real signatures. Bodies exist only for the JVM tests; apps bring
// the real library (android/campro/build.gradle.kts).

/** Stub of androidx.lifecycle.LifecycleOwner. */
interface LifecycleOwner {
    val lifecycle: Lifecycle
}

/** Stub of androidx.lifecycle.LifecycleObserver (a marker). */
interface LifecycleObserver

/** Stub of androidx.lifecycle.DefaultLifecycleObserver: every callback has an empty default. */
interface DefaultLifecycleObserver : LifecycleObserver {
    fun onCreate(owner: LifecycleOwner) {}
    fun onStart(owner: LifecycleOwner) {}
    fun onResume(owner: LifecycleOwner) {}
    fun onPause(owner: LifecycleOwner) {}
    fun onStop(owner: LifecycleOwner) {}
    fun onDestroy(owner: LifecycleOwner) {}
}

/** Stub of androidx.lifecycle.Lifecycle. */
abstract class Lifecycle {
    abstract fun addObserver(observer: LifecycleObserver)
    abstract fun removeObserver(observer: LifecycleObserver)
    abstract val currentState: State

    enum class State {
        DESTROYED, INITIALIZED, CREATED, STARTED, RESUMED;

        fun isAtLeast(state: State): Boolean = compareTo(state) >= 0
    }
}
