//! The tuning file of `study tune` (TUNE.toml): the gains to choose with their bounds, the test
//! plan (weighted excitations, as in a study), the objective (weighted metrics), the constraints,
//! the uncertain parameters and the optimiser's settings. Every problem names its key path and is
//! reported before any work.
//!
//! ```toml
//! [tune]
//! name = "tune_firm"
//! seed = 1
//! generations = 40          # at most (CMA-ES; it stops earlier when the spread falls below tolerance)
//! # population = 8          # default 4 + floor(3 ln n) for n gains
//! # sigma0 = 0.3            # initial step, a fraction of each gain's range
//! # tolerance = 0.001       # stop when the search spread is below this fraction of the ranges
//!
//! [[gains]]                 # controller.* parameters; start = the model's value unless given
//! name = "controller.l_d"
//! low = -0.2
//! high = 0.5
//!
//! [objective]               # metric = weight, summed over the plan's excitations (each weighted)
//! spectral_err_mean = 1.0
//! rms_err_accel_ratio = 1.0
//!
//! [constraints]
//! valve_cmd_fraction = 0.9  # max |valve command| / servovalve.u_lim (default 0.9)
//!
//! [robust]                  # with [[uncertain]]: each candidate runs on `draws` LHS draws
//! draws = 16
//! statistic = "quantile"    # mean | quantile (of the objective over the draws)
//! quantile = 0.9
//!
//! [[uncertain]]             # as a study's [[variables]]
//! name = "platen.m"
//! distribution = "normal"
//! mean = 2.0e6
//! std = 1.0e5
//!
//! [[excitations]]           # as a study's, plus weight (default 1)
//! name = "firm_0p5g"
//! kind = "stochastic"
//! duration_s = 15
//! pga_g = 0.5
//! weight = 1.0
//! ```
//!
//! `[model.*]`, `[spectrum]`, `[solver]` are a study's; `[output] dir` is the folder of results
//! (default: the tuning's name).

use crate::runs::spec::{self, ExcitationSpec};
use crate::study::problem::{self, NamedExcitation, Variable};
use crate::toml_fields::{Fields, InputError, Issues};
use std::path::PathBuf;
use vshake_kernel::metrics::Metrics;
use vshake_kernel::params::{Component, ModelParams, ParamInfo};
use vshake_kernel::simulate::Solver;
use vshake_kernel::spectrum::SpectrumSpec;

/// One gain to choose, inside [low, high], starting from `start`.
#[derive(Debug, Clone)]
pub struct Gain {
    pub info: &'static ParamInfo,
    pub low: f64,
    pub high: f64,
    pub start: f64,
}

/// What a candidate's objective over the uncertain draws is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Statistic {
    Mean,
    /// The quantile q of the draws' objectives (linear between order statistics).
    Quantile(f64),
}

/// The optimiser's settings.
#[derive(Debug, Clone, Copy)]
pub struct Search {
    pub generations: usize,
    pub population: Option<usize>,
    pub sigma0: f64,
    pub tolerance: f64,
}

/// A parsed, validated tuning file.
#[derive(Debug, Clone)]
pub struct TuneSpec {
    pub name: String,
    pub description: String,
    pub seed: u64,
    pub model: ModelParams,
    pub gains: Vec<Gain>,
    pub excitations: Vec<NamedExcitation>,
    /// One weight per excitation.
    pub weights: Vec<f64>,
    /// (metric, weight), in file order.
    pub objective: Vec<(&'static str, f64)>,
    /// The largest allowed max |u| / u_lim.
    pub valve_cmd_fraction: f64,
    pub uncertain: Vec<Variable>,
    /// Uncertain draws per candidate (1 without `[[uncertain]]`).
    pub draws: usize,
    pub statistic: Statistic,
    pub search: Search,
    pub spectrum: SpectrumSpec,
    pub solver: Solver,
    pub output: PathBuf,
}

/// Metrics measured only on a sine (on a record they are NaN).
pub const SINE_ONLY: [&str; 14] = [
    "amp_ratio",
    "phase_err_deg",
    "h2_ratio",
    "h3_ratio",
    "h4_ratio",
    "h5_ratio",
    "h6_ratio",
    "h7_ratio",
    "h8_ratio",
    "h9_ratio",
    "thd_odd_ratio",
    "thd_even_ratio",
    "disp_amp_ratio",
    "disp_phase_err_deg",
];
/// Metrics measured only on a record (a sine has no response spectrum).
pub const RECORD_ONLY: [&str; 2] = ["spectral_err_mean", "spectral_err_max"];

/// Whether `metric` is measured on an excitation that is (or is not) a sine.
pub fn applies(metric: &str, sine: bool) -> bool {
    if sine {
        !RECORD_ONLY.contains(&metric)
    } else {
        !SINE_ONLY.contains(&metric)
    }
}

/// Whether `metric` is measured on `e` at the controller rate `f_s`: [`applies`], and for a sine
/// a harmonic (or the THD that sums them) below the Nyquist frequency.
pub fn measures(metric: &str, e: &ExcitationSpec, f_s: f64) -> bool {
    let ExcitationSpec::Sine { sine, .. } = e else {
        return applies(metric, false);
    };
    let top = Metrics::highest_harmonic(sine.freq_hz, f_s);
    let lowest = match metric {
        "thd_odd_ratio" => 3,
        "thd_even_ratio" => 2,
        m => m
            .strip_prefix('h')
            .and_then(|r| r.strip_suffix("_ratio"))
            .and_then(|k| k.parse().ok())
            .unwrap_or(1),
    };
    applies(metric, true) && lowest <= top
}

const ROOT_KEYS: [&str; 11] = [
    "tune",
    "gains",
    "objective",
    "constraints",
    "robust",
    "uncertain",
    "excitations",
    "model",
    "spectrum",
    "solver",
    "output",
];

impl TuneSpec {
    /// Parses a tuning file's text on the model `base` (a model file's, or the defaults); `file`
    /// names it in errors.
    pub fn from_toml_on(text: &str, file: &str, base: ModelParams) -> Result<TuneSpec, InputError> {
        let table = crate::toml_fields::parse(text, file)?;
        let mut issues = Issues::default();
        let mut root = Fields::new("", &table);
        let (name, description, seed, search) = read_header(&mut root, &mut issues);
        let mut model = base;
        if let Some(m) = root.table("model", &mut issues) {
            spec::read_model(m, &mut model, &mut issues);
        }
        spec::validate_model(&model, "model", &mut issues);
        let gains = read_gains(&mut root, &mut model, &mut issues);
        let mut weights = Vec::new();
        let excitations = problem::read_excitations_with(
            &mut root,
            &model,
            &mut issues,
            &["weight"],
            |f, issues| weights.push(read_weight(f, issues)),
        );
        let objective = read_objective(&mut root, &excitations, model.controller.f_s, &mut issues);
        let valve_cmd_fraction = read_constraints(&mut root, &mut issues);
        let uncertain = problem::read_variables_at(&mut root, "uncertain", &model, &mut issues);
        let (draws, statistic) = read_robust(&mut root, !uncertain.is_empty(), &mut issues);
        let spectrum = crate::runs::quake_spec::read_spectrum(&mut root, &mut issues);
        let (solver, _) = problem::read_study_solver(&mut root, &mut issues);
        let output = read_output(&mut root, &mut issues);
        check_overlap(&gains, &uncertain, &excitations, &mut issues);
        root.finish(&ROOT_KEYS, &mut issues);
        issues.into_result(file)?;
        let name = name.expect("checked");
        Ok(TuneSpec {
            output: output.unwrap_or_else(|| PathBuf::from(&name)),
            name,
            description,
            seed,
            model,
            gains,
            excitations,
            weights,
            objective,
            valve_cmd_fraction,
            uncertain,
            draws,
            statistic,
            search,
            spectrum,
            solver,
        })
    }

    /// The gains' starting values (the published ones unless the file sets `start`).
    pub fn start(&self) -> Vec<f64> {
        self.gains.iter().map(|g| g.start).collect()
    }
}

type Header = (Option<String>, String, u64, Search);

/// `[tune]`: name, description, seed and the optimiser's settings.
fn read_header(root: &mut Fields<'_>, issues: &mut Issues) -> Header {
    let mut search = Search {
        generations: 40,
        population: None,
        sigma0: 0.3,
        tolerance: 1e-3,
    };
    let Some(mut t) = root.table("tune", issues) else {
        issues.push("tune", "missing ([tune] with name = \"...\")");
        return (None, String::new(), 0, search);
    };
    let name = t.str("name", issues).map(str::to_string);
    match &name {
        None => issues.push(t.path_of("name"), "missing"),
        Some(n) if !problem::is_word(n) => issues.push(
            t.path_of("name"),
            format!("{n:?} must be a non-empty word of letters, digits, _ - ."),
        ),
        _ => {}
    }
    let description = t.str("description", issues).unwrap_or("").to_string();
    let seed = t.int("seed", issues).unwrap_or(0);
    if seed < 0 {
        issues.push(t.path_of("seed"), "must not be negative");
    }
    let seed = seed.max(0) as u64;
    if let Some(g) = positive_int(&mut t, "generations", 100_000, issues) {
        search.generations = g;
    }
    search.population = positive_int(&mut t, "population", 100_000, issues);
    if let Some(p) = search.population.filter(|p| *p < 4) {
        issues.push(
            t.path_of("population"),
            format!("{p} must be in 4..=100000"),
        );
    }
    if let Some(s) = t.f64("sigma0", issues) {
        if !(s > 0.0 && s <= 1.0) {
            issues.push(
                t.path_of("sigma0"),
                format!("{s} must be in (0, 1] (a fraction of each gain's range)"),
            );
        }
        search.sigma0 = s;
    }
    if let Some(s) = t.f64("tolerance", issues) {
        if !(s > 0.0 && s < 1.0) {
            issues.push(t.path_of("tolerance"), format!("{s} must be in (0, 1)"));
        }
        search.tolerance = s;
    }
    let keys = [
        "name",
        "description",
        "seed",
        "generations",
        "population",
        "sigma0",
        "tolerance",
    ];
    t.finish(&keys, issues);
    (name, description, seed, search)
}

/// An integer in 1..=max at `key`, if given.
fn positive_int(t: &mut Fields<'_>, key: &str, max: i64, issues: &mut Issues) -> Option<usize> {
    let v = t.int(key, issues)?;
    if (1..=max).contains(&v) {
        Some(v as usize)
    } else {
        issues.push(t.path_of(key), format!("{v} must be in 1..={max}"));
        None
    }
}

/// `[[gains]]`: at least one controller or compensator parameter (which switches the compensator
/// on in `model`), each once, with low < start ≤ high.
fn read_gains(root: &mut Fields<'_>, model: &mut ModelParams, issues: &mut Issues) -> Vec<Gain> {
    let Some(list) = root.tables("gains", issues) else {
        issues.push(
            "gains",
            "missing ([[gains]] with name, low, high: the controller parameters to choose)",
        );
        return Vec::new();
    };
    if list.is_empty() {
        issues.push("gains", "the list is empty: at least one gain to choose");
    }
    let mut gains: Vec<Gain> = Vec::new();
    for mut f in list {
        let info = problem::read_parameter(&mut f, issues);
        let (low, high) = (f.f64("low", issues), f.f64("high", issues));
        let start = f.f64("start", issues);
        for (k, v) in [("low", low), ("high", high)] {
            if v.is_none() {
                issues.push(f.path_of(k), "missing");
            }
        }
        let path = f.path_of("name");
        f.finish(&["name", "low", "high", "start"], issues);
        let (Some(info), Some(low), Some(high)) = (info, low, high) else {
            continue;
        };
        let compensator = info.component.effect().filter(|e| e.compensates());
        if info.component != Component::Controller && compensator.is_none() {
            issues.push(&path, format!("{} is not a controller parameter (the gains are controller.* or a compensator's, e.g. harmonic_cancellation.gain; an uncertain plant parameter goes under [[uncertain]])", info.path()));
            continue;
        }
        if let Some(e) = compensator {
            // A compensator's setting tuned: the compensator is on in every run of the tuning.
            *model.effects.get_mut(e) = true;
        }
        if gains.iter().any(|g| std::ptr::eq(g.info, info)) {
            issues.push(&path, format!("{} is listed twice", info.path()));
        }
        let start = start.unwrap_or(info.get(model));
        let here = path.trim_end_matches(".name");
        if !(low < high) {
            issues.push(
                format!("{here}.low"),
                format!("the bounds are inverted or empty: low {low} is not below high {high}"),
            );
        } else if !(low..=high).contains(&start) {
            issues.push(
                format!("{here}.start"),
                format!(
                    "the start {start} (the model's value unless given) is outside [{low}, {high}]"
                ),
            );
        }
        gains.push(Gain {
            info,
            low,
            high,
            start,
        });
    }
    gains
}

/// An excitation's `weight` (default 1): finite and positive.
fn read_weight(f: &mut Fields<'_>, issues: &mut Issues) -> f64 {
    let w = f.f64("weight", issues).unwrap_or(1.0);
    if !(w.is_finite() && w > 0.0) {
        issues.push(f.path_of("weight"), format!("{w} must be positive"));
    }
    w
}

/// `[objective]`: metric = weight, each a result metric that some excitation of the plan measures.
fn read_objective(
    root: &mut Fields<'_>,
    excitations: &[NamedExcitation],
    f_s: f64,
    issues: &mut Issues,
) -> Vec<(&'static str, f64)> {
    let Some(mut t) = root.table("objective", issues) else {
        issues.push(
            "objective",
            "missing ([objective] with metric = weight, e.g. spectral_err_mean = 1.0)",
        );
        return Vec::new();
    };
    let all = problem::all_metric_names();
    let keys: Vec<String> = t.keys().cloned().collect();
    let mut objective = Vec::new();
    for k in keys {
        let Some(&metric) = all.iter().find(|m| **m == k) else {
            continue; // reported as unknown by finish
        };
        let Some(w) = t.f64(&k, issues) else { continue };
        if Metrics::SPECIMEN.contains(&metric) {
            issues.push(
                t.path_of(&k),
                format!("{metric} is what the specimen experiences, not a tracking error: it is not tuned for (evaluations.parquet has it as a column)"),
            );
        }
        if !(w.is_finite() && w > 0.0) {
            issues.push(t.path_of(&k), format!("{w} must be a positive weight"));
        }
        if !excitations.is_empty() && !excitations.iter().any(|e| measures(metric, &e.spec, f_s)) {
            let why = if SINE_ONLY.contains(&metric) {
                "is measured only on a sine (and a harmonic only below the Nyquist frequency f_s/2)"
            } else {
                "is measured only on a motion that is not a sine (a record, stochastic, sweep, random)"
            };
            issues.push(
                t.path_of(&k),
                format!("{metric} {why}, and the plan has no excitation where it is"),
            );
        }
        objective.push((metric, w));
    }
    if objective.is_empty() && t.keys().next().is_none() {
        issues.push("objective", "empty: at least one metric = weight");
    }
    t.finish(&all, issues);
    objective
}

/// `[constraints]`: `valve_cmd_fraction` in (0, 1] (default 0.9).
fn read_constraints(root: &mut Fields<'_>, issues: &mut Issues) -> f64 {
    let Some(mut t) = root.table("constraints", issues) else {
        return 0.9;
    };
    let v = t.f64("valve_cmd_fraction", issues).unwrap_or(0.9);
    if !(v > 0.0 && v <= 1.0) {
        issues.push(
            t.path_of("valve_cmd_fraction"),
            format!("{v} must be in (0, 1] (max |valve command| over servovalve.u_lim)"),
        );
    }
    t.finish(&["valve_cmd_fraction"], issues);
    v
}

/// `[robust]`: draws (default 16 with `[[uncertain]]`, else 1) and the statistic (default the
/// mean; `quantile` defaults to 0.9).
fn read_robust(root: &mut Fields<'_>, uncertain: bool, issues: &mut Issues) -> (usize, Statistic) {
    let default_draws = if uncertain { 16 } else { 1 };
    let Some(mut t) = root.table("robust", issues) else {
        return (default_draws, Statistic::Mean);
    };
    let draws = positive_int(&mut t, "draws", 4096, issues).unwrap_or(default_draws);
    if draws > 1 && !uncertain {
        issues.push(
            t.path_of("draws"),
            "draws need [[uncertain]] parameters to draw",
        );
    }
    let q = t.f64("quantile", issues);
    if let Some(q) = q.filter(|q| !(*q > 0.0 && *q < 1.0)) {
        issues.push(t.path_of("quantile"), format!("{q} must be in (0, 1)"));
    }
    let statistic = match t.str("statistic", issues) {
        None | Some("mean") if q.is_none() => Statistic::Mean,
        None | Some("quantile") => Statistic::Quantile(q.unwrap_or(0.9)),
        Some("mean") => {
            issues.push(
                t.path_of("quantile"),
                "a quantile with statistic = \"mean\": say statistic = \"quantile\"",
            );
            Statistic::Mean
        }
        Some(s) => {
            issues.push(
                t.path_of("statistic"),
                format!("{s:?}: expected \"mean\" or \"quantile\""),
            );
            Statistic::Mean
        }
    };
    t.finish(&["draws", "statistic", "quantile"], issues);
    (draws, statistic)
}

/// `[output] dir`.
fn read_output(root: &mut Fields<'_>, issues: &mut Issues) -> Option<PathBuf> {
    let mut t = root.table("output", issues)?;
    let dir = t.str("dir", issues).map(PathBuf::from);
    t.finish(&["dir"], issues);
    dir
}

/// A parameter both tuned and uncertain, and motions made per sample, are refused: a candidate's
/// runs must differ from another's only by its gains.
fn check_overlap(
    gains: &[Gain],
    uncertain: &[Variable],
    excitations: &[NamedExcitation],
    issues: &mut Issues,
) {
    for (i, v) in uncertain.iter().enumerate() {
        if gains.iter().any(|g| std::ptr::eq(g.info, v.info)) {
            issues.push(
                format!("uncertain[{i}].name"),
                format!("{} is also a gain", v.path()),
            );
        }
    }
    let varied: Vec<String> = uncertain.iter().map(Variable::path).collect();
    for (i, e) in excitations.iter().enumerate() {
        if e.spec.per_sample(|p| varied.iter().any(|v| v == p)) {
            issues.push(format!("excitations[{i}]"), "a motion made per sample (realisation = \"per_sample\" or an uncertain ground.* parameter) would differ between candidates: list fixed realisations as excitations instead");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TUNE: &str = r#"
[tune]
name = "t"
seed = 2
[[gains]]
name = "controller.l_v"
low = 0.1
high = 1.0
[[gains]]
name = "controller.l_a"
low = 0.1
high = 1.0
[objective]
spectral_err_mean = 1.0
rms_err_accel_ratio = 0.5
[[excitations]]
name = "m"
kind = "stochastic"
duration_s = 5
weight = 2.0
"#;

    fn problems(text: &str) -> Vec<String> {
        match TuneSpec::from_toml_on(text, "t.toml", ModelParams::default()) {
            Ok(_) => Vec::new(),
            Err(e) => e.issues.iter().map(|i| i.to_string()).collect(),
        }
    }

    #[test]
    fn a_tuning_file_is_read_with_its_defaults() {
        let s = TuneSpec::from_toml_on(TUNE, "t.toml", ModelParams::default()).unwrap();
        assert_eq!(s.start(), vec![0.38, 0.52]);
        assert_eq!(s.weights, vec![2.0]);
        assert_eq!(
            s.objective,
            vec![("spectral_err_mean", 1.0), ("rms_err_accel_ratio", 0.5)]
        );
        assert_eq!((s.draws, s.statistic), (1, Statistic::Mean));
        assert_eq!(s.valve_cmd_fraction, 0.9);
        assert_eq!(s.output, PathBuf::from("t"));
        assert_eq!(s.search.generations, 40);
    }

    #[test]
    fn an_unknown_gain_is_refused_with_its_key_path() {
        let p = problems(&TUNE.replace("controller.l_a", "controller.l_q"));
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(
            p[0].starts_with("gains[1].name: unknown parameter `controller.l_q`"),
            "{p:?}"
        );
        let p = problems(&TUNE.replace("controller.l_a", "platen.m"));
        assert!(
            p[0].starts_with("gains[1].name: platen.m is not a controller parameter"),
            "{p:?}"
        );
    }

    #[test]
    fn a_compensators_setting_is_a_gain_and_switches_it_on() {
        use vshake_kernel::effects::EffectId;
        let text = TUNE.replace(
            "name = \"controller.l_a\"\nlow = 0.1\nhigh = 1.0",
            "name = \"harmonic_cancellation.gain\"\nlow = 0.5\nhigh = 8.0",
        );
        let s = TuneSpec::from_toml_on(&text, "t.toml", ModelParams::default())
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(s.model.effects.get(EffectId::HarmonicCancellation));
        assert!(!s.model.effects.get(EffectId::AmplitudePhase));
        assert_eq!(s.gains[1].info.path(), "harmonic_cancellation.gain");
        // A plant effect's parameter is not a gain.
        let p = problems(&TUNE.replace("controller.l_a", "leakage.c_int"));
        assert!(p[0].contains("is not a controller parameter"), "{p:?}");
    }

    #[test]
    fn inverted_bounds_and_a_start_outside_are_refused() {
        let p = problems(&TUNE.replacen("low = 0.1\nhigh = 1.0", "low = 1.0\nhigh = 0.1", 1));
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(
            p[0].starts_with("gains[0].low: the bounds are inverted"),
            "{p:?}"
        );
        let p = problems(&TUNE.replacen("high = 1.0", "high = 1.0\nstart = 3.0", 1));
        assert!(p[0].starts_with("gains[0].start: the start 3"), "{p:?}");
    }

    #[test]
    fn an_empty_plan_or_objective_is_refused() {
        let cut = TUNE.find("[[excitations]]").unwrap();
        let p = problems(&format!("excitations = []\n{}", &TUNE[..cut]));
        assert!(
            p.iter()
                .any(|m| m.starts_with("excitations: the excitation list is empty")),
            "{p:?}"
        );
        let p = problems(&TUNE[..cut]);
        assert!(
            p.iter().any(|m| m.starts_with("excitations: missing")),
            "{p:?}"
        );
        let p = problems(&TUNE.replace("spectral_err_mean = 1.0\nrms_err_accel_ratio = 0.5\n", ""));
        assert!(p.iter().any(|m| m.starts_with("objective: empty")), "{p:?}");
        let p = problems(&TUNE.replace(
            "[[gains]]\nname = \"controller.l_v\"",
            "[[nogains]]\nname = \"controller.l_v\"",
        ));
        assert!(
            p.iter().any(|m| m.starts_with("nogains: unknown key")),
            "{p:?}"
        );
    }

    #[test]
    fn a_metric_the_plan_does_not_measure_is_refused() {
        let p = problems(&TUNE.replace("spectral_err_mean = 1.0", "thd_odd_ratio = 1.0"));
        assert!(
            p[0].starts_with("objective.thd_odd_ratio: thd_odd_ratio is measured only on a sine"),
            "{p:?}"
        );
        let p = problems(&TUNE.replace("rms_err_accel_ratio", "rms_err_acel_ratio"));
        assert!(
            p[0].starts_with(
                "objective.rms_err_acel_ratio: unknown key (did you mean `rms_err_accel_ratio`?)"
            ),
            "{p:?}"
        );
    }

    #[test]
    fn a_harmonic_above_nyquist_is_not_measured() {
        let sine = "[[excitations]]\nname = \"s\"\nkind = \"sine\"\nfreq_hz = 60.0\namp_g = 0.1\n";
        let cut = TUNE.find("[[excitations]]").unwrap();
        let text =
            format!("{}{sine}", &TUNE[..cut]).replace("spectral_err_mean = 1.0", "h9_ratio = 1.0");
        let p = problems(&text);
        assert!(p[0].starts_with("objective.h9_ratio: h9_ratio is measured only on a sine (and a harmonic only below"), "{p:?}");
        // 60 Hz at 1024 Hz: h8 (480 Hz) is below Nyquist, and so is the odd THD (h3 … h7).
        let ok = text
            .replace("h9_ratio", "h8_ratio")
            .replace("rms_err_accel_ratio", "thd_odd_ratio");
        assert_eq!(problems(&ok), Vec::<String>::new());
    }

    #[test]
    fn robust_settings_are_checked() {
        let robust = "[robust]\ndraws = 8\nstatistic = \"quantile\"\n[[uncertain]]\nname = \"platen.m\"\ndistribution = \"uniform\"\nlow = 1.4e5\nhigh = 1.6e5\n";
        let s = TuneSpec::from_toml_on(&format!("{TUNE}{robust}"), "t", ModelParams::default())
            .unwrap();
        assert_eq!((s.draws, s.statistic), (8, Statistic::Quantile(0.9)));
        let p = problems(&format!("{TUNE}[robust]\ndraws = 8\n"));
        assert_eq!(
            p,
            vec!["robust.draws: draws need [[uncertain]] parameters to draw"]
        );
        let p = problems(&format!(
            "{TUNE}{}",
            robust
                .replace("platen.m", "controller.l_v")
                .replace("1.4e5", "0.2")
                .replace("1.6e5", "0.3")
        ));
        assert_eq!(p, vec!["uncertain[0].name: controller.l_v is also a gain"]);
    }
}
