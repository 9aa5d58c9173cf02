//! Model versus measurement: where, in which harmonic and in which part of the cycle the model
//! fails.
//!
//! Over the analysis window (a sine's last whole cycles, MODEL.md §5; a record's whole length),
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

use super::super::kernel::excitation::Reference;
use crate::kernel::metrics::{Basis, N_HARM};

/// A complex number (re, im).
pub type C64 = (f64, f64);

/// The channels compared, sampled at the reference ticks.
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
    /// h_2 … h_9.
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
    /// not see (a moving reaction mass, a compliant sensor mount).
    pub accel_over_disp_model: f64,
    pub accel_over_disp_measured: f64,
}

/// H_k (k = 1…9) of `s` over ticks [w0, w1).
pub fn project(s: &[f64], w0: usize, w1: usize, f_s: f64, f: f64) -> [C64; N_HARM] {
    let mut out = [(0.0, 0.0); N_HARM];
    for (k, &x) in s.iter().enumerate().take(w1).skip(w0) {
        let b = Basis::at(k, f_s, f);
        for (o, (c, sn)) in out.iter_mut().zip(b.cos.iter().zip(&b.sin)) {
            o.0 += x * c;
            o.1 -= x * sn;
        }
    }
    let scale = 2.0 / (w1 - w0).max(1) as f64;
    out.map(|(re, im)| (re * scale, im * scale))
}

fn mag(c: C64) -> f64 {
    c.0.hypot(c.1)
}

fn phase_deg(a: C64, r: C64) -> f64 {
    let mut d = (a.1.atan2(a.0) - r.1.atan2(r.0)).to_degrees() % 360.0;
    if d > 180.0 {
        d -= 360.0;
    } else if d <= -180.0 {
        d += 360.0;
    }
    d
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
    let sxy: f64 = amps.iter().enumerate().map(|(i, y)| (i as f64 - xm) * (y - ym)).sum();
    let sxx: f64 = (0..n).map(|i| (i as f64 - xm).powi(2)).sum();
    sxy / sxx / ym
}

/// Compares `model` with `measured` over the reference's window.
pub fn compare(reference: &Reference, measured: &Channels<'_>, model: &Channels<'_>) -> Comparison {
    let (w0, w1) = reference.window;
    let f_s = reference.f_s;
    let win = w0..w1;
    let ra = |s: &[f64], t: &[f64]| rms(win.clone().map(|k| s[k] - t[k])) / rms(win.clone().map(|k| t[k]));
    let rms_meas = rms(win.clone().map(|k| measured.accel[k]));
    let vmax = win.clone().map(|k| reference.v[k].abs()).fold(0.0, f64::max);
    let xmax = win.clone().map(|k| reference.x[k].abs()).fold(0.0, f64::max);
    let bin = |name: &'static str, pick: &dyn Fn(usize) -> bool| {
        let ks: Vec<usize> = win.clone().filter(|&k| pick(k)).collect();
        Bin {
            name,
            fraction: ks.len() as f64 / (w1 - w0).max(1) as f64,
            rms_residual_ratio: if ks.is_empty() { f64::NAN } else { rms(ks.iter().map(|&k| model.accel[k] - measured.accel[k])) / rms_meas },
        }
    };
    let bins = [
        bin("velocity_reversal", &|k| reference.v[k].abs() <= 0.1 * vmax),
        bin("peak_velocity", &|k| reference.v[k].abs() >= 0.95 * vmax),
        bin("peak_displacement", &|k| reference.x[k].abs() >= 0.95 * xmax),
    ];
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
    let Some(f) = reference.fundamental_hz else { return c };
    let hr = project(&reference.a, w0, w1, f_s, f);
    let hm = project(model.accel, w0, w1, f_s, f);
    let hx = project(measured.accel, w0, w1, f_s, f);
    let r1 = mag(hr[0]);
    c.amp_ratio_model = mag(hm[0]) / r1;
    c.amp_ratio_measured = mag(hx[0]) / r1;
    c.phase_model_deg = phase_deg(hm[0], hr[0]);
    c.phase_measured_deg = phase_deg(hx[0], hr[0]);
    for k in 2..=N_HARM {
        c.h_model[k - 2] = mag(hm[k - 1]) / mag(hm[0]);
        c.h_measured[k - 2] = mag(hx[k - 1]) / mag(hx[0]);
    }
    c.harm_model = hm.map(|(re, im)| (re / r1, im / r1));
    c.harm_measured = hx.map(|(re, im)| (re / r1, im / r1));
    for k in 0..N_HARM {
        c.residual[k] = (c.harm_model[k].0 - c.harm_measured[k].0, c.harm_model[k].1 - c.harm_measured[k].1);
    }
    // Whole cycles of the window: boundaries at round(i·f_s/f) from the window start.
    let per = f_s / f;
    let cycles = ((w1 - w0) as f64 / per + 1e-9).floor() as usize;
    for i in 0..cycles {
        let (a, b) = (w0 + (i as f64 * per).round() as usize, (w0 + ((i + 1) as f64 * per).round() as usize).min(w1));
        let r = mag(project(&reference.a, a, b, f_s, f)[0]);
        c.cycle_amp_model.push(mag(project(model.accel, a, b, f_s, f)[0]) / r);
        c.cycle_amp_measured.push(mag(project(measured.accel, a, b, f_s, f)[0]) / r);
    }
    c.drift_model = drift(&c.cycle_amp_model);
    c.drift_measured = drift(&c.cycle_amp_measured);
    let w2 = (2.0 * std::f64::consts::PI * f).powi(2);
    c.accel_over_disp_model = mag(hm[0]) / (w2 * mag(project(model.disp, w0, w1, f_s, f)[0]));
    c.accel_over_disp_measured = mag(hx[0]) / (w2 * mag(project(measured.disp, w0, w1, f_s, f)[0]));
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::excitation::Sine;

    #[test]
    fn a_known_difference_is_found_where_it_is() {
        let r = Sine { freq_hz: 2.0, amp_m: 0.05, taper_s: 0.0, duration_s: 4.0, window_cycles: Some(6) }.reference(1024.0);
        let w = 2.0 * std::f64::consts::PI * 2.0;
        let n = r.len();
        let t = |k: usize| k as f64 / 1024.0;
        // "Measured": the reference plus 3 % third harmonic; "model": the reference with a
        // growing envelope (1 % per cycle).
        let meas: Vec<f64> = (0..n).map(|k| r.a[k] + 0.03 * r.a.iter().map(|v| v.abs()).fold(0.0, f64::max) * (3.0 * w * t(k)).sin()).collect();
        let model: Vec<f64> = (0..n).map(|k| r.a[k] * (1.0 + 0.01 * t(k) * 2.0)).collect();
        let c = compare(&r, &Channels { accel: &meas, disp: &r.x, force: None }, &Channels { accel: &model, disp: &r.x, force: None });
        assert!((c.h_measured[1] - 0.03).abs() < 1e-6, "h3 measured {}", c.h_measured[1]);
        // The model's linear envelope is not periodic over the window, so it leaks into every
        // harmonic: its component at 2f bounds h3 by 0.02·(3 s)/(π·12) ≈ 1.6e-3.
        assert!(c.h_model[1] < 1.6e-3, "h3 model {}", c.h_model[1]);
        assert!((mag(c.residual[2]) - 0.03).abs() < 1.6e-3, "the residual sits in k = 3: {}", mag(c.residual[2]));
        // Envelope slope 0.01 per cycle over a window-mean envelope of 1 + 0.02·2.5 s = 1.05.
        assert!((c.drift_model - 0.01 / 1.05).abs() < 1e-4, "model drift {}", c.drift_model);
        assert!(c.drift_measured.abs() < 1e-9);
        assert!((c.amp_ratio_measured - 1.0).abs() < 1e-9 && c.phase_measured_deg.abs() < 1e-9);
        assert_eq!(c.cycle_amp_model.len(), 6);
        assert!(c.rms_residual_disp_ratio == 0.0);
        let fr: f64 = c.bins.iter().map(|b| b.fraction).sum();
        assert!(fr > 0.2 && fr < 1.0);
    }

    #[test]
    fn identical_channels_have_zero_residual() {
        let r = Sine { freq_hz: 3.0, amp_m: 0.02, taper_s: 1.0, duration_s: 3.0, window_cycles: Some(4) }.reference(1024.0);
        let ch = Channels { accel: &r.a, disp: &r.x, force: None };
        let c = compare(&r, &ch, &ch);
        assert_eq!(c.rms_residual_accel_ratio, 0.0);
        assert!(c.residual.iter().all(|z| z.0 == 0.0 && z.1 == 0.0));
        assert!((c.amp_ratio_model - 1.0).abs() < 1e-12);
        // The reference's a and x are one body's: a = −ω²x in the window.
        assert!((c.accel_over_disp_measured - 1.0).abs() < 1e-9, "{}", c.accel_over_disp_measured);
    }
}
