package org.campro.sample

import android.app.Application
import android.content.res.AssetManager
import java.io.File
import java.util.zip.ZipEntry
import java.util.zip.ZipOutputStream

/**
 * The sample's application under Robolectric, with the assets the library's AAR brings
 * (`campro/params/NAME.json`, android/campro/build.gradle.kts: the protective presets
 * only): Robolectric's binary resources hold no app assets without Gradle, so they are
 * packed here as an asset-only APK from the repository's params/, each kept when the core
 * calls it protective, and opened by a real AssetManager.
 */
class PresetAssetsApp : Application() {
    private val presetAssets: AssetManager by lazy {
        val dir = File(System.getProperty("campro.params.dir") ?: error("campro.params.dir is not set"))
        val apk = File.createTempFile("campro-presets", ".apk").also { it.deleteOnExit() }
        ZipOutputStream(apk.outputStream()).use { z ->
            org.campro.Fixtures.load()
            val protective = dir.listFiles { f -> f.name.endsWith(".json") }!!.sortedBy { it.name }
                .filter { f -> org.campro.CamProSession.fromBytes(f.readBytes()).use { it.protective } }
            for (f in protective) {
                z.putNextEntry(ZipEntry("assets/campro/params/${f.name}"))
                z.write(f.readBytes())
                z.closeEntry()
            }
        }
        @Suppress("DEPRECATION")
        AssetManager().apply { check(addAssetPath(apk.path) != 0) { "the preset APK did not load" } }
    }

    override fun getAssets(): AssetManager = presetAssets
}
