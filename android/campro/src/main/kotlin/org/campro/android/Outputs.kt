package org.campro.android

import java.io.File
import java.io.IOException
import java.nio.file.Files
import java.nio.file.StandardCopyOption

// How the library's outputs (photos, videos, their records) reach the app's names: written
// beside them as `.NAME.part`, then moved into place, so a crash never leaves a half-written
// file under the app's name and an existing file is replaced only when the app said so.

/** The temporary file [target] is written as, beside it. */
internal fun partOf(target: File) = File(target.absoluteFile.parentFile, ".${target.name}.part")

/**
 * Moves [part] onto [target] in one step; an existing [target] is replaced only with
 * [overwrite] (`ATOMIC_MOVE` replaces on POSIX, so a file that appeared meanwhile is refused
 * here first).
 */
internal fun moveIntoPlace(part: File, target: File, overwrite: Boolean) {
    if (!overwrite && target.exists()) throw IOException("$target exists; it is not replaced")
    val how = if (overwrite) arrayOf(StandardCopyOption.ATOMIC_MOVE, StandardCopyOption.REPLACE_EXISTING) else arrayOf(StandardCopyOption.ATOMIC_MOVE)
    Files.move(part.toPath(), target.toPath(), *how)
}

/** Writes [bytes] to [target] through its part file ([moveIntoPlace]). */
internal fun writeAtomically(target: File, bytes: ByteArray, overwrite: Boolean) {
    val part = partOf(target)
    try {
        part.writeBytes(bytes)
        moveIntoPlace(part, target, overwrite)
    } finally {
        part.delete()
    }
}
