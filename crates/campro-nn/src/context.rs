//! Where a training run computes: the device and the CPU threads, handed to every loop
//! instead of a hard-coded CPU. (The seed stays in each run's configuration, which
//! checkpoints and provenance record: one source for it.) The ops dispatch on the device their tensors live on
//! (fast custom ops on the CPU, candle's generic ops elsewhere), so a run on another
//! device needs no change to a loop: only a context made with that device.

use candle_core::Device;

/// A training run's device and threads.
#[derive(Debug, Clone)]
pub struct Context {
    /// Where tensors are made and computed.
    pub device: Device,
    /// CPU worker threads (rayon's pool, and the CPU kernels' parallel loops), at least 1.
    pub threads: usize,
}

impl Context {
    /// The CPU with every core (`RAYON_NUM_THREADS` if set).
    pub fn cpu() -> Self {
        Context { device: Device::Cpu, threads: rayon::current_num_threads() }
    }

    /// `threads` CPU threads (at least 1).
    pub fn with_threads(self, threads: usize) -> Self {
        Context { threads: threads.max(1), ..self }
    }

    /// Runs `f` in a rayon pool of [`Context::threads`] threads (the CPU ops' parallel
    /// loops), or in the current pool if a new one cannot be made.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        match rayon::ThreadPoolBuilder::new().num_threads(self.threads).build() {
            Ok(pool) => pool.install(f),
            Err(_) => f(),
        }
    }

    /// The same context on `device`.
    pub fn on(self, device: Device) -> Self {
        Context { device, ..self }
    }
}

/// The device a `--device` value names: `cpu`, `cuda` (GPU 0) or `cuda:N`. A GPU on a
/// build without CUDA, or none at that index, is an error naming why (the build command
/// is in docs/gpu.md).
pub fn device(name: &str) -> Result<Device, String> {
    let ordinal = match name {
        "cpu" => return Ok(Device::Cpu),
        "cuda" => 0,
        _ => match name.strip_prefix("cuda:").map(str::parse::<usize>) {
            Some(Ok(n)) if n < 64 => n,
            _ => return Err(format!("{}: not a device (cpu, cuda or cuda:N, N < 64)", name.escape_debug())),
        },
    };
    if !cfg!(feature = "cuda") {
        return Err(format!("{name}: this build has no CUDA (build with --features cuda: docs/gpu.md)"));
    }
    #[cfg(feature = "cuda")]
    driver_present().map_err(|e| format!("{name}: no CUDA driver ({e})"))?;
    Device::new_cuda(ordinal)
        .map_err(|e| format!("{name}: no CUDA device ({})", e.to_string().lines().next().unwrap_or("")))
}

/// Whether the CUDA driver library opens (cudarc loads it at run time and panics where it
/// cannot; a machine without a GPU has none).
#[cfg(feature = "cuda")]
fn driver_present() -> Result<(), String> {
    // SAFETY: opening the driver runs only its initialisers, which the CUDA runtime runs
    // anyway; the handle is dropped at once.
    unsafe { libloading::Library::new("libcuda.so.1") }.map(drop).map_err(|e| format!("libcuda.so.1: {e}"))
}

impl Default for Context {
    /// The CPU with every core.
    fn default() -> Self {
        Context::cpu()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_names() {
        assert!(matches!(device("cpu"), Ok(Device::Cpu)));
        for bad in ["gpu", "cuda:", "cuda:x", "cuda:64", "CPU", ""] {
            assert!(device(bad).unwrap_err().contains("not a device"), "{bad}");
        }
        // Without the feature a GPU is refused with the way to build one; with it, this
        // machine's answer (a GPU or why not) is what candle says.
        if !cfg!(feature = "cuda") {
            assert!(device("cuda:1").unwrap_err().contains("--features cuda"));
        }
    }
}
