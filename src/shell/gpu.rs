//! Which engine runs the batch: the CPU kernel, or an NVIDIA GPU found at run time (`--backend
//! auto|cpu|cuda`). The CUDA driver and NVRTC are loaded dynamically by cudarc, so the build
//! needs no CUDA toolkit and runs everywhere; their presence is checked before any call (cudarc's
//! loader panics when a library is missing).
//!
//! The kernel is `crates/kernel/src/cuda/lane.cu` (CUDA C++), compiled at run time by NVRTC and
//! cached as PTX; [`Cuda`] runs a plan's lanes with it
//! ([`crate::orchestration::study::batch::LaneEngine`]).
//! `auto` uses it where a GPU is found and the work is covered, else runs on the CPU and says
//! why; `cuda` refuses (exit 2) with the cause, never silently running on the CPU.

use crate::kernel::excitation::Reference;
use crate::kernel::gpu_lanes::{self, Shared, Uniform, LANE_FIELDS};
use crate::kernel::params::ModelParams;
use crate::kernel::simulate::{LaneResult, SetupError, Solver};
use crate::orchestration::study::batch::LaneEngine;
use crate::shell::BadInput;
use cudarc::driver::{
    CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, LaunchConfig, PinnedHostSlice,
    PushKernelArg,
};
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The engine asked for on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Backend {
    /// A GPU when one is found and the work is covered, else the CPU (saying why).
    #[default]
    Auto,
    /// The CPU kernel on every worker thread.
    Cpu,
    /// An NVIDIA GPU (CUDA); refused, with the cause, where none can be used (also `gpu`).
    #[value(alias = "gpu")]
    Cuda,
}

/// What was found on this machine: a GPU's name and driver version, or why there is none.
pub fn probe() -> Result<String, String> {
    // SAFETY: these only try to open the shared libraries; they call nothing in them.
    if !unsafe { cudarc::driver::sys::is_culib_present() } {
        return Err("no NVIDIA driver (libcuda.so not found)".into());
    }
    use cudarc::driver::result;
    result::init().map_err(|e| match e.0 {
        cudarc::driver::sys::CUresult::CUDA_ERROR_NO_DEVICE => {
            "no GPU visible to the NVIDIA driver".to_string()
        }
        _ => format!("the NVIDIA driver did not start ({e})"),
    })?;
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
/// (`auto`), or the GPU; an error (exit 2) for `cuda` that cannot run.
pub fn choose(backend: Backend) -> anyhow::Result<Engine> {
    if backend == Backend::Cpu {
        return Ok(Engine::cpu(backend, None));
    }
    match probe().and_then(|name| Cuda::open(&name)) {
        Ok(cuda) => Ok(Engine {
            backend,
            why_cpu: None,
            cuda: Some(Arc::new(cuda)),
        }),
        Err(cause) if backend == Backend::Cuda => {
            Err(BadInput(format!("--backend cuda: {cause}")).into())
        }
        Err(cause) => Ok(Engine::cpu(backend, Some(cause))),
    }
}

/// The engine for a command the GPU never runs (`why`): the CPU, saying why under `auto`, without
/// opening the GPU; an error (exit 2) under `cuda`.
pub fn uncovered(backend: Backend, why: &str) -> anyhow::Result<Engine> {
    match backend {
        Backend::Cpu => Ok(Engine::cpu(backend, None)),
        Backend::Auto => Ok(Engine::cpu(
            backend,
            Some(format!("not supported on the GPU: {why}")),
        )),
        Backend::Cuda => {
            Err(BadInput(format!("--backend cuda: not supported on the GPU: {why}")).into())
        }
    }
}

/// The engine chosen: the CPU kernel (and why a GPU is not used), or the CUDA kernel.
#[derive(Clone)]
pub struct Engine {
    backend: Backend,
    pub why_cpu: Option<String>,
    cuda: Option<Arc<Cuda>>,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

impl Engine {
    fn cpu(backend: Backend, why_cpu: Option<String>) -> Engine {
        Engine {
            backend,
            why_cpu,
            cuda: None,
        }
    }

    /// `"CUDA on <GPU>"`, `"CPU"`, or `"CPU (no GPU used: <cause>)"` when `auto` looked for one.
    pub fn describe(&self) -> String {
        match (&self.cuda, &self.why_cpu) {
            (Some(c), _) => format!("CUDA on {} (float64, one thread per lane)", c.name),
            (None, Some(c)) => format!("CPU (no GPU used: {c})"),
            (None, None) => "CPU".into(),
        }
    }

    /// The engine for work the GPU cannot take (`why`): the CPU, saying why under `auto`; an
    /// error (exit 2) naming what is not covered under `cuda`.
    pub(crate) fn not_covering(self, why: &str) -> anyhow::Result<Engine> {
        if self.cuda.is_none() {
            return Ok(self);
        }
        if self.backend == Backend::Cuda {
            return Err(
                BadInput(format!("--backend cuda: not supported on the GPU: {why}")).into(),
            );
        }
        Ok(Engine::cpu(
            self.backend,
            Some(format!("not supported on the GPU: {why}")),
        ))
    }

    /// The lane engine for a plan (None: the CPU kernel), given the GPU's coverage `unsupported`.
    pub(crate) fn for_plan(
        self,
        unsupported: Option<String>,
    ) -> anyhow::Result<(Engine, Option<Arc<dyn LaneEngine>>)> {
        let engine = match unsupported {
            Some(why) => self.not_covering(&why)?,
            None => self,
        };
        let lanes = engine.cuda.clone().map(|c| c as Arc<dyn LaneEngine>);
        Ok((engine, lanes))
    }

    /// `cuda` or `cpu`: the engine as a results file's `vshake.backend` names it.
    pub fn tag(&self) -> &'static str {
        if self.cuda.is_some() {
            "cuda"
        } else {
            "cpu"
        }
    }

    /// The CUDA engine, when one runs.
    pub fn cuda(&self) -> Option<&Arc<Cuda>> {
        self.cuda.as_ref()
    }
}

/// Threads per block of the launch: few enough that float64 lanes with their whole state in
/// registers fit the register file of every CUDA GPU.
const BLOCK: u32 = 128;

/// What a build of the kernel is specialised for: the effects' bits
/// ([`gpu_lanes::effect_bits`]) and the parameter fields that vary between lanes
/// ([`Uniform::vary`]).
type BuildKey = (i64, [u64; gpu_lanes::MASK_WORDS]);

/// The CUDA kernel on GPU 0: one build per set of effects and of varying fields (lane.cu's
/// `VS_EFFECTS`, `VS_VARY0..3`), loaded when a launch first needs it.
pub struct Cuda {
    pub name: String,
    ctx: Arc<CudaContext>,
    stream: Arc<CudaStream>,
    /// The loaded builds: the module (its constant `vs_u`) and the entry point.
    builds: Mutex<HashMap<BuildKey, (Arc<CudaModule>, CudaFunction)>>,
    /// The output on the device, kept between launches (grown when one needs more); its lock
    /// lets one batch on the device at a time (worker threads share the GPU).
    device_out: Mutex<Option<CudaSlice<f64>>>,
    /// Page-locked host buffers the outputs come back to (faster than pageable memory, and no
    /// page faults), each taken by one launch until its lanes are finished.
    host_out: Mutex<Vec<PinnedHostSlice<f64>>>,
    /// Where the last run's time went ([`Timings`]).
    pub last: Mutex<Timings>,
}

/// Seconds of one run on the GPU, by stage.
#[derive(Debug, Clone, Copy, Default)]
pub struct Timings {
    /// The run's shared data (reference, drive, basis, oscillators) and the parameter records.
    pub setup: f64,
    /// The shared fields, the run and the records up to the device.
    pub upload: f64,
    pub kernel: f64,
    /// The sums back to the host.
    pub download: f64,
    /// The lanes' metrics from their sums, on every worker thread.
    pub finish: f64,
}

/// Outputs larger than this come back to pageable memory rather than a page-locked buffer kept
/// for the next launch (f64 values: 64 MiB).
const PINNED_MAX: usize = 1 << 23;

/// Most page-locked memory kept between launches, all buffers together (f64 values: 256 MiB).
const PINNED_KEPT_MAX: usize = 1 << 25;

impl Cuda {
    /// Opens GPU 0, named `name`, and loads the baseline's build (compiled, or from the cache),
    /// so that a kernel or driver that cannot work is found before any work.
    fn open(name: &str) -> Result<Cuda, String> {
        let ctx = CudaContext::new(0).map_err(|e| format!("{name}: no CUDA context ({e})"))?;
        let cuda = Cuda {
            name: name.into(),
            stream: ctx.default_stream(),
            ctx,
            builds: Mutex::new(HashMap::new()),
            device_out: Mutex::new(None),
            host_out: Mutex::new(Vec::new()),
            last: Mutex::new(Timings::default()),
        };
        cuda.build((0, [0; gpu_lanes::MASK_WORDS]))?;
        Ok(cuda)
    }

    /// The kernel built for `key`.
    fn build(&self, key: BuildKey) -> Result<(Arc<CudaModule>, CudaFunction), String> {
        let mut builds = self.builds.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(b) = builds.get(&key) {
            return Ok(b.clone());
        }
        let name = &self.name;
        let module = self
            .ctx
            .load_module(cudarc::nvrtc::Ptx::from_src(ptx(key)?))
            .map_err(|e| format!("{name}: the kernel did not load ({e})"))?;
        let func = module
            .load_function("vs_lanes")
            .map_err(|e| format!("{name}: the kernel did not load ({e})"))?;
        builds.insert(key, (module.clone(), func.clone()));
        Ok((module, func))
    }

    /// Runs the lanes on the device: the shared fields into the build's constant `vs_u`, the
    /// shared run and the parameters up, the kernel, the sums back into `host` (n lanes).
    fn launch(
        &self,
        shared: &Shared,
        packed: &Packed,
        n: usize,
        host: &mut Output,
        times: &mut Timings,
    ) -> anyhow::Result<()> {
        let uniform = &packed.uniform;
        let (module, func) = self
            .build((shared.ints[9], uniform.vary))
            .map_err(anyhow::Error::msg)?;
        let len = gpu_lanes::out_fields(shared.n_osc()) * n;
        let mut kept = self.device_out.lock().unwrap_or_else(|e| e.into_inner());
        let t0 = Instant::now();
        let s = &self.stream;
        if kept.as_ref().is_none_or(|o| o.len() < len) {
            *kept = None;
            // SAFETY: f64 has no invalid bit patterns, and the memset below zeroes the values the
            // kernel adds to before it runs.
            *kept = Some(unsafe { s.alloc::<f64>(len) }?);
        }
        let out = kept.as_mut().expect("made above");
        s.memset_zeros(&mut out.slice_mut(0..len))?;
        let bytes: Vec<u8> = uniform
            .values
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        s.memcpy_htod(&bytes, &mut module.get_global("vs_u", s)?)?;
        let [x, v, a, j] = [0, 1, 2, 3].map(|i| s.clone_htod(&shared.refs[i]));
        let (x, v, a, j) = (x?, v?, a?, j?);
        let (drive, basis, osc) = (
            s.clone_htod(&shared.drive)?,
            s.clone_htod(&shared.basis)?,
            s.clone_htod(&shared.osc)?,
        );
        let p = s.clone_htod(&packed.varying)?;
        let lanes = n as i64;
        let mut b = s.launch_builder(&func);
        for i in &shared.ints {
            b.arg(i);
        }
        b.arg(&shared.f_s);
        for d in [&x, &v, &a, &j, &drive, &basis, &osc, &p] {
            b.arg(d);
        }
        b.arg(&mut *out).arg(&lanes);
        let cfg = LaunchConfig {
            grid_dim: ((n as u32).div_ceil(BLOCK), 1, 1),
            block_dim: (BLOCK, 1, 1),
            shared_mem_bytes: 0,
        };
        s.synchronize()?;
        let t1 = Instant::now();
        // SAFETY: the arguments match `vs_lanes` in lane.cu (10 int64, a float64, 8 device
        // pointers of the sizes gpu_lanes.rs gives, the output of at least `len` values, the
        // lane count).
        unsafe { b.launch(cfg) }?;
        s.synchronize()?;
        let t2 = Instant::now();
        host.fill_from(s, &out.slice(0..len))?;
        (times.upload, times.kernel, times.download) = (
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            t2.elapsed().as_secs_f64(),
        );
        Ok(())
    }

    /// A host buffer for `len` output values: a kept page-locked one, a new one, or (past
    /// [`PINNED_MAX`]) pageable memory.
    fn output(&self, len: usize) -> anyhow::Result<Output> {
        if len > PINNED_MAX {
            return Ok(Output::Pageable(vec![0.0; len]));
        }
        let mut kept = self.host_out.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(i) = kept.iter().position(|h| h.len() >= len) {
            return Ok(Output::Pinned(kept.swap_remove(i)));
        }
        drop(kept);
        // SAFETY: the buffer is written by the download before it is read. Flags 0: cached
        // (cudarc's `alloc_pinned` makes write-combined memory, slow for the CPU to read).
        Ok(Output::Pinned(unsafe {
            self.ctx.alloc_pinned_with_flags::<f64>(len, 0)
        }?))
    }

    /// Keeps a page-locked buffer for the next launch (at most one per worker thread, and
    /// [`PINNED_KEPT_MAX`] values in all); a buffer not kept is freed.
    fn give_back(&self, out: Output) {
        if let Output::Pinned(h) = out {
            let mut kept = self.host_out.lock().unwrap_or_else(|e| e.into_inner());
            let total: usize = kept.iter().map(|k| k.len()).sum();
            if kept.len() < rayon::current_num_threads() && total + h.len() <= PINNED_KEPT_MAX {
                kept.push(h);
            }
        }
    }
}

/// Where a launch's output comes back to.
enum Output {
    Pinned(PinnedHostSlice<f64>),
    Pageable(Vec<f64>),
}

impl Output {
    /// Copies `src` from the device into the buffer's start, and waits for it.
    fn fill_from(
        &mut self,
        s: &Arc<CudaStream>,
        src: &cudarc::driver::CudaView<'_, f64>,
    ) -> anyhow::Result<()> {
        match self {
            Output::Pinned(h) => {
                s.memcpy_dtoh(src, h)?;
                h.as_slice()?;
            }
            Output::Pageable(v) => s.memcpy_dtoh(src, v)?,
        }
        Ok(())
    }

    /// The first `len` values (after [`Output::fill_from`]).
    fn values(&self, len: usize) -> anyhow::Result<&[f64]> {
        Ok(match self {
            Output::Pinned(h) => &h.as_slice()?[..len],
            Output::Pageable(v) => &v[..len],
        })
    }
}

/// Most bytes of per-lane references in one launch: lanes that each bring their own motion go in
/// launches of at most this much (a 15 s motion is 0.5 MB a lane).
const REFS_PER_LAUNCH: usize = 1 << 30;

impl LaneEngine for Cuda {
    fn run(
        &self,
        models: &[&ModelParams],
        refs: &[&Reference],
        solver: &Solver,
    ) -> anyhow::Result<Result<Vec<LaneResult>, SetupError>> {
        if refs.len() == 1 {
            return self.run_group(models, refs, solver);
        }
        let per_lane = 32 * refs[0].len().max(1);
        let lanes = (REFS_PER_LAUNCH / per_lane).max(1);
        let mut all = Vec::with_capacity(models.len());
        for (m, r) in models.chunks(lanes).zip(refs.chunks(lanes)) {
            match self.run_group(m, r, solver)? {
                Ok(done) => all.extend(done),
                Err(e) => return Ok(Err(e)),
            }
        }
        Ok(Ok(all))
    }
}

impl Cuda {
    /// One launch: `models` on `refs` (one, or one per model).
    fn run_group(
        &self,
        models: &[&ModelParams],
        refs: &[&Reference],
        solver: &Solver,
    ) -> anyhow::Result<Result<Vec<LaneResult>, SetupError>> {
        let t = Instant::now();
        // The shared run on one worker while the others pack the parameters.
        let (shared, packed) =
            match rayon::join(|| Shared::new(models, refs, solver), || pack(models)) {
                (Ok(shared), Ok(packed)) => (shared, packed),
                (Err(e), _) | (_, Err(e)) => return Ok(Err(e)),
            };
        let mut times = Timings {
            setup: t.elapsed().as_secs_f64(),
            ..Timings::default()
        };
        let n = models.len();
        let len = gpu_lanes::out_fields(shared.n_osc()) * n;
        let failed = |e: anyhow::Error| anyhow::anyhow!("the GPU ({}) failed: {e}", self.name);
        let mut host = self.output(len).map_err(failed)?;
        self.launch(&shared, &packed, n, &mut host, &mut times)
            .map_err(failed)?;
        let t = Instant::now();
        let out = host.values(len).map_err(failed)?;
        let lane_ref = |l: usize| refs[l.min(refs.len() - 1)];
        let finish = gpu_lanes::Finisher::new(refs[0], shared.n_osc());
        let done = (0..n)
            .into_par_iter()
            .map(|l| finish.lane(out, n, l, lane_ref(l)))
            .collect();
        self.give_back(host);
        times.finish = t.elapsed().as_secs_f64();
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = times;
        Ok(Ok(done))
    }
}

/// Lanes per piece of the parameter records made on one worker thread.
const PACK_PIECE: usize = 512;

/// A launch's parameters: the fields every lane shares, and the records of the others.
pub(crate) struct Packed {
    pub uniform: Uniform,
    /// The varying fields' records, field-major ([`Uniform::compact`]; one zero when none).
    pub varying: Vec<f64>,
}

/// The parameters of `models` ([`gpu_lanes::record`]s), made once each on the worker threads:
/// each piece of lanes keeps the records of the fields that differ from the first lane's within
/// it; the fields that differ anywhere are then placed row by row (a few fields of a study's
/// varied parameters instead of all 177).
pub(crate) fn pack(models: &[&ModelParams]) -> Result<Packed, SetupError> {
    let first = models[0];
    if let Some(lane) = models
        .iter()
        .position(|m| m.controller.f_s != first.controller.f_s || m.valve_law != first.valve_law)
    {
        return Err(SetupError::NotUniform { lane });
    }
    let head = gpu_lanes::record(first)?;
    let every = shared_fields_off();
    let pieces: Vec<Piece> = models
        .par_chunks(PACK_PIECE)
        .map(|lanes| Piece::new(lanes, &head, every))
        .collect::<Result<_, SetupError>>()?;
    let vary = pieces.iter().fold([0; gpu_lanes::MASK_WORDS], |a, p| {
        gpu_lanes::union(a, p.vary)
    });
    let uniform = Uniform {
        vary,
        values: head.to_vec(),
    };
    let fields = uniform.varying();
    let varying = place(&pieces, &fields, &head, models.len());
    Ok(Packed { uniform, varying })
}

/// The records of some lanes' fields that differ from the first lane's (all of them, `every`).
struct Piece {
    vary: [u64; gpu_lanes::MASK_WORDS],
    /// Those fields, in order, and their values: a row of the piece's lanes each.
    fields: Vec<usize>,
    rows: Vec<f64>,
}

impl Piece {
    fn new(
        lanes: &[&ModelParams],
        head: &[f64; LANE_FIELDS],
        every: bool,
    ) -> Result<Piece, SetupError> {
        let records = lanes
            .iter()
            .map(|m| gpu_lanes::record(m))
            .collect::<Result<Vec<_>, _>>()?;
        let vary = match every {
            true => [!0; gpu_lanes::MASK_WORDS],
            false => records.iter().fold([0; gpu_lanes::MASK_WORDS], |a, r| {
                gpu_lanes::union(a, Uniform::differing(head, r))
            }),
        };
        let fields = gpu_lanes::fields(vary);
        let rows = fields
            .iter()
            .flat_map(|&f| records.iter().map(move |r| r[f]))
            .collect();
        Ok(Piece { vary, fields, rows })
    }
}

/// The rows of `fields` for `n` lanes in pieces of [`PACK_PIECE`], field-major: a piece's own
/// row where the field differs within it, else the first lane's value (one zero when no field
/// varies).
fn place(pieces: &[Piece], fields: &[usize], head: &[f64; LANE_FIELDS], n: usize) -> Vec<f64> {
    if fields.is_empty() {
        return vec![0.0];
    }
    let mut varying = vec![0.0; fields.len() * n];
    varying.par_chunks_mut(n).zip(fields).for_each(|(out, &f)| {
        for (piece, out) in pieces.iter().zip(out.chunks_mut(PACK_PIECE)) {
            match piece.fields.iter().position(|&g| g == f) {
                Some(r) => out.copy_from_slice(&piece.rows[r * out.len()..][..out.len()]),
                None => out.fill(head[f]),
            }
        }
    });
    varying
}

/// Whether NVRTC contracts multiplies and adds into FMAs: yes (about 20 % fewer float64
/// instructions; the metrics then differ from the CPU kernel's by rounding, 4e-11 relative at
/// most on the gains and record sweeps), unless `VSHAKE_CUDA_FMAD=0`, which gives the CPU
/// kernel's numbers bit for bit.
fn fma_contraction() -> bool {
    std::env::var_os("VSHAKE_CUDA_FMAD").is_none_or(|v| v != "0")
}

/// `VSHAKE_CUDA_SHARED_FIELDS=0`: every parameter read from each lane's record, none from the
/// constant bank (for measuring what sharing them gains; results are the same).
fn shared_fields_off() -> bool {
    std::env::var_os("VSHAKE_CUDA_SHARED_FIELDS").is_some_and(|v| v == "0")
}

/// The NVRTC options of a build: the effects, the varying fields, and the resident blocks per
/// multiprocessor where `VSHAKE_CUDA_MIN_BLOCKS` sets them (for measuring; lane.cu's
/// `VS_MIN_BLOCKS` default otherwise).
fn build_options((bits, vary): BuildKey) -> Vec<String> {
    let mut options = vec![format!("-DVS_EFFECTS={bits}")];
    for (i, word) in vary.iter().enumerate() {
        options.push(format!("-DVS_VARY{i}={word:#x}ULL"));
    }
    if let Some(b) = std::env::var("VSHAKE_CUDA_MIN_BLOCKS")
        .ok()
        .and_then(|b| b.parse::<u32>().ok())
    {
        options.push(format!("-DVS_MIN_BLOCKS={b}"));
    }
    options
}

/// The kernel's PTX for a build: from the cache (`$XDG_CACHE_HOME/vshake` or `~/.cache/vshake`,
/// keyed by the source and the build's options), else compiled by NVRTC (about a second) and
/// cached.
pub(crate) fn ptx(key: BuildKey) -> Result<String, String> {
    let options = build_options(key);
    let key = fnv1a(&format!(
        "{}\n{} fmad={}",
        gpu_lanes::SOURCE,
        options.join(" "),
        fma_contraction()
    ));
    let path = cache_dir().map(|d| d.join(format!("lane-{key:016x}.ptx")));
    if let Some(text) = path.as_ref().and_then(|p| std::fs::read_to_string(p).ok()) {
        return Ok(text);
    }
    let text = compile_ptx(options)?;
    if let Some(p) = path {
        // A cache that cannot be written costs a compile next time, nothing else.
        let tmp = p.with_extension(format!("tmp{}", std::process::id()));
        let _ = std::fs::create_dir_all(p.parent().unwrap_or(&p))
            .and_then(|_| std::fs::write(&tmp, &text))
            .and_then(|_| std::fs::rename(&tmp, &p));
    }
    Ok(text)
}

/// Compiles the kernel with NVRTC with a build's `options` ([`build_options`]: a build carries
/// only the states of its effects, and reads only the varying fields from the lanes' records),
/// contracting into FMAs as [`fma_contraction`] says.
pub(crate) fn compile_ptx(options: Vec<String>) -> Result<String, String> {
    // SAFETY: only tries to open the shared library.
    if !unsafe { cudarc::nvrtc::sys::is_culib_present() } {
        return Err(
            "no NVRTC (libnvrtc.so not found: `pip install nvidia-cuda-nvrtc` and add its \
                    nvidia/cu13/lib folder to LD_LIBRARY_PATH)"
                .into(),
        );
    }
    let opts = cudarc::nvrtc::CompileOptions {
        fmad: Some(fma_contraction()),
        name: Some("lane.cu".into()),
        options,
        ..Default::default()
    };
    cudarc::nvrtc::compile_ptx_with_opts(gpu_lanes::SOURCE, opts)
        .map(|p| p.to_src())
        .map_err(|e| format!("NVRTC did not compile the kernel: {e}"))
}

fn cache_dir() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("vshake"))
}

/// FNV-1a, 64 bits: a hash that stays the same across builds (the cache key).
fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
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
    /// the same cause.
    #[test]
    fn auto_says_why_and_cuda_is_refused_with_the_cause() {
        let auto = choose(Backend::Auto).unwrap();
        if auto.cuda().is_some() {
            // A machine with a usable GPU: auto took it, and so does cuda.
            assert!(auto.why_cpu.is_none(), "{}", auto.describe());
            assert!(choose(Backend::Cuda).unwrap().cuda().is_some());
            return;
        }
        let why = auto.why_cpu.clone().unwrap();
        assert!(auto.describe().contains(&why));
        let err = choose(Backend::Cuda).unwrap_err();
        assert_eq!(super::super::exit_code(&err), 2);
        assert_eq!(err.to_string(), format!("--backend cuda: {why}"));
        assert_eq!(err.to_string().lines().count(), 1);
    }

    /// NVRTC compiles the kernel to PTX with its entry point, without effects and with all.
    /// Where the tests were built without a libnvrtc in sight (build.rs), the test is ignored
    /// with the reason; where one was (or `VSHAKE_REQUIRE_NVRTC` is set: CI installs the NVRTC
    /// wheel), an NVRTC that cannot be loaded fails it.
    #[test]
    #[cfg_attr(
        vshake_no_nvrtc,
        ignore = "no libnvrtc (LD_LIBRARY_PATH or the usual folders) when the tests were built"
    )]
    fn the_kernel_compiles_to_ptx() {
        // SAFETY: only tries to open the shared library.
        assert!(
            unsafe { cudarc::nvrtc::sys::is_culib_present() },
            "no libnvrtc can be loaded (LD_LIBRARY_PATH?)"
        );
        // The baseline's build and the one with every effect and both actuators.
        let all = gpu_lanes::EFFECT_BITS
            .iter()
            .fold(gpu_lanes::TWO_ACTUATORS, |b, (_, bit)| b | bit);
        for key in [
            (0, [0; gpu_lanes::MASK_WORDS]),
            (all, [!0; gpu_lanes::MASK_WORDS]),
        ] {
            let t = std::time::Instant::now();
            let ptx = compile_ptx(build_options(key)).unwrap_or_else(|e| panic!("{e}"));
            eprintln!(
                "NVRTC, effects {:#x}: {} bytes of PTX in {:.2} s",
                key.0,
                ptx.len(),
                t.elapsed().as_secs_f64()
            );
            assert!(
                ptx.contains(".entry vs_lanes"),
                "no vs_lanes entry in the PTX"
            );
            assert!(ptx.contains(".f64"), "the kernel is float64");
            if key.1 == [0; gpu_lanes::MASK_WORDS] {
                assert!(ptx.contains("vs_u["), "no constant for the shared fields");
            }
        }
    }

    /// Made in pieces on the worker threads, the shared fields and the varying records are
    /// those of the whole records packed in one go.
    #[test]
    fn packing_in_pieces_equals_packing_at_once() {
        let models: Vec<ModelParams> = (0..PACK_PIECE * 2 + 5)
            .map(|i| {
                let mut m = ModelParams::default();
                m.controller.g_d = 1.0 + i as f64 * 1e-4;
                m.platen.m = 1.4e5 + (i % 7) as f64;
                if i == 2 * PACK_PIECE + 3 {
                    // A field that differs in the last piece alone.
                    m.controller.l_a = 0.6;
                }
                m
            })
            .collect();
        let refs: Vec<&ModelParams> = models.iter().collect();
        let whole = gpu_lanes::pack_params(&refs).unwrap();
        let want = Uniform::of(&whole, refs.len());
        let got = pack(&refs).unwrap();
        assert_eq!(got.uniform, want);
        assert_eq!(got.varying, want.compact(&whole, refs.len()));
        assert_eq!(
            got.uniform.varying().len(),
            4,
            "c_fb, c_a, 1/m and the Coulomb force mu m g"
        );
        let same = pack(&refs[..1]).unwrap();
        assert_eq!(
            (same.uniform.vary, same.varying),
            ([0; gpu_lanes::MASK_WORDS], vec![0.0])
        );
    }

    #[test]
    fn the_cache_key_is_stable() {
        assert_eq!(fnv1a(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a("a"), 0xaf63_dc4c_8601_ec8c);
    }
}
