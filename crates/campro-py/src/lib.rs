//! `campro._campro`: the native half of the Python package (`python/campro`, which holds
//! the typed API, its docstrings and stubs). Thin by design: arrays in, `campro_cli::api`
//! on their samples with the GIL released, new arrays out; every error is the command's
//! one line, as `campro.Error`. Shapes and dtypes are checked here too, whatever the
//! Python layer did, so that no call can read past an array.

use campro_cli::api::{self, BitDepth, Frame, Pixels};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rayon::prelude::*;
use std::path::PathBuf;

pyo3::create_exception!(
    _campro,
    Error,
    pyo3::exceptions::PyException,
    "A campro error: the one line the command prints."
);

fn error(e: anyhow::Error) -> PyErr {
    Error::new_err(api::error_line(&e))
}

/// Samples of an H x W x 3 array, borrowed read-only for as long as the guard lives.
enum Samples<'py> {
    Eight(PyReadonlyArrayDyn<'py, u8>),
    Sixteen(PyReadonlyArrayDyn<'py, u16>),
}

impl<'py> Samples<'py> {
    /// `obj` as an H x W x 3 C-contiguous array of uint8 or uint16 (`index`: its place in
    /// a batch, for the message), with its width and height.
    fn of(obj: &Bound<'py, PyAny>, index: Option<usize>) -> PyResult<(Self, u32, u32)> {
        let at = index.map_or(String::new(), |i| format!("image {i}: "));
        let s = if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'py, u8>>() {
            Samples::Eight(a)
        } else if let Ok(a) = obj.extract::<PyReadonlyArrayDyn<'py, u16>>() {
            Samples::Sixteen(a)
        } else {
            return Err(PyValueError::new_err(format!(
                "{at}expected a numpy array of uint8 (or uint16) RGB samples, got {}",
                describe(obj)
            )));
        };
        let shape = match &s {
            Samples::Eight(a) => a.shape().to_vec(),
            Samples::Sixteen(a) => a.shape().to_vec(),
        };
        let contiguous = match &s {
            Samples::Eight(a) => a.is_c_contiguous(),
            Samples::Sixteen(a) => a.is_c_contiguous(),
        };
        match shape[..] {
            [h, w, 3] if h > 0 && w > 0 && h <= u32::MAX as usize && w <= u32::MAX as usize => {
                if !contiguous {
                    return Err(PyValueError::new_err(format!("{at}the array is not C-contiguous")));
                }
                Ok((s, w as u32, h as u32))
            }
            _ => Err(PyValueError::new_err(format!(
                "{at}expected an H x W x 3 RGB array (H, W >= 1), got shape {shape:?}"
            ))),
        }
    }

    fn frame(&self) -> Frame<'_> {
        match self {
            Samples::Eight(a) => Frame::Eight(a.as_slice().expect("checked C-contiguous")),
            Samples::Sixteen(a) => Frame::Sixteen(a.as_slice().expect("checked C-contiguous")),
        }
    }
}

/// The type of `obj` for a message: its dtype and shape when it is an array.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    match (obj.getattr("dtype"), obj.getattr("shape")) {
        (Ok(d), Ok(s)) => format!("dtype {d} of shape {s}"),
        _ => obj.get_type().name().map_or_else(|_| "an object".into(), |n| n.to_string()),
    }
}

/// Pixels as a new H x W x 3 array (the vector moved in, not copied).
fn array<'py>(py: Python<'py>, p: Pixels, w: u32, h: u32) -> PyResult<Bound<'py, PyAny>> {
    let shape = [h as usize, w as usize, 3];
    Ok(match p {
        Pixels::Eight(v) => PyArray1::from_vec(py, v).reshape(shape)?.into_any(),
        Pixels::Sixteen(v) => PyArray1::from_vec(py, v).reshape(shape)?.into_any(),
    })
}

fn depth(bit_depth: u8) -> PyResult<BitDepth> {
    match bit_depth {
        8 => Ok(BitDepth::Eight),
        16 => Ok(BitDepth::Sixteen),
        d => Err(PyValueError::new_err(format!("bit_depth must be 8 or 16, got {d}"))),
    }
}

/// Why a picture has no output: its kind ("refused", "error") and the one-line reason.
type Failure = (&'static str, String);

/// One picture's result in [`Camera::capture_each`]: its output, or why there is none.
type Row<'py> = (Option<Bound<'py, PyAny>>, Option<Failure>);

/// The camera of one parameter set (see `campro.Camera`).
#[pyclass(frozen, module = "campro._campro", name = "Camera")]
struct Camera {
    inner: api::Camera,
    /// What it was made from, for pickling: the spec as given, or the JSON of a file.
    spec: String,
}

#[pymethods]
impl Camera {
    #[new]
    #[pyo3(signature = (preset, allow_grey = false))]
    fn new(py: Python<'_>, preset: &str, allow_grey: bool) -> PyResult<Self> {
        let inner = py.detach(|| api::Camera::new(preset, allow_grey)).map_err(error)?;
        // A file's path is pickled as its JSON: the copy needs no file on the worker.
        let spec = match inner.source() {
            api::Source::Path(p) if p.components().count() > 1 || p.is_file() => inner.params().to_json(),
            _ => preset.to_string(),
        };
        Ok(Self { inner, spec })
    }

    /// The parameter set's name.
    #[getter]
    fn name(&self) -> String {
        self.inner.params().name.clone()
    }

    /// The parameter set as JSON text.
    #[getter]
    fn json(&self) -> String {
        self.inner.params().to_json()
    }

    #[getter]
    fn allow_grey(&self) -> bool {
        self.inner.allows_grey()
    }

    /// What `pickle` rebuilds it from.
    #[getter]
    fn spec(&self) -> String {
        self.spec.clone()
    }

    /// An N x H x W x 3 uint8 batch (C order) through the camera at 8 bits into one new
    /// array: the pictures in parallel, each written in place, the GIL released. A grey
    /// picture raises `Error` naming its index unless the camera allows grey.
    fn capture_batch<'py>(&self, py: Python<'py>, batch: PyReadonlyArrayDyn<'py, u8>) -> PyResult<Bound<'py, PyAny>> {
        let (n, h, w) = match batch.shape()[..] {
            [n, h, w, 3] if n > 0 && h > 0 && w > 0 && h <= u32::MAX as usize && w <= u32::MAX as usize => (n, h, w),
            ref s => return Err(PyValueError::new_err(format!("expected an N x H x W x 3 batch, got shape {s:?}"))),
        };
        let src = batch.as_slice().map_err(|_| PyValueError::new_err("the batch is not C-contiguous"))?;
        let frame = 3 * h * w;
        let mut out = vec![0u8; src.len()];
        let failed: Option<String> = py.detach(|| {
            src.par_chunks(frame).zip(out.par_chunks_mut(frame)).enumerate().find_map_first(|(i, (s, d))| {
                self.inner
                    .capture_into(s, d, w as u32, h as u32)
                    .err()
                    .map(|e| format!("image {i}: {}", api::error_line(&e)))
            })
        });
        if let Some(line) = failed {
            return Err(Error::new_err(line));
        }
        Ok(PyArray1::from_vec(py, out).reshape([n, h, w, 3])?.into_any())
    }

    /// Each array of `images` through the camera, in parallel, the GIL released; one
    /// result a picture and never an exception for one: `(array, None)`, or `(None, (kind,
    /// message))` with kind "invalid" (not an H x W x 3 uint8 or uint16 C-order array),
    /// "refused" (a grey picture) or "error".
    #[pyo3(signature = (images, bit_depth = 8))]
    fn capture_each<'py>(
        &self,
        py: Python<'py>,
        images: &Bound<'py, PyList>,
        bit_depth: u8,
    ) -> PyResult<Vec<Row<'py>>> {
        let depth = depth(bit_depth)?;
        let held: Vec<Result<(Samples, u32, u32), String>> =
            images.iter().map(|a| Samples::of(&a, None).map_err(|e| e.to_string())).collect();
        let frames: Vec<Option<(Frame, u32, u32)>> =
            held.iter().map(|r| r.as_ref().ok().map(|(s, w, h)| (s.frame(), *w, *h))).collect();
        let out: Vec<Option<Result<Pixels, Failure>>> = py.detach(|| {
            frames
                .par_iter()
                .map(|f| {
                    f.map(|(f, w, h)| {
                        self.inner.capture(f, w, h, depth).map(|(p, _)| p).map_err(|e| {
                            let grey = !self.inner.allows_grey() && api::is_grey_refusal(&e);
                            (if grey { "refused" } else { "error" }, api::error_line(&e))
                        })
                    })
                })
                .collect()
        });
        out.into_iter()
            .zip(&held)
            .map(|(r, h)| match (r, h) {
                (Some(Ok(p)), Ok((_, w, h))) => Ok((Some(array(py, p, *w, *h)?), None)),
                (Some(Err(e)), _) => Ok((None, Some(e))),
                (_, Err(line)) => Ok((None, Some(("invalid", line.clone())))),
                (None, Ok(_)) => unreachable!("a held frame is captured"),
            })
            .collect()
    }

    /// Seconds each of `runs` captures of `image` takes inside Rust (the same call as
    /// `capture_each`, without the arrays around it): what `bench.py` measures the Python
    /// call's overhead against.
    fn bench_capture(&self, py: Python<'_>, image: &Bound<'_, PyAny>, runs: usize) -> PyResult<Vec<f64>> {
        let (s, w, h) = Samples::of(image, None)?;
        let f = s.frame();
        py.detach(|| {
            (0..runs)
                .map(|_| {
                    let t = std::time::Instant::now();
                    let out = self.inner.capture(f, w, h, BitDepth::Eight);
                    let dt = t.elapsed().as_secs_f64();
                    out.map(|_| dt)
                })
                .collect::<anyhow::Result<Vec<f64>>>()
        })
        .map_err(error)
    }

    /// The enhancer behind the face guard on a captured uint8 H x W x 3 array.
    #[pyo3(signature = (captured, models = None))]
    fn enhance<'py>(
        &self,
        py: Python<'py>,
        captured: &Bound<'py, PyAny>,
        models: Option<PathBuf>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (s, w, h) = Samples::of(captured, None)?;
        let Frame::Eight(v) = s.frame() else {
            return Err(PyValueError::new_err("the enhancer takes the camera's 8-bit output: a uint8 array"));
        };
        let v = v.to_vec();
        let out = py.detach(|| self.inner.enhance(v, w, h, models.as_deref())).map_err(error)?;
        array(py, Pixels::Eight(out), w, h)
    }

    /// Photo files through the camera, as `simulate` writes them, in parallel (rayon, as
    /// `simulate` runs its photos), the GIL released: `jobs` are (input name, its bytes,
    /// output path). Never raises for a photo: one `(status, line)` each, status `"ok"`,
    /// `"ok-grey"` (grey, let through by `allow_grey`), `"skipped"` (unless `force`, an
    /// output whose record verifies), `"refused"` (grey) or `"error"`.
    #[pyo3(signature = (jobs, bit_depth = 8, quality = 92, metadata = "keep-safe", enhance = false, models = None, record = true, force = false))]
    #[allow(clippy::too_many_arguments)]
    fn protect_each(
        &self,
        py: Python<'_>,
        jobs: Vec<(PathBuf, Vec<u8>, PathBuf)>,
        bit_depth: u8,
        quality: i64,
        metadata: &str,
        enhance: bool,
        models: Option<PathBuf>,
        record: bool,
        force: bool,
    ) -> PyResult<Vec<(&'static str, Option<String>)>> {
        let job = api::Job {
            depth: depth(bit_depth)?,
            quality: quality_of(quality)?,
            metadata: policy(metadata)?,
            enhance,
            models,
            record,
            force,
        };
        Ok(py.detach(|| {
            jobs.par_iter()
                .map(|(input, data, output)| {
                    if !force && self.inner.verified(data, output) {
                        return ("skipped", None);
                    }
                    match self.inner.protect(input, data, output, &job) {
                        Ok(false) => ("ok", None),
                        Ok(true) => ("ok-grey", None),
                        Err(e) if api::is_grey_refusal(&e) => ("refused", Some(api::error_line(&e))),
                        Err(e) => ("error", Some(api::error_line(&e))),
                    }
                })
                .collect()
        }))
    }

    /// SHA-256 of the parameter file's bytes, as records name the preset.
    #[getter]
    fn preset_sha256(&self) -> String {
        self.inner.preset_sha256().to_string()
    }

    /// The Camera2 values as JSON text.
    #[pyo3(signature = (capture_result = None))]
    fn camera2_json(&self, capture_result: Option<&str>) -> PyResult<String> {
        self.inner.camera2(capture_result).map_err(error)
    }
}

/// Every bundled preset as a dict (name, pick, enhancer, rated_for_grey, description).
#[pyfunction]
fn presets(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    api::presets()
        .map_err(error)?
        .into_iter()
        .map(|p| {
            let d = PyDict::new(py);
            d.set_item("name", p.name)?;
            d.set_item("pick", p.pick)?;
            d.set_item("enhancer", p.enhancer)?;
            d.set_item("rated_for_grey", p.rated_for_grey)?;
            d.set_item("protective", p.protective)?;
            d.set_item("description", p.description)?;
            Ok(d)
        })
        .collect()
}

/// The photo at `path`, upright, as a new H x W x 3 uint8 or uint16 array.
#[pyfunction]
fn read(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyAny>> {
    let photo = py.detach(|| api::read(&path)).map_err(error)?;
    array(py, photo.pixels, photo.width, photo.height)
}

fn policy(metadata: &str) -> PyResult<api::Policy> {
    match metadata {
        "strip" => Ok(api::Policy::Strip),
        "keep-safe" => Ok(api::Policy::KeepSafe),
        "keep" => Ok(api::Policy::Keep),
        m => Err(PyValueError::new_err(format!("metadata must be 'strip', 'keep-safe' or 'keep', got {m:?}"))),
    }
}

fn quality_of(quality: i64) -> PyResult<u8> {
    u8::try_from(quality)
        .ok()
        .filter(|q| (1..=100).contains(q))
        .ok_or_else(|| PyValueError::new_err(format!("quality must be 1..=100, got {quality}")))
}

/// Where `simulate` writes the input `input` (relative to its folder): its format kept, or
/// `image_format` ("png", "jpeg", "tiff", "webp"); HEIC becomes JPEG, 16 bits PNG.
#[pyfunction]
#[pyo3(signature = (input, bit_depth = 8, image_format = None))]
fn output_name(input: PathBuf, bit_depth: u8, image_format: Option<&str>) -> PyResult<PathBuf> {
    let format = match image_format {
        None => None,
        Some("png") => Some(api::Format::Png),
        Some("jpeg" | "jpg") => Some(api::Format::Jpeg),
        Some("tiff" | "tif") => Some(api::Format::Tiff),
        Some("webp") => Some(api::Format::Webp),
        Some(f) => {
            return Err(PyValueError::new_err(format!("image_format must be png, jpeg, tiff or webp, got {f:?}")))
        }
    };
    Ok(api::output_name(&input, depth(bit_depth)?, format))
}

/// Writes `image` to `path` with what `simulate` keeps of `like`'s metadata.
#[pyfunction]
#[pyo3(signature = (path, image, like = None, metadata = "keep-safe", quality = 92, force = false))]
fn write(
    py: Python<'_>,
    path: PathBuf,
    image: &Bound<'_, PyAny>,
    like: Option<PathBuf>,
    metadata: &str,
    quality: i64,
    force: bool,
) -> PyResult<()> {
    let policy = policy(metadata)?;
    let quality = quality_of(quality)?;
    let (s, w, h) = Samples::of(image, None)?;
    let pixels = match s.frame() {
        Frame::Eight(v) => Pixels::Eight(v.to_vec()),
        Frame::Sixteen(v) => Pixels::Sixteen(v.to_vec()),
    };
    let o = api::Write { like: like.as_deref(), metadata: policy, quality, force };
    py.detach(|| api::write(&path, &pixels, w, h, &o)).map_err(error)
}

/// Runs the `campro` command on `argv` (the program's name first) and exits the process
/// with its status: the console script `campro`.
#[pyfunction]
fn main(argv: Vec<std::ffi::OsString>) -> PyResult<()> {
    if argv.is_empty() {
        return Err(PyTypeError::new_err("argv must hold the program's name first"));
    }
    campro_cli::main_with(argv)
}

#[pymodule]
fn _campro(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Error", m.py().get_type::<Error>())?;
    m.add_class::<Camera>()?;
    m.add_function(wrap_pyfunction!(presets, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(write, m)?)?;
    m.add_function(wrap_pyfunction!(output_name, m)?)?;
    m.add_function(wrap_pyfunction!(main, m)?)?;
    Ok(())
}
