package org.campro

import java.io.File
import java.util.concurrent.Executor

/** Shared by the JVM tests: the real libcampro_jni.so, a bundled preset, scripted devices. */
object Fixtures {
    /** A phone-like auto-mode transform (18 ints: numerator, denominator pairs). */
    val PHONE = intArrayOf(178, 100, -62, 100, -16, 100, -28, 100, 162, 100, -34, 100, 2, 100, -71, 100, 169, 100)
    val GAINS = floatArrayOf(2.0f, 1.0f, 1.0f, 1.6f)

    private var loaded = false

    /** Loads the .so named by the `campro.jni.lib` system property (check-on-jvm.sh sets it). */
    @Synchronized
    fun load() {
        if (loaded) return
        val lib = System.getProperty("campro.jni.lib") ?: error("campro.jni.lib is not set: run android/check-on-jvm.sh")
        check(File(lib).isFile) { "$lib does not exist: run android/check-on-jvm.sh (it builds it)" }
        CamProNative.load(lib)
        loaded = true
    }

    /** The recommended preset's JSON. */
    fun params(): String {
        val dir = System.getProperty("campro.params.dir") ?: error("campro.params.dir is not set")
        return File(dir, "campro-omega-0.5.json").readText()
    }

    fun session(maxCurvePoints: Int = 64): CamProSession {
        load()
        return CamProSession.fromJson(params(), maxCurvePoints)
    }

    fun supported(points: Int = 64) = DeviceSupport.check(intArrayOf(0, 2), intArrayOf(0, 1, 2), points, intArrayOf(0, 1))

    /** Runs deliveries when told to: shows what is delivered on the app's executor and when. */
    class QueueExecutor : Executor {
        val queue = ArrayDeque<Runnable>()
        override fun execute(command: Runnable) { synchronized(this) { queue.addLast(command) } }
        fun runAll() { while (true) { val r = synchronized(this) { queue.removeFirstOrNull() } ?: return; r.run() } }
    }

    /** A scripted camera: records what the pipeline asked for; can be made to fail. */
    class FakeCamera : CameraRequests {
        val calls = mutableListOf<String>()
        var lastTransform: IntArray? = null
        var lastCurves: Array<FloatArray>? = null
        var lastGains: FloatArray? = null
        var failWith: Exception? = null

        override fun meter() { failWith?.let { throw it }; calls += "meter" }
        override fun protect(transform: IntArray, curves: Array<FloatArray>, gains: FloatArray, burst: Burst?) {
            failWith?.let { throw it }
            calls += if (burst == null) "protect" else "protect+meter${burst.meteringRun}/${burst.length}" + if (burst.probes.isEmpty()) "" else "+probe${burst.probes.size}"
            lastTransform = transform; lastCurves = curves; lastGains = gains
        }
        override fun halt() { calls += "halt" }

        /** Probe requests sent ([PixelProbe]), oldest first: their transform, curve and gains (not in [calls]). */
        val probes = mutableListOf<Triple<IntArray, FloatArray, FloatArray>>()
        override fun probe(transform: IntArray, curve: FloatArray, gains: FloatArray) {
            failWith?.let { throw it }
            probes += Triple(transform.copyOf(), curve.copyOf(), gains.copyOf())
        }

        /** What a device honouring the last probe request reports. */
        fun honouredProbe(): CaptureReport {
            val (t, c, g) = probes.last()
            return CaptureReport(0, 0, 0, t.copyOf(), listOf(c, c.copyOf(), c.copyOf()), g.copyOf())
        }

        /** What a device honouring the last request reports. */
        fun honoured(): CaptureReport {
            return CaptureReport(0, 0, 0, lastTransform!!.copyOf(), lastCurves!!.map { it.copyOf() }, lastGains!!.copyOf())
        }
    }

    fun CaptureReport.with(
        awbMode: Int? = this.awbMode,
        colorCorrectionMode: Int? = this.colorCorrectionMode,
        tonemapMode: Int? = this.tonemapMode,
        transform: IntArray? = this.transform,
        curves: List<FloatArray>? = this.curves,
        gains: FloatArray? = this.gains,
    ) = CaptureReport(awbMode, colorCorrectionMode, tonemapMode, transform, curves, gains)

    /** The flat luma an honest device gives for a probe curve (its level at 0, in 8-bit codes): 64 or 128. */
    fun probeLevel(curve: FloatArray): Int = Math.round(curve[1] * 255f)

    /**
     * Answers [p]'s pixel probe as an honest device would ([cam]'s last probe request
     * honoured: its result, and a flat frame at the probe curve's level), until it stops
     * probing; timestamps from [ts]. Returns how many probe frames it answered.
     */
    fun answerProbes(p: CamProPipeline<*>, cam: FakeCamera, ts: Long = -1000): Int {
        var n = 0
        while (p.isProbing && n < 4) {
            val t = ts - n
            p.onProbeResult(t, cam.honouredProbe())
            p.onProbeFrame(t, ByteArray(4800) { probeLevel(cam.probes.last().second).toByte() })
            n++
        }
        return n
    }

    fun converged(transform: IntArray = PHONE, gains: FloatArray = GAINS) = MeteringReport(1, CamProPipeline.AWB_STATE_CONVERGED, transform, gains)

    /**
     * A lifecycle the test moves by hand ([moveTo]), dispatching the events between the
     * states in order to each [androidx.lifecycle.DefaultLifecycleObserver], as
     * `LifecycleRegistry` does; an observer added late is brought up to the current state.
     */
    class TestOwner : androidx.lifecycle.LifecycleOwner {
        private val registry = object : androidx.lifecycle.Lifecycle() {
            val observers = ArrayList<androidx.lifecycle.LifecycleObserver>()
            var state = State.INITIALIZED
            override val currentState: State get() = state
            override fun addObserver(observer: androidx.lifecycle.LifecycleObserver) {
                observers += observer
                val target = state
                state = State.INITIALIZED
                walk(target, listOf(observer))
            }
            override fun removeObserver(observer: androidx.lifecycle.LifecycleObserver) { observers -= observer }
            fun walk(target: State, to: List<androidx.lifecycle.LifecycleObserver>) {
                val owner = this@TestOwner
                while (state != target) {
                    val up = target > state
                    val next = if (up) State.values()[state.ordinal + 1] else State.values()[state.ordinal - 1]
                    for (o in to.toList()) {
                        val d = o as? androidx.lifecycle.DefaultLifecycleObserver ?: continue
                        when {
                            up && next == State.CREATED -> d.onCreate(owner)
                            up && next == State.STARTED -> d.onStart(owner)
                            up && next == State.RESUMED -> d.onResume(owner)
                            !up && next == State.STARTED -> d.onPause(owner)
                            !up && next == State.CREATED -> d.onStop(owner)
                            !up && next == State.DESTROYED -> d.onDestroy(owner)
                        }
                    }
                    state = next
                }
            }
        }
        override val lifecycle: androidx.lifecycle.Lifecycle get() = registry

        fun moveTo(state: androidx.lifecycle.Lifecycle.State) = registry.walk(state, registry.observers)
    }
}
