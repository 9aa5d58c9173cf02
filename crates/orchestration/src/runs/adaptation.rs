//! How an adaptive compensator's run settles (issue 52: "the adaptation's history"): the
//! fundamental's amplitude ratio and THD_odd of the acceleration over each whole cycle of a sine
//! run, from its time history, as docs/model.md §5 defines them over the analysis window.

use super::single::History;
use vshake_kernel::excitation::Reference;
use vshake_kernel::metrics::Metrics;

/// One cycle's figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cycle {
    /// The cycle's end, s.
    pub end_s: f64,
    /// |A₁| of the achieved acceleration over |A₁| of the reference's.
    pub amp_ratio: f64,
    /// √(Σ|A_k|², k = 3, 5, 7, 9 below Nyquist) / |A₁| of the achieved acceleration.
    pub thd_odd: f64,
}

/// Each whole cycle of a sine run (none where the reference has no fundamental, or where the
/// history ends before a whole cycle: a failed run's).
pub fn cycles(history: &History, reference: &Reference) -> Vec<Cycle> {
    match (
        reference.fundamental_hz,
        history.channel("accel_mps2"),
        history.channel("ref_accel_mps2"),
    ) {
        (Some(f0), Some(a), Some(r)) => cycles_of(a, r, f0, reference.f_s),
        _ => Vec::new(),
    }
}

/// [`cycles`] of the achieved acceleration `a` against the reference's `r`, sampled at `f_s` Hz
/// from t = 0, at the fundamental `f0` Hz.
pub fn cycles_of(a: &[f64], r: &[f64], f0: f64, f_s: f64) -> Vec<Cycle> {
    let per = f_s / f0;
    let top = Metrics::highest_harmonic(f0, f_s);
    let count = (a.len().min(r.len()) as f64 / per).floor() as usize;
    let tick = |c: usize| (c as f64 * per).round() as usize;
    (0..count)
        .map(|c| {
            let (i0, i1) = (tick(c), tick(c + 1));
            let h = |x: &[f64], k: usize| harmonic(&x[i0..i1], i0, k as f64 * f0 / f_s);
            let h1 = h(a, 1);
            let odd: f64 = (3..=top.min(9)).step_by(2).map(|k| h(a, k).powi(2)).sum();
            Cycle {
                end_s: i1 as f64 / f_s,
                amp_ratio: h1 / h(r, 1),
                thd_odd: odd.sqrt() / h1,
            }
        })
        .collect()
}

/// |X(f)| of `x` (its first sample at tick `k0`) at `f` cycles per tick, by one DFT bin.
fn harmonic(x: &[f64], k0: usize, f: f64) -> f64 {
    let w = 2.0 * std::f64::consts::PI * f;
    let (re, im) = x.iter().enumerate().fold((0.0, 0.0), |(re, im), (i, &v)| {
        let th = w * (k0 + i) as f64;
        (re + v * th.cos(), im - v * th.sin())
    });
    2.0 * (re * re + im * im).sqrt() / x.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A known signal: a sine with a 3rd harmonic of 5 % of its fundamental, 0.9 of the
    /// reference's, at 1024 Hz: exact where a cycle is a whole number of ticks (4 Hz), and within
    /// the leak of the window's rounding where it is not (3 Hz: 341⅓ ticks; measured 1.6e-4 and
    /// 9.5e-4).
    #[test]
    fn a_known_distortion_is_read_back_per_cycle() {
        let (f_s, n) = (1024.0, 4096);
        for (f0, count, tol_ratio, tol_thd) in [(4.0, 16, 1e-12, 1e-12), (3.0, 12, 3e-4, 1.5e-3)] {
            let w = 2.0 * std::f64::consts::PI * f0 / f_s;
            let r: Vec<f64> = (0..n).map(|i| (w * i as f64).sin()).collect();
            let a: Vec<f64> = (0..n)
                .map(|i| {
                    let th = w * i as f64;
                    0.9 * (th + 0.2).sin() + 0.045 * (3.0 * th).cos()
                })
                .collect();
            let cs = cycles_of(&a, &r, f0, f_s);
            assert_eq!(cs.len(), count, "{f0} Hz: {cs:?}");
            for c in &cs {
                assert!((c.amp_ratio - 0.9).abs() < tol_ratio, "{f0} Hz: {c:?}");
                assert!((c.thd_odd - 0.05).abs() < tol_thd, "{f0} Hz: {c:?}");
            }
        }
    }
}
