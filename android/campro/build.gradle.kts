// The library module: the Kotlin wrapper (org.campro.*, host-tested through jni-bridge's
// tests/jvm_host.rs) and libcampro_jni.so for three ABIs, built from the Rust crate
// `jni-bridge` with cargo-ndk before every build.
plugins {
    id("com.android.library")
    id("org.jetbrains.kotlin.android")
    `maven-publish`
}

android {
    namespace = "org.campro"
    compileSdk = 35
    // NDK r28+ links 16 KB-page-aligned ELF by default (required for new apps on Android 15+
    // devices with 16 KB pages); .cargo/config.toml also passes -z max-page-size=16384.
    ndkVersion = "28.0.13004108"
    defaultConfig {
        minSdk = 29
        consumerProguardFiles("consumer-rules.pro")
    }
    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }
    sourceSets["main"].jniLibs.srcDir(layout.buildDirectory.dir("rustJniLibs"))
    // The protective presets (params/*.json with a protection rating, copyPresets below) as
    // assets/campro/params/NAME.json, which Preset.Named opens; the detectors (.onnx) and the
    // sets that do not protect (identity, srgb-passthrough, color-inversion: for tests) stay
    // out of the AAR.
    sourceSets["main"].assets.srcDir(layout.buildDirectory.dir("presetAssets"))
    publishing {
        singleVariant("release") { withSourcesJar() }
    }
}

dependencies {
    // CamPro.open ties the camera to a LifecycleOwner and exposes the state as a StateFlow.
    api("androidx.lifecycle:lifecycle-common:2.8.7")
    api("org.jetbrains.kotlinx:kotlinx-coroutines-core:1.10.1")
    // CameraX is the app's choice: CamProCameraX compiles against it, apps that use it
    // bring their own CameraX (1.3 or later).
    compileOnly("androidx.camera:camera-core:1.4.1")
    compileOnly("androidx.camera:camera-camera2:1.4.1")
    compileOnly("androidx.annotation:annotation:1.9.1")
}

// An AAR with libcampro_jni.so for arm64-v8a, armeabi-v7a and x86_64, published to a
// Maven repository in this project: ./gradlew :campro:publishReleasePublicationToLocalRepository
// writes android/build/repo/org/campro/campro/0.1.0/campro-0.1.0.aar.
publishing {
    publications {
        register<MavenPublication>("release") {
            groupId = "org.campro"
            artifactId = "campro"
            version = "0.1.0"
            afterEvaluate { from(components["release"]) }
        }
    }
    repositories {
        maven {
            name = "local"
            url = uri(rootProject.layout.buildDirectory.dir("repo"))
        }
    }
}

// cargo install cargo-ndk; rustup target add aarch64-linux-android armv7-linux-androideabi x86_64-linux-android
val cargoNdk by tasks.registering(Exec::class) {
    val repo = rootProject.projectDir.parentFile
    val out = layout.buildDirectory.dir("rustJniLibs").get().asFile
    workingDir = repo
    commandLine(
        "cargo", "ndk",
        "-t", "arm64-v8a", "-t", "armeabi-v7a", "-t", "x86_64",
        "-o", out.absolutePath,
        "build", "--release", "--locked", "-p", "campro-jni",
    )
    environment("ANDROID_NDK_HOME", android.ndkDirectory.absolutePath)
    inputs.dir(File(repo, "src"))
    inputs.dir(File(repo, "jni-bridge/src"))
    inputs.files(File(repo, "Cargo.toml"), File(repo, "Cargo.lock"), File(repo, "jni-bridge/Cargo.toml"), File(repo, ".cargo/config.toml"))
    outputs.dir(out)
}
// campro::provenance::PROTECTIVE_TOP1: a set is protective when its provenance's
// protection.worst_top1 is at most this (the core's test `the_aars_threshold_is_the_cores`
// holds the two equal; the JVM tests filter with the core itself).
val PROTECTIVE_TOP1 = 0.15
fun protective(f: File): Boolean {
    val provenance = (groovy.json.JsonSlurper().parse(f) as Map<*, *>)["provenance"] as? Map<*, *>
    val worst = ((provenance?.get("protection") as? Map<*, *>)?.get("worst_top1") as? Number)?.toDouble()
    return worst != null && worst >= 0.0 && worst <= PROTECTIVE_TOP1
}
val copyPresets by tasks.registering(Copy::class) {
    from(rootProject.file("../params")) {
        include("*.json")
        exclude { !it.isDirectory && !protective(it.file) }
    }
    into(layout.buildDirectory.dir("presetAssets/campro/params"))
}
tasks.named("preBuild") { dependsOn(cargoNdk, copyPresets) }

kotlin {
    compilerOptions {
        jvmTarget.set(org.jetbrains.kotlin.gradle.dsl.JvmTarget.JVM_17)
        // Consumers on Kotlin 2.0 or later can read the library's metadata.
        apiVersion.set(org.jetbrains.kotlin.gradle.dsl.KotlinVersion.KOTLIN_2_0)
        languageVersion.set(org.jetbrains.kotlin.gradle.dsl.KotlinVersion.KOTLIN_2_0)
    }
}
