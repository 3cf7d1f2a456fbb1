// The library module: the Kotlin wrapper (org.campro.*, host-tested through jni-bridge's
// tests/jvm_host.rs) and libcampro_jni.so for three ABIs, built from the Rust crate
// `jni-bridge` with cargo-ndk before every build.
plugins {
    id("com.android.library")
    id("org.jetbrains.kotlin.android")
}

android {
    namespace = "org.campro"
    compileSdk = 35
    defaultConfig {
        minSdk = 28
        consumerProguardFiles("consumer-rules.pro")
    }
    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }
    kotlinOptions { jvmTarget = "17" }
    sourceSets["main"].jniLibs.srcDir(layout.buildDirectory.dir("rustJniLibs"))
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
        "build", "--release", "-p", "campro-jni",
    )
    inputs.dir(File(repo, "src"))
    inputs.dir(File(repo, "jni-bridge/src"))
    outputs.dir(out)
}
tasks.named("preBuild") { dependsOn(cargoNdk) }
