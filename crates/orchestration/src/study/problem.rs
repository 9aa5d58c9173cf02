//! Study files: a SALib-style problem (named parameters with distributions) in Dakota-style blocks.
//!
//! ```toml
//! [study]                       # what and how many
//! name = "gains_sweep"
//! seed = 20261122
//! samples = 4096                # runs (Saltelli: base points N, runs N·(d+2))
//!
//! [method]                      # how the design is sampled
//! sampling = "sobol"            # monte_carlo | lhs | sobol | grid | saltelli | file
//! # levels = 5                  # grid: levels of each continuous variable
//! # file = "design.csv"         # file: one column per parameter path, one row per sample
//!
//! [model.servovalve]            # fixed model overrides, as in `study sim`
//! law = "orifice"
//!
//! [[variables]]                 # any parameter of `study params`, addressed by path
//! name = "controller.g_d"
//! distribution = "uniform"      # fixed | uniform | log_uniform | normal | log_normal | triangular | list
//! low = 1.0
//! high = 2.0
//!
//! [[excitations]]               # every sample runs every excitation
//! name = "3hz_1p73g"
//! kind = "sine"
//! freq_hz = 3.0
//! amp_g = 1.73                  # kinds: sine | record | stochastic | sweep | random (spec)
//!
//! [spectrum]                    # the response spectrum of the non-sine excitations' metrics
//! damping = 0.05                # default 0.05; periods 0.05–4 s, 20 log-spaced; band: all
//!
//! [responses]
//! metrics = ["amp_ratio", "thd_odd_ratio"]    # default: all
//!
//! [output]
//! file = "gains_sweep.parquet"  # default <name>.parquet; `study run --out` overrides
//! histories = [0]               # sample ids whose full time history is also written
//!
//! [solver]
//! substeps = 4                  # RK4 steps per controller tick (default 4)
//! chunk = 64                    # samples per parallel work item (results do not depend on it)
//! ```
//!
//! Distribution keys: `fixed`: value; `uniform`, `log_uniform`: low, high; `normal`: mean, std,
//! optional low/high (truncation); `log_normal`: mu, sigma (of ln x); `triangular`: low, mode,
//! high; `list`: values.

use crate::runs::spec::{self, ExcitationSpec};
use crate::study::sampling::{Design, Distribution, SOBOL_MAX_DIMS, SOBOL_MAX_POINTS};
use crate::toml_fields::{Fields, InputError, Issues};
use std::path::PathBuf;
use vshake_kernel::effects::{building, EffectId};
use vshake_kernel::metrics::Metrics;
use vshake_kernel::params::{Component, ModelParams, ParamInfo};
use vshake_kernel::simulate::Solver;
use vshake_kernel::spectrum::SpectrumSpec;

/// A varied (or fixed) parameter.
#[derive(Debug, Clone)]
pub struct Variable {
    pub info: &'static ParamInfo,
    pub dist: Distribution,
}

impl Variable {
    pub fn path(&self) -> String {
        self.info.path()
    }
}

/// One excitation of a study.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedExcitation {
    pub name: String,
    pub spec: ExcitationSpec,
}

/// Sampling method as written.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    MonteCarlo,
    Lhs,
    Sobol,
    Grid {
        levels: usize,
    },
    Saltelli,
    /// A design read from a file: one column per parameter path (or column name).
    File {
        path: PathBuf,
    },
}

impl Method {
    pub fn name(&self) -> &'static str {
        match self {
            Method::MonteCarlo => "monte_carlo",
            Method::Lhs => "lhs",
            Method::Sobol => "sobol",
            Method::Grid { .. } => "grid",
            Method::Saltelli => "saltelli",
            Method::File { .. } => "file",
        }
    }
}

/// A parsed, validated study.
#[derive(Debug, Clone)]
pub struct StudySpec {
    pub name: String,
    pub description: String,
    pub seed: u64,
    /// Samples as written (Saltelli: base points).
    pub samples: usize,
    pub method: Method,
    pub model: ModelParams,
    pub variables: Vec<Variable>,
    pub excitations: Vec<NamedExcitation>,
    /// Metric column names to write.
    pub metrics: Vec<&'static str>,
    /// The response spectrum of the earthquake-type excitations' metrics (`[spectrum]`).
    pub spectrum: SpectrumSpec,
    pub output: PathBuf,
    pub histories: Vec<u64>,
    pub solver: Solver,
    pub chunk: usize,
    /// What the study file leaves out that a user should know (e.g. harmonics omitted at or
    /// above the Nyquist frequency); printed by `study run`.
    pub notes: Vec<String>,
}

/// Every metric column name, in table order.
pub(crate) fn all_metric_names() -> Vec<&'static str> {
    Metrics::NAN.columns().into_iter().map(|(n, _)| n).collect()
}

/// Why a parameter cannot differ between the samples of a study (None: it can). The one such
/// parameter is the controller rate, which every lane of a batch shares (the reference is sampled
/// at it). Used for `[[variables]]` and for the columns of a design file.
pub fn cannot_vary(info: &ParamInfo) -> Option<&'static str> {
    (info.path() == "controller.f_s").then_some("controller.f_s cannot be varied: every lane of a batch shares the controller rate; set it under [model.controller]")
}

/// Largest memory a design may hold before its first sample (a Latin hypercube's permutations).
pub const DESIGN_MAX_BYTES: usize = 1 << 30;

/// The limits of each design's size: Sobol' points, Saltelli base points, and the memory of a
/// Latin hypercube's permutations (one u32 per sample and varied dimension, all made before the
/// first sample runs); Monte Carlo and grid points are made one at a time.
fn design_size(method: &Method, samples: usize, varied: usize) -> Result<(), String> {
    match method {
        Method::Sobol if samples > SOBOL_MAX_POINTS => Err(format!("{samples}: the Sobol' sequence has at most {SOBOL_MAX_POINTS} points; use lhs or monte_carlo for more")),
        Method::Saltelli if samples > SOBOL_MAX_POINTS => Err(format!("{samples}: a Saltelli design takes at most {SOBOL_MAX_POINTS} base points")),
        Method::Lhs if samples > u32::MAX as usize || samples.saturating_mul(varied).saturating_mul(4) > DESIGN_MAX_BYTES => Err(format!(
            "{samples}: a Latin hypercube of {samples} samples in {varied} dimensions keeps {varied} permutations of {samples} entries in memory ({:.1} GiB, at most {} GiB); use monte_carlo or sobol, or at most {} samples",
            samples as f64 * varied as f64 * 4.0 / (1u64 << 30) as f64,
            DESIGN_MAX_BYTES >> 30,
            DESIGN_MAX_BYTES / 4 / varied.max(1)
        )),
        _ => Ok(()),
    }
}

/// Whether `name` is a word safe in file names and in comma-separated metadata lists: letters,
/// digits, `_`, `-` and `.` (study and excitation names).
pub fn is_word(name: &str) -> bool {
    !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.')
}

/// `[study]`: name, description, seed, samples.
struct Header {
    name: Option<String>,
    description: String,
    seed: u64,
    samples: Option<usize>,
    /// Whether `samples` is written at all: a bad value is reported as bad, never as missing.
    samples_given: bool,
}

fn read_header(root: &mut Fields<'_>, issues: &mut Issues) -> Header {
    let mut h = Header {
        name: None,
        description: String::new(),
        seed: 0,
        samples: None,
        samples_given: false,
    };
    let Some(mut s) = root.table("study", issues) else {
        issues.push("study", "missing table ([study] name, seed, samples)");
        return h;
    };
    h.name = s.str("name", issues).map(str::to_string);
    h.description = s.str("description", issues).unwrap_or("").to_string();
    if let Some(v) = s.int("seed", issues) {
        if v < 0 {
            issues.push(s.path_of("seed"), "must not be negative");
        }
        h.seed = v as u64;
    }
    h.samples_given = s.has("samples");
    if let Some(n) = s.int("samples", issues) {
        if n < 1 {
            issues.push(s.path_of("samples"), format!("{n} must be at least 1"));
        } else {
            h.samples = Some(n as usize);
        }
    }
    match &h.name {
        None => issues.push(
            "study.name",
            "missing (names the study and its default output file)",
        ),
        Some(n) if !is_word(n) => issues.push(
            "study.name",
            format!("{n:?} must be a non-empty file-name-safe word (letters, digits, _ - .)"),
        ),
        Some(_) => {}
    }
    s.finish(&["name", "description", "seed", "samples"], issues);
    h
}

/// `[method]`: the sampling method (Monte Carlo when absent).
fn read_method(root: &mut Fields<'_>, issues: &mut Issues) -> Method {
    let Some(mut m) = root.table("method", issues) else {
        return Method::MonteCarlo;
    };
    let sampling = m.str("sampling", issues).unwrap_or("monte_carlo");
    let levels = m.int("levels", issues);
    let mfile = m.str("file", issues);
    let method = match sampling {
        "monte_carlo" => Method::MonteCarlo,
        "lhs" => Method::Lhs,
        "sobol" => Method::Sobol,
        "saltelli" => Method::Saltelli,
        "grid" => {
            let l = levels.unwrap_or(5);
            if !(1..=1000).contains(&l) {
                issues.push(m.path_of("levels"), format!("{l} must be in 1..=1000"));
            }
            Method::Grid {
                levels: l.clamp(1, 1000) as usize,
            }
        }
        "file" => match mfile {
            Some(p) => Method::File {
                path: PathBuf::from(p),
            },
            None => {
                issues.push(
                    m.path_of("file"),
                    "missing (the CSV or Parquet design file)",
                );
                Method::MonteCarlo
            }
        },
        other => {
            issues.push(m.path_of("sampling"), format!("unknown method {other:?}; expected monte_carlo, lhs, sobol, grid, saltelli or file"));
            Method::MonteCarlo
        }
    };
    m.finish(&["sampling", "levels", "file"], issues);
    method
}

/// `[[variables]]`: each one read and checked against the model (an effect's parameter needs the
/// effect on; a parameter is listed once).
fn read_variables(
    root: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
) -> Vec<Variable> {
    read_variables_at(root, "variables", model, issues)
}

/// The array of variable tables under `key` (`[[variables]]` of a study, `[[uncertain]]` of a
/// tuning): each a parameter that may vary, listed once, its effect switched on.
pub(crate) fn read_variables_at(
    root: &mut Fields<'_>,
    key: &str,
    model: &ModelParams,
    issues: &mut Issues,
) -> Vec<Variable> {
    let variables: Vec<Variable> = root
        .tables(key, issues)
        .unwrap_or_default()
        .into_iter()
        .filter_map(|v| read_variable(v, issues))
        .collect();
    for (i, v) in variables.iter().enumerate() {
        let comp = v.info.component;
        if comp.effect().is_some_and(|e| !model.effects.get(e)) {
            issues.push(
                format!("{key}[{i}].name"),
                format!("effect `{comp}` is not switched on: add a [model.{comp}] table"),
            );
        }
        if let Some(why) = not_whole(v) {
            issues.push(format!("{key}[{i}].distribution"), why);
        }
        if let Some(why) = unused_storey(v, &variables, model) {
            issues.push(format!("{key}[{i}].name"), why);
        }
        if variables[..i].iter().any(|w| std::ptr::eq(w.info, v.info)) {
            issues.push(
                format!("{key}[{i}].name"),
                format!("{} is listed twice", v.path()),
            );
        }
    }
    variables
}

/// The parameters that take whole numbers only (a count, a law's number).
const WHOLE_NUMBERS: [&str; 3] = ["building.storeys", "building.law", "servovalve.n_val"];

/// Why variable `v` would make runs that fail validation: a continuous distribution of a
/// parameter that takes whole numbers only, or a listed value that is not one.
fn not_whole(v: &Variable) -> Option<String> {
    let path = v.path();
    if !WHOLE_NUMBERS.contains(&path.as_str()) {
        return None;
    }
    match &v.dist {
        Distribution::Fixed { value } if value.fract() == 0.0 => None,
        Distribution::List { values } if values.iter().all(|x| x.fract() == 0.0) => None,
        Distribution::Fixed { .. } | Distribution::List { .. } => Some(format!(
            "{path} takes whole numbers only: every value must be one"
        )),
        _ => Some(format!(
            "{path} takes whole numbers only: use distribution = \"list\" with values = [...]"
        )),
    }
}

/// Why variable `v` changes nothing: a storey's parameter above the building's storeys, where
/// the number of storeys is not itself varied.
fn unused_storey(v: &Variable, all: &[Variable], model: &ModelParams) -> Option<String> {
    let building = Component::Effect(EffectId::Building);
    let storeys_vary = all
        .iter()
        .any(|w| w.info.component == building && w.info.name == "storeys");
    if v.info.component != building || storeys_vary || !model.effects.get(EffectId::Building) {
        return None;
    }
    building::unused(v.info.name, building::Params::of(model))
}

/// `[[excitations]]`: at least one, each with a distinct name that is a word ([`is_word`]).
fn read_excitations(
    root: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
) -> Vec<NamedExcitation> {
    read_excitations_with(root, model, issues, &[], |_, _| {})
}

/// `[[excitations]]` whose tables also hold the `extra` keys, each read by `take` (called with
/// every table, in order, before its excitation keys are read).
pub(crate) fn read_excitations_with(
    root: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
    extra: &[&str],
    mut take: impl FnMut(&mut Fields<'_>, &mut Issues),
) -> Vec<NamedExcitation> {
    let mut excitations: Vec<NamedExcitation> = Vec::new();
    match root.tables("excitations", issues) {
        Some(list) if list.is_empty() => issues.push(
            "excitations",
            "the excitation list is empty: every sample needs at least one excitation",
        ),
        Some(list) => {
            for (i, mut e) in list.into_iter().enumerate() {
                let ename = e
                    .str("name", issues)
                    .map(str::to_string)
                    .unwrap_or_else(|| format!("exc{i}"));
                let path = e.path_of("name");
                if !is_word(&ename) {
                    issues.push(path.clone(), format!("{ename:?} must be a non-empty word of letters, digits, _ - . (it names history files and is listed in the results' metadata)"));
                }
                take(&mut e, issues);
                // Read the excitation keys from the same table (name is consumed above).
                if let Some(x) = read_named_excitation(e, model, issues, extra) {
                    if excitations.iter().any(|n| n.name == ename) {
                        issues.push(path, format!("excitation name {ename:?} is used twice"));
                    }
                    excitations.push(NamedExcitation {
                        name: ename,
                        spec: x,
                    });
                }
            }
        }
        None => issues.push(
            "excitations",
            format!(
                "missing ([[excitations]] with kind = one of {})",
                spec::KINDS.join(", ")
            ),
        ),
    }
    excitations
}

/// A `ground.*` variable that a stochastic excitation also sets: the excitation's value would
/// win, so the variable would vary nothing there.
fn ground_overlap(variables: &[Variable], excitations: &[NamedExcitation], issues: &mut Issues) {
    for v in variables
        .iter()
        .filter(|v| v.info.component == vshake_kernel::params::Component::Ground && v.dist.varies())
    {
        for e in excitations {
            if let ExcitationSpec::Stochastic { ground, .. } = &e.spec {
                if ground.iter().any(|(n, _)| *n == v.info.name) {
                    issues.push(
                        format!("excitations.{}.{}", e.name, v.info.name),
                        format!(
                            "is fixed here, but the study varies {}: remove one",
                            v.info.path()
                        ),
                    );
                }
            }
        }
    }
}

/// Whether a study's runs may carry a building: on in its model, or one of its parameters varied.
pub(crate) fn carries_building(model: &ModelParams, variables: &[Variable]) -> bool {
    model.effects.building || variables.iter().any(|v| v.path().starts_with("building."))
}

/// `[responses] metrics`: the metrics written, and whether the list was written. When absent,
/// every metric, but the specimen's ([`Metrics::SPECIMEN`]) only where the study carries one
/// (`specimen`): a bare table's results have no building columns.
fn read_responses(
    root: &mut Fields<'_>,
    specimen: bool,
    issues: &mut Issues,
) -> (Vec<&'static str>, bool) {
    let all = all_metric_names();
    let Some(mut r) = root.table("responses", issues) else {
        let mut metrics = all;
        metrics.retain(|m| specimen || !Metrics::SPECIMEN.contains(m));
        return (metrics, false);
    };
    let listed = r.has("metrics");
    let mut metrics = all.clone();
    if let Some(list) = r.str_array("metrics", issues) {
        metrics = Vec::new();
        for (i, m) in list.iter().enumerate() {
            match all.iter().find(|a| *a == m) {
                Some(a) => metrics.push(*a),
                None => {
                    let hint = crate::toml_fields::suggest(m, &all)
                        .map(|s| format!(" (did you mean `{s}`?)"))
                        .unwrap_or_default();
                    issues.push(
                        format!("responses.metrics[{i}]"),
                        format!(
                            "unknown metric {m:?}{hint}; expected one of: {}",
                            all.join(", ")
                        ),
                    );
                }
            }
        }
        if list.is_empty() {
            issues.push("responses.metrics", "the metric list is empty");
        }
    }
    r.finish(&["metrics"], issues);
    (metrics, listed)
}

/// `[output]`: the results file and the samples whose full histories are written.
fn read_output(root: &mut Fields<'_>, issues: &mut Issues) -> (Option<PathBuf>, Vec<u64>) {
    let Some(mut o) = root.table("output", issues) else {
        return (None, Vec::new());
    };
    let output = o.str("file", issues).map(PathBuf::from);
    let mut histories = Vec::new();
    if let Some(h) = o.f64_array("histories", issues) {
        for (i, x) in h.iter().enumerate() {
            if *x < 0.0 || x.fract() != 0.0 {
                issues.push(
                    format!("output.histories[{i}]"),
                    format!("{x} is not a sample id"),
                );
            } else {
                histories.push(*x as u64);
            }
        }
        if histories.len() > 100 {
            issues.push(
                "output.histories",
                "at most 100 full histories may be requested",
            );
        }
    }
    o.finish(&["file", "histories"], issues);
    (output, histories)
}

/// `[solver]`: the solver and the samples per work item.
pub(crate) fn read_study_solver(root: &mut Fields<'_>, issues: &mut Issues) -> (Solver, usize) {
    let Some(mut s) = root.table("solver", issues) else {
        return (Solver::default(), 64);
    };
    let mut chunk = 64;
    if let Some(c) = s.int("chunk", issues) {
        if (1..=1 << 20).contains(&c) {
            chunk = c as usize;
        } else {
            issues.push(s.path_of("chunk"), format!("{c} must be in 1..=1048576"));
        }
    }
    // `substeps` is read by the shared solver reader; `chunk` was taken above.
    (spec::read_solver(s, issues, &["chunk"]), chunk)
}

/// The design as a whole: samples where the method needs them, its size, its dimensions.
fn check_design(method: &Method, header: &Header, variables: &[Variable], issues: &mut Issues) {
    let varied = variables.iter().filter(|v| v.dist.varies()).count();
    if matches!(
        method,
        Method::MonteCarlo | Method::Lhs | Method::Sobol | Method::Saltelli
    ) && header.samples.is_none()
        && !header.samples_given
    {
        issues.push(
            "study.samples",
            format!("missing (required by sampling = \"{}\")", method.name()),
        );
    }
    if let Some(n) = header.samples {
        if let Err(why) = design_size(method, n, varied) {
            issues.push("study.samples", why);
        }
    }
    if matches!(method, Method::Sobol | Method::Saltelli) && 2 * varied > SOBOL_MAX_DIMS {
        issues.push(
            "variables",
            format!(
                "at most {} varied parameters for Sobol' designs",
                SOBOL_MAX_DIMS / 2
            ),
        );
    }
    if matches!(method, Method::Saltelli) && varied == 0 {
        issues.push(
            "variables",
            "a Saltelli design needs at least one varied parameter",
        );
    }
    if let Method::Grid { levels } = method {
        let runs: f64 = variables
            .iter()
            .map(|v| v.dist.grid(*levels).len() as f64)
            .product();
        if runs > 1e8 {
            issues.push("method.levels", format!("the grid has {runs:.3e} points"));
        }
    }
    if matches!(method, Method::File { .. }) && !variables.is_empty() {
        issues.push("variables", "a design file names its own parameters (its columns); remove [[variables]] or choose another sampling");
    }
}

/// Harmonic metrics at or above the Nyquist frequency f_s/2 of some sine excitation: the
/// harmonic would be an alias of a lower frequency. Listed in `[responses] metrics`, it is refused
/// (an issue at its index); by default it is kept as a column of NaN for that excitation (and left
/// out of the THD sums), with a note.
fn aliased_harmonics(
    excitations: &[NamedExcitation],
    metrics: &[&str],
    listed: bool,
    f_s: f64,
    issues: &mut Issues,
) -> Vec<String> {
    let mut notes = Vec::new();
    for e in excitations {
        let ExcitationSpec::Sine { sine, .. } = &e.spec else {
            continue;
        };
        let top = Metrics::highest_harmonic(sine.freq_hz, f_s);
        let aliased: Vec<(usize, usize)> = metrics
            .iter()
            .enumerate()
            .filter_map(|(i, m)| {
                Some((
                    i,
                    m.strip_prefix('h')?
                        .strip_suffix("_ratio")?
                        .parse::<usize>()
                        .ok()?,
                ))
            })
            .filter(|&(_, k)| k > top)
            .collect();
        if aliased.is_empty() {
            continue;
        }
        let nyq = 0.5 * f_s;
        if listed {
            for (i, k) in aliased {
                issues.push(
                    format!("responses.metrics[{i}]"),
                    format!(
                        "h{k}_ratio: harmonic {k} of excitation `{}` ({} Hz) is at or above the Nyquist frequency {nyq} Hz of f_s = {f_s} Hz; remove it or lower freq_hz",
                        e.name,
                        k as f64 * sine.freq_hz
                    ),
                );
            }
        } else {
            let ks: Vec<String> = aliased.iter().map(|(_, k)| format!("h{k}")).collect();
            notes.push(format!(
                "excitation `{}` ({} Hz): {} at or above the Nyquist frequency {nyq} Hz are NaN and left out of thd_odd/thd_even",
                e.name,
                sine.freq_hz,
                ks.join(", ")
            ));
        }
    }
    notes
}

const DIST_KEYS: [&str; 12] = [
    "name",
    "distribution",
    "value",
    "low",
    "high",
    "mean",
    "std",
    "mu",
    "sigma",
    "mode",
    "values",
    "levels",
];

fn read_variable(mut f: Fields<'_>, issues: &mut Issues) -> Option<Variable> {
    let info = read_parameter(&mut f, issues);
    let d = read_distribution(&mut f, issues);
    if let (Some(info), Some(d)) = (info, &d) {
        check_support(&f, info, d, issues);
    }
    f.finish(&DIST_KEYS, issues);
    Some(Variable {
        info: info?,
        dist: d?,
    })
}

/// A variable's `name`: a registered parameter that may vary.
pub(crate) fn read_parameter(
    f: &mut Fields<'_>,
    issues: &mut Issues,
) -> Option<&'static ParamInfo> {
    let Some(n) = f.str("name", issues) else {
        issues.push(
            f.path_of("name"),
            "missing (a parameter path such as \"controller.g_d\")",
        );
        return None;
    };
    let Some(info) = ModelParams::lookup(n) else {
        let all: Vec<String> = ModelParams::registry().map(|p| p.path()).collect();
        let refs: Vec<&str> = all.iter().map(String::as_str).collect();
        let hint = crate::toml_fields::suggest(n, &refs)
            .map(|s| format!(" (did you mean `{s}`?)"))
            .unwrap_or_default();
        issues.push(
            f.path_of("name"),
            format!("unknown parameter `{n}`{hint}; `study params` lists them"),
        );
        return None;
    };
    if let Some(why) = cannot_vary(info) {
        issues.push(f.path_of("name"), why);
    }
    Some(info)
}

/// A variable's `distribution` and its keys.
fn read_distribution(f: &mut Fields<'_>, issues: &mut Issues) -> Option<Distribution> {
    let fail = |path: String, why: String, issues: &mut Issues| -> Option<Distribution> {
        issues.push(path, why);
        None
    };
    match f.str("distribution", issues) {
        Some("fixed") => f.f64("value", issues).map(|value| Distribution::Fixed { value }),
        Some(kind @ ("uniform" | "log_uniform")) => read_bounded(f, kind == "log_uniform", issues),
        Some("normal") => read_normal(f, issues),
        Some("log_normal") => match (f.f64("mu", issues), f.f64("sigma", issues)) {
            (Some(mu), Some(sigma)) if sigma > 0.0 => Some(Distribution::LogNormal { mu, sigma }),
            (Some(_), Some(sigma)) => fail(f.path_of("sigma"), format!("sigma = {sigma} must be positive"), issues),
            _ => fail(f.path_of("mu"), "mu and sigma (of ln x) are required".into(), issues),
        },
        Some("triangular") => match (f.f64("low", issues), f.f64("mode", issues), f.f64("high", issues)) {
            (Some(low), Some(mode), Some(high)) if low <= mode && mode <= high && low < high => Some(Distribution::Triangular { low, mode, high }),
            (Some(low), Some(mode), Some(high)) => fail(f.path_of("mode"), format!("need low <= mode <= high and low < high (got {low}, {mode}, {high})"), issues),
            _ => fail(f.path_of("low"), "low, mode and high are required".into(), issues),
        },
        Some("list") => match f.f64_array("values", issues) {
            Some(v) if !v.is_empty() => Some(Distribution::List { values: v }),
            Some(_) => fail(f.path_of("values"), "the list is empty".into(), issues),
            None => fail(f.path_of("values"), "missing (the list of values)".into(), issues),
        },
        Some(other) => fail(
            f.path_of("distribution"),
            format!("unknown distribution {other:?}; expected fixed, uniform, log_uniform, normal, log_normal, triangular or list"),
            issues,
        ),
        None => fail(f.path_of("distribution"), "missing".into(), issues),
    }
}

/// A uniform or log-uniform distribution: `low` < `high` (and `low` > 0 for a log-uniform one).
fn read_bounded(f: &mut Fields<'_>, log: bool, issues: &mut Issues) -> Option<Distribution> {
    let (Some(low), Some(high)) = (f.f64("low", issues), f.f64("high", issues)) else {
        issues.push(f.path_of("low"), "low and high are required");
        return None;
    };
    if low >= high {
        issues.push(
            f.path_of("low"),
            format!("low = {low} must be below high = {high}"),
        );
        None
    } else if log && low <= 0.0 {
        issues.push(
            f.path_of("low"),
            format!("low = {low} must be positive for a log-uniform distribution"),
        );
        None
    } else if log {
        Some(Distribution::LogUniform { low, high })
    } else {
        Some(Distribution::Uniform { low, high })
    }
}

/// A normal distribution, optionally truncated to [`low`, `high`].
fn read_normal(f: &mut Fields<'_>, issues: &mut Issues) -> Option<Distribution> {
    let (mean, std) = (f.f64("mean", issues), f.f64("std", issues));
    let (low, high) = (f.f64("low", issues), f.f64("high", issues));
    match (mean, std) {
        (Some(mean), Some(std)) if std > 0.0 => {
            if let (Some(l), Some(h)) = (low, high) {
                if l >= h {
                    issues.push(
                        f.path_of("low"),
                        format!("low = {l} must be below high = {h}"),
                    );
                }
            }
            Some(Distribution::Normal {
                mean,
                std,
                low,
                high,
            })
        }
        (Some(_), Some(std)) => {
            issues.push(f.path_of("std"), format!("std = {std} must be positive"));
            None
        }
        _ => {
            issues.push(f.path_of("mean"), "mean and std are required");
            None
        }
    }
}

/// Values outside the parameter's valid range are caught per sample, except where the whole
/// support is outside: a fixed value, a list entry, or both bounds.
fn check_support(f: &Fields<'_>, info: &ParamInfo, d: &Distribution, issues: &mut Issues) {
    let candidates: Vec<f64> = match d {
        Distribution::Fixed { value } => vec![*value],
        Distribution::List { values } => values.clone(),
        Distribution::Uniform { low, high }
        | Distribution::LogUniform { low, high }
        | Distribution::Triangular { low, high, .. } => {
            if !info.range.contains(*low) && !info.range.contains(*high) {
                vec![*low]
            } else {
                vec![]
            }
        }
        Distribution::Normal { .. } | Distribution::LogNormal { .. } => vec![],
    };
    if let Some(v) = candidates.into_iter().find(|v| !info.range.contains(*v)) {
        issues.push(
            f.path_of("name"),
            format!(
                "{} = {v} {} is outside its valid range {}",
                info.path(),
                info.unit,
                info.range
            ),
        );
    }
}

impl StudySpec {
    /// Parses a study file's text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<StudySpec, InputError> {
        Self::from_toml_on(text, file, ModelParams::default())
    }

    /// [`StudySpec::from_toml`] from the parameters `base` (a model file's, `--model`) instead of
    /// the defaults: the study's `[model.*]` tables change them further, its variables vary them.
    pub fn from_toml_on(
        text: &str,
        file: &str,
        base: ModelParams,
    ) -> Result<StudySpec, InputError> {
        let table = crate::toml_fields::parse(text, file)?;
        let mut issues = Issues::default();
        let mut root = Fields::new("", &table);
        let header = read_header(&mut root, &mut issues);
        let method = read_method(&mut root, &mut issues);
        let mut model = base;
        if let Some(m) = root.table("model", &mut issues) {
            spec::read_model(m, &mut model, &mut issues);
        }
        spec::validate_model(&model, "model", &mut issues);
        let variables = read_variables(&mut root, &model, &mut issues);
        let excitations = read_excitations(&mut root, &model, &mut issues);
        let specimen = carries_building(&model, &variables);
        let (metrics, metrics_listed) = read_responses(&mut root, specimen, &mut issues);
        let notes = aliased_harmonics(
            &excitations,
            &metrics,
            metrics_listed,
            model.controller.f_s,
            &mut issues,
        );
        let (output, histories) = read_output(&mut root, &mut issues);
        let (solver, chunk) = read_study_solver(&mut root, &mut issues);
        let spectrum = crate::runs::quake_spec::read_spectrum(&mut root, &mut issues);
        ground_overlap(&variables, &excitations, &mut issues);
        root.finish(
            &[
                "study",
                "method",
                "model",
                "variables",
                "excitations",
                "responses",
                "output",
                "solver",
                "spectrum",
            ],
            &mut issues,
        );
        check_design(&method, &header, &variables, &mut issues);
        issues.into_result(file)?;
        let name = header.name.expect("checked");
        Ok(StudySpec {
            output: output.unwrap_or_else(|| PathBuf::from(format!("{name}.parquet"))),
            name,
            description: header.description,
            seed: header.seed,
            samples: header.samples.unwrap_or(0),
            method,
            model,
            variables,
            excitations,
            metrics,
            spectrum,
            histories,
            solver,
            chunk,
            notes,
        })
    }

    /// Whether the design can be made with `samples` as it is now (after `--samples`).
    pub fn check_design_size(&self) -> Result<(), String> {
        design_size(&self.method, self.samples, self.varied().len())
    }

    /// The varied variables (the design's dimensions), in file order.
    pub fn varied(&self) -> Vec<&Variable> {
        self.variables.iter().filter(|v| v.dist.varies()).collect()
    }

    /// The design of this study (not for `Method::File`).
    pub fn design(&self) -> Design {
        match &self.method {
            Method::MonteCarlo => Design::MonteCarlo,
            Method::Lhs => Design::LatinHypercube,
            Method::Sobol => Design::Sobol,
            Method::Saltelli => Design::Saltelli { base: self.samples },
            Method::Grid { levels } => Design::Grid {
                values: self.varied().iter().map(|v| v.dist.grid(*levels)).collect(),
            },
            Method::File { .. } => panic!("a file design is read, not generated"),
        }
    }

    /// The study after defaults, as TOML, for result metadata.
    pub fn resolved_toml(&self) -> String {
        let mut root = toml::Table::new();
        let mut s = toml::Table::new();
        s.insert("name".into(), self.name.clone().into());
        s.insert("description".into(), self.description.clone().into());
        s.insert("seed".into(), (self.seed as i64).into());
        s.insert("samples".into(), (self.samples as i64).into());
        root.insert("study".into(), s.into());
        root.insert("method".into(), self.method_table().into());
        root.insert("model".into(), spec::model_table(&self.model).into());
        root.insert(
            "variables".into(),
            toml::Value::Array(
                self.variables
                    .iter()
                    .map(|v| variable_table(v).into())
                    .collect(),
            ),
        );
        let exc: Vec<toml::Value> = self
            .excitations
            .iter()
            .map(|e| {
                let sim = spec::SimSpec {
                    model: self.model.clone(),
                    excitation: e.spec.clone(),
                    solver: self.solver,
                    spectrum: self.spectrum.clone(),
                };
                let full: toml::Table = sim.resolved_toml().parse().expect("own TOML");
                let mut t = full["excitation"].as_table().cloned().unwrap_or_default();
                t.insert("name".into(), e.name.clone().into());
                toml::Value::Table(t)
            })
            .collect();
        root.insert("excitations".into(), toml::Value::Array(exc));
        let mut r = toml::Table::new();
        r.insert(
            "metrics".into(),
            toml::Value::Array(self.metrics.iter().map(|m| (*m).into()).collect()),
        );
        root.insert("responses".into(), r.into());
        let mut o = toml::Table::new();
        o.insert("file".into(), self.output.display().to_string().into());
        o.insert(
            "histories".into(),
            toml::Value::Array(self.histories.iter().map(|h| (*h as i64).into()).collect()),
        );
        root.insert("output".into(), o.into());
        let mut sv = toml::Table::new();
        sv.insert("substeps".into(), (self.solver.substeps as i64).into());
        sv.insert("chunk".into(), (self.chunk as i64).into());
        root.insert("solver".into(), sv.into());
        let sp = &self.spectrum;
        let mut t = toml::Table::new();
        t.insert("damping".into(), sp.damping.into());
        t.insert(
            "periods_s".into(),
            toml::Value::Array(sp.periods.iter().map(|p| (*p).into()).collect()),
        );
        t.insert(
            "band_s".into(),
            toml::Value::Array(vec![sp.band.0.into(), sp.band.1.into()]),
        );
        root.insert("spectrum".into(), t.into());
        toml::to_string(&root).expect("TOML of plain values")
    }

    /// `[method]` as written.
    fn method_table(&self) -> toml::Table {
        let mut m = toml::Table::new();
        m.insert("sampling".into(), self.method.name().into());
        match &self.method {
            Method::Grid { levels } => {
                m.insert("levels".into(), (*levels as i64).into());
            }
            Method::File { path } => {
                m.insert("file".into(), path.display().to_string().into());
            }
            Method::MonteCarlo | Method::Lhs | Method::Sobol | Method::Saltelli => {}
        }
        m
    }
}

/// One `[[variables]]` entry as written: its name, distribution and the distribution's keys.
fn variable_table(v: &Variable) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("name".into(), v.path().into());
    let (kind, keys): (&str, Vec<(&str, f64)>) = match &v.dist {
        Distribution::Fixed { value } => ("fixed", vec![("value", *value)]),
        Distribution::Uniform { low, high } => ("uniform", vec![("low", *low), ("high", *high)]),
        Distribution::LogUniform { low, high } => {
            ("log_uniform", vec![("low", *low), ("high", *high)])
        }
        Distribution::Normal {
            mean,
            std,
            low,
            high,
        } => {
            let bounds = [("low", *low), ("high", *high)]
                .into_iter()
                .filter_map(|(k, x)| x.map(|x| (k, x)));
            (
                "normal",
                [("mean", *mean), ("std", *std)]
                    .into_iter()
                    .chain(bounds)
                    .collect(),
            )
        }
        Distribution::LogNormal { mu, sigma } => {
            ("log_normal", vec![("mu", *mu), ("sigma", *sigma)])
        }
        Distribution::Triangular { low, mode, high } => (
            "triangular",
            vec![("low", *low), ("mode", *mode), ("high", *high)],
        ),
        Distribution::List { values } => {
            t.insert(
                "values".into(),
                toml::Value::Array(values.iter().map(|x| (*x).into()).collect()),
            );
            ("list", vec![])
        }
    };
    for (k, x) in keys {
        t.insert(k.into(), x.into());
    }
    t.insert("distribution".into(), kind.into());
    t
}

fn read_named_excitation(
    f: Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
    extra: &[&str],
) -> Option<ExcitationSpec> {
    // The excitation reader reports unknown keys; `name` (and `extra`) were already consumed
    // from this table.
    let known: Vec<&str> = std::iter::once("name")
        .chain(extra.iter().copied())
        .collect();
    spec::read_excitation_with_extra(f, model, issues, &known)
}

#[cfg(test)]
mod tests {
    use super::*;

    const STUDY: &str = r#"
[study]
name = "t"
seed = 3
samples = 16
[method]
sampling = "lhs"
[[variables]]
name = "controller.g_d"
distribution = "uniform"
low = 1.0
high = 2.0
[[variables]]
name = "platen.mu_coef"
distribution = "fixed"
value = 0.006
[[excitations]]
name = "a"
kind = "sine"
freq_hz = 3.0
amp_g = 1.0
"#;

    #[test]
    fn parses_and_round_trips() {
        let s = StudySpec::from_toml(STUDY, "t.toml").unwrap();
        assert_eq!(s.varied().len(), 1);
        assert_eq!(s.output, PathBuf::from("t.parquet"));
        let again = StudySpec::from_toml(&s.resolved_toml(), "resolved").unwrap();
        assert_eq!(again.variables.len(), 2);
        assert_eq!(again.excitations, s.excitations);
        assert_eq!(again.metrics, s.metrics);
    }

    #[test]
    fn bad_studies_name_the_key_path() {
        let cases: [(&str, &str, &str); 4] = [
            (
                "name = \"controller.g_d\"",
                "name = \"controller.gd\"",
                "variables[0].name",
            ),
            (
                "low = 1.0\nhigh = 2.0",
                "low = 3.0\nhigh = 2.0",
                "variables[0].low",
            ),
            (
                "sampling = \"lhs\"",
                "sampling = \"latin\"",
                "method.sampling",
            ),
            (
                "distribution = \"uniform\"\nlow = 1.0\nhigh = 2.0",
                "distribution = \"normal\"\nmean = 1.0\nstd = -2.0",
                "variables[0].std",
            ),
        ];
        for (from, to, path) in cases {
            let text = STUDY.replacen(from, to, 1);
            assert_ne!(text, STUDY, "{from}");
            let e = StudySpec::from_toml(&text, "bad.toml").unwrap_err();
            assert!(e.issues.iter().any(|i| i.path == path), "{path} not in {e}");
        }
        // An empty excitation list (a top-level key, before any table header).
        let (head, _) = STUDY.split_once("[[excitations]]").unwrap();
        let text = format!("excitations = []\n{head}");
        let e = StudySpec::from_toml(&text, "bad.toml").unwrap_err();
        assert_eq!(e.issues.len(), 1, "{e}");
        assert_eq!(e.issues[0].path, "excitations");
        assert!(e.issues[0].message.contains("empty"), "{e}");
    }
}
