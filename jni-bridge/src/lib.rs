//! `libcampro_jni.so`: the campro core behind native handles, for the Kotlin class
//! `org.campro.CamProNative` (wrapped by `org.campro.CamProSession`).
//!
//! Thin by design: every function parses its arguments, calls the core
//! ([`campro::targets::camera2::Camera2Loop`], [`campro::targets::camera2`]) and copies the
//! results into caller-provided primitive arrays. Nothing is allocated on the Java heap
//! per update, and no local reference is created in a loop.
//!
//! Errors: bad arguments throw `IllegalArgumentException`, a closed or never-issued
//! handle (or one left broken by an internal error) `IllegalStateException`, each with a
//! message naming the argument and the rule. A Rust panic never crosses the boundary: it
//! is caught and thrown as `RuntimeException("campro internal error: ...")`.
//!
//! Threads: handles are process-wide integers, never addresses, so a foreign or stale
//! value is detected rather than dereferenced. Every handle has its own mutex: calls on
//! one handle from several threads are serialised (each sees a consistent loop state),
//! calls on different handles run in parallel. `close` while another thread is inside an
//! update is safe: the update finishes on its reference and later calls see the handle
//! closed.

use campro::color_temp::DngCalibration;
use campro::targets::camera2::{self, ConvertError, Options, RationalMode};
use campro::targets::camera2::{Camera2Loop, Update};
use campro::{Params, ValidationError};
use jni::errors::ErrorPolicy;
use jni::objects::{
    JByteArray, JClass, JDoubleArray, JFloatArray, JIntArray, JObject, JPrimitiveArray, JString, TypeArray,
};
use jni::refs::Reference;
use jni::sys::{jboolean, jdouble, jint, jlong};
use jni::{jni_str, Env, EnvUnowned};
use std::collections::HashMap;
use std::fmt;
use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::{Arc, LazyLock, Mutex, MutexGuard};

mod still;

/// Layout of the `DoubleArray` report every update fills (`CamProNative.REPORT_*`).
pub mod report {
    /// 1.0 when the values changed (rebuild the request), else 0.0.
    pub const RECOMPUTED: usize = 0;
    /// Guaranteed bound on |device - desktop|, output units (1 = full scale).
    pub const BOUND: usize = 1;
    /// Largest rational rounding error over the nine matrix entries.
    pub const MATRIX_MAX_ABS: usize = 2;
    /// Max |sent curve - wanted curve| over [0, 1].
    pub const CURVE_MAX_ABS: usize = 3;
    /// Largest slope of the sent curve.
    pub const CURVE_LIPSCHITZ: usize = 4;
    /// Range scale folded into the curve (>= 1).
    pub const SCALE: usize = 5;
    /// The most (Pin, Pout) points written for a channel.
    pub const CURVE_POINTS: usize = 6;
    /// 1.0 when knots were dropped to fit the device's point budget.
    pub const CURVE_SIMPLIFIED: usize = 7;
    /// (Pin, Pout) points written for red; green and blue follow (a set with one curve
    /// writes the same curve three times).
    pub const CURVE_POINTS_RED: usize = 8;
    /// Array length.
    pub const LEN: usize = 11;
}

/// Layout of the `DoubleArray` the readback comparison fills.
pub mod readback {
    pub const MATRIX_MAX_ABS: usize = 0;
    pub const CURVE_MAX_ABS: usize = 1;
    pub const BOUND: usize = 2;
    pub const LEN: usize = 3;
}

/// Why a native call failed; each kind becomes one Java exception class.
#[derive(Debug)]
enum BridgeError {
    /// `IllegalArgumentException`.
    Argument(String),
    /// `IllegalStateException`.
    State(String),
    /// A JNI call failed (an exception is usually pending already).
    Jni(jni::errors::Error),
}

impl fmt::Display for BridgeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Argument(m) | Self::State(m) => f.write_str(m),
            Self::Jni(e) => write!(f, "JNI: {e}"),
        }
    }
}

impl std::error::Error for BridgeError {}

impl From<jni::errors::Error> for BridgeError {
    fn from(e: jni::errors::Error) -> Self {
        Self::Jni(e)
    }
}

impl From<ConvertError> for BridgeError {
    /// By kind: a missing calibration is the session's state, not the caller's argument.
    fn from(e: ConvertError) -> Self {
        match &e {
            ConvertError::NoCalibration => Self::State(e.to_string()),
            _ => Self::Argument(e.to_string()),
        }
    }
}

fn arg(e: ValidationError) -> BridgeError {
    BridgeError::Argument(e.to_string())
}

type Result<T> = std::result::Result<T, BridgeError>;

/// Throws the Java exception matching the error; panics become `RuntimeException`.
struct ThrowJava;

impl<T: Default> ErrorPolicy<T, BridgeError> for ThrowJava {
    type Captures<'unowned_env_local: 'native_method, 'native_method> = ();

    fn on_error<'unowned_env_local: 'native_method, 'native_method>(
        env: &mut Env<'unowned_env_local>,
        _: &mut (),
        err: BridgeError,
    ) -> jni::errors::Result<T> {
        if env.exception_check() {
            return Ok(T::default()); // the JNI failure already threw
        }
        log::warn!("{err}");
        let msg = jni::strings::JNIString::new(err.to_string());
        let _ = match err {
            BridgeError::Argument(_) => env.throw_new(jni_str!("java/lang/IllegalArgumentException"), msg),
            BridgeError::State(_) => env.throw_new(jni_str!("java/lang/IllegalStateException"), msg),
            BridgeError::Jni(_) => env.throw_new(jni_str!("java/lang/RuntimeException"), msg),
        };
        Ok(T::default())
    }

    fn on_panic<'unowned_env_local: 'native_method, 'native_method>(
        env: &mut Env<'unowned_env_local>,
        _: &mut (),
        payload: Box<dyn std::any::Any + Send + 'static>,
    ) -> jni::errors::Result<T> {
        let what = match payload.downcast_ref::<&'static str>() {
            Some(s) => (*s).to_string(),
            None => payload.downcast_ref::<String>().cloned().unwrap_or_else(|| "non-string panic payload".into()),
        };
        // Dropping a payload can itself panic; leak it rather than unwind here.
        std::mem::forget(payload);
        log::error!("campro internal error: {what}");
        if !env.exception_check() {
            let _ = env.throw_new(
                jni_str!("java/lang/RuntimeException"),
                jni::strings::JNIString::new(format!("campro internal error: {what}")),
            );
        }
        Ok(T::default())
    }
}

// ---------------------------------------------------------------------------------
// Handles

/// Handles are never reused and start far from small integers and from addresses.
static NEXT_HANDLE: AtomicI64 = AtomicI64::new(0x4350_0000_0000_0001);
static HANDLES: LazyLock<Mutex<HashMap<jlong, Arc<Mutex<Camera2Loop>>>>> = LazyLock::new(Default::default);

fn registry() -> MutexGuard<'static, HashMap<jlong, Arc<Mutex<Camera2Loop>>>> {
    // The registry is only inserted into and removed from; a panic elsewhere cannot
    // leave it half-updated, so a poisoned lock is still consistent.
    HANDLES.lock().unwrap_or_else(|p| p.into_inner())
}

fn register(l: Camera2Loop) -> jlong {
    let h = NEXT_HANDLE.fetch_add(1, Ordering::Relaxed);
    registry().insert(h, Arc::new(Mutex::new(l)));
    h
}

fn lookup(handle: jlong) -> Result<Arc<Mutex<Camera2Loop>>> {
    registry()
        .get(&handle)
        .cloned()
        .ok_or_else(|| BridgeError::State(format!("handle {handle:#x} is closed or was never issued by campro")))
}

fn with_loop<T>(handle: jlong, f: impl FnOnce(&mut Camera2Loop) -> Result<T>) -> Result<T> {
    let l = lookup(handle)?;
    let mut guard = l.lock().map_err(|_| {
        BridgeError::State(format!("handle {handle:#x} was left inconsistent by an internal error; close it"))
    })?;
    f(&mut guard)
}

// ---------------------------------------------------------------------------------
// Argument helpers

fn options(max_curve_points: jint, max_denominator: jint) -> Result<Options> {
    let positive = |name: &str, v: jint| {
        u32::try_from(v)
            .ok()
            .filter(|&v| v > 0)
            .ok_or_else(|| BridgeError::Argument(format!("{name}: must be positive, got {v}")))
    };
    let o = Options {
        max_curve_points: positive("maxCurvePoints", max_curve_points)? as usize,
        rational: RationalMode::Best { max_denominator: positive("maxDenominator", max_denominator)? },
    };
    camera2::check_options(&o).map_err(arg)?;
    Ok(o)
}

fn non_null(name: &str, obj: &impl Reference) -> Result<()> {
    if obj.is_null() {
        return Err(BridgeError::Argument(format!("{name}: must not be null")));
    }
    Ok(())
}

fn read_ints<const N: usize>(env: &Env, name: &str, a: &JIntArray) -> Result<[i32; N]> {
    non_null(name, a)?;
    let len = a.len(env)?;
    if len != N {
        return Err(BridgeError::Argument(format!("{name}: must have {N} elements, got {len}")));
    }
    let mut out = [0i32; N];
    a.get_region(env, 0, &mut out)?;
    Ok(out)
}

fn read_floats(env: &Env, name: &str, a: &JFloatArray, count: jint) -> Result<Vec<f32>> {
    read_floats_at(env, name, a, 0, count)
}

/// `count` floats of `a` from `offset` (both checked against its length).
fn read_floats_at(env: &Env, name: &str, a: &JFloatArray, offset: jint, count: jint) -> Result<Vec<f32>> {
    non_null(name, a)?;
    let len = a.len(env)?;
    let range = usize::try_from(offset)
        .ok()
        .zip(usize::try_from(count).ok())
        .and_then(|(o, n)| Some(o..o.checked_add(n)?))
        .filter(|r| r.end <= len)
        .ok_or_else(|| {
            BridgeError::Argument(format!(
                "{name}: offset {offset} and count {count} are negative or exceed the array's {len} elements"
            ))
        })?;
    let mut out = vec![0f32; range.len()];
    // start < len, a Java array's length (an i32).
    a.get_region(env, range.start as jint, &mut out)?;
    Ok(out)
}

fn check_len<T: TypeArray>(env: &Env, name: &str, a: &JPrimitiveArray<'_, T>, min: usize, exact: bool) -> Result<()> {
    non_null(name, &**a)?;
    let len = a.len(env)?;
    if (exact && len != min) || len < min {
        let rule = if exact { "exactly" } else { "at least" };
        return Err(BridgeError::Argument(format!("{name}: must have {rule} {min} elements, got {len}")));
    }
    Ok(())
}

fn dng_matrix(env: &Env, name: &str, a: &JIntArray) -> Result<campro::Mat3> {
    let ints: [i32; 18] = read_ints(env, name, a)?;
    camera2::matrix_from_rationals(&ints).map_err(|e| arg(e.within(name)))
}

fn illuminant(name: &str, code: jint) -> Result<u8> {
    u8::try_from(code).map_err(|_| BridgeError::Argument(format!("{name}: unknown reference illuminant code {code}")))
}

fn create(bytes: &[u8], max_curve_points: jint, max_denominator: jint, skip_tolerance: jdouble) -> Result<jlong> {
    let text = std::str::from_utf8(bytes).map_err(|e| BridgeError::Argument(format!("paramsJson: not UTF-8: {e}")))?;
    let params = Params::from_json(text).map_err(|e| BridgeError::Argument(format!("params: {e}")))?;
    let l = Camera2Loop::new(params, options(max_curve_points, max_denominator)?, skip_tolerance).map_err(arg)?;
    log::info!("campro: loaded parameter set '{}'", l.params().name);
    Ok(register(l))
}

/// The outputs of one update, checked before the loop state moves.
struct Outputs<'a, 'local> {
    transform: &'a JIntArray<'local>,
    curve: &'a JFloatArray<'local>,
    report: &'a JDoubleArray<'local>,
}

impl Outputs<'_, '_> {
    fn check(&self, env: &Env, max_points: usize) -> Result<()> {
        check_len(env, "outTransform", self.transform, 18, true)?;
        check_len(env, "outCurve", self.curve, 3 * 2 * max_points, false)?;
        check_len(env, "outReport", self.report, report::LEN, false)
    }

    /// Writes the values; channel c's curve at `c · 2 · max_points` of `outCurve`.
    fn write(&self, env: &Env, u: &Update<'_>, max_points: usize) -> Result<jboolean> {
        let v = u.values;
        let r = &v.report;
        self.transform.set_region(env, 0, &v.color_correction_transform)?;
        let t = &v.tonemap_curve;
        let mut rep = [0f64; report::LEN];
        for (c, pairs) in [&t.red, &t.green, &t.blue].into_iter().enumerate() {
            // Within outCurve's checked length, a Java array's (an i32).
            self.curve.set_region(env, (c * 2 * max_points) as jint, pairs)?;
            rep[report::CURVE_POINTS_RED + c] = (pairs.len() / 2) as f64;
        }
        rep[report::RECOMPUTED] = u.recomputed as u8 as f64;
        rep[report::BOUND] = u.bound;
        rep[report::MATRIX_MAX_ABS] = r.matrix_max_abs;
        rep[report::CURVE_MAX_ABS] = r.curve_max_abs;
        rep[report::CURVE_LIPSCHITZ] = r.curve_lipschitz;
        rep[report::SCALE] = v.scale;
        rep[report::CURVE_POINTS] = r.curve_points as f64;
        rep[report::CURVE_SIMPLIFIED] = r.curve_simplified as u8 as f64;
        self.report.set_region(env, 0, &rep)?;
        Ok(u.recomputed)
    }
}

fn update(
    env: &Env,
    handle: jlong,
    out: Outputs<'_, '_>,
    step: impl FnOnce(&mut Camera2Loop) -> std::result::Result<Update<'_>, ConvertError>,
) -> Result<jboolean> {
    with_loop(handle, |l| {
        let max_points = l.options().max_curve_points;
        out.check(env, max_points)?;
        let u = step(l)?;
        out.write(env, &u, max_points)
    })
}

// ---------------------------------------------------------------------------------
// Native methods of org.campro.CamProNative (all static).

/// `create(paramsJson: String, maxCurvePoints: Int, maxDenominator: Int, skipTolerance: Double): Long`
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_create<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    json: JString<'local>,
    max_curve_points: jint,
    max_denominator: jint,
    skip_tolerance: jdouble,
) -> jlong {
    env.with_env(|env| -> Result<jlong> {
        non_null("paramsJson", &json)?;
        let text = json.try_to_string(env)?;
        create(text.as_bytes(), max_curve_points, max_denominator, skip_tolerance)
    })
    .resolve::<ThrowJava>()
}

/// `createFromBytes(paramsJson: ByteArray, ...): Long` (UTF-8 JSON, e.g. a file's bytes).
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_createFromBytes<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    bytes: JByteArray<'local>,
    max_curve_points: jint,
    max_denominator: jint,
    skip_tolerance: jdouble,
) -> jlong {
    env.with_env(|env| -> Result<jlong> {
        non_null("paramsJson", &bytes)?;
        let len = bytes.len(env)?;
        if len > campro::params::MAX_JSON_BYTES {
            return Err(BridgeError::Argument(format!(
                "paramsJson: {len} bytes; the limit is {}",
                campro::params::MAX_JSON_BYTES
            )));
        }
        let data = env.convert_byte_array(&bytes)?;
        create(&data, max_curve_points, max_denominator, skip_tolerance)
    })
    .resolve::<ThrowJava>()
}

/// `createFromAsset(assetManager: Any, path: String, ...): Long`: a parameter file from
/// the APK's assets, read natively through the NDK's AAssetManager. Android only; on
/// other hosts it throws `IllegalStateException`.
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_createFromAsset<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    asset_manager: JObject<'local>,
    path: JString<'local>,
    max_curve_points: jint,
    max_denominator: jint,
    skip_tolerance: jdouble,
) -> jlong {
    env.with_env(|env| -> Result<jlong> {
        non_null("assetManager", &asset_manager)?;
        non_null("path", &path)?;
        let path = path.try_to_string(env)?;
        let data = android::read_asset(env, &asset_manager, &path)?;
        create(&data, max_curve_points, max_denominator, skip_tolerance)
    })
    .resolve::<ThrowJava>()
}

/// `close(handle: Long)`: frees the handle; a closed or unknown handle throws.
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_close<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
) {
    env.with_env(|_env| -> Result<()> {
        registry()
            .remove(&handle)
            .map(drop)
            .ok_or_else(|| BridgeError::State(format!("handle {handle:#x} is closed or was never issued by campro")))
    })
    .resolve::<ThrowJava>()
}

/// `liveHandles(): Int`: handles created and not yet closed (leak checks).
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_liveHandles<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
) -> jint {
    env.with_env(|_env| -> Result<jint> { Ok(registry().len() as jint) }).resolve::<ThrowJava>()
}

/// `protective(handle: Long): Boolean`: whether the session's parameter set protects faces
/// ([`campro::Params::protective`]: a protection rating in its provenance within the
/// threshold). A device never calls an unprotective set's frames "Protected".
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_protective<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
) -> jboolean {
    env.with_env(|_env| -> Result<jboolean> { with_loop(handle, |l| Ok(l.params().protective())) })
        .resolve::<ThrowJava>()
}

/// `deviceGrids(handle: Long): String`: the grids a HAL may put the values on with the set's
/// protection measured to hold ([`campro::Params::device_grids`]), comma-separated (`q10,lut64`;
/// empty: none).
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_deviceGrids<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
) -> JString<'local> {
    env.with_env(|env| -> Result<JString<'local>> {
        let grids = with_loop(handle, |l| Ok(l.params().device_grids()))?;
        let text = grids.iter().map(ToString::to_string).collect::<Vec<_>>().join(",");
        Ok(env.new_string(text)?)
    })
    .resolve::<ThrowJava>()
}

/// `setMaxCurvePoints(handle: Long, n: Int)`: the device's `TONEMAP_MAX_CURVE_POINTS`.
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_setMaxCurvePoints<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
    n: jint,
) {
    env.with_env(|_env| -> Result<()> {
        let n = usize::try_from(n)
            .map_err(|_| BridgeError::Argument(format!("maxCurvePoints: must be positive, got {n}")))?;
        with_loop(handle, |l| l.set_max_curve_points(n).map_err(|e| arg(e.within("maxCurvePoints"))))
    })
    .resolve::<ThrowJava>()
}

/// `setDngCalibration(handle, illuminant1: Int, forwardMatrix1: IntArray(18), illuminant2: Int, forwardMatrix2: IntArray(18))`:
/// `SENSOR_REFERENCE_ILLUMINANT1/2` and `SENSOR_FORWARD_MATRIX1/2` for [`updateFromColorTemperature`].
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_setDngCalibration<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
    illuminant1: jint,
    forward_matrix1: JIntArray<'local>,
    illuminant2: jint,
    forward_matrix2: JIntArray<'local>,
) {
    env.with_env(|env| -> Result<()> {
        let cal = DngCalibration {
            illuminant1: illuminant("illuminant1", illuminant1)?,
            forward_matrix1: dng_matrix(env, "forwardMatrix1", &forward_matrix1)?,
            illuminant2: illuminant("illuminant2", illuminant2)?,
            forward_matrix2: dng_matrix(env, "forwardMatrix2", &forward_matrix2)?,
        };
        with_loop(handle, |l| l.set_dng_calibration(cal).map_err(arg))
    })
    .resolve::<ThrowJava>()
}

/// `updateFromTransform(handle, deviceTransform: IntArray(18), outTransform: IntArray(18),
/// outCurve: FloatArray(>= 3 * 2 * maxCurvePoints), outReport: DoubleArray(>= REPORT_LEN)): Boolean`:
/// (`outCurve` holds red, green and blue, each from `c * 2 * maxCurvePoints`, with
/// `REPORT_CURVE_POINTS_RED + c` points)
/// one frame, from the `COLOR_CORRECTION_TRANSFORM` of an auto-mode `CaptureResult`.
/// Returns whether the values changed (the request must be rebuilt); the arrays always
/// hold the values to send.
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_updateFromTransform<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
    device_transform: JIntArray<'local>,
    out_transform: JIntArray<'local>,
    out_curve: JFloatArray<'local>,
    out_report: JDoubleArray<'local>,
) -> jboolean {
    env.with_env(|env| -> Result<jboolean> {
        let ints: [i32; 18] = read_ints(env, "deviceTransform", &device_transform)?;
        let device = camera2::matrix_from_rationals(&ints).map_err(|e| arg(e.within("deviceTransform")))?;
        let out = Outputs { transform: &out_transform, curve: &out_curve, report: &out_report };
        update(env, handle, out, |l| l.update(&device))
    })
    .resolve::<ThrowJava>()
}

/// `updateFromColorTemperature(handle, kelvin: Double, outTransform, outCurve, outReport): Boolean`:
/// one frame from a colour temperature, through the DNG calibration (if set) or the
/// parameter set's `ct_calibration`.
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_updateFromColorTemperature<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
    kelvin: jdouble,
    out_transform: JIntArray<'local>,
    out_curve: JFloatArray<'local>,
    out_report: JDoubleArray<'local>,
) -> jboolean {
    env.with_env(|env| -> Result<jboolean> {
        let out = Outputs { transform: &out_transform, curve: &out_curve, report: &out_report };
        update(env, handle, out, |l| l.update_ct(kelvin))
    })
    .resolve::<ThrowJava>()
}

/// `readback(requestedTransform: IntArray(18), requestedCurve: FloatArray, requestedOffset: Int,
/// requestedCount: Int, reportedTransform: IntArray(18), reportedCurve: FloatArray, reportedCount: Int,
/// channel: Int, out: DoubleArray(>= 3))`: how far a `CaptureResult`'s transform and the curve
/// of one channel (0 red, 1 green, 2 blue) are from the request, and the bound on that
/// channel's output (counts are floats used, i.e. 2 x points; the requested curve starts at
/// `requestedOffset`, as a session's packed curves do).
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub extern "system" fn Java_org_campro_CamProNative_readback<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    requested_transform: JIntArray<'local>,
    requested_curve: JFloatArray<'local>,
    requested_offset: jint,
    requested_count: jint,
    reported_transform: JIntArray<'local>,
    reported_curve: JFloatArray<'local>,
    reported_count: jint,
    channel: jint,
    out: JDoubleArray<'local>,
) {
    env.with_env(|env| -> Result<()> {
        let rt: [i32; 18] = read_ints(env, "requestedTransform", &requested_transform)?;
        let gt: [i32; 18] = read_ints(env, "reportedTransform", &reported_transform)?;
        let rc = read_floats_at(env, "requestedCurve", &requested_curve, requested_offset, requested_count)?;
        let gc = read_floats(env, "reportedCurve", &reported_curve, reported_count)?;
        check_len(env, "out", &out, readback::LEN, false)?;
        let channel = usize::try_from(channel).unwrap_or(usize::MAX);
        let r = camera2::readback_channel(channel, &rt, &rc, &gt, &gc).map_err(arg)?;
        let mut vals = [0f64; readback::LEN];
        vals[readback::MATRIX_MAX_ABS] = r.matrix_max_abs;
        vals[readback::CURVE_MAX_ABS] = r.curve_max_abs;
        vals[readback::BOUND] = r.bound;
        out.set_region(env, 0, &vals)?;
        Ok(())
    })
    .resolve::<ThrowJava>()
}

/// Largest byte array a still's call copies (a plane or RGB): 64 MP of RGB.
const MAX_STILL_ARRAY: usize = 3 * still::MAX_PIXELS as usize;

/// A byte array's contents, its length checked before anything is copied.
fn read_bytes(env: &Env, name: &str, a: &JByteArray) -> Result<Vec<u8>> {
    non_null(name, a)?;
    let len = a.len(env)?;
    if len > MAX_STILL_ARRAY {
        return Err(BridgeError::Argument(format!("{name}: {len} bytes; the limit is {MAX_STILL_ARRAY}")));
    }
    Ok(env.convert_byte_array(a)?)
}

fn stride(name: &str, v: jint) -> Result<usize> {
    usize::try_from(v).map_err(|_| BridgeError::Argument(format!("{name}: must be >= 0, got {v}")))
}

fn side(name: &str, v: jint) -> Result<u32> {
    u32::try_from(v).map_err(|_| BridgeError::Argument(format!("{name}: must be >= 1, got {v}")))
}

/// `org.campro.CamProNative.encodeJpegYuv(width, height, y: ByteArray, yRowStride, u: ByteArray,
/// v: ByteArray, uvRowStride, uvPixelStride, exifOrientation, quality): ByteArray`: a verified
/// `YUV_420_888` frame's planes as a JPEG whose only metadata is its EXIF orientation
/// ([`still`]).
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub extern "system" fn Java_org_campro_CamProNative_encodeJpegYuv<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    width: jint,
    height: jint,
    y: JByteArray<'local>,
    y_row_stride: jint,
    u: JByteArray<'local>,
    v: JByteArray<'local>,
    uv_row_stride: jint,
    uv_pixel_stride: jint,
    exif_orientation: jint,
    quality: jint,
) -> JByteArray<'local> {
    env.with_env(|env| -> Result<JByteArray<'local>> {
        let (yb, ub, vb) = (read_bytes(env, "y", &y)?, read_bytes(env, "u", &u)?, read_bytes(env, "v", &v)?);
        let frame = still::Yuv420 {
            width: side("width", width)?,
            height: side("height", height)?,
            y: &yb,
            y_row_stride: stride("yRowStride", y_row_stride)?,
            u: &ub,
            v: &vb,
            uv_row_stride: stride("uvRowStride", uv_row_stride)?,
            uv_pixel_stride: stride("uvPixelStride", uv_pixel_stride)?,
        };
        let (o, q) = (still::orientation(exif_orientation.into())?, still::quality(quality.into())?);
        let jpeg = still::jpeg_from_yuv420(&frame, o, q)?;
        Ok(env.byte_array_from_slice(&jpeg)?)
    })
    .resolve::<ThrowJava>()
}

/// `org.campro.CamProNative.encodeJpegRgb(width, height, rgb: ByteArray, exifOrientation,
/// quality): ByteArray`: interleaved 8-bit RGB as a JPEG whose only metadata is its EXIF
/// orientation ([`still::jpeg_from_rgb`]).
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_CamProNative_encodeJpegRgb<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    width: jint,
    height: jint,
    rgb: JByteArray<'local>,
    exif_orientation: jint,
    quality: jint,
) -> JByteArray<'local> {
    env.with_env(|env| -> Result<JByteArray<'local>> {
        let px = read_bytes(env, "rgb", &rgb)?;
        let (o, q) = (still::orientation(exif_orientation.into())?, still::quality(quality.into())?);
        let jpeg = still::jpeg_from_rgb(&px, side("width", width)?, side("height", height)?, o, q)?;
        Ok(env.byte_array_from_slice(&jpeg)?)
    })
    .resolve::<ThrowJava>()
}

/// A string argument, non-null, at most `max` bytes.
fn read_string(env: &Env, name: &str, s: &JString, max: usize) -> Result<String> {
    non_null(name, s)?;
    let text = s.try_to_string(env)?;
    if text.len() > max {
        return Err(BridgeError::Argument(format!("{name}: {} bytes; the limit is {max}", text.len())));
    }
    Ok(text)
}

/// `org.campro.CamProNative.record(presetJson: ByteArray, given, presetSha256, cameraId,
/// transform: IntArray(18), curvePoints, gains: FloatArray(4), conversionBoundLsb,
/// worstDeviationLsb, maxDeviationLsb, jpegQuality, metadata, outputName, outputSha256,
/// outputBytes): String`: the record (`NAME.campro.json`, [`campro::record`]) of a phone's
/// protected output: the preset (its name and training round read from `presetJson`, its
/// SHA-256 as the app hashed those bytes), the values sent, and the output's hash; checked by
/// the rules `campro check --record` reads it with. The bound is the conversion's (the last
/// update's report) plus the largest reported deviation the guard accepts. `jpegQuality` 0:
/// not a JPEG. Takes no handle: a still's record is written after its camera may have closed.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub extern "system" fn Java_org_campro_CamProNative_record<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    preset_json: JByteArray<'local>,
    given: JString<'local>,
    preset_sha256: JString<'local>,
    camera_id: JString<'local>,
    transform: JIntArray<'local>,
    curve_points: jint,
    gains: JFloatArray<'local>,
    conversion_bound_lsb: jdouble,
    worst_deviation_lsb: jdouble,
    max_deviation_lsb: jdouble,
    jpeg_quality: jint,
    metadata: JString<'local>,
    output_name: JString<'local>,
    output_sha256: JString<'local>,
    output_bytes: jlong,
) -> JString<'local> {
    env.with_env(|env| -> Result<JString<'local>> {
        use campro::record::{DeviceRecord, FileRecord, PresetRecord, Record};
        let bytes = read_bytes(env, "presetJson", &preset_json)?;
        if bytes.len() > campro::params::MAX_JSON_BYTES {
            return Err(BridgeError::Argument(format!(
                "presetJson: {} bytes; the limit is {}",
                bytes.len(),
                campro::params::MAX_JSON_BYTES
            )));
        }
        let text =
            std::str::from_utf8(&bytes).map_err(|e| BridgeError::Argument(format!("presetJson: not UTF-8: {e}")))?;
        let params = Params::from_json(text).map_err(|e| BridgeError::Argument(format!("presetJson: {e}")))?;
        let t: [i32; 18] = read_ints(env, "transform", &transform)?;
        let g = read_floats(env, "gains", &gains, 4)?;
        let non_negative = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(v)
            } else {
                Err(BridgeError::Argument(format!("{name}: must be finite and >= 0, got {v}")))
            }
        };
        let count = |name: &str, v: i64| {
            u64::try_from(v).map_err(|_| BridgeError::Argument(format!("{name}: must be >= 0, got {v}")))
        };
        let r = Record {
            campro_record: campro::record::RECORD_VERSION,
            campro_version: env!("CARGO_PKG_VERSION").to_string(),
            preset: PresetRecord {
                name: params.name.clone(),
                given: read_string(env, "given", &given, 4096)?,
                sha256: read_string(env, "presetSha256", &preset_sha256, 64)?,
                best_round: params.provenance_fields().ok().and_then(|f| f.best_round),
            },
            path: campro::record::PATH_CAMERA2.to_string(),
            bit_depth: 8,
            bound_lsb: non_negative("conversionBoundLsb", conversion_bound_lsb)?
                + non_negative("maxDeviationLsb", max_deviation_lsb)?,
            enhancer_sha256: None,
            jpeg_quality: match jpeg_quality {
                0 => None,
                q => Some(still::quality(q.into())?), // 0: not a JPEG
            },
            metadata: read_string(env, "metadata", &metadata, 64)?,
            input: None,
            output: FileRecord {
                name: read_string(env, "outputName", &output_name, 4096)?,
                sha256: read_string(env, "outputSha256", &output_sha256, 64)?,
                bytes: count("outputBytes", output_bytes)?,
            },
            device: Some(DeviceRecord {
                camera_id: read_string(env, "cameraId", &camera_id, 256)?,
                transform: t.to_vec(),
                gains: g,
                curve_points: count("curvePoints", i64::from(curve_points))? as u32,
                worst_reported_deviation_lsb: non_negative("worstDeviationLsb", worst_deviation_lsb)?,
            }),
        };
        r.check().map_err(|e| BridgeError::Argument(e.to_string()))?;
        Ok(env.new_string(r.to_json())?)
    })
    .resolve::<ThrowJava>()
}

/// The pixels of `raw` (linear sensor RGB, 3 floats a pixel) as 8-bit codes, through
/// `f`: what a simulated camera's frame holds. `out` has one byte a float.
#[cfg(feature = "test-exports")]
fn render(env: &mut Env, raw: &JFloatArray, out: &JByteArray, f: impl Fn([f64; 3]) -> [f64; 3]) -> Result<()> {
    non_null("raw", raw)?;
    let n = raw.len(env)?;
    if n % 3 != 0 || n > 3 << 20 {
        return Err(BridgeError::Argument(format!("raw: must hold 3 floats a pixel, at most 2^20 pixels, got {n}")));
    }
    check_len(env, "out", out, n, true)?;
    let v = read_floats(env, "raw", raw, n as jint)?;
    let codes: Vec<i8> = v
        .chunks_exact(3)
        .flat_map(|p| f([p[0] as f64, p[1] as f64, p[2] as f64]))
        .map(|c| ((c.clamp(0.0, 1.0) * 255.0).round() as u8) as i8)
        .collect();
    out.set_region(env, 0, &codes)?;
    Ok(())
}

/// White-balance gains `(R, G_even, G_odd, B)` as the per-channel factors a Bayer ISP
/// applies to RGB: R, the mean of the two greens, B.
#[cfg(feature = "test-exports")]
fn rgb_gains(env: &Env, gains: &JFloatArray) -> Result<[f64; 3]> {
    let g = read_floats(env, "gains", gains, 4)?;
    if g.len() != 4 || g.iter().any(|v| !v.is_finite()) {
        return Err(BridgeError::Argument("gains: must hold 4 finite values (R, G_even, G_odd, B)".into()));
    }
    Ok([g[0] as f64, (g[1] as f64 + g[2] as f64) / 2.0, g[3] as f64])
}

/// `org.campro.hal.HalNative.emulate(transform: IntArray(18), curve: FloatArray, stride: Int,
/// counts: IntArray(3), gains: FloatArray(4), raw: FloatArray(3n), out: ByteArray(3n))`: what a
/// Camera2 device applying this transform, these curves (channel c's `counts[c]` floats from
/// `c * stride` of `curve`) and these gains makes of linear
/// sensor RGB, through the core's emulator ([`campro::emulate::Isp`]): gains, matrix, clip,
/// curve, 8-bit rounding. Test builds only: the JVM suite's simulated camera renders its
/// frames with it.
#[cfg(feature = "test-exports")]
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub extern "system" fn Java_org_campro_hal_HalNative_emulate<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    transform: JIntArray<'local>,
    curve: JFloatArray<'local>,
    stride: jint,
    counts: JIntArray<'local>,
    gains: JFloatArray<'local>,
    raw: JFloatArray<'local>,
    out: JByteArray<'local>,
) {
    env.with_env(|env| -> Result<()> {
        use campro::emulate::Emulator;
        let t: [i32; 18] = read_ints(env, "transform", &transform)?;
        let matrix = camera2::matrix_from_rationals(&t).map_err(|e| arg(e.within("transform")))?;
        let counts: [i32; 3] = read_ints(env, "counts", &counts)?;
        let mut curves = Vec::with_capacity(3);
        for (c, &count) in counts.iter().enumerate() {
            let offset = (c as jint)
                .checked_mul(stride)
                .ok_or_else(|| BridgeError::Argument(format!("stride: {stride} is too large")))?;
            let pairs = read_floats_at(env, "curve", &curve, offset, count)?;
            curves.push(camera2::curve_from_pairs(&pairs).map_err(|e| arg(e.within("curve")))?);
        }
        let [r, g_curve, b]: [campro::ToneCurve; 3] = curves.try_into().expect("three channels");
        let g = rgb_gains(env, &gains)?;
        let isp = campro::emulate::Isp { matrix, curves: campro::ToneCurves::per_channel([r, g_curve, b]) };
        render(env, &raw, &out, |p| isp.sensor_to_output([p[0] * g[0], p[1] * g[1], p[2] * g[2]]))
    })
    .resolve::<ThrowJava>()
}

/// `org.campro.hal.HalNative.desktop(handle, deviceTransform: IntArray(18), gains: FloatArray(4),
/// raw: FloatArray(3n), out: ByteArray(3n))`: what the desktop pipeline makes of the same
/// scene with the handle's parameter set: the device's own rendering to linear sRGB
/// (`deviceTransform` on the white-balanced sensor RGB), then CamPro
/// ([`campro::pipeline::from_linear`]), 8-bit rounding. The reference a protected frame
/// is held to. Test builds only.
#[cfg(feature = "test-exports")]
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_hal_HalNative_desktop<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    handle: jlong,
    device_transform: JIntArray<'local>,
    gains: JFloatArray<'local>,
    raw: JFloatArray<'local>,
    out: JByteArray<'local>,
) {
    env.with_env(|env| -> Result<()> {
        let t: [i32; 18] = read_ints(env, "deviceTransform", &device_transform)?;
        let device = camera2::matrix_from_rationals(&t).map_err(|e| arg(e.within("deviceTransform")))?;
        let g = rgb_gains(env, &gains)?;
        let params = with_loop(handle, |l| Ok(l.params().clone()))?;
        render(env, &raw, &out, |p| {
            let lin = campro::ccm::apply(&device, [p[0] * g[0], p[1] * g[1], p[2] * g[2]]);
            campro::pipeline::from_linear(&params, lin)
        })
    })
    .resolve::<ThrowJava>()
}

/// Called by the VM when it loads the library, before any native method runs: routes `log`
/// to logcat on Android (so every entry point's messages reach it from the first call on)
/// and names the JNI version the bridge needs (1.6). Nothing here can panic across the
/// boundary: a panic while setting up logging is caught and the library loads without it.
#[unsafe(no_mangle)]
pub extern "system" fn JNI_OnLoad(_vm: *mut jni::sys::JavaVM, _reserved: *mut std::ffi::c_void) -> jint {
    let _ = std::panic::catch_unwind(android::init_logging);
    jni::sys::JNI_VERSION_1_6
}

/// `org.campro.TestHooks.selfTestPanic(message: String)`: panics inside a native method,
/// so the host test can check that the panic arrives as a `RuntimeException` and the
/// library keeps working. Only in builds with the `test-exports` feature (never in the
/// production `.so`).
#[cfg(feature = "test-exports")]
#[unsafe(no_mangle)]
pub extern "system" fn Java_org_campro_TestHooks_selfTestPanic<'local>(
    mut env: EnvUnowned<'local>,
    _class: JClass<'local>,
    message: JString<'local>,
) {
    env.with_env(|env| -> Result<()> {
        let m = if message.is_null() { "null".to_string() } else { message.try_to_string(env)? };
        panic!("self-test panic: {m}");
    })
    .resolve::<ThrowJava>()
}

/// Android-only glue: logging to logcat and reading the APK's assets. Type-checked on the
/// host with the `android-check` feature.
#[cfg(any(target_os = "android", feature = "android-check"))]
mod android {
    use super::{BridgeError, Result};
    use jni::objects::JObject;
    use jni::Env;
    use std::ffi::CString;
    use std::io::Read;
    use std::ptr::NonNull;

    /// Routes `log` to logcat under the tag `campro` (idempotent).
    pub fn init_logging() {
        android_logger::init_once(
            android_logger::Config::default().with_tag("campro").with_max_level(log::LevelFilter::Info),
        );
    }

    pub fn read_asset(env: &mut Env, manager: &JObject, path: &str) -> Result<Vec<u8>> {
        // SAFETY: `manager` is a live local reference to an android.content.res.AssetManager
        // for the duration of this native call, and `env` is this thread's JNIEnv.
        let raw = unsafe { ndk_sys::AAssetManager_fromJava(env.get_raw() as *mut _, manager.as_raw() as _) };
        let raw = NonNull::new(raw)
            .ok_or_else(|| BridgeError::Argument("assetManager: not an android.content.res.AssetManager".into()))?;
        // SAFETY: the pointer came from AAssetManager_fromJava and outlives this call.
        let mgr = unsafe { ndk::asset::AssetManager::from_ptr(raw) };
        let c = CString::new(path).map_err(|_| BridgeError::Argument("path: contains a NUL byte".into()))?;
        let asset = mgr.open(&c).ok_or_else(|| BridgeError::Argument(format!("path: no asset named '{path}'")))?;
        let limit = campro::params::MAX_JSON_BYTES;
        if asset.length() > limit {
            return Err(BridgeError::Argument(format!(
                "path: asset '{path}' is {} bytes; the limit is {limit}",
                asset.length()
            )));
        }
        let mut data = Vec::with_capacity(asset.length());
        asset
            .take(limit as u64 + 1)
            .read_to_end(&mut data)
            .map_err(|e| BridgeError::Argument(format!("path: reading '{path}': {e}")))?;
        Ok(data)
    }
}

#[cfg(not(any(target_os = "android", feature = "android-check")))]
mod android {
    use super::{BridgeError, Result};
    use jni::objects::JObject;
    use jni::Env;

    /// Off Android `log` goes wherever the host process sends it (nowhere by default).
    pub fn init_logging() {}

    pub fn read_asset(_env: &mut Env, _manager: &JObject, path: &str) -> Result<Vec<u8>> {
        Err(BridgeError::State(format!(
            "createFromAsset('{path}'): APK assets exist only on Android; use create or createFromBytes"
        )))
    }
}
