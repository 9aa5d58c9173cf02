//! Model versus measurement: where, in which harmonic and in which part of the cycle the model
//! fails.
//!
//! Over the analysis window (a sine's last whole cycles, docs/model.md §5; a record's whole length),
//! with the harmonic projection H_k(s) = (2/n) Σ s[n]·exp(−j 2π k f t_n):
//!
//! - fundamental amplitude ratio |H_1(a)|/|H_1(a_r)| and phase ∠H_1(a) − ∠H_1(a_r), model and
//!   measured, against the reference;
//! - h_k = |H_k(a)|/|H_1(a)| for k = 2…9, model and measured;
//! - complex residuals R_k = (H_k(a_model) − H_k(a_measured)) / |H_1(a_r)|, k = 1…9;
//! - residual RMS rms(model − measured)/rms(measured) for acceleration, displacement and force
//!   (where the file has it);
//! - the acceleration residual binned by the part of the cycle, from the reference states:
//!   near velocity reversal (|v_r| ≤ 0.1 max|v_r|), near peak velocity (|v_r| ≥ 0.95 max|v_r|),
//!   near peak displacement (|x_r| ≥ 0.95 max|x_r|), each as rms(residual in bin)/rms(a_measured);
//! - the cycle-to-cycle envelope: |H_1(a)| of every whole cycle of the window, and its drift,
//!   the least-squares slope over cycles divided by the mean (fraction per cycle).
//!
//! For a record the harmonic and envelope quantities are NaN/empty.

use crate::diagnosis::projector::{Projector, C64};
use crate::measured::aligned::{wrap_deg, AlignedTest, OpenLoop, Samples};
use crate::runs::single;
use rayon::prelude::*;
use std::f64::consts::PI;
use vshake_kernel::metrics::N_HARM;
use vshake_kernel::resample::ch;
use vshake_kernel::simulate::{LaneStatus, Solver};

/// The channels compared, at the compared samples.
#[derive(Debug, Clone, Copy)]
pub struct Channels<'a> {
    pub accel: &'a [f64],
    pub disp: &'a [f64],
    pub force: Option<&'a [f64]>,
}

/// Residual of one part of the cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bin {
    pub name: &'static str,
    /// Fraction of the window's samples in the bin.
    pub fraction: f64,
    /// rms(a_model − a_measured) in the bin / rms(a_measured) over the window.
    pub rms_residual_ratio: f64,
}

/// The comparison of one test.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    pub amp_ratio_model: f64,
    pub amp_ratio_measured: f64,
    pub phase_model_deg: f64,
    pub phase_measured_deg: f64,
    /// h_2 … h_9 (NaN at or above the file's Nyquist frequency).
    pub h_model: [f64; N_HARM - 1],
    pub h_measured: [f64; N_HARM - 1],
    /// H_k/|H_1(a_r)| of model and measurement, and the residual, k = 1 … 9.
    pub harm_model: [C64; N_HARM],
    pub harm_measured: [C64; N_HARM],
    pub residual: [C64; N_HARM],
    pub rms_residual_accel_ratio: f64,
    pub rms_residual_disp_ratio: f64,
    pub rms_residual_force_ratio: Option<f64>,
    pub bins: [Bin; 3],
    /// |H_1(a)|/|H_1(a_r)| per whole cycle of the window.
    pub cycle_amp_model: Vec<f64>,
    pub cycle_amp_measured: Vec<f64>,
    /// Least-squares slope of the per-cycle amplitude divided by its mean (per cycle).
    pub drift_model: f64,
    pub drift_measured: f64,
    /// Kinematic consistency |A₁|/(ω²|X₁|) of the acceleration and displacement channels: 1 when
    /// both sensors see one rigid body; not 1 when the LVDT reads a stroke the accelerometer does
    /// not see (a moving reaction mass, a compliant sensor mount) — or a channel in other units.
    pub accel_over_disp_model: f64,
    pub accel_over_disp_measured: f64,
}

fn mag(c: C64) -> f64 {
    c.0.hypot(c.1)
}

fn phase_deg(a: C64, r: C64) -> f64 {
    wrap_deg((a.1.atan2(a.0) - r.1.atan2(r.0)).to_degrees())
}

fn rms(xs: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for x in xs {
        s += x * x;
        n += 1;
    }
    (s / n.max(1) as f64).sqrt()
}

fn drift(amps: &[f64]) -> f64 {
    let n = amps.len();
    if n < 2 {
        return f64::NAN;
    }
    let xm = (n - 1) as f64 / 2.0;
    let ym = amps.iter().sum::<f64>() / n as f64;
    let sxy: f64 = amps
        .iter()
        .enumerate()
        .map(|(i, y)| (i as f64 - xm) * (y - ym))
        .sum();
    let sxx: f64 = (0..n).map(|i| (i as f64 - xm).powi(2)).sum();
    sxy / sxx / ym
}

/// Compares `model` with `measured` at the compared samples `s`.
pub fn compare(s: &Samples, measured: &Channels<'_>, model: &Channels<'_>) -> Comparison {
    let n = s.len();
    let ra = |m: &[f64], t: &[f64]| rms((0..n).map(|k| m[k] - t[k])) / rms(t.iter().copied());
    let bins = residual_bins(s, measured, model);
    let mut c = Comparison {
        amp_ratio_model: f64::NAN,
        amp_ratio_measured: f64::NAN,
        phase_model_deg: f64::NAN,
        phase_measured_deg: f64::NAN,
        h_model: [f64::NAN; N_HARM - 1],
        h_measured: [f64::NAN; N_HARM - 1],
        harm_model: [(f64::NAN, f64::NAN); N_HARM],
        harm_measured: [(f64::NAN, f64::NAN); N_HARM],
        residual: [(f64::NAN, f64::NAN); N_HARM],
        rms_residual_accel_ratio: ra(model.accel, measured.accel),
        rms_residual_disp_ratio: ra(model.disp, measured.disp),
        rms_residual_force_ratio: match (model.force, measured.force) {
            (Some(m), Some(x)) => Some(ra(m, x)),
            _ => None,
        },
        bins,
        cycle_amp_model: Vec::new(),
        cycle_amp_measured: Vec::new(),
        drift_model: f64::NAN,
        drift_measured: f64::NAN,
        accel_over_disp_model: f64::NAN,
        accel_over_disp_measured: f64::NAN,
    };
    let Some(f) = s.fundamental_hz else { return c };
    let proj = Projector::new(&s.tau, f, s.n_harm);
    let hr = proj.apply(&s.ref_a);
    let hm = proj.apply(model.accel);
    let hx = proj.apply(measured.accel);
    set_harmonics(&mut c, (&hr, &hm, &hx), s.n_harm);
    cycle_amplitudes(&mut c, s, (measured, model), f);
    c.drift_model = drift(&c.cycle_amp_model);
    c.drift_measured = drift(&c.cycle_amp_measured);
    let w2 = (2.0 * PI * f).powi(2);
    c.accel_over_disp_model = mag(hm[0]) / (w2 * mag(proj.apply(model.disp)[0]));
    c.accel_over_disp_measured = mag(hx[0]) / (w2 * mag(proj.apply(measured.disp)[0]));
    c
}

/// The acceleration residual's rms (over the measured rms) in the bins of the reference's
/// motion: velocity reversals, peak velocity, peak displacement.
fn residual_bins(s: &Samples, measured: &Channels<'_>, model: &Channels<'_>) -> [Bin; 3] {
    let n = s.len();
    let rms_meas = rms(measured.accel.iter().copied());
    let vmax = s.ref_v.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let xmax = s.ref_x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let bin = |name: &'static str, pick: &dyn Fn(usize) -> bool| {
        let ks: Vec<usize> = (0..n).filter(|&k| pick(k)).collect();
        Bin {
            name,
            fraction: ks.len() as f64 / n.max(1) as f64,
            rms_residual_ratio: if ks.is_empty() {
                f64::NAN
            } else {
                rms(ks.iter().map(|&k| model.accel[k] - measured.accel[k])) / rms_meas
            },
        }
    };
    [
        bin("velocity_reversal", &|k| s.ref_v[k].abs() <= 0.1 * vmax),
        bin("peak_velocity", &|k| s.ref_v[k].abs() >= 0.95 * vmax),
        bin("peak_displacement", &|k| s.ref_x[k].abs() >= 0.95 * xmax),
    ]
}

/// The fundamental's amplitude ratios and phases, the harmonic ratios and the harmonics (over
/// the reference's fundamental) of the model (`hm`) and the measurement (`hx`), from the
/// reference's (`hr`) and their first `n_harm` harmonics.
fn set_harmonics(
    c: &mut Comparison,
    (hr, hm, hx): (&[C64; N_HARM], &[C64; N_HARM], &[C64; N_HARM]),
    n_harm: usize,
) {
    let r1 = mag(hr[0]);
    c.amp_ratio_model = mag(hm[0]) / r1;
    c.amp_ratio_measured = mag(hx[0]) / r1;
    c.phase_model_deg = phase_deg(hm[0], hr[0]);
    c.phase_measured_deg = phase_deg(hx[0], hr[0]);
    // Harmonics at or above the file's Nyquist frequency stay NaN.
    for k in 2..=n_harm {
        c.h_model[k - 2] = mag(hm[k - 1]) / mag(hm[0]);
        c.h_measured[k - 2] = mag(hx[k - 1]) / mag(hx[0]);
    }
    for k in 0..n_harm {
        c.harm_model[k] = (hm[k].0 / r1, hm[k].1 / r1);
        c.harm_measured[k] = (hx[k].0 / r1, hx[k].1 / r1);
        c.residual[k] = (
            c.harm_model[k].0 - c.harm_measured[k].0,
            c.harm_model[k].1 - c.harm_measured[k].1,
        );
    }
}

/// The fundamental's amplitude ratio of the model and the measurement in each whole cycle of
/// the window (boundaries at round(i·R/f) from the window's start).
fn cycle_amplitudes(
    c: &mut Comparison,
    s: &Samples,
    (measured, model): (&Channels<'_>, &Channels<'_>),
    f: f64,
) {
    let n = s.len();
    let per = s.rate_hz / f;
    let cycles = (n as f64 / per + 1e-9).floor() as usize;
    for i in 0..cycles {
        let (a, b) = (
            (i as f64 * per).round() as usize,
            (((i + 1) as f64 * per).round() as usize).min(n),
        );
        let cycle = Projector::new(&s.tau[a..b], f, s.n_harm);
        let r = mag(cycle.apply(&s.ref_a[a..b])[0]);
        c.cycle_amp_model
            .push(mag(cycle.apply(&model.accel[a..b])[0]) / r);
        c.cycle_amp_measured
            .push(mag(cycle.apply(&measured.accel[a..b])[0]) / r);
    }
}

/// Share of the measured signal above which a residual is reported as implausible.
pub const IMPLAUSIBLE_RESIDUAL: f64 = 0.5;

/// One compared test: the comparison and the model's channels at the compared samples.
#[derive(Debug, Clone)]
pub struct ComparedTest {
    pub test: AlignedTest,
    pub comparison: Comparison,
    pub accel_model: Vec<f64>,
    pub disp_model: Vec<f64>,
    pub force_model: Vec<f64>,
    /// The plant's states at the compared samples ([`crate::diagnosis::states::test_states`]): measured
    /// where the file has the channel, the model's otherwise.
    pub states: [Vec<f64>; 5],
    /// The model's own spool position and platen velocity at the compared samples.
    pub spool_model: Vec<f64>,
    pub vel_model: Vec<f64>,
    /// The cap-side pressure the states were computed with (measured, or the model's corrected by
    /// the measured force), and the model's own.
    pub p1: Vec<f64>,
    pub p1_model: Vec<f64>,
    /// The rod-side pressure likewise.
    pub p2: Vec<f64>,
    pub p2_model: Vec<f64>,
}

impl ComparedTest {
    /// The warning for a residual above [`IMPLAUSIBLE_RESIDUAL`] of the signal, if any.
    pub fn residual_warning(&self) -> Option<String> {
        let r = self.comparison.rms_residual_accel_ratio;
        (r > IMPLAUSIBLE_RESIDUAL).then(|| {
            format!(
                "test {:?}: the model's residual is {:.0} % of the measured acceleration: the file of another test, a channel in other units, or a test that did not run as the campaign says?",
                self.test.name,
                100.0 * r
            )
        })
    }
}

/// Drives the test's model as the test was driven, samples it at the test's samples and
/// compares. Fails (with the reason) when the model fails.
pub(crate) fn compare_test(test: &AlignedTest, solver: &Solver) -> Result<ComparedTest, String> {
    let (result, rs) = single::run_sampled(&test.model, &test.drive, solver, &test.samples.tau)
        .map_err(|e| format!("test {:?}: {e}", test.name))?;
    if let LaneStatus::Failed { time_s, reason } = result.status {
        return Err(format!("test {:?}: the model failed at t = {time_s:.4} s after the excitation's start: {reason}", test.name));
    }
    let (accel, disp, force) = (
        rs.channel(ch::ACCEL, 0),
        rs.channel(ch::DISP, 0),
        rs.channel(ch::FORCE, 0),
    );
    let m = &test.measured;
    let comparison = compare(
        &test.samples,
        &Channels {
            accel: &m.accel,
            disp: &m.disp,
            force: m.force.as_deref(),
        },
        &Channels {
            accel: &accel,
            disp: &disp,
            force: Some(&force),
        },
    );
    let pick = |measured: &Option<Vec<f64>>, c: usize| {
        measured.clone().unwrap_or_else(|| rs.channel(c, 0))
    };
    // Chamber pressures: measured, else the model's corrected by the measured force where the
    // file has it (a load the model lacks moves them: the force residual split between the
    // chambers, A1·δP1 − A2·δP2 = r_F/n_act with A1·δP1 = −A2·δP2 [chosen]).
    let (mut p1, mut p2) = (pick(&m.p1, ch::P1), pick(&m.p2, ch::P2));
    if let (Some(f), None, None) = (&m.force, &m.p1, &m.p2) {
        let (a1, a2, n_act) = (
            test.model.actuator.a1,
            test.model.actuator.a2,
            vshake_kernel::N_ACT as f64,
        );
        for k in 0..p1.len() {
            let r = f[k] - force[k];
            p1[k] += r / (2.0 * n_act * a1);
            p2[k] -= r / (2.0 * n_act * a2);
        }
    }
    // The spool: measured, else the opening the measured command asks for, else the model's.
    let sv = &test.model.servovalve;
    let spool = m
        .spool
        .clone()
        .or_else(|| {
            m.valve_cmd.as_ref().map(|u| {
                u.iter()
                    .map(|u| sv.k_sp * u.clamp(-sv.u_lim, sv.u_lim))
                    .collect()
            })
        })
        .unwrap_or_else(|| rs.channel(ch::SPOOL, 0));
    let states = crate::diagnosis::states::test_states(
        &test.model,
        &spool,
        &rs.channel(ch::VEL, 0),
        &p1,
        &p2,
        &m.disp,
    );
    Ok(ComparedTest {
        test: test.clone(),
        comparison,
        accel_model: accel,
        disp_model: disp,
        force_model: force,
        states,
        spool_model: rs.channel(ch::SPOOL, 0),
        vel_model: rs.channel(ch::VEL, 0),
        p1,
        p1_model: rs.channel(ch::P1, 0),
        p2,
        p2_model: rs.channel(ch::P2, 0),
    })
}

/// A comparison to run: the tests as aligned to the model (each with its model and its drive:
/// closed loop, or open loop on the measured column `open_loop` names) and the solver.
pub struct CompareSpec {
    pub tests: Vec<AlignedTest>,
    pub open_loop: Option<OpenLoop>,
    pub solver: Solver,
}

impl CompareSpec {
    /// How the model is driven, in words.
    pub fn drive_label(&self) -> String {
        drive_label(self.open_loop)
    }

    /// Compares every test, in parallel on the current thread pool; a model failure stops the
    /// comparison with its test and reason.
    pub fn run(&self) -> Result<Vec<ComparedTest>, String> {
        self.run_with(&|| {})
    }

    /// [`CompareSpec::run`], calling `done` as each test is compared (from any thread).
    pub fn run_with(&self, done: &(dyn Fn() + Sync)) -> Result<Vec<ComparedTest>, String> {
        self.tests
            .par_iter()
            .map(|t| {
                let c = compare_test(t, &self.solver);
                done();
                c
            })
            .collect()
    }
}

/// How a model driven by `open_loop` (or closed loop) runs, in words.
pub(crate) fn drive_label(open_loop: Option<OpenLoop>) -> String {
    match open_loop {
        None => "closed loop".to_string(),
        Some(m) => format!("open loop on the measured {}", m.column()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;
    use vshake_kernel::excitation::Sine;

    /// The samples of a sine's analysis window at the controller's rate.
    fn samples(s: &Sine) -> Samples {
        let r = s.reference(1024.0);
        let (w0, w1) = r.window;
        Samples {
            rate_hz: 1024.0,
            tau: (w0..w1).map(|k| k as f64 / 1024.0).collect(),
            time: (w0..w1).map(|k| k as f64 / 1024.0).collect(),
            ref_x: r.x[w0..w1].to_vec(),
            ref_v: r.v[w0..w1].to_vec(),
            ref_a: r.a[w0..w1].to_vec(),
            fundamental_hz: Some(s.freq_hz),
            n_harm: N_HARM,
        }
    }

    #[test]
    fn a_known_difference_is_found_where_it_is() {
        let sine = Sine {
            freq_hz: 2.0,
            amp_m: 0.05,
            taper_s: 0.0,
            duration_s: 4.0,
            window_cycles: Some(6),
        };
        let s = samples(&sine);
        let w = 2.0 * std::f64::consts::PI * 2.0;
        let amax = s.ref_a.iter().map(|v| v.abs()).fold(0.0, f64::max);
        // "Measured": the reference plus 3 % third harmonic; "model": the reference with a
        // growing envelope (1 % per cycle).
        let meas: Vec<f64> = s
            .tau
            .iter()
            .zip(&s.ref_a)
            .map(|(t, a)| a + 0.03 * amax * (3.0 * w * t).sin())
            .collect();
        let model: Vec<f64> = s
            .tau
            .iter()
            .zip(&s.ref_a)
            .map(|(t, a)| a * (1.0 + 0.01 * t * 2.0))
            .collect();
        let c = compare(
            &s,
            &Channels {
                accel: &meas,
                disp: &s.ref_x,
                force: None,
            },
            &Channels {
                accel: &model,
                disp: &s.ref_x,
                force: None,
            },
        );
        assert!(
            (c.h_measured[1] - 0.03).abs() < 1e-6,
            "h3 measured {}",
            c.h_measured[1]
        );
        // The model's linear envelope is not periodic over the window, so it leaks into every
        // harmonic: its component at 2f bounds h3 by 0.02·(3 s)/(π·12) ≈ 1.6e-3.
        assert!(c.h_model[1] < 1.6e-3, "h3 model {}", c.h_model[1]);
        assert!(
            (mag(c.residual[2]) - 0.03).abs() < 1.6e-3,
            "the residual sits in k = 3: {}",
            mag(c.residual[2])
        );
        // Envelope slope 0.01 per cycle over a window-mean envelope of 1 + 0.02·2.5 s = 1.05.
        assert!(
            (c.drift_model - 0.01 / 1.05).abs() < 1e-4,
            "model drift {}",
            c.drift_model
        );
        assert!(c.drift_measured.abs() < 1e-9);
        assert!((c.amp_ratio_measured - 1.0).abs() < 1e-9 && c.phase_measured_deg.abs() < 1e-9);
        assert_eq!(c.cycle_amp_model.len(), 6);
        assert!(c.rms_residual_disp_ratio == 0.0);
        // Over whole cycles of a sine the bins hold the share of the phase where |cos θ| ≤ 0.1,
        // |cos θ| ≥ 0.95 and |sin θ| ≥ 0.95: (2/π)·asin 0.1 and (2/π)·acos 0.95 (twice), 0.468
        // together, to within the four bin edges per cycle (a sample each).
        let edge = 4.0 * 2.0 / s.rate_hz;
        let (reversal, peak) = (0.1f64.asin() / FRAC_PI_2, 0.95f64.acos() / FRAC_PI_2);
        for (b, want) in c.bins.iter().zip([reversal, peak, peak]) {
            assert!(
                (b.fraction - want).abs() <= edge,
                "{}: {} of the samples, {want} expected",
                b.name,
                b.fraction
            );
        }
    }

    #[test]
    fn identical_channels_have_zero_residual() {
        let s = samples(&Sine {
            freq_hz: 3.0,
            amp_m: 0.02,
            taper_s: 1.0,
            duration_s: 3.0,
            window_cycles: Some(4),
        });
        let ch = Channels {
            accel: &s.ref_a,
            disp: &s.ref_x,
            force: None,
        };
        let c = compare(&s, &ch, &ch);
        assert_eq!(c.rms_residual_accel_ratio, 0.0);
        assert!(c.residual.iter().all(|z| z.0 == 0.0 && z.1 == 0.0));
        assert!((c.amp_ratio_model - 1.0).abs() < 1e-12);
        // The reference's a and x are one body's: a = −ω²x in the window.
        assert!(
            (c.accel_over_disp_measured - 1.0).abs() < 1e-9,
            "{}",
            c.accel_over_disp_measured
        );
    }

    /// Harmonics at or above the Nyquist frequency of the file are left out (NaN), the rest
    /// computed on the file's own samples.
    #[test]
    fn harmonics_above_nyquist_are_left_out() {
        let sine = Sine {
            freq_hz: 30.0,
            amp_m: 0.001,
            taper_s: 0.0,
            duration_s: 1.0,
            window_cycles: Some(20),
        };
        let mut s = samples(&sine);
        // Every 5th sample: a 204.8 Hz file, Nyquist 102.4 Hz: h1…h3 remain.
        let keep = |v: &Vec<f64>| v.iter().step_by(5).copied().collect::<Vec<f64>>();
        s = Samples {
            rate_hz: 204.8,
            tau: keep(&s.tau),
            time: keep(&s.time),
            ref_x: keep(&s.ref_x),
            ref_v: keep(&s.ref_v),
            ref_a: keep(&s.ref_a),
            n_harm: 3,
            ..s
        };
        let meas: Vec<f64> = s.ref_a.iter().map(|a| 0.9 * a).collect();
        let c = compare(
            &s,
            &Channels {
                accel: &meas,
                disp: &s.ref_x,
                force: None,
            },
            &Channels {
                accel: &s.ref_a,
                disp: &s.ref_x,
                force: None,
            },
        );
        assert!(
            (c.amp_ratio_measured - 0.9).abs() < 1e-3,
            "{}",
            c.amp_ratio_measured
        );
        assert!(c.h_measured[0].is_finite() && c.h_measured[1].is_finite());
        assert!(
            c.h_measured[2..].iter().all(|h| h.is_nan()),
            "{:?}",
            c.h_measured
        );
        assert!(c.residual[3..].iter().all(|z| z.0.is_nan()));
    }
}
