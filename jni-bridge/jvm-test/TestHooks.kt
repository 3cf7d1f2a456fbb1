package org.campro

/** Test-only natives, exported by a `campro-jni` built with `--features test-exports`. */
object TestHooks {
    /** Panics inside native code on purpose: the panic must arrive as an exception. */
    @JvmStatic external fun selfTestPanic(message: String?)
}
