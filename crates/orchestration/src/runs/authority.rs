//! The authority a compensated run used (issue 52), from its time history: how much of the valve
//! command it took (beside the TVC alone's), and where a compensator has a cap, the most it used
//! of it: the valve compensator's gain 1/g against 1/g_min, and each adaptive canceller's
//! correction |D| against authority·A (A the reference's amplitude, its peak displacement).
//! Adaptive inverse control has no cap: the command's row is its authority.

use super::single::History;
use vshake_kernel::effects::valve_compensator::ValveCompensator;
use vshake_kernel::effects::{amplitude_phase, harmonic_cancellation, EffectId, LibraryEffect};
use vshake_kernel::params::ModelParams;

/// One row: what, the most the run used, the TVC alone's where it has one, and the limit.
#[derive(Debug, Clone, PartialEq)]
pub struct Authority {
    pub what: String,
    pub unit: &'static str,
    pub used: f64,
    pub alone: Option<f64>,
    pub limit: f64,
}

/// The rows of a run of `model` whose history is `with` (`alone`: the TVC alone's history).
pub fn authority_used(
    model: &ModelParams,
    with: &History,
    alone: Option<&History>,
) -> Vec<Authority> {
    let peak = |h: &History, name: &str| h.channel(name).map(peak_abs);
    let mut rows = Vec::new();
    if let Some(used) = peak(with, "valve_cmd_v") {
        rows.push(Authority {
            what: "valve command, peak |u|".into(),
            unit: "V",
            used,
            alone: alone.and_then(|a| peak(a, "valve_cmd_v")),
            limit: model.servovalve.u_lim,
        });
    }
    if model.effects.get(EffectId::ValveCompensator) {
        rows.extend(valve_gain(model, with));
    }
    let amp = peak(with, "ref_disp_m").unwrap_or(f64::NAN);
    if model.effects.get(EffectId::AmplitudePhase) {
        let cap = amplitude_phase::Params::of(model).authority * amp;
        rows.extend(correction(
            with,
            amplitude_phase::CORRECTION,
            "fundamental",
            cap,
        ));
    }
    if model.effects.get(EffectId::HarmonicCancellation) {
        let cap = harmonic_cancellation::Params::of(model).authority * amp;
        let names = harmonic_cancellation::CORRECTIONS;
        for (name, k) in names.iter().zip(harmonic_cancellation::HARMONICS) {
            rows.extend(correction(with, name, &format!("harmonic {k}"), cap));
        }
    }
    rows
}

/// The valve compensator's largest gain 1/max(g, g_min) over the run, g the orifice law's factor
/// at each tick's chamber pressures for the command's sign.
fn valve_gain(model: &ModelParams, h: &History) -> Option<Authority> {
    let vc = ValveCompensator::<1>::new([model]);
    let g_min = vc.lane(0)[7];
    let ch = |n| h.channel(n);
    let (u, p1, p2) = (ch("valve_cmd_v")?, ch("p1_pa")?, ch("p2_pa")?);
    let (q1, q2) = (ch("p1_act2_pa")?, ch("p2_act2_pa")?);
    let used = (0..u.len())
        .map(|i| {
            1.0 / vc
                .factor(0, u[i], &[(p1[i], p2[i]), (q1[i], q2[i])])
                .max(g_min)
        })
        .fold(f64::NAN, f64::max);
    Some(Authority {
        what: "valve compensator, gain 1/g".into(),
        unit: "x",
        used,
        alone: None,
        limit: 1.0 / g_min,
    })
}

/// A canceller's largest correction |D| (channel `name`) against its cap.
fn correction(h: &History, name: &str, what: &str, cap: f64) -> Option<Authority> {
    Some(Authority {
        what: format!("{what}, correction |D|"),
        unit: "m",
        used: peak_abs(h.channel(name)?),
        alone: None,
        limit: cap,
    })
}

/// max |x| (NaN for none).
fn peak_abs(x: &[f64]) -> f64 {
    x.iter().fold(f64::NAN, |m, v| m.max(v.abs()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runs::single::{reference_for, run_sim};
    use crate::runs::spec::SimSpec;

    /// At SP09 (3 Hz, 3.20 g) with harmonic cancellation: each harmonic's correction is within its
    /// cap and the command within the clamp; the valve compensator's gain at least 1 (no load: 1)
    /// and at most 1/g_min.
    #[test]
    fn a_compensated_runs_authority_is_within_its_limits() {
        let text = "[model.harmonic_cancellation]\n[model.valve_compensator]\n[excitation]\nkind = \"sine\"\nfreq_hz = 3.0\namp_g = 3.2\nduration_s = 6.0\n";
        let spec = SimSpec::from_toml(text, "sp09.toml").unwrap();
        let reference = reference_for(&spec.excitation, &spec.model, None, 0).unwrap();
        let run = run_sim(&spec, &reference).unwrap();
        let rows = authority_used(&spec.model, &run.history, None);
        assert_eq!(rows.len(), 1 + 1 + 4, "{rows:?}");
        for r in &rows {
            assert!(r.used > 0.0 && r.used <= r.limit * (1.0 + 1e-12), "{r:?}");
        }
        assert!(rows[1].used >= 1.0, "{:?}", rows[1]);
    }
}
