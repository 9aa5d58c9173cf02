//! Run specifications read from TOML: model overrides, one excitation, solver settings.
//!
//! ```toml
//! [model.servovalve]          # any parameter of `study params`, as [model.<component>] <name> = value
//! kv = 0.018551
//! law = "orifice"             # or "linear" (the published counter-example)
//!
//! [excitation]                # kind = "sine" | "record"
//! kind = "sine"
//! freq_hz = 3.0
//! amp_g = 1.73                # or amp_m (displacement amplitude)
//! taper_s = 1.0               # half-cosine taper-in, default 1 s
//! duration_s = 3.0            # default taper_s + 2 s
//! window_cycles = 4           # default: every whole cycle after taper_s + 1 s
//!
//! [solver]
//! substeps = 4                # RK4 steps per controller tick (default 4)
//! ```
//!
//! A record excitation names a file and its columns instead:
//! `{ kind = "record", file = "quake.csv", column = "ref_disp_m", time_column = "time_s", f_ref_hz = 50.0, scale = 1.0 }`
//! (the path is relative to the spec file); `unit = "g"` or `"m/s2"` makes the column a ground
//! acceleration, and a PEER `.AT2` file is one by itself (`pga_g` scales it to a peak,
//! `highpass_hz` sets its processing into a displacement, kernel::ground). The earthquake-type
//! kinds (docs/formats.md "Excitations"):
//! - `{ kind = "stochastic", duration_s = 20, realisation = 0 }` (or `"per_sample"`), with any
//!   `ground.*` parameter as a key (`f_g_hz = 3.0`);
//! - `{ kind = "sweep", f0_hz = 0.5, f1_hz = 20, duration_s = 40, amp_g = 0.2, law = "log" }`;
//! - `{ kind = "random", f_lo_hz = 0.5, f_hi_hz = 15, rms_g = 0.1, duration_s = 20 }`.
//!
//! Every problem is reported at once with its key path.

pub use crate::runs::excitation_spec::{ExcitationSpec, Realisation, RecordUnit};
use crate::toml_fields::{Fields, InputError, Issues};
use std::path::PathBuf;
use vshake_kernel::effects::expression::Hook;
use vshake_kernel::excitation::{Signal, Sine};
use vshake_kernel::params::{Component, EffectId, ModelParams, Range, ValveLaw};
use vshake_kernel::simulate::Solver;
use vshake_kernel::spectrum::SpectrumSpec;

/// A single-run specification (`study sim`).
#[derive(Debug, Clone, PartialEq)]
pub struct SimSpec {
    pub model: ModelParams,
    pub excitation: ExcitationSpec,
    pub solver: Solver,
    /// `[spectrum]`: the response spectrum of the earthquake-type metrics (as a study's).
    pub spectrum: SpectrumSpec,
}

/// Reads `[model.<component>]` overrides into `model` (defaults for everything not named); the
/// effects it switches off by name (`enabled = false`).
pub(crate) fn read_model(
    mut f: Fields<'_>,
    model: &mut ModelParams,
    issues: &mut Issues,
) -> Vec<EffectId> {
    let mut off = Vec::new();
    for comp in ModelParams::components() {
        let Some(mut t) = f.table(comp.name(), issues) else {
            continue;
        };
        let names: Vec<&str> = ModelParams::registry()
            .filter(|p| p.component == comp)
            .map(|p| p.name)
            .collect();
        let mut expected = names.clone();
        if comp == Component::Effect(EffectId::Expression) {
            read_expression(&mut t, model, issues);
            if !model.effects.expression {
                off.push(EffectId::Expression);
            }
            continue;
        }
        if let Some(e) = comp.effect() {
            // An optional effect is on when its table is given (`enabled = false` switches it off).
            expected.push("enabled");
            let on = t.bool("enabled", issues).unwrap_or(true);
            *model.effects.get_mut(e) = on;
            if !on {
                off.push(e);
            }
        }
        if comp == Component::Servovalve {
            expected.push("law");
            if let Some(law) = t.str("law", issues) {
                match law {
                    "orifice" => model.valve_law = ValveLaw::Orifice,
                    "linear" => model.valve_law = ValveLaw::Linear,
                    other => issues.push(
                        t.path_of("law"),
                        format!("unknown valve law {other:?}; expected \"orifice\" or \"linear\""),
                    ),
                }
            }
        }
        for name in &names {
            if let Some(v) = t.f64(name, issues) {
                let info = ModelParams::lookup(&format!("{comp}.{name}")).expect("registry name");
                info.set(model, v);
            }
        }
        t.finish(&expected, issues);
    }
    f.finish(
        &ModelParams::components()
            .map(Component::name)
            .collect::<Vec<_>>(),
        issues,
    );
    off
}

/// Reads `[model.expression]`: `enabled`, each hook's expression (`force = "-c * v"`, keys of
/// [`Hook`]) and every other key a named parameter, `c = 4.0e4` or `c = { value = 4.0e4, unit =
/// "N·s/m", range = [0, inf] }` (unit "-" and any value unless given).
fn read_expression(t: &mut Fields<'_>, model: &mut ModelParams, issues: &mut Issues) {
    model.effects.expression = t.bool("enabled", issues).unwrap_or(true);
    let keys: Vec<&String> = t.keys().filter(|k| k.as_str() != "enabled").collect();
    let (hooks, params): (Vec<&String>, Vec<&String>) =
        keys.into_iter().partition(|k| Hook::parse(k).is_some());
    let hook_keys: Vec<&str> = Hook::ALL.iter().map(|h| h.key()).collect();
    let mut misnamed = false;
    for name in params {
        // A string is an expression: its key names a hook the effect does not have.
        if let Some(toml::Value::String(_)) = t.value(name) {
            let hint = crate::toml_fields::suggest(name, &hook_keys)
                .map_or(String::new(), |s| format!(" (did you mean `{s}`?)"));
            let keys = hook_keys.join(", ");
            issues.push(t.path_of(name), format!("unknown hook{hint}; an expression is one of {keys} (a number or a table is a parameter)"));
            misnamed = true;
            continue;
        }
        read_expression_param(t, name, model, issues);
    }
    for key in &hooks {
        let (Some(src), Some(hook)) = (t.str(key, issues), Hook::parse(key)) else {
            continue;
        };
        if let Err(e) = model.expression.set(hook, src) {
            issues.push(t.path_of(key), format!("{e}, in {src:?}"));
        }
    }
    // A table that only changes parameters (a run file's, over a model file's) needs none.
    if hooks.is_empty() && !misnamed && model.expression.hooks.is_empty() {
        let path = t.path_of("");
        issues.push(
            path.trim_end_matches('.'),
            format!(
                "no expression: give one or more of {}",
                hook_keys.join(", ")
            ),
        );
    }
}

/// Reads the named parameter `name` of `[model.expression]` into `model`.
fn read_expression_param(
    t: &mut Fields<'_>,
    name: &str,
    model: &mut ModelParams,
    issues: &mut Issues,
) {
    let path = t.path_of(name);
    let (value, unit, range) = match t.value(name) {
        Some(toml::Value::Table(_)) => {
            let Some(mut f) = t.table(name, issues) else {
                return;
            };
            let value = f.f64("value", issues);
            let unit = f.str("unit", issues).unwrap_or("-").to_string();
            let range = read_range(&mut f, issues);
            f.finish(&["value", "unit", "range"], issues);
            let Some(value) = value else {
                issues.push(format!("{path}.value"), "missing: the parameter's value");
                return;
            };
            (value, unit, range.unwrap_or(Range::any()))
        }
        _ => match t.f64(name, issues) {
            Some(v) => (v, "-".to_string(), Range::any()),
            None => return,
        },
    };
    if let Err(e) = model.name_expression_param(name, &unit, range, value) {
        issues.push(path, e);
    }
}

/// A parameter's `range = [lo, hi]` (either end may be ±inf).
fn read_range(f: &mut Fields<'_>, issues: &mut Issues) -> Option<Range> {
    let v = f.value("range")?;
    let ends: Option<Vec<f64>> = v.as_array().and_then(|a| {
        a.iter()
            .map(|x| x.as_float().or(x.as_integer().map(|n| n as f64)))
            .collect()
    });
    match ends.as_deref() {
        Some(&[lo, hi]) if lo < hi && !lo.is_nan() && !hi.is_nan() => Some(Range::closed(lo, hi)),
        _ => {
            issues.push(
                f.path_of("range"),
                format!("expected [lo, hi] with lo < hi, found {v}"),
            );
            None
        }
    }
}

/// The `[model.expression]` table of `model`: its hooks' expressions and its named parameters.
fn expression_table(model: &ModelParams) -> toml::Table {
    let mut t = toml::Table::new();
    for h in &model.expression.hooks {
        t.insert(h.hook.key().into(), h.source.clone().into());
    }
    let named = model.expression.names.iter().filter(|n| !n.is_empty());
    for info in named.filter_map(|n| ModelParams::lookup(&format!("expression.{n}"))) {
        let mut p = toml::Table::new();
        p.insert("value".into(), info.get(model).into());
        p.insert("unit".into(), info.unit.into());
        let range = vec![info.range.lo.into(), info.range.hi.into()];
        p.insert("range".into(), toml::Value::Array(range));
        t.insert(info.name.into(), toml::Value::Table(p));
    }
    t
}

/// Validates a model, prefixing every path with `prefix` (e.g. `model`).
pub(crate) fn validate_model(model: &ModelParams, prefix: &str, issues: &mut Issues) {
    if let Err(list) = model.validate() {
        for i in list {
            let path = i
                .path
                .split(", ")
                .map(|p| format!("{prefix}.{p}"))
                .collect::<Vec<_>>()
                .join(", ");
            issues.push(path, i.message);
        }
    }
}

/// Reads an excitation table (`[excitation]` or an inline table of a campaign test).
pub fn read_excitation(
    f: Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
) -> Option<ExcitationSpec> {
    read_excitation_in(f, model, issues, &[], None)
}

/// [`read_excitation`] for a table that also holds `extra` keys read by the caller.
pub(crate) fn read_excitation_with_extra(
    f: Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
    extra: &[&str],
) -> Option<ExcitationSpec> {
    read_excitation_in(f, model, issues, extra, None)
}

/// [`read_excitation`] with extra keys and, for a campaign test, its data file: a record
/// without `file` is a column of it, and a record is by default the reference the controller
/// tracked (`signal = "reference"`; elsewhere the default is `"command"`, docs/model.md §4).
pub(crate) fn read_excitation_in(
    mut f: Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
    extra: &[&str],
    test_data: Option<&std::path::Path>,
) -> Option<ExcitationSpec> {
    let kind = f.str("kind", issues);
    let (out, expected): (_, &[&str]) = match kind {
        Some("sine") => (read_sine(&mut f, model, issues), &SINE_KEYS),
        Some("record") => (read_record(&mut f, model, issues, test_data), &RECORD_KEYS),
        Some("stochastic") => (
            crate::runs::quake_spec::read_stochastic(&mut f, model, issues),
            &crate::runs::quake_spec::STOCHASTIC_KEYS[..],
        ),
        Some("sweep") => (
            crate::runs::quake_spec::read_sweep(&mut f, model, issues),
            &crate::runs::quake_spec::SWEEP_KEYS[..],
        ),
        Some("random") => (
            crate::runs::quake_spec::read_random(&mut f, model, issues),
            &crate::runs::quake_spec::RANDOM_KEYS[..],
        ),
        Some(other) => {
            issues.push(
                f.path_of("kind"),
                format!(
                    "unknown excitation kind {other:?}; expected one of {}",
                    KINDS.join(", ")
                ),
            );
            // The other keys depend on the kind: none of them is judged.
            return None;
        }
        None => {
            issues.push(
                f.path_of("kind"),
                format!("missing (one of {})", KINDS.join(", ")),
            );
            return None;
        }
    };
    f.finish(&[expected, extra].concat(), issues);
    out
}

/// The excitation kinds.
pub const KINDS: [&str; 5] = [
    "\"sine\"",
    "\"record\"",
    "\"stochastic\"",
    "\"sweep\"",
    "\"random\"",
];

/// A sine: its frequency below Nyquist, its amplitude (in g or in metres) within the stroke,
/// a taper shorter than the run, and an analysis window that fits.
fn read_sine(
    f: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
) -> Option<ExcitationSpec> {
    let freq = f.f64("freq_hz", issues);
    let amp_g = f.f64("amp_g", issues);
    let amp_m = f.f64("amp_m", issues);
    let taper = f.f64("taper_s", issues).unwrap_or(1.0);
    let duration = f.f64("duration_s", issues).unwrap_or(taper + 2.0);
    let cycles = f.int("window_cycles", issues);
    let freq = sine_frequency(f, freq, 0.5 * model.controller.f_s, issues);
    check_sine_timing(f, taper, duration, issues);
    let x_amp = sine_amplitude(f, model, (amp_g, amp_m), freq, issues);
    let cycles = sine_window_cycles(f, cycles, issues);
    let (Some(freq), Some(x_amp)) = (freq, x_amp) else {
        return None;
    };
    let mut sine = Sine {
        freq_hz: freq,
        amp_m: x_amp,
        taper_s: taper,
        duration_s: duration,
        window_cycles: cycles,
    };
    let n = cycles.unwrap_or_else(|| sine.default_cycles());
    sine.window_cycles = Some(n);
    check_sine_window(f, n, freq, duration, issues);
    Some(ExcitationSpec::Sine {
        sine,
        amp_g: amp_g.filter(|_| amp_m.is_none()),
    })
}

/// A sine's frequency, Hz: given, and in (0, Nyquist).
fn sine_frequency(f: &Fields<'_>, freq: Option<f64>, nyq: f64, issues: &mut Issues) -> Option<f64> {
    match freq {
        Some(x) if x > 0.0 && x < nyq => Some(x),
        Some(x) => {
            issues.push(
                f.path_of("freq_hz"),
                format!(
                    "{x} Hz must be in (0, {nyq}) Hz (below the controller's Nyquist frequency)"
                ),
            );
            None
        }
        None => {
            issues.push(f.path_of("freq_hz"), "missing (sine frequency in Hz)");
            None
        }
    }
}

/// A sine's taper is not negative, its duration in (0, 3600] s and longer than the taper.
fn check_sine_timing(f: &Fields<'_>, taper: f64, duration: f64, issues: &mut Issues) {
    if taper < 0.0 {
        issues.push(
            f.path_of("taper_s"),
            format!("{taper} s must not be negative"),
        );
    }
    if duration <= 0.0 || duration > 3600.0 {
        issues.push(
            f.path_of("duration_s"),
            format!("{duration} s must be in (0, 3600] s"),
        );
    } else if taper >= duration {
        issues.push(f.path_of("taper_s"), format!("{taper} s must be shorter than duration_s = {duration} s (the taper would fill the whole run)"));
    }
}

/// A sine's `window_cycles`, where given: at least 1.
fn sine_window_cycles(f: &Fields<'_>, cycles: Option<i64>, issues: &mut Issues) -> Option<u32> {
    match cycles {
        Some(c) if c >= 1 => Some(c as u32),
        Some(c) => {
            issues.push(
                f.path_of("window_cycles"),
                format!("{c} must be at least 1"),
            );
            None
        }
        None => None,
    }
}

/// A sine's analysis window of `n` cycles is at least one cycle and fits in the run.
fn check_sine_window(f: &Fields<'_>, n: u32, freq: f64, duration: f64, issues: &mut Issues) {
    if n == 0 {
        issues.push(f.path_of("duration_s"), format!("{duration} s leaves no whole cycle after taper_s + 1 s for the analysis window; lengthen the run or set window_cycles"));
    } else if n as f64 / freq > duration + 1e-9 {
        issues.push(
            f.path_of("window_cycles"),
            format!(
                "{n} cycles ({:.3} s) do not fit in the {duration} s run",
                n as f64 / freq
            ),
        );
    }
}

/// A sine's displacement amplitude, m, from `amp_g` or `amp_m` (exactly one), positive and below
/// the half stroke.
fn sine_amplitude(
    f: &Fields<'_>,
    model: &ModelParams,
    (amp_g, amp_m): (Option<f64>, Option<f64>),
    freq: Option<f64>,
    issues: &mut Issues,
) -> Option<f64> {
    let (x, key, given) = match (amp_g, amp_m, freq) {
        (Some(_), Some(_), _) => {
            issues.push(
                f.path_of("amp_m"),
                "give the amplitude once: amp_g or amp_m, not both",
            );
            return None;
        }
        (None, None, _) => {
            issues.push(
                f.path_of("amp_g"),
                "missing (acceleration amplitude in g, or amp_m in metres)",
            );
            return None;
        }
        (Some(g), None, Some(fr)) => (Sine::amp_from_g(g, fr), "amp_g", g),
        (None, Some(m), Some(_)) => (m, "amp_m", m),
        (_, _, None) => return None,
    };
    let l = model.actuator.l;
    if x <= 0.0 {
        issues.push(f.path_of(key), format!("{given} must be positive"));
        None
    } else if x >= l {
        issues.push(f.path_of(key), format!("displacement amplitude {x:.4} m exceeds the stroke: |x| must stay below the half stroke actuator.l = {l} m"));
        None
    } else if let Some(why) = freq.and_then(|fr| {
        crate::runs::limits::force_exceeded(model, x * (2.0 * std::f64::consts::PI * fr).powi(2))
    }) {
        issues.push(f.path_of(key), why);
        None
    } else {
        Some(x)
    }
}

/// The unit of a record's column: g for a PEER .AT2 file, else `unit` (metres when absent,
/// where the column's name does not say acceleration).
fn record_unit(
    f: &mut Fields<'_>,
    unit_key: Option<&str>,
    at2: bool,
    column: &str,
    issues: &mut Issues,
) -> RecordUnit {
    match (unit_key, at2) {
        (None, true) | (Some("g"), true) => RecordUnit::G,
        (Some(u), true) => {
            issues.push(
                f.path_of("unit"),
                format!("{u:?}: a PEER .AT2 file holds acceleration in g"),
            );
            RecordUnit::G
        }
        (None, false) if looks_like_acceleration(column) => {
            issues.push(
                f.path_of("unit"),
                format!(
                    "missing: column {column:?} is named like an acceleration, and without a \
                     unit a record column is read as a displacement in metres; give unit = \"g\" \
                     or \"m/s2\" (or unit = \"m\" if it is a displacement)"
                ),
            );
            RecordUnit::M
        }
        (None, false) => RecordUnit::M,
        (Some(u), false) => RecordUnit::parse(u).unwrap_or_else(|| {
            issues.push(
                f.path_of("unit"),
                format!(
                    "unknown unit {u:?}; expected one of {:?}",
                    RecordUnit::NAMES
                ),
            );
            RecordUnit::M
        }),
    }
}

/// Whether a column's name says acceleration: `acc` anywhere, or a unit suffix of g or m/s²
/// (`_g`, `mps2`, `ms2`), in any case.
fn looks_like_acceleration(column: &str) -> bool {
    let c = column.to_ascii_lowercase();
    c.contains("acc") || c.ends_with("_g") || c.ends_with("mps2") || c.ends_with("ms2")
}

/// A record: its file (or the campaign test's own data file), columns, the reference filter's
/// cut-off, a scale and what it is (`signal`: the tracked reference by default in a campaign
/// test, whose data file `test_data` is; a command elsewhere).
fn read_record(
    f: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
    test_data: Option<&std::path::Path>,
) -> Option<ExcitationSpec> {
    let signal = read_signal(f, issues, test_data.is_some());
    let default_file = test_data;
    let file = f.str("file", issues);
    let column = f.str("column", issues).unwrap_or("ref_disp_m");
    let time_column = f.str("time_column", issues).unwrap_or("time_s");
    let f_ref = crate::runs::quake_spec::read_f_ref(f, model, issues);
    let scale = f.f64("scale", issues);
    let pga_g = f.f64("pga_g", issues);
    let unit_key = f.str("unit", issues);
    let processing = crate::runs::quake_spec::read_processing(f, issues);
    let Some(file) = file
        .map(PathBuf::from)
        .or_else(|| default_file.map(PathBuf::from))
    else {
        issues.push(
            f.path_of("file"),
            "missing (the CSV, Parquet or .AT2 file holding the record)",
        );
        return None;
    };
    let at2 = vshake_kernel::channels::is_at2(&file);
    let unit = record_unit(f, unit_key, at2, column, issues);
    if let Some(g) = pga_g {
        if !unit.is_acceleration() {
            issues.push(f.path_of("pga_g"), "scaling to a peak acceleration needs an acceleration record (unit = \"g\" or \"m/s2\", or a .AT2 file); use scale");
        } else if scale.is_some() {
            issues.push(f.path_of("pga_g"), "give scale or pga_g, not both");
        } else if !(g > 0.0 && g.is_finite()) {
            issues.push(f.path_of("pga_g"), format!("{g} g must be positive"));
        }
    }
    let column = if at2 {
        crate::runs::quake_spec::AT2_COLUMN
    } else {
        column
    };
    let time_column = if at2 {
        crate::runs::quake_spec::AT2_TIME
    } else {
        time_column
    };
    Some(ExcitationSpec::Record {
        file,
        column: column.to_string(),
        time_column: time_column.to_string(),
        f_ref_hz: f_ref,
        scale: scale.unwrap_or(1.0),
        unit,
        pga_g,
        processing,
        signal,
    })
}

/// The `signal` key of a record: "reference" or "command" (docs/model.md §4); the default is the
/// tracked reference for a measured test, the command elsewhere.
fn read_signal(f: &mut Fields<'_>, issues: &mut Issues, measured: bool) -> Signal {
    match f.str("signal", issues) {
        None if measured => Signal::Reference,
        None => Signal::Command,
        Some("reference") => Signal::Reference,
        Some("command") => Signal::Command,
        Some(other) => {
            issues.push(
                f.path_of("signal"),
                format!(
                    "{other:?}: expected \"reference\" (the reference the controller tracked, as a \
                     data-acquisition system records it) or \"command\" (the command into the \
                     controller's reference generator)"
                ),
            );
            Signal::Command
        }
    }
}

/// The keys of a sine excitation (campaign tests, study excitations); docs/formats.md lists each.
pub const SINE_KEYS: [&str; 7] = [
    "kind",
    "freq_hz",
    "amp_g",
    "amp_m",
    "taper_s",
    "duration_s",
    "window_cycles",
];
/// The keys of a record excitation; docs/formats.md lists each.
pub const RECORD_KEYS: [&str; 11] = [
    "kind",
    "file",
    "column",
    "time_column",
    "f_ref_hz",
    "scale",
    "unit",
    "pga_g",
    "highpass_hz",
    "taper_s",
    "signal",
];

/// Reads `[solver]`; `extra` names keys of the same table read by the caller.
pub(crate) fn read_solver(mut f: Fields<'_>, issues: &mut Issues, extra: &[&str]) -> Solver {
    let mut s = Solver::default();
    if let Some(n) = f.int("substeps", issues) {
        if (1..=4096).contains(&n) {
            s.substeps = n as usize;
        } else {
            issues.push(f.path_of("substeps"), format!("{n} must be in 1..=4096"));
        }
    }
    f.finish(&[&["substeps"][..], extra].concat(), issues);
    s
}

impl SimSpec {
    /// Parses a sim file's text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<SimSpec, InputError> {
        Self::from_toml_on(text, file, ModelParams::default())
    }

    /// [`SimSpec::from_toml`] from the parameters `base` (a model file's, `--model`) instead of
    /// the defaults: the run file's `[model.*]` tables change them further.
    pub fn from_toml_on(text: &str, file: &str, base: ModelParams) -> Result<SimSpec, InputError> {
        let table = crate::toml_fields::parse(text, file)?;
        let mut issues = Issues::default();
        let mut root = Fields::new("", &table);
        let mut model = base;
        if let Some(m) = root.table("model", &mut issues) {
            read_model(m, &mut model, &mut issues);
        }
        validate_model(&model, "model", &mut issues);
        let excitation = match root.table("excitation", &mut issues) {
            Some(e) => read_excitation(e, &model, &mut issues),
            None => {
                issues.push(
                    "excitation",
                    format!("missing table (kind = one of {})", KINDS.join(", ")),
                );
                None
            }
        };
        let solver = match root.table("solver", &mut issues) {
            Some(s) => read_solver(s, &mut issues, &[]),
            None => Solver::default(),
        };
        let spectrum = crate::runs::quake_spec::read_spectrum(&mut root, &mut issues);
        root.finish(&["model", "excitation", "solver", "spectrum"], &mut issues);
        issues.into_result(file)?;
        Ok(SimSpec {
            model,
            excitation: excitation.expect("no issues means an excitation"),
            solver,
            spectrum,
        })
    }

    /// The spec after defaults, as TOML (every parameter written out), for result metadata.
    pub fn resolved_toml(&self) -> String {
        let mut root = toml::Table::new();
        root.insert("model".into(), toml::Value::Table(model_table(&self.model)));
        let mut e = toml::Table::new();
        match &self.excitation {
            ExcitationSpec::Sine { sine, amp_g } => {
                e.insert("kind".into(), "sine".into());
                e.insert("freq_hz".into(), sine.freq_hz.into());
                if let Some(g) = amp_g {
                    e.insert("amp_g".into(), (*g).into());
                } else {
                    e.insert("amp_m".into(), sine.amp_m.into());
                }
                e.insert("taper_s".into(), sine.taper_s.into());
                e.insert("duration_s".into(), sine.duration_s.into());
                e.insert(
                    "window_cycles".into(),
                    (sine.window_cycles.unwrap_or_else(|| sine.default_cycles()) as i64).into(),
                );
            }
            other => e = crate::runs::quake_spec::excitation_table(other),
        }
        root.insert("excitation".into(), toml::Value::Table(e));
        let mut s = toml::Table::new();
        s.insert("substeps".into(), (self.solver.substeps as i64).into());
        root.insert("solver".into(), toml::Value::Table(s));
        let mut sp = toml::Table::new();
        sp.insert("damping".into(), self.spectrum.damping.into());
        let periods = self.spectrum.periods.iter().map(|&p| p.into()).collect();
        sp.insert("periods_s".into(), toml::Value::Array(periods));
        let (lo, hi) = self.spectrum.band;
        sp.insert(
            "band_s".into(),
            toml::Value::Array(vec![lo.into(), hi.into()]),
        );
        root.insert("spectrum".into(), toml::Value::Table(sp));
        toml::to_string(&root).expect("TOML of plain values")
    }
}

/// Every model parameter as `[component] name = value` tables.
pub fn model_table(model: &ModelParams) -> toml::Table {
    let mut m = toml::Table::new();
    for comp in ModelParams::components() {
        let mut t = toml::Table::new();
        if comp == Component::Servovalve {
            let law = match model.valve_law {
                ValveLaw::Orifice => "orifice",
                ValveLaw::Linear => "linear",
            };
            t.insert("law".into(), law.into());
        }
        if comp.effect().is_some_and(|e| !model.effects.get(e)) {
            continue;
        }
        if comp == Component::Effect(EffectId::Expression) {
            m.insert(comp.name().into(), expression_table(model).into());
            continue;
        }
        for p in ModelParams::registry().filter(|p| p.component == comp) {
            t.insert(p.name.into(), p.get(model).into());
        }
        m.insert(comp.name().into(), toml::Value::Table(t));
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[model.platen]
m = 150000.0
[model.servovalve]
law = "linear"
[excitation]
kind = "sine"
freq_hz = 3.0
amp_g = 1.73
window_cycles = 4
"#;

    #[test]
    fn reads_overrides_and_defaults() {
        let s = SimSpec::from_toml(GOOD, "good.toml").unwrap();
        assert_eq!(s.model.platen.m, 150000.0);
        assert_eq!(s.model.valve_law, ValveLaw::Linear);
        assert_eq!(s.model.platen.k, 1.266e6);
        assert_eq!(s.solver.substeps, Solver::default().substeps);
        let ExcitationSpec::Sine { sine, .. } = s.excitation else {
            panic!()
        };
        assert_eq!(sine.duration_s, 3.0);
        assert_eq!(sine.window_cycles, Some(4));
        // The resolved TOML reads back to the same spec.
        let again = SimSpec::from_toml(&s.resolved_toml(), "resolved").unwrap();
        assert_eq!(again.model, s.model);
    }

    #[test]
    fn reports_all_problems_with_key_paths() {
        let bad = r#"
[model.platen]
m = -5.0
mm = 3
[model.actuator]
beta = 0.0
[excitation]
kind = "sine"
freq_hz = 0.5
amp_g = 10.0
"#;
        let e = SimSpec::from_toml(bad, "bad.toml").unwrap_err();
        let paths: Vec<&str> = e.issues.iter().map(|i| i.path.as_str()).collect();
        assert!(paths.contains(&"model.platen.m"), "{e}");
        assert!(paths.contains(&"model.platen.mm"), "{e}");
        assert!(paths.contains(&"model.actuator.beta"), "{e}");
        assert!(paths.contains(&"excitation.amp_g"), "{e}");
        assert!(e.to_string().contains("exceeds the stroke"), "{e}");
        assert!(e.to_string().contains("did you mean `m`"), "{e}");
    }
}
