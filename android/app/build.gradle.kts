plugins {
    id("com.android.application")
    id("org.jetbrains.kotlin.android")
}

android {
    namespace = "org.campro.sample"
    compileSdk = 35
    defaultConfig {
        applicationId = "org.campro.sample"
        minSdk = 29
        targetSdk = 35
        versionCode = 1
        versionName = "0.1.0"
    }
    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }
    // The bundled parameter sets (repository's params/) become assets/params/*.json.
    sourceSets["main"].assets.srcDir(layout.buildDirectory.dir("paramsAssets"))
}

val copyParams by tasks.registering(Copy::class) {
    from(rootProject.file("../params")) { include("*.json") }
    into(layout.buildDirectory.dir("paramsAssets/params"))
}
tasks.named("preBuild") { dependsOn(copyParams) }

dependencies {
    implementation(project(":campro"))
}

kotlin {
    compilerOptions { jvmTarget.set(org.jetbrains.kotlin.gradle.dsl.JvmTarget.JVM_17) }
}
