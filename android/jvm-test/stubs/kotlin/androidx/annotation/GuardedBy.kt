package androidx.annotation

/** Stub of androidx.annotation.GuardedBy (annotation 1.9): the lock that guards a field. */
@Retention(AnnotationRetention.BINARY)
@Target(AnnotationTarget.FIELD, AnnotationTarget.FUNCTION, AnnotationTarget.PROPERTY)
annotation class GuardedBy(val value: String)
