package org.campro

import androidx.annotation.GuardedBy
import java.util.concurrent.Executor

/** How a still ended: its JPEG, or why there is none. */
sealed class StillResult {
    /**
     * The JPEG of the verified frame taken at sensor time [timestampNs] (its only metadata: the
     * orientation), and the record written beside the file where there is one.
     */
    class Taken(val jpeg: ByteArray, val timestampNs: Long, val record: java.io.File? = null) : StillResult()

    /** No still: [reason] says why (the camera stopped, encoding failed, the app cancelled). */
    data class Failed(val reason: String) : StillResult()
}

/**
 * Protected stills: each request takes the **next** frame the gate delivers (a verified
 * one, made after the request) and encodes it as JPEG; the camera's own JPEG is never used.
 *
 * On the frame thread [onFrame] only copies what the encoders need ([snapshot], e.g. an
 * `Image`'s planes, once for every waiting request); encoding and the callbacks run on
 * [background], so the preview and a recording never wait for a JPEG. A request waits
 * through transient states (Verifying, Violated: no frame is delivered meanwhile) and ends
 * on [cancel] (the app's timeout) or [fail] (the camera stopped). Every request's callback
 * runs exactly once. Threads: any; the request list is synchronized.
 */
class StillCapture<T, S>(
    /** Copies a borrowed frame (called on the frame thread; must not keep the frame). */
    private val snapshot: (T) -> S,
    private val background: Executor,
) {
    /** One waiting request: what makes its still from the snapshot (encoding, writing: the request's) and its callback. */
    class Request<S> internal constructor(internal val make: (S) -> StillResult, internal val callback: (StillResult) -> Unit)

    private val pending = ArrayList<Request<S>>()

    /** Requests waiting for a frame. */
    val waiting: Int @Synchronized get() = pending.size

    /**
     * Asks for a still, made from the next verified frame's snapshot by [make] (on the
     * background executor: encoding, writing); [callback] runs there too, exactly once, with
     * what [make] returned or why there is none (an exception from [make] is a failure).
     */
    @Synchronized
    fun request(make: (S) -> StillResult, callback: (StillResult) -> Unit): Request<S> = Request(make, callback).also { pending += it }

    /** One verified frame, borrowed: taken by every waiting request (one snapshot). */
    fun onFrame(frame: T) {
        val takers = synchronized(this) {
            if (pending.isEmpty()) return
            pending.toList().also { pending.clear() }
        }
        val snap = try {
            snapshot(frame)
        } catch (e: RuntimeException) {
            return finish(takers, StillResult.Failed("the frame could not be read: ${e.message}"))
        }
        run(takers) { r ->
            try {
                r.make(snap)
            } catch (e: Exception) {
                StillResult.Failed("the still failed: ${e.message}")
            }
        }
    }

    /** Ends [request] with [reason] if it still waits; returns whether it did. */
    fun cancel(request: Request<S>, reason: String): Boolean {
        val removed = synchronized(this) { pending.remove(request) }
        if (removed) finish(listOf(request), StillResult.Failed(reason))
        return removed
    }

    /** Fails every waiting request with [reason]. */
    fun fail(reason: String) {
        val takers = synchronized(this) { pending.toList().also { pending.clear() } }
        if (takers.isNotEmpty()) finish(takers, StillResult.Failed(reason))
    }

    private fun finish(takers: List<Request<S>>, r: StillResult) = run(takers) { r }

    /** Runs each request's callback with its result on [background] (here when it is shut down). */
    private fun run(takers: List<Request<S>>, result: (Request<S>) -> StillResult) {
        val task = Runnable { for (t in takers) t.callback(result(t)) }
        try {
            background.execute(task)
        } catch (e: java.util.concurrent.RejectedExecutionException) {
            task.run()
        }
    }
}

/** Where each verified frame goes, in this order: stills and the recording borrow it, the preview takes it. */
class FrameRouter<T>(
    /** Closes a frame nobody took. */
    private val close: (T) -> Unit,
) {
    /** The preview's renderer: takes ownership (closes the frame); `null`: no preview. */
    @Volatile
    var preview: ((T) -> Unit)? = null

    /** The recording under way, if any. */
    @Volatile
    var recording: ProtectedRecording<T>? = null

    /** Still requests. */
    @Volatile
    var stills: StillCapture<T, *>? = null

    /** Frames routed so far. */
    @Volatile
    var routed = 0L
        private set

    /** One verified frame, owned: borrowed by stills and the recording, then given to the preview or closed. */
    fun deliver(frame: T) {
        routed++
        try {
            stills?.onFrame(frame)
            recording?.onFrame(frame)
        } finally {
            val p = preview
            if (p == null) close(frame) else p(frame)
        }
    }
}

/**
 * The preview's own path: the newest verified frame waits in one slot for [show], which
 * runs on [executor] (one task at a time); a frame that arrives while the slot is full
 * replaces the one waiting, which is closed unshown. [offer] never blocks: a preview that
 * stalls (a hidden view, a writer with no free buffer, a view being torn down) costs only
 * preview frames, never the recording's or a still's, which share the frame thread.
 *
 * Ownership: [offer] takes the frame; [show] owns each frame it is given (it must close it,
 * or hand it on); frames replaced or left at [close] are closed here.
 */
class LatestFrame<T>(
    /** Runs [show] (a thread of the preview's own: never the frame thread). */
    private val executor: java.util.concurrent.Executor,
    private val show: (T) -> Unit,
    private val close: (T) -> Unit,
) {
    @GuardedBy("this")
    private var slot: T? = null
    @GuardedBy("this")
    private var scheduled = false
    @GuardedBy("this")
    private var closed = false

    /** Frames closed unshown because a newer one replaced them. */
    @Volatile
    var replaced = 0L
        private set

    /** Takes [frame]: it waits for [show], replacing (and closing) the one waiting. */
    fun offer(frame: T) {
        var old: T? = null
        var schedule = false
        synchronized(this) {
            if (closed) {
                old = frame
            } else {
                old = slot
                slot = frame
                if (!scheduled) { scheduled = true; schedule = true }
                if (old != null) replaced++
            }
        }
        old?.let(close)
        if (schedule) {
            try {
                executor.execute { drain() }
            } catch (e: java.util.concurrent.RejectedExecutionException) {
                close() // the preview's thread is gone: nothing will be shown again
            }
        }
    }

    private fun drain() {
        while (true) {
            val frame = synchronized(this) {
                val f = slot
                slot = null
                if (f == null) scheduled = false
                f
            } ?: return
            try {
                show(frame)
            } catch (e: RuntimeException) {
                // show owns the frame; a failing preview must not stop the next one.
            }
        }
    }

    /** Closes the frame waiting and every later one: the preview is gone. */
    fun close() {
        val f = synchronized(this) {
            closed = true
            val f = slot
            slot = null
            f
        }
        f?.let(close)
    }
}
