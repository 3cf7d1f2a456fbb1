package androidx.activity

import android.app.Activity
import android.os.Bundle
import androidx.lifecycle.DefaultLifecycleObserver
import androidx.lifecycle.Lifecycle
import androidx.lifecycle.LifecycleObserver
import androidx.lifecycle.LifecycleOwner

/**
 * Stub of androidx.activity.ComponentActivity (activity 1.9): an `Activity` that is a
 * `LifecycleOwner`. Like the real one (through `ReportFragment`), its lifecycle reaches
 * CREATED after `onCreate`, STARTED after `onStart`, RESUMED after `onResume`, and leaves
 * them before `onPause`, `onStop` and `onDestroy`. What the stub cannot prove: the real
 * class's exact dispatch timing on every API level.
 */
open class ComponentActivity : Activity(), LifecycleOwner {
    private val registry = object : Lifecycle() {
        val observers = ArrayList<LifecycleObserver>()
        var state = State.INITIALIZED
        override val currentState: State get() = state
        override fun addObserver(observer: LifecycleObserver) {
            observers += observer
            val d = observer as? DefaultLifecycleObserver ?: return
            val owner = this@ComponentActivity
            if (state.isAtLeast(State.CREATED)) d.onCreate(owner)
            if (state.isAtLeast(State.STARTED)) d.onStart(owner)
            if (state.isAtLeast(State.RESUMED)) d.onResume(owner)
        }
        override fun removeObserver(observer: LifecycleObserver) { observers -= observer }
        fun move(to: State, event: (DefaultLifecycleObserver) -> Unit) {
            state = to
            for (o in observers.toList()) (o as? DefaultLifecycleObserver)?.let(event)
        }
    }

    override val lifecycle: Lifecycle get() = registry

    override fun onCreate(savedInstanceState: Bundle?) {
        super.onCreate(savedInstanceState)
        registry.move(Lifecycle.State.CREATED) { it.onCreate(this) }
    }

    override fun onStart() {
        super.onStart()
        registry.move(Lifecycle.State.STARTED) { it.onStart(this) }
    }

    override fun onResume() {
        super.onResume()
        registry.move(Lifecycle.State.RESUMED) { it.onResume(this) }
    }

    override fun onPause() {
        registry.move(Lifecycle.State.STARTED) { it.onPause(this) }
        super.onPause()
    }

    override fun onStop() {
        registry.move(Lifecycle.State.CREATED) { it.onStop(this) }
        super.onStop()
    }

    override fun onDestroy() {
        registry.move(Lifecycle.State.DESTROYED) { it.onDestroy(this) }
        super.onDestroy()
    }
}
