package androidx.annotation

import kotlin.reflect.KClass

/** Stub of androidx.annotation.OptIn (annotation 1.9). */
@Retention(AnnotationRetention.BINARY)
@Target(AnnotationTarget.CLASS, AnnotationTarget.FUNCTION, AnnotationTarget.CONSTRUCTOR, AnnotationTarget.PROPERTY)
annotation class OptIn(vararg val markerClass: KClass<out Annotation>)
