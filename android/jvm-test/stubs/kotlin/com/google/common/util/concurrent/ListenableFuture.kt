package com.google.common.util.concurrent

/** Stub of Guava's ListenableFuture (listenablefuture 1.0), the return type of CameraX calls. */
interface ListenableFuture<V> : java.util.concurrent.Future<V> {
    fun addListener(listener: Runnable, executor: java.util.concurrent.Executor)
}
