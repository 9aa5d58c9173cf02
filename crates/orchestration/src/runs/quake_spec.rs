//! The earthquake-type excitations of a spec (`stochastic`, `sweep`, `random`) and what record
//! excitations share with them (the reference filter, the acceleration processing); read like
//! [`crate::runs::spec`]'s sine and record, every problem at its key path.

use crate::runs::excitation_spec::{ExcitationSpec, Realisation};
use crate::toml_fields::{Fields, Issues};
use vshake_kernel::ground::{Processing, Sweep, SweepLaw};
use vshake_kernel::params::{Component, ModelParams, G};
use vshake_kernel::spectrum::SpectrumSpec;

/// The columns an `.AT2` file is read into (shell::at2).
pub const AT2_COLUMN: &str = "accel_g";
pub const AT2_TIME: &str = "time_s";

/// The keys of a stochastic excitation: its own and every `ground.*` parameter's name.
pub const STOCHASTIC_KEYS: [&str; 15] = [
    "kind",
    "duration_s",
    "realisation",
    "seed",
    "f_ref_hz",
    "highpass_hz",
    "taper_s",
    "pga_g",
    "f_g_hz",
    "zeta_g",
    "f_f_hz",
    "zeta_f",
    "t_rise_s",
    "t_strong_s",
    "decay_per_s",
];
/// The keys of a sweep.
pub const SWEEP_KEYS: [&str; 8] = [
    "kind",
    "f0_hz",
    "f1_hz",
    "duration_s",
    "amp_g",
    "amp_m",
    "law",
    "taper_s",
];
/// The keys of a band-limited random excitation.
pub const RANDOM_KEYS: [&str; 8] = [
    "kind",
    "f_lo_hz",
    "f_hi_hz",
    "rms_g",
    "duration_s",
    "taper_s",
    "realisation",
    "seed",
];

/// Default corner of a record's reference filter, Hz [chosen: docs/model.md §4].
pub const F_REF_DEFAULT: f64 = 50.0;

/// `f_ref_hz`: the corner of the reference's filter (default 50 Hz), below f_s/2.
pub(crate) fn read_f_ref(f: &mut Fields<'_>, model: &ModelParams, issues: &mut Issues) -> f64 {
    let f_ref = f.f64("f_ref_hz", issues).unwrap_or(F_REF_DEFAULT);
    if !(f_ref > 0.0 && f_ref < 0.5 * model.controller.f_s) {
        issues.push(
            f.path_of("f_ref_hz"),
            format!("{f_ref} Hz must be in (0, f_s/2)"),
        );
    }
    f_ref
}

/// `highpass_hz` and `taper_s` of an acceleration's processing (kernel::ground::Processing).
pub(crate) fn read_processing(f: &mut Fields<'_>, issues: &mut Issues) -> Processing {
    let mut p = Processing::default();
    if let Some(hp) = f.f64("highpass_hz", issues) {
        if hp > 0.0 && hp <= 10.0 {
            p.highpass_hz = hp;
        } else {
            issues.push(
                f.path_of("highpass_hz"),
                format!("{hp} Hz must be in (0, 10] Hz"),
            );
        }
    }
    if let Some(t) = f.f64("taper_s", issues) {
        if t >= 0.0 {
            p.taper_s = t;
        } else {
            issues.push(f.path_of("taper_s"), format!("{t} s must not be negative"));
        }
    }
    p
}

/// A positive run length `duration_s` of at most an hour (`default` when absent).
fn read_duration(f: &mut Fields<'_>, issues: &mut Issues, default: Option<f64>) -> Option<f64> {
    match f.f64("duration_s", issues).or(default) {
        Some(d) if d > 0.0 && d <= 3600.0 => Some(d),
        Some(d) => {
            issues.push(
                f.path_of("duration_s"),
                format!("{d} s must be in (0, 3600] s"),
            );
            None
        }
        None => {
            issues.push(f.path_of("duration_s"), "missing (the run length in s)");
            None
        }
    }
}

/// `realisation` (a whole number ≥ 0 or "per_sample"; default 0) and `seed`.
fn read_realisation(f: &mut Fields<'_>, issues: &mut Issues) -> (Realisation, Option<u64>) {
    let r = match f.int_or_str("realisation", issues) {
        None => Realisation::Fixed(0),
        Some(Ok(k)) if k >= 0 => Realisation::Fixed(k as u64),
        Some(Err("per_sample")) => Realisation::PerSample,
        Some(other) => {
            let given = match other {
                Ok(k) => k.to_string(),
                Err(s) => format!("{s:?}"),
            };
            issues.push(f.path_of("realisation"), format!("{given}: expected a whole number ≥ 0 (the same realisation for every sample) or \"per_sample\""));
            Realisation::Fixed(0)
        }
    };
    let seed = f.int("seed", issues).map(|s| s as u64);
    (r, seed)
}

/// A stochastic ground motion: its length, realisation and any `ground.*` parameter.
pub(crate) fn read_stochastic(
    f: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
) -> Option<ExcitationSpec> {
    let duration = read_duration(f, issues, Some(20.0));
    let (realisation, seed) = read_realisation(f, issues);
    let f_ref_hz = read_f_ref(f, model, issues);
    let processing = read_processing(f, issues);
    let mut ground = Vec::new();
    for p in ModelParams::rows(Component::Ground) {
        if let Some(v) = f.f64(p.name, issues) {
            if p.range.contains(v) {
                ground.push((p.name, v));
            } else {
                issues.push(
                    f.path_of(p.name),
                    format!(
                        "{} is outside the valid range {}",
                        vshake_kernel::params::with_unit(v, p.unit),
                        p.range
                    ),
                );
            }
        }
    }
    Some(ExcitationSpec::Stochastic {
        duration_s: duration?,
        realisation,
        seed,
        ground,
        processing,
        f_ref_hz,
    })
}

/// Two frequencies `lo_key` < `hi_key` in (0, f_s/2).
fn read_band(
    f: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
    (lo_key, hi_key): (&str, &str),
    increasing: bool,
) -> Option<(f64, f64)> {
    let nyq = 0.5 * model.controller.f_s;
    let mut one = |key: &str, issues: &mut Issues| match f.f64(key, issues) {
        Some(x) if x > 0.0 && x < nyq => Some(x),
        Some(x) => {
            issues.push(
                f.path_of(key),
                format!(
                    "{x} Hz must be in (0, {nyq}) Hz (below the controller's Nyquist frequency)"
                ),
            );
            None
        }
        None => {
            issues.push(f.path_of(key), "missing (a frequency in Hz)");
            None
        }
    };
    let (lo, hi) = (one(lo_key, issues)?, one(hi_key, issues)?);
    if increasing && lo >= hi {
        issues.push(
            f.path_of(hi_key),
            format!("{hi} Hz must be above {lo_key} = {lo} Hz"),
        );
        return None;
    }
    Some((lo, hi))
}

/// A taper (`taper_s`, default 1 s) shorter than half the run.
fn read_taper(f: &mut Fields<'_>, issues: &mut Issues, duration: Option<f64>) -> f64 {
    let t = f.f64("taper_s", issues).unwrap_or(1.0);
    if t < 0.0 || duration.is_some_and(|d| 2.0 * t >= d) {
        issues.push(
            f.path_of("taper_s"),
            format!("{t} s must be ≥ 0 and shorter than half the run (the taper is in and out)"),
        );
    }
    t
}

/// A sine sweep: f0 → f1 (either direction), its law, amplitude and taper.
pub(crate) fn read_sweep(
    f: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
) -> Option<ExcitationSpec> {
    let band = read_band(f, model, issues, ("f0_hz", "f1_hz"), false);
    let duration = read_duration(f, issues, None);
    let taper = read_taper(f, issues, duration);
    let law = match f.str("law", issues).unwrap_or("log") {
        "log" => SweepLaw::Log,
        "linear" => SweepLaw::Linear,
        other => {
            issues.push(
                f.path_of("law"),
                format!("unknown sweep law {other:?}; expected \"log\" or \"linear\""),
            );
            SweepLaw::Log
        }
    };
    let (amp_g, amp_m) = (f.f64("amp_g", issues), f.f64("amp_m", issues));
    let amp = match (amp_g, amp_m) {
        (Some(g), None) if g > 0.0 => Some((None, g * G)),
        (None, Some(m)) if m > 0.0 && m < model.actuator.l => Some((Some(m), 0.0)),
        (None, None) => {
            issues.push(f.path_of("amp_g"), "missing (a constant acceleration amplitude in g, or amp_m: a constant displacement amplitude in m)");
            None
        }
        (Some(_), Some(_)) => {
            issues.push(
                f.path_of("amp_m"),
                "give the amplitude once: amp_g or amp_m, not both",
            );
            None
        }
        (g, m) => {
            let key = if g.is_some() { "amp_g" } else { "amp_m" };
            issues.push(
                f.path_of(key),
                format!(
                    "{} must be positive (and amp_m below the half stroke actuator.l = {} m)",
                    g.or(m).unwrap_or(0.0),
                    model.actuator.l
                ),
            );
            None
        }
    };
    let ((f0, f1), duration, (amp_m, accel)) = (band?, duration?, amp?);
    let sweep = Sweep {
        f0_hz: f0,
        f1_hz: f1,
        duration_s: duration,
        taper_s: taper,
        law,
        amp_m,
        accel_mps2: accel,
    };
    Some(ExcitationSpec::Sweep {
        sweep,
        amp_g: amp_g.filter(|_| amp_m.is_none()),
    })
}

/// Band-limited random: the band, the rms acceleration, the run and its realisation.
pub(crate) fn read_random(
    f: &mut Fields<'_>,
    model: &ModelParams,
    issues: &mut Issues,
) -> Option<ExcitationSpec> {
    let band = read_band(f, model, issues, ("f_lo_hz", "f_hi_hz"), true);
    let duration = read_duration(f, issues, None);
    let taper_s = read_taper(f, issues, duration);
    let rms = match f.f64("rms_g", issues) {
        Some(g) if g > 0.0 => Some(g),
        Some(g) => {
            issues.push(f.path_of("rms_g"), format!("{g} g must be positive"));
            None
        }
        None => {
            issues.push(f.path_of("rms_g"), "missing (the rms acceleration in g)");
            None
        }
    };
    let (realisation, seed) = read_realisation(f, issues);
    let ((f_lo_hz, f_hi_hz), duration_s, rms_g) = (band?, duration?, rms?);
    if duration_s * (f_hi_hz - f_lo_hz) < 1.0 {
        issues.push(f.path_of("duration_s"), format!("{duration_s} s holds no multiple of 1/duration_s in [{f_lo_hz}, {f_hi_hz}] Hz; widen the band or lengthen the run"));
        return None;
    }
    Some(ExcitationSpec::Random {
        f_lo_hz,
        f_hi_hz,
        rms_g,
        duration_s,
        taper_s,
        realisation,
        seed,
    })
}

/// An excitation other than a sine as a resolved TOML table (every default written out).
pub(crate) fn excitation_table(e: &ExcitationSpec) -> toml::Table {
    let mut t = toml::Table::new();
    let mut put = |k: &str, v: toml::Value| {
        t.insert(k.into(), v);
    };
    match e {
        ExcitationSpec::Sine { .. } => {
            unreachable!("a sine's table is written by spec::resolved_toml")
        }
        ExcitationSpec::Record { .. } => put_record(e, &mut put),
        ExcitationSpec::Stochastic { .. } => put_stochastic(e, &mut put),
        ExcitationSpec::Sweep { .. } => put_sweep(e, &mut put),
        ExcitationSpec::Random { .. } => put_random(e, &mut put),
    }
    t
}

/// Puts a key and its value into a table being written.
type Put<'a> = dyn FnMut(&str, toml::Value) + 'a;

/// A realisation as written: its number, or "per_sample".
fn realisation_value(r: &Realisation) -> toml::Value {
    match r {
        Realisation::Fixed(k) => toml::Value::Integer(*k as i64),
        Realisation::PerSample => "per_sample".into(),
    }
}

/// A record's keys: its file (and columns, but for an AT2 file), unit, scale and processing.
fn put_record(e: &ExcitationSpec, put: &mut Put<'_>) {
    let ExcitationSpec::Record {
        file,
        column,
        time_column,
        f_ref_hz,
        scale,
        unit,
        pga_g,
        processing,
        signal,
    } = e
    else {
        unreachable!("a record")
    };
    put("kind", "record".into());
    put("signal", signal.name().into());
    put("file", file.display().to_string().into());
    if !vshake_kernel::channels::is_at2(file) {
        put("column", column.clone().into());
        put("time_column", time_column.clone().into());
    }
    put("unit", unit.name().into());
    put("f_ref_hz", (*f_ref_hz).into());
    match pga_g {
        Some(g) => put("pga_g", (*g).into()),
        None => put("scale", (*scale).into()),
    }
    if unit.is_acceleration() {
        put("highpass_hz", processing.highpass_hz.into());
        put("taper_s", processing.taper_s.into());
    }
}

/// A stochastic motion's keys: its run, realisation, processing and ground parameters.
fn put_stochastic(e: &ExcitationSpec, put: &mut Put<'_>) {
    let ExcitationSpec::Stochastic {
        duration_s,
        realisation: r,
        seed,
        ground,
        processing,
        f_ref_hz,
    } = e
    else {
        unreachable!("a stochastic motion")
    };
    put("kind", "stochastic".into());
    put("duration_s", (*duration_s).into());
    put("realisation", realisation_value(r));
    if let Some(s) = seed {
        put("seed", (*s as i64).into());
    }
    put("f_ref_hz", (*f_ref_hz).into());
    put("highpass_hz", processing.highpass_hz.into());
    put("taper_s", processing.taper_s.into());
    for (k, v) in ground {
        put(k, (*v).into());
    }
}

/// A sweep's keys: its frequencies, run, law and amplitude.
fn put_sweep(e: &ExcitationSpec, put: &mut Put<'_>) {
    let ExcitationSpec::Sweep { sweep, amp_g } = e else {
        unreachable!("a sweep")
    };
    put("kind", "sweep".into());
    put("f0_hz", sweep.f0_hz.into());
    put("f1_hz", sweep.f1_hz.into());
    put("duration_s", sweep.duration_s.into());
    put("taper_s", sweep.taper_s.into());
    put(
        "law",
        if sweep.law == SweepLaw::Log {
            "log"
        } else {
            "linear"
        }
        .into(),
    );
    match (sweep.amp_m, amp_g) {
        (Some(m), _) => put("amp_m", m.into()),
        (None, Some(g)) => put("amp_g", (*g).into()),
        (None, None) => put("amp_g", (sweep.accel_mps2 / G).into()),
    }
}

/// Band-limited random's keys: its band, rms, run and realisation.
fn put_random(e: &ExcitationSpec, put: &mut Put<'_>) {
    let ExcitationSpec::Random {
        f_lo_hz,
        f_hi_hz,
        rms_g,
        duration_s,
        taper_s,
        realisation: r,
        seed,
    } = e
    else {
        unreachable!("a band-limited random motion")
    };
    put("kind", "random".into());
    put("f_lo_hz", (*f_lo_hz).into());
    put("f_hi_hz", (*f_hi_hz).into());
    put("rms_g", (*rms_g).into());
    put("duration_s", (*duration_s).into());
    put("taper_s", (*taper_s).into());
    put("realisation", realisation_value(r));
    if let Some(s) = seed {
        put("seed", (*s as i64).into());
    }
}

/// The spectrum taken when a study does not say: 5 % damping, 20 periods log-spaced over
/// 0.05–4 s [chosen: the usual range of design spectra], the error over all of them.
pub fn default_spectrum() -> SpectrumSpec {
    SpectrumSpec::log_spaced(0.05, 4.0, 20, 0.05)
}

/// `[spectrum]`: the response spectrum of the earthquake-type metrics — `damping` (default 0.05),
/// the periods (`periods_s = [...]`, or `t_min_s`, `t_max_s`, `count`: log-spaced, default
/// 0.05–4 s, 20) and the error band `band_s = [low, high]` (default every period).
pub fn read_spectrum(root: &mut Fields<'_>, issues: &mut Issues) -> SpectrumSpec {
    let mut spec = default_spectrum();
    let Some(mut t) = root.table("spectrum", issues) else {
        return spec;
    };
    let damping = t.f64("damping", issues).unwrap_or(spec.damping);
    if !(damping > 0.0 && damping < 1.0) {
        issues.push(
            t.path_of("damping"),
            format!("{damping} must be in (0, 1) (a damping ratio)"),
        );
    }
    let periods = spectrum_periods(&mut t, damping, issues);
    let band = spectrum_band(&mut t, &periods, issues);
    t.finish(
        &[
            "damping",
            "periods_s",
            "t_min_s",
            "t_max_s",
            "count",
            "band_s",
        ],
        issues,
    );
    spec = SpectrumSpec {
        periods,
        damping,
        band,
    };
    if spec.in_band().next().is_none() {
        issues.push(
            "spectrum.band_s",
            "no period of the spectrum lies in the band",
        );
    }
    spec
}

/// `[spectrum]`'s periods: `periods_s`, or log-spaced from `t_min_s`, `t_max_s`, `count` (not
/// both), positive and increasing.
fn spectrum_periods(t: &mut Fields<'_>, damping: f64, issues: &mut Issues) -> Vec<f64> {
    let (t_min, t_max, count) = (
        t.f64("t_min_s", issues),
        t.f64("t_max_s", issues),
        t.int("count", issues),
    );
    let periods = match t.f64_array("periods_s", issues) {
        Some(p) => {
            if t_min.or(t_max).is_some() || count.is_some() {
                issues.push(
                    t.path_of("periods_s"),
                    "give periods_s or t_min_s/t_max_s/count, not both",
                );
            }
            p
        }
        None => {
            let (lo, hi, n) = (
                t_min.unwrap_or(0.05),
                t_max.unwrap_or(4.0),
                count.unwrap_or(20),
            );
            if !(lo > 0.0 && hi > lo && (1..=200).contains(&n)) {
                issues.push(t.path_of("count"), format!("t_min_s = {lo}, t_max_s = {hi}, count = {n}: need 0 < t_min_s < t_max_s and 1 ≤ count ≤ 200"));
                Vec::new()
            } else {
                SpectrumSpec::log_spaced(lo, hi, n as usize, damping).periods
            }
        }
    };
    if periods.is_empty()
        || periods.iter().any(|p| !(*p > 0.0))
        || periods.windows(2).any(|w| w[1] <= w[0])
    {
        issues.push(
            t.path_of("periods_s"),
            "the periods must be positive and increasing (at least one)",
        );
    }
    periods
}

/// `[spectrum]`'s error band `band_s = [low, high]`, s (default: the first to the last period).
fn spectrum_band(t: &mut Fields<'_>, periods: &[f64], issues: &mut Issues) -> (f64, f64) {
    match t.f64_array("band_s", issues) {
        Some(b) if b.len() == 2 && b[0] <= b[1] => (b[0], b[1]),
        Some(b) => {
            issues.push(
                t.path_of("band_s"),
                format!("{b:?}: expected [low, high] periods in s, low ≤ high"),
            );
            (0.0, f64::INFINITY)
        }
        None => (
            periods.first().copied().unwrap_or(0.0),
            periods.last().copied().unwrap_or(0.0),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stochastic_keys_name_every_ground_parameter() {
        for p in ModelParams::rows(Component::Ground) {
            assert!(STOCHASTIC_KEYS.contains(&p.name), "{}", p.name);
        }
        assert_eq!(
            STOCHASTIC_KEYS.len(),
            7 + ModelParams::rows(Component::Ground).count()
        );
    }
}
