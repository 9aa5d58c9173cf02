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
//! amp_g = 1.73
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

use super::sampling::{Design, Distribution, SOBOL_MAX_DIMS, SOBOL_MAX_POINTS};
use super::spec::{self, ExcitationSpec};
use super::toml_fields::{Fields, InputError, Issues};
use crate::kernel::metrics::Metrics;
use crate::kernel::params::{ModelParams, ParamInfo};
use crate::kernel::simulate::Solver;
use std::path::PathBuf;

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
    Grid { levels: usize },
    Saltelli,
    /// A design read from a file: one column per parameter path (or column name).
    File { path: PathBuf },
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
    pub output: PathBuf,
    pub histories: Vec<u64>,
    pub solver: Solver,
    pub chunk: usize,
    /// What the study file leaves out that a user should know (e.g. harmonics omitted at or
    /// above the Nyquist frequency); printed by `study run`.
    pub notes: Vec<String>,
}

/// Every metric column name, in table order.
pub fn all_metric_names() -> Vec<&'static str> {
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

/// Harmonic metrics at or above the Nyquist frequency f_s/2 of some sine excitation: the
/// harmonic would be an alias of a lower frequency. Listed in `[responses] metrics`, it is refused
/// (an issue at its index); by default it is kept as a column of NaN for that excitation (and left
/// out of the THD sums), with a note.
fn aliased_harmonics(excitations: &[NamedExcitation], metrics: &[&str], listed: bool, f_s: f64, issues: &mut Issues) -> Vec<String> {
    let mut notes = Vec::new();
    for e in excitations {
        let ExcitationSpec::Sine { sine, .. } = &e.spec else { continue };
        let top = Metrics::highest_harmonic(sine.freq_hz, f_s);
        let aliased: Vec<(usize, usize)> = metrics
            .iter()
            .enumerate()
            .filter_map(|(i, m)| Some((i, m.strip_prefix('h')?.strip_suffix("_ratio")?.parse::<usize>().ok()?)))
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

const DIST_KEYS: [&str; 12] = ["name", "distribution", "value", "low", "high", "mean", "std", "mu", "sigma", "mode", "values", "levels"];

fn read_variable(mut f: Fields<'_>, issues: &mut Issues) -> Option<Variable> {
    let name = f.str("name", issues);
    let dist = f.str("distribution", issues);
    let info = match name {
        Some(n) => match ModelParams::lookup(n) {
            Some(i) => Some(i),
            None => {
                let all: Vec<String> = ModelParams::registry().map(|p| p.path()).collect();
                let refs: Vec<&str> = all.iter().map(String::as_str).collect();
                let hint = super::toml_fields::suggest(n, &refs).map(|s| format!(" (did you mean `{s}`?)")).unwrap_or_default();
                issues.push(f.path_of("name"), format!("unknown parameter `{n}`{hint}; `study params` lists them"));
                None
            }
        },
        None => {
            issues.push(f.path_of("name"), "missing (a parameter path such as \"controller.g_d\")");
            None
        }
    };
    if let Some(why) = info.and_then(cannot_vary) {
        issues.push(f.path_of("name"), why);
    }
    let mut num = |key: &str, issues: &mut Issues| f.f64(key, issues);
    let d = match dist {
        Some("fixed") => num("value", issues).map(|value| Distribution::Fixed { value }),
        Some("uniform") | Some("log_uniform") => {
            let (lo, hi) = (num("low", issues), num("high", issues));
            match (lo, hi) {
                (Some(low), Some(high)) => {
                    if low >= high {
                        issues.push(f.path_of("low"), format!("low = {low} must be below high = {high}"));
                        None
                    } else if dist == Some("log_uniform") && low <= 0.0 {
                        issues.push(f.path_of("low"), format!("low = {low} must be positive for a log-uniform distribution"));
                        None
                    } else if dist == Some("uniform") {
                        Some(Distribution::Uniform { low, high })
                    } else {
                        Some(Distribution::LogUniform { low, high })
                    }
                }
                _ => {
                    issues.push(f.path_of("low"), "low and high are required");
                    None
                }
            }
        }
        Some("normal") => {
            let (mean, std) = (num("mean", issues), num("std", issues));
            let (low, high) = (num("low", issues), num("high", issues));
            match (mean, std) {
                (Some(mean), Some(std)) if std > 0.0 => {
                    if let (Some(l), Some(h)) = (low, high) {
                        if l >= h {
                            issues.push(f.path_of("low"), format!("low = {l} must be below high = {h}"));
                        }
                    }
                    Some(Distribution::Normal { mean, std, low, high })
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
        Some("log_normal") => match (num("mu", issues), num("sigma", issues)) {
            (Some(mu), Some(sigma)) if sigma > 0.0 => Some(Distribution::LogNormal { mu, sigma }),
            (Some(_), Some(sigma)) => {
                issues.push(f.path_of("sigma"), format!("sigma = {sigma} must be positive"));
                None
            }
            _ => {
                issues.push(f.path_of("mu"), "mu and sigma (of ln x) are required");
                None
            }
        },
        Some("triangular") => match (num("low", issues), num("mode", issues), num("high", issues)) {
            (Some(low), Some(mode), Some(high)) if low <= mode && mode <= high && low < high => Some(Distribution::Triangular { low, mode, high }),
            (Some(low), Some(mode), Some(high)) => {
                issues.push(f.path_of("mode"), format!("need low <= mode <= high and low < high (got {low}, {mode}, {high})"));
                None
            }
            _ => {
                issues.push(f.path_of("low"), "low, mode and high are required");
                None
            }
        },
        Some("list") => match f.f64_array("values", issues) {
            Some(v) if !v.is_empty() => Some(Distribution::List { values: v }),
            Some(_) => {
                issues.push(f.path_of("values"), "the list is empty");
                None
            }
            None => {
                issues.push(f.path_of("values"), "missing (the list of values)");
                None
            }
        },
        Some(other) => {
            issues.push(
                f.path_of("distribution"),
                format!("unknown distribution {other:?}; expected fixed, uniform, log_uniform, normal, log_normal, triangular or list"),
            );
            None
        }
        None => {
            issues.push(f.path_of("distribution"), "missing");
            None
        }
    };
    // Values outside the parameter's valid range are caught per sample, except where the whole
    // support is outside: a fixed value, a list entry, or both bounds.
    if let (Some(info), Some(d)) = (info, &d) {
        let bad: Vec<f64> = match d {
            Distribution::Fixed { value } => vec![*value],
            Distribution::List { values } => values.clone(),
            Distribution::Uniform { low, high } | Distribution::LogUniform { low, high } | Distribution::Triangular { low, high, .. } => {
                if !info.range.contains(*low) && !info.range.contains(*high) { vec![*low] } else { vec![] }
            }
            _ => vec![],
        }
        .into_iter()
        .filter(|v| !info.range.contains(*v))
        .collect();
        if let Some(v) = bad.first() {
            issues.push(f.path_of("name"), format!("{} = {v} {} is outside its valid range {}", info.path(), info.unit, info.range));
        }
    }
    f.finish(&DIST_KEYS, issues);
    Some(Variable { info: info?, dist: d? })
}

impl StudySpec {
    /// Parses a study file's text; `file` names it in errors; `base` resolves relative paths.
    pub fn from_toml(text: &str, file: &str) -> Result<StudySpec, InputError> {
        let table = super::toml_fields::parse(text, file)?;
        let mut issues = Issues::default();
        let mut root = Fields::new("", &table);

        let (mut name, mut description, mut seed, mut samples) = (None, String::new(), 0u64, None);
        // Whether `samples` is written at all: a bad value is reported as bad, never as missing.
        let mut samples_given = false;
        match root.table("study", &mut issues) {
            Some(mut s) => {
                name = s.str("name", &mut issues).map(str::to_string);
                description = s.str("description", &mut issues).unwrap_or("").to_string();
                if let Some(v) = s.int("seed", &mut issues) {
                    if v < 0 {
                        issues.push(s.path_of("seed"), "must not be negative");
                    }
                    seed = v as u64;
                }
                samples_given = s.has("samples");
                if let Some(n) = s.int("samples", &mut issues) {
                    if n < 1 {
                        issues.push(s.path_of("samples"), format!("{n} must be at least 1"));
                    } else {
                        samples = Some(n as usize);
                    }
                }
                if name.is_none() {
                    issues.push("study.name", "missing (names the study and its default output file)");
                }
                s.finish(&["name", "description", "seed", "samples"], &mut issues);
            }
            None => issues.push("study", "missing table ([study] name, seed, samples)"),
        }
        if let Some(n) = &name {
            if n.is_empty() || !n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.') {
                issues.push("study.name", format!("{n:?} must be a non-empty file-name-safe word (letters, digits, _ - .)"));
            }
        }

        let mut method = Method::MonteCarlo;
        if let Some(mut m) = root.table("method", &mut issues) {
            let sampling = m.str("sampling", &mut issues).unwrap_or("monte_carlo");
            let levels = m.int("levels", &mut issues);
            let mfile = m.str("file", &mut issues);
            method = match sampling {
                "monte_carlo" => Method::MonteCarlo,
                "lhs" => Method::Lhs,
                "sobol" => Method::Sobol,
                "saltelli" => Method::Saltelli,
                "grid" => {
                    let l = levels.unwrap_or(5);
                    if !(1..=1000).contains(&l) {
                        issues.push(m.path_of("levels"), format!("{l} must be in 1..=1000"));
                    }
                    Method::Grid { levels: l.clamp(1, 1000) as usize }
                }
                "file" => match mfile {
                    Some(p) => Method::File { path: PathBuf::from(p) },
                    None => {
                        issues.push(m.path_of("file"), "missing (the CSV or Parquet design file)");
                        Method::MonteCarlo
                    }
                },
                other => {
                    issues.push(
                        m.path_of("sampling"),
                        format!("unknown method {other:?}; expected monte_carlo, lhs, sobol, grid, saltelli or file"),
                    );
                    Method::MonteCarlo
                }
            };
            m.finish(&["sampling", "levels", "file"], &mut issues);
        }

        let mut model = ModelParams::default();
        if let Some(m) = root.table("model", &mut issues) {
            spec::read_model(m, &mut model, &mut issues);
        }
        spec::validate_model(&model, "model", &mut issues);

        let mut variables = Vec::new();
        if let Some(list) = root.tables("variables", &mut issues) {
            for v in list {
                if let Some(v) = read_variable(v, &mut issues) {
                    variables.push(v);
                }
            }
        }
        for (i, v) in variables.iter().enumerate() {
            let comp = v.info.component;
            if model.effects.get(comp) == Some(false) {
                issues.push(format!("variables[{i}].name"), format!("effect `{comp}` is not switched on: add a [model.{comp}] table"));
            }
            if variables[..i].iter().any(|w| std::ptr::eq(w.info, v.info)) {
                issues.push(format!("variables[{i}].name"), format!("{} is listed twice", v.path()));
            }
        }

        let mut excitations = Vec::new();
        match root.tables("excitations", &mut issues) {
            Some(list) if list.is_empty() => issues.push("excitations", "the excitation list is empty: every sample needs at least one excitation"),
            Some(list) => {
                for (i, mut e) in list.into_iter().enumerate() {
                    let ename = e.str("name", &mut issues).map(str::to_string).unwrap_or_else(|| format!("exc{i}"));
                    let path = e.path_of("");
                    // Read the excitation keys from the same table (name is consumed above).
                    if let Some(x) = read_named_excitation(e, &model, &mut issues) {
                        if excitations.iter().any(|n: &NamedExcitation| n.name == ename) {
                            issues.push(format!("{}name", path), format!("excitation name {ename:?} is used twice"));
                        }
                        excitations.push(NamedExcitation { name: ename, spec: x });
                    }
                }
            }
            None => issues.push("excitations", "missing ([[excitations]] with kind = \"sine\" or \"record\")"),
        }

        let mut metrics = all_metric_names();
        let mut metrics_listed = false;
        if let Some(mut r) = root.table("responses", &mut issues) {
            metrics_listed = r.has("metrics");
            if let Some(list) = r.str_array("metrics", &mut issues) {
                let all = all_metric_names();
                let mut chosen = Vec::new();
                for (i, m) in list.iter().enumerate() {
                    match all.iter().find(|a| *a == m) {
                        Some(a) => chosen.push(*a),
                        None => {
                            let hint = super::toml_fields::suggest(m, &all).map(|s| format!(" (did you mean `{s}`?)")).unwrap_or_default();
                            issues.push(format!("responses.metrics[{i}]"), format!("unknown metric {m:?}{hint}; expected one of: {}", all.join(", ")));
                        }
                    }
                }
                if list.is_empty() {
                    issues.push("responses.metrics", "the metric list is empty");
                }
                metrics = chosen;
            }
            r.finish(&["metrics"], &mut issues);
        }

        let notes = aliased_harmonics(&excitations, &metrics, metrics_listed, model.controller.f_s, &mut issues);

        let mut output = None;
        let mut histories = Vec::new();
        if let Some(mut o) = root.table("output", &mut issues) {
            output = o.str("file", &mut issues).map(PathBuf::from);
            if let Some(h) = o.f64_array("histories", &mut issues) {
                for (i, x) in h.iter().enumerate() {
                    if *x < 0.0 || x.fract() != 0.0 {
                        issues.push(format!("output.histories[{i}]"), format!("{x} is not a sample id"));
                    } else {
                        histories.push(*x as u64);
                    }
                }
                if histories.len() > 100 {
                    issues.push("output.histories", "at most 100 full histories may be requested");
                }
            }
            o.finish(&["file", "histories"], &mut issues);
        }

        let mut solver = Solver::default();
        let mut chunk = 64;
        if let Some(mut s) = root.table("solver", &mut issues) {
            if let Some(c) = s.int("chunk", &mut issues) {
                if (1..=1 << 20).contains(&c) {
                    chunk = c as usize;
                } else {
                    issues.push(s.path_of("chunk"), format!("{c} must be in 1..=1048576"));
                }
            }
            // `substeps` is read by the shared solver reader; `chunk` was taken above.
            solver = spec::read_solver(s, &mut issues, &["chunk"]);
        }
        root.finish(&["study", "method", "model", "variables", "excitations", "responses", "output", "solver"], &mut issues);

        let varied = variables.iter().filter(|v| v.dist.varies()).count();
        match &method {
            Method::MonteCarlo | Method::Lhs | Method::Sobol | Method::Saltelli if samples.is_none() && !samples_given => {
                issues.push("study.samples", format!("missing (required by sampling = \"{}\")", method.name()));
            }
            _ => {}
        }
        if let Some(n) = samples {
            if let Err(why) = design_size(&method, n, varied) {
                issues.push("study.samples", why);
            }
        }
        if matches!(method, Method::Sobol | Method::Saltelli) && 2 * varied > SOBOL_MAX_DIMS {
            issues.push("variables", format!("at most {} varied parameters for Sobol' designs", SOBOL_MAX_DIMS / 2));
        }
        if matches!(method, Method::Saltelli) && varied == 0 {
            issues.push("variables", "a Saltelli design needs at least one varied parameter");
        }
        if let Method::Grid { levels } = method {
            let runs: f64 = variables.iter().map(|v| v.dist.grid(levels).len() as f64).product();
            if runs > 1e8 {
                issues.push("method.levels", format!("the grid has {runs:.3e} points"));
            }
        }
        if matches!(method, Method::File { .. }) && !variables.is_empty() {
            issues.push("variables", "a design file names its own parameters (its columns); remove [[variables]] or choose another sampling");
        }

        issues.into_result(file)?;
        let name = name.expect("checked");
        Ok(StudySpec {
            output: output.unwrap_or_else(|| PathBuf::from(format!("{name}.parquet"))),
            name,
            description,
            seed,
            samples: samples.unwrap_or(0),
            method,
            model,
            variables,
            excitations,
            metrics,
            histories,
            solver,
            chunk,
            notes,
        })
    }

    /// The varied variables (the design's dimensions), in file order.
    /// Whether the design can be made with `samples` as it is now (after `--samples`).
    pub fn check_design_size(&self) -> Result<(), String> {
        design_size(&self.method, self.samples, self.varied().len())
    }

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
            Method::Grid { levels } => Design::Grid { values: self.varied().iter().map(|v| v.dist.grid(*levels)).collect() },
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
        let mut m = toml::Table::new();
        m.insert("sampling".into(), self.method.name().into());
        match &self.method {
            Method::Grid { levels } => {
                m.insert("levels".into(), (*levels as i64).into());
            }
            Method::File { path } => {
                m.insert("file".into(), path.display().to_string().into());
            }
            _ => {}
        }
        root.insert("method".into(), m.into());
        root.insert("model".into(), spec::model_table(&self.model).into());
        let vars: Vec<toml::Value> = self
            .variables
            .iter()
            .map(|v| {
                let mut t = toml::Table::new();
                t.insert("name".into(), v.path().into());
                let mut put = |k: &str, x: f64| {
                    t.insert(k.into(), x.into());
                };
                let kind = match &v.dist {
                    Distribution::Fixed { value } => {
                        put("value", *value);
                        "fixed"
                    }
                    Distribution::Uniform { low, high } => {
                        put("low", *low);
                        put("high", *high);
                        "uniform"
                    }
                    Distribution::LogUniform { low, high } => {
                        put("low", *low);
                        put("high", *high);
                        "log_uniform"
                    }
                    Distribution::Normal { mean, std, low, high } => {
                        put("mean", *mean);
                        put("std", *std);
                        if let Some(l) = low {
                            put("low", *l);
                        }
                        if let Some(h) = high {
                            put("high", *h);
                        }
                        "normal"
                    }
                    Distribution::LogNormal { mu, sigma } => {
                        put("mu", *mu);
                        put("sigma", *sigma);
                        "log_normal"
                    }
                    Distribution::Triangular { low, mode, high } => {
                        put("low", *low);
                        put("mode", *mode);
                        put("high", *high);
                        "triangular"
                    }
                    Distribution::List { values } => {
                        t.insert("values".into(), toml::Value::Array(values.iter().map(|x| (*x).into()).collect()));
                        "list"
                    }
                };
                t.insert("distribution".into(), kind.into());
                toml::Value::Table(t)
            })
            .collect();
        root.insert("variables".into(), toml::Value::Array(vars));
        let exc: Vec<toml::Value> = self
            .excitations
            .iter()
            .map(|e| {
                let sim = spec::SimSpec { model: self.model.clone(), excitation: e.spec.clone(), solver: self.solver };
                let full: toml::Table = sim.resolved_toml().parse().expect("own TOML");
                let mut t = full["excitation"].as_table().cloned().unwrap_or_default();
                t.insert("name".into(), e.name.clone().into());
                toml::Value::Table(t)
            })
            .collect();
        root.insert("excitations".into(), toml::Value::Array(exc));
        let mut r = toml::Table::new();
        r.insert("metrics".into(), toml::Value::Array(self.metrics.iter().map(|m| (*m).into()).collect()));
        root.insert("responses".into(), r.into());
        let mut o = toml::Table::new();
        o.insert("file".into(), self.output.display().to_string().into());
        o.insert("histories".into(), toml::Value::Array(self.histories.iter().map(|h| (*h as i64).into()).collect()));
        root.insert("output".into(), o.into());
        let mut sv = toml::Table::new();
        sv.insert("substeps".into(), (self.solver.substeps as i64).into());
        sv.insert("chunk".into(), (self.chunk as i64).into());
        root.insert("solver".into(), sv.into());
        toml::to_string(&root).expect("TOML of plain values")
    }
}

fn read_named_excitation(f: Fields<'_>, model: &ModelParams, issues: &mut Issues) -> Option<ExcitationSpec> {
    // The excitation reader reports unknown keys; `name` was already consumed from this table.
    spec::read_excitation_with_extra(f, model, issues, &["name"])
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
            ("name = \"controller.g_d\"", "name = \"controller.gd\"", "variables[0].name"),
            ("low = 1.0\nhigh = 2.0", "low = 3.0\nhigh = 2.0", "variables[0].low"),
            ("sampling = \"lhs\"", "sampling = \"latin\"", "method.sampling"),
            ("distribution = \"uniform\"\nlow = 1.0\nhigh = 2.0", "distribution = \"normal\"\nmean = 1.0\nstd = -2.0", "variables[0].std"),
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
