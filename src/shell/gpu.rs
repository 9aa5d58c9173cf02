//! Which engine runs the batch: the CPU kernel, or an NVIDIA GPU found at run time (`--backend
//! auto|cpu|cuda`). The CUDA driver and NVRTC are loaded dynamically by cudarc, so the build
//! needs no CUDA toolkit and runs everywhere; their presence is checked before any call (cudarc's
//! loader panics when a library is missing).
//!
//! This version finds the GPU and says what it found, but has no CUDA kernel yet: `auto` runs on
//! the CPU and says why, `cuda` is refused (exit 2) with the cause, never silently run on the CPU.

use super::BadInput;

/// The engine asked for on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Backend {
    /// A GPU when one is found and the work is covered, else the CPU (saying why).
    #[default]
    Auto,
    /// The CPU kernel on every worker thread.
    Cpu,
    /// An NVIDIA GPU (CUDA); refused, with the cause, where none can be used.
    Cuda,
}

/// What was found on this machine: a GPU's name and driver version, or why there is none.
pub fn probe() -> Result<String, String> {
    // SAFETY: these only try to open the shared libraries; they call nothing in them.
    if !unsafe { cudarc::driver::sys::is_culib_present() } {
        return Err("no NVIDIA driver (libcuda.so not found)".into());
    }
    use cudarc::driver::result;
    result::init().map_err(|e| format!("the NVIDIA driver did not start ({e})"))?;
    let count = result::device::get_count().map_err(|e| format!("no GPU visible ({e})"))?;
    if count < 1 {
        return Err("no GPU visible to the NVIDIA driver".into());
    }
    let dev = result::device::get(0).map_err(|e| format!("GPU 0 not usable ({e})"))?;
    let name = result::device::get_name(dev).unwrap_or_else(|_| "an NVIDIA GPU".into());
    if !unsafe { cudarc::nvrtc::sys::is_culib_present() } {
        return Err(format!(
            "{name} found, but no NVRTC (libnvrtc.so not found: install the CUDA runtime \
             compiler, e.g. `pip install nvidia-cuda-nvrtc`, and add its lib folder to \
             LD_LIBRARY_PATH)"
        ));
    }
    Ok(name)
}

/// The engine that runs: the CPU, with the reason where another was possible or asked for
/// (`auto`), or an error (exit 2) for `cuda` that cannot run.
pub fn choose(backend: Backend) -> anyhow::Result<Engine> {
    if backend == Backend::Cpu {
        return Ok(Engine { why_cpu: None });
    }
    let cause = match probe() {
        Ok(gpu) => format!("{gpu} found, but this version of vshake has no CUDA kernel yet"),
        Err(cause) => cause,
    };
    match backend {
        Backend::Cuda => Err(BadInput(format!("--backend cuda: {cause}")).into()),
        _ => Ok(Engine {
            why_cpu: Some(cause),
        }),
    }
}

/// The engine chosen (today always the CPU kernel) and why a GPU is not used, for the engine line.
#[derive(Debug, Clone)]
pub struct Engine {
    pub why_cpu: Option<String>,
}

impl Engine {
    /// `"CPU"`, or `"CPU (no GPU: <cause>)"` when `auto` looked for one.
    pub fn describe(&self) -> String {
        match &self.why_cpu {
            Some(c) => format!("CPU (no GPU used: {c})"),
            None => "CPU".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_is_always_chosen_without_looking() {
        let e = choose(Backend::Cpu).unwrap();
        assert_eq!(e.describe(), "CPU");
    }

    /// On a machine without a usable GPU (this one, CI): auto says why, cuda is bad input naming
    /// the same cause. On a GPU machine both say that the kernel is not in this version.
    #[test]
    fn auto_says_why_and_cuda_is_refused_with_the_cause() {
        let auto = choose(Backend::Auto).unwrap();
        let why = auto.why_cpu.clone().unwrap();
        assert!(auto.describe().contains(&why));
        let err = choose(Backend::Cuda).unwrap_err();
        assert_eq!(super::super::exit_code(&err), 2);
        assert_eq!(err.to_string(), format!("--backend cuda: {why}"));
        assert_eq!(err.to_string().lines().count(), 1);
    }
}
