//! Offline drive iteration (transfer-function iteration), as shake-table controllers do before an
//! earthquake test: find the drive d whose achieved acceleration a(d) reproduces a target a*.
//!
//! 1. The table's frequency response H from a band-limited random run (drive d₀, response a₀):
//!    the H1 estimate H = Σ D̄·A / Σ |D|² over Hann-windowed segments overlapping by half
//!    (Welch; Bendat & Piersol, *Random Data*, 4th ed., 2010, §9.2.3).
//! 2. From d₀ = a*, the update d_{k+1} = d_k + α·H⁻¹(a* − a_k), applied in the frequency domain
//!    on the whole record (zero-padded to twice its length, so that the correction does not wrap
//!    around), with H interpolated linearly to each bin and inverted with Tikhonov regularisation,
//!    H⁻¹ ≈ H̄ / (|H|² + ε·max|H|²), so that bins where the table barely responds (above its band)
//!    are not amplified.
//! 3. Stop when the rms error falls below the goal, stops falling, or after the most iterations.
//!
//! [`iterate`] is pure: the caller runs the table (a real one, or anything) and hands the
//! responses over. [`iterate_on_model`] runs it on the model: the drive is the controller's
//! reference with an acceleration correction added, its velocity and displacement integrated from
//! rest (so the table starts where it stands), and the response is the recorded acceleration.

use crate::fourier::fft;
use crate::runs::single::{run_one, History};
use chacha20::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use vshake_kernel::excitation::Reference;
use vshake_kernel::params::ModelParams;
use vshake_kernel::simulate::{LaneStatus, Solver};

/// A frequency response at bins k = 0…N/2 of an N-point transform of rate `rate_hz`.
#[derive(Debug, Clone)]
pub struct Frf {
    pub rate_hz: f64,
    pub n_fft: usize,
    pub re: Vec<f64>,
    pub im: Vec<f64>,
}

impl Frf {
    /// H at frequency `f_hz`, linear between bins (0 above Nyquist).
    pub fn at(&self, f_hz: f64) -> (f64, f64) {
        let x = f_hz * self.n_fft as f64 / self.rate_hz;
        let k = x.floor() as usize;
        if k + 1 >= self.re.len() {
            return (0.0, 0.0);
        }
        let w = x - k as f64;
        (
            self.re[k] + w * (self.re[k + 1] - self.re[k]),
            self.im[k] + w * (self.im[k + 1] - self.im[k]),
        )
    }
}

/// The H1 estimate of the response to `drive` from segments of `segment` samples (a power of
/// two), Hann-windowed, overlapping by half; 0 at bins the drive did not excite (power below 1e-9
/// of its largest).
pub(crate) fn estimate_frf(drive: &[f64], response: &[f64], rate_hz: f64, segment: usize) -> Frf {
    assert!(segment.is_power_of_two() && drive.len() == response.len());
    let half = segment / 2 + 1;
    let (mut num_re, mut num_im, mut den) = (vec![0.0; half], vec![0.0; half], vec![0.0; half]);
    let hann =
        |j: usize| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * j as f64 / segment as f64).cos();
    let mut start = 0;
    while start + segment <= drive.len() {
        let spectrum = |x: &[f64]| {
            let mut re: Vec<f64> = (0..segment).map(|j| x[start + j] * hann(j)).collect();
            let mut im = vec![0.0; segment];
            fft(&mut re, &mut im);
            (re, im)
        };
        let (dr, di) = spectrum(drive);
        let (ar, ai) = spectrum(response);
        for k in 0..half {
            // conj(D)·A
            num_re[k] += dr[k] * ar[k] + di[k] * ai[k];
            num_im[k] += dr[k] * ai[k] - di[k] * ar[k];
            den[k] += dr[k] * dr[k] + di[k] * di[k];
        }
        start += segment / 2;
    }
    // Where the drive put (almost) no power, the response says nothing of H: 0 there.
    let top = den.iter().copied().fold(0.0, f64::max);
    let safe = |d: f64| if d > 1e-9 * top { d } else { f64::INFINITY };
    Frf {
        rate_hz,
        n_fft: segment,
        re: (0..half).map(|k| num_re[k] / safe(den[k])).collect(),
        im: (0..half).map(|k| num_im[k] / safe(den[k])).collect(),
    }
}

/// H⁻¹ applied to `error` (a record at the FRF's rate), regularised by `epsilon` (a fraction of
/// max |H|²) and zero below `f_min_hz`: the drive correction, as long as `error`.
pub fn correction(frf: &Frf, error: &[f64], epsilon: f64, f_min_hz: f64) -> Vec<f64> {
    let n = (2 * error.len()).next_power_of_two();
    let mut re = error.to_vec();
    re.resize(n, 0.0);
    let mut im = vec![0.0; n];
    fft(&mut re, &mut im);
    let peak = (0..frf.re.len())
        .map(|k| frf.re[k] * frf.re[k] + frf.im[k] * frf.im[k])
        .fold(0.0, f64::max);
    let floor = epsilon * peak;
    for k in 0..=n / 2 {
        let f = k as f64 * frf.rate_hz / n as f64;
        let (hr, hi) = frf.at(f);
        let mag2 = if f < f_min_hz {
            0.0
        } else {
            hr * hr + hi * hi + floor
        };
        // E·conj(H)/(|H|² + ε): real and imaginary parts.
        let (er, ei) = (re[k], im[k]);
        let (cr, ci) = if mag2 > 0.0 {
            ((er * hr + ei * hi) / mag2, (ei * hr - er * hi) / mag2)
        } else {
            (0.0, 0.0)
        };
        re[k] = cr;
        im[k] = ci;
        if k > 0 && k < n / 2 {
            re[n - k] = cr;
            im[n - k] = -ci;
        }
    }
    // The inverse transform: conj, forward, conj, / n (the result is real).
    for v in im.iter_mut() {
        *v = -*v;
    }
    fft(&mut re, &mut im);
    re.truncate(error.len());
    re.iter().map(|v| v / n as f64).collect()
}

/// The settings of an iteration.
#[derive(Debug, Clone, Copy)]
pub struct IterationSettings {
    /// Gain α of each update (0 < α ≤ 1).
    pub gain: f64,
    /// Regularisation ε, a fraction of max |H|².
    pub epsilon: f64,
    /// Most iterations (updates of the drive).
    pub max_iterations: usize,
    /// Stop when the rms error is below this fraction of the target's rms.
    pub goal: f64,
    /// Below this frequency the correction is zero (no drift of the table), Hz.
    pub f_min_hz: f64,
    /// The ticks [start, end) the rms error is taken over (None: all).
    pub window: Option<(usize, usize)>,
}

impl Default for IterationSettings {
    /// α = 0.8, ε = 1e-3, 10 iterations, goal 1 %, no correction below 0.1 Hz [chosen: the
    /// usual settings of offline iteration, a partial step that tolerates an FRF error of a few
    /// tens of percent; 0.1 Hz is below the usable band of a strong-motion record].
    fn default() -> Self {
        IterationSettings {
            gain: 0.8,
            epsilon: 1e-3,
            max_iterations: 10,
            goal: 0.01,
            f_min_hz: 0.1,
            window: None,
        }
    }
}

/// One iteration's outcome: its drive's rms error relative to the target's rms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IterationRow {
    /// 0: the target itself as the drive.
    pub iteration: usize,
    pub rms_error_ratio: f64,
}

/// rms(a − b) / rms(b) over `window` (None: all).
pub(crate) fn rms_ratio_in(a: &[f64], b: &[f64], window: Option<(usize, usize)>) -> f64 {
    let (w0, w1) = window.unwrap_or((0, b.len()));
    let (w1, w0) = (w1.min(a.len()).min(b.len()), w0.min(w1));
    rms_ratio(&a[w0..w1], &b[w0..w1])
}

/// rms(a − b) / rms(b).
pub(crate) fn rms_ratio(a: &[f64], b: &[f64]) -> f64 {
    let e: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let r: f64 = b.iter().map(|y| y * y).sum();
    (e / r).sqrt()
}

/// Iterates the drive of `target` through `run` (drive → response), from the target itself, with
/// the FRF `frf`: the best drive and every iteration's row (`progress` sees each as it comes).
/// Stops at the goal, at the most iterations, or when an update does not lower the error (that
/// drive is then not kept). A failed run ends the iteration with its error.
pub fn iterate<E>(
    target: &[f64],
    frf: &Frf,
    settings: &IterationSettings,
    mut run: impl FnMut(&[f64]) -> Result<Vec<f64>, E>,
    mut progress: impl FnMut(&IterationRow),
) -> Result<(Vec<f64>, Vec<IterationRow>), E> {
    let ratio = |a: &[f64]| rms_ratio_in(a, target, settings.window);
    let mut drive = target.to_vec();
    let mut response = run(&drive)?;
    let mut err = ratio(&response);
    let mut rows = vec![IterationRow {
        iteration: 0,
        rms_error_ratio: err,
    }];
    progress(&rows[0]);
    for iteration in 1..=settings.max_iterations {
        if err <= settings.goal {
            break;
        }
        let e: Vec<f64> = target.iter().zip(&response).map(|(t, a)| t - a).collect();
        let c = correction(frf, &e, settings.epsilon, settings.f_min_hz);
        let next: Vec<f64> = drive
            .iter()
            .zip(&c)
            .map(|(d, c)| d + settings.gain * c)
            .collect();
        let got = run(&next)?;
        let next_err = ratio(&got);
        rows.push(IterationRow {
            iteration,
            rms_error_ratio: next_err,
        });
        progress(&rows[iteration]);
        if !(next_err < err) {
            break;
        }
        (drive, response, err) = (next, got, next_err);
    }
    Ok((drive, rows))
}

/// The band of the random run that measures the table's FRF, Hz [chosen: up to the reference
/// filter's corner (50 Hz), from 0.2 Hz, below which a white acceleration's displacement grows
/// as 1/f³].
pub const FRF_BAND_HZ: (f64, f64) = (0.2, 50.0);

/// Segment of the FRF estimate, samples [chosen: 2 s at 1024 Hz, 0.5 Hz bins; a 20 s run gives
/// 19 averages].
pub const FRF_SEGMENT: usize = 2048;

/// `base` with the acceleration correction `c` (per tick) added and its integrals from rest:
/// v += ∫c, x += ∫∫c (trapezoidal), j += dc/dt (central differences); the command is the new x.
pub(crate) fn with_correction(base: &Reference, c: &[f64]) -> Reference {
    let n = base.len();
    let dt = 1.0 / base.f_s;
    let mut r = base.clone();
    let (mut v, mut x) = (0.0, 0.0);
    for k in 0..n {
        if k > 0 {
            let dv = 0.5 * dt * (c[k - 1] + c[k]);
            x += dt * (v + 0.5 * dv);
            v += dv;
        }
        let (lo, hi) = (k.saturating_sub(1), (k + 1).min(n - 1));
        let j = if hi > lo {
            (c[hi] - c[lo]) / (dt * (hi - lo) as f64)
        } else {
            0.0
        };
        r.x[k] += x;
        r.v[k] += v;
        r.a[k] += c[k];
        r.j[k] += j;
    }
    r.command = r.x.clone();
    r
}

/// `x` with only its content in `band` (Hz) kept, at `rate_hz`.
fn band_limited(x: &[f64], rate_hz: f64, band: (f64, f64)) -> Vec<f64> {
    let n = x.len().next_power_of_two();
    let mut re = x.to_vec();
    re.resize(n, 0.0);
    let mut im = vec![0.0; n];
    fft(&mut re, &mut im);
    for k in 0..n {
        let f = k.min(n - k) as f64 * rate_hz / n as f64;
        if f < band.0 || f > band.1 {
            re[k] = 0.0;
            im[k] = 0.0;
        }
    }
    im.iter_mut().for_each(|v| *v = -*v);
    fft(&mut re, &mut im);
    re.truncate(x.len());
    re.iter().map(|v| v / n as f64).collect()
}

/// A random drive as long as `like`: white noise of `seed` in [`FRF_BAND_HZ`], tapered over 1 s
/// at both ends, of acceleration rms `rms`, from rest.
pub(crate) fn random_drive(like: &Reference, rms: f64, seed: u64) -> Reference {
    let n = like.len();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise: Vec<f64> = (0..n)
        .map(|_| rng.sample::<f64, _>(StandardNormal))
        .collect();
    let mut a = band_limited(&noise, like.f_s, FRF_BAND_HZ);
    let ramp = like.f_s.min(n as f64 / 4.0);
    for (k, v) in a.iter_mut().enumerate() {
        let edge = (k.min(n - 1 - k) as f64 / ramp).min(1.0);
        *v *= 0.5 - 0.5 * (std::f64::consts::PI * edge).cos();
    }
    let scale = rms / (a.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    a.iter_mut().for_each(|v| *v *= scale);
    let mut rest = like.clone();
    for col in [&mut rest.x, &mut rest.v, &mut rest.a, &mut rest.j] {
        col.iter_mut().for_each(|v| *v = 0.0);
    }
    rest.spectrum = None;
    with_correction(&rest, &a)
}

/// The acceleration the model's table records on `reference`, per tick, or why the run failed.
pub(crate) fn table_accel(
    model: &ModelParams,
    solver: &Solver,
    reference: &Reference,
) -> Result<Vec<f64>, String> {
    let mut h = History::with_capacity(reference.len());
    let result = run_one(model, reference, solver, &mut h).map_err(|e| e.to_string())?;
    if let LaneStatus::Failed { time_s, reason } = result.status {
        return Err(format!("the run failed at t = {time_s:.3} s: {reason}"));
    }
    Ok(h.channel("accel_mps2")
        .expect("a history has accel_mps2")
        .to_vec())
}

/// An iteration on the model: the FRF it measured, every iteration's row, the final drive and
/// the acceleration the table achieves with it.
#[derive(Debug, Clone)]
pub struct TableIteration {
    pub frf: Frf,
    /// The target acceleration per tick, m/s².
    pub target: Vec<f64>,
    pub rows: Vec<IterationRow>,
    pub drive: Reference,
    pub achieved: Vec<f64>,
}

/// Iterates the drive of `target` (its acceleration is the target) on `model`: the FRF from a
/// random run of the target's rms (noise of `seed`), then [`iterate`], the error over the
/// target's window.
pub fn iterate_on_model(
    model: &ModelParams,
    solver: &Solver,
    target: &Reference,
    settings: &IterationSettings,
    seed: u64,
    progress: impl FnMut(&IterationRow),
) -> Result<TableIteration, String> {
    if target.len() < 2 * FRF_SEGMENT {
        return Err(format!(
            "the target is {:.2} s long; the frequency response needs at least {:.1} s",
            target.len() as f64 / target.f_s,
            (2 * FRF_SEGMENT) as f64 / target.f_s
        ));
    }
    let a_star = &target.a;
    let rms = (a_star.iter().map(|v| v * v).sum::<f64>() / a_star.len() as f64).sqrt();
    let noise = random_drive(target, rms, seed);
    let response = table_accel(model, solver, &noise)
        .map_err(|e| format!("the random run that measures the FRF: {e}"))?;
    let frf = estimate_frf(&noise.a, &response, target.f_s, FRF_SEGMENT);
    let drive_of = |d: &[f64]| {
        let c: Vec<f64> = d.iter().zip(a_star).map(|(d, t)| d - t).collect();
        with_correction(target, &c)
    };
    let settings = IterationSettings {
        window: Some(target.window),
        ..*settings
    };
    let run = |d: &[f64]| table_accel(model, solver, &drive_of(d));
    let (d, rows) = iterate(a_star, &frf, &settings, run, progress)?;
    let drive = drive_of(&d);
    let achieved = table_accel(model, solver, &drive)?;
    Ok(TableIteration {
        frf,
        target: a_star.clone(),
        rows,
        drive,
        achieved,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use chacha20::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;

    const RATE: f64 = 1024.0;

    /// A linear "table": a resonance at 12 Hz (ζ = 0.2) and a 2-sample delay, as a biquad by the
    /// bilinear transform; its exact response at f.
    struct Plant {
        b: [f64; 3],
        a: [f64; 3],
    }

    impl Plant {
        fn new() -> Self {
            let (w0, zeta) = (2.0 * std::f64::consts::PI * 12.0, 0.2);
            let k = 2.0 * RATE;
            // H(s) = w0² / (s² + 2ζw0 s + w0²), s = k (1 − z⁻¹)/(1 + z⁻¹).
            let a0 = k * k + 2.0 * zeta * w0 * k + w0 * w0;
            Plant {
                b: [w0 * w0 / a0, 2.0 * w0 * w0 / a0, w0 * w0 / a0],
                a: [
                    1.0,
                    (2.0 * w0 * w0 - 2.0 * k * k) / a0,
                    (k * k - 2.0 * zeta * w0 * k + w0 * w0) / a0,
                ],
            }
        }
        fn run(&self, x: &[f64]) -> Vec<f64> {
            let mut y = vec![0.0; x.len()];
            let at = |v: &[f64], i: isize| if i >= 0 { v[i as usize] } else { 0.0 };
            for n in 0..x.len() {
                let i = n as isize - 2; // the delay
                y[n] = self.b[0] * at(x, i) + self.b[1] * at(x, i - 1) + self.b[2] * at(x, i - 2)
                    - self.a[1] * at(&y, n as isize - 1)
                    - self.a[2] * at(&y, n as isize - 2);
            }
            y
        }
        fn exact(&self, f: f64) -> (f64, f64) {
            let w = 2.0 * std::f64::consts::PI * f / RATE;
            let z = |k: f64| ((-k * w).cos(), (-k * w).sin());
            let poly = |c: &[f64; 3], shift: f64| {
                (0..3).fold((0.0, 0.0), |(r, i), j| {
                    let (zr, zi) = z(j as f64 + shift);
                    (r + c[j] * zr, i + c[j] * zi)
                })
            };
            let (nr, ni) = poly(&self.b, 2.0);
            let (dr, di) = poly(&self.a, 0.0);
            let d = dr * dr + di * di;
            ((nr * dr + ni * di) / d, (ni * dr - nr * di) / d)
        }
    }

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| rng.sample::<f64, _>(StandardNormal))
            .collect()
    }

    #[test]
    fn the_frf_of_a_known_plant_is_estimated() {
        let plant = Plant::new();
        // 0.25 Hz bins: the Hann window's smoothing of the resonance (bandwidth 2ζf = 4.8 Hz)
        // stays below 1 %.
        let d = noise(1 << 17, 1);
        let frf = estimate_frf(&d, &plant.run(&d), RATE, 4096);
        for f in [1.0, 5.0, 12.0, 30.0, 80.0] {
            let (er, ei) = plant.exact(f);
            let (hr, hi) = frf.at(f);
            let err = ((hr - er).powi(2) + (hi - ei).powi(2)).sqrt() / (er * er + ei * ei).sqrt();
            assert!(err < 0.03, "{f} Hz: {hr} {hi} vs {er} {ei} ({err})");
        }
    }

    /// With the plant's FRF estimated from noise, a band-limited target (20 s, 0.5–25 Hz) is
    /// reproduced to 1 % rms within 6 iterations, from an error of tens of percent.
    #[test]
    fn the_iteration_converges_on_a_linear_plant() {
        let plant = Plant::new();
        let d = noise(1 << 15, 2);
        let frf = estimate_frf(&d, &plant.run(&d), RATE, 1024);
        let n = (20.0 * RATE) as usize;
        let target: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / RATE;
                let taper = (t / 2.0).min(1.0).min((20.0 - t) / 2.0);
                taper
                    * [0.7, 2.0, 5.5, 11.0, 19.0]
                        .iter()
                        .enumerate()
                        .map(|(i, f)| {
                            (2.0 * std::f64::consts::PI * f * t + i as f64).sin() / (1.0 + i as f64)
                        })
                        .sum::<f64>()
            })
            .collect();
        let settings = IterationSettings {
            goal: 0.01,
            ..Default::default()
        };
        let (drive, rows) = iterate(
            &target,
            &frf,
            &settings,
            |d| Ok::<_, ()>(plant.run(d)),
            |_| {},
        )
        .unwrap();
        eprintln!("{rows:?}");
        assert!(rows[0].rms_error_ratio > 0.2, "{rows:?}");
        let last = rows.last().unwrap();
        assert!(
            last.rms_error_ratio <= 0.01 && last.iteration <= 6,
            "{rows:?}"
        );
        assert!((rms_ratio(&plant.run(&drive), &target) - last.rms_error_ratio).abs() < 1e-15);
        for w in rows.windows(2) {
            assert!(w[1].rms_error_ratio < w[0].rms_error_ratio, "{rows:?}");
        }
    }

    /// The correction of an exact FRF inverts the plant: H⁻¹(H x) = x inside the band.
    #[test]
    fn the_correction_inverts_an_exact_frf() {
        let plant = Plant::new();
        let n_fft = 16384; // the correction's own grid: no interpolation
        let (re, im): (Vec<f64>, Vec<f64>) = (0..=n_fft / 2)
            .map(|k| plant.exact(k as f64 * RATE / n_fft as f64))
            .unzip();
        let frf = Frf {
            rate_hz: RATE,
            n_fft,
            re,
            im,
        };
        // A 3 Hz burst over 0–7 s in an 8 s record, so that the response's tail is recorded.
        let x: Vec<f64> = (0..8192)
            .map(|k| {
                let t = k as f64 / RATE;
                let envelope = (std::f64::consts::PI * t.min(7.0) / 7.0).sin().powi(2);
                (2.0 * std::f64::consts::PI * 3.0 * t).sin() * envelope
            })
            .collect();
        let back = correction(&frf, &plant.run(&x), 1e-9, 0.0);
        assert!(rms_ratio(&back, &x) < 1e-6, "{}", rms_ratio(&back, &x));
    }

    /// The model's table on a 20 s stochastic motion (firm ground, 0.5 g): from the raw motion's
    /// error (26 % rms) to at most 5 % within 6 iterations (here 2.9 % at the second), the drive
    /// kept being the best iteration's.
    #[test]
    fn the_model_table_is_iterated_to_5_percent() {
        use crate::runs::quake;
        use crate::runs::spec::{ExcitationSpec, Realisation};
        use vshake_kernel::ground::Processing;
        let exc = ExcitationSpec::Stochastic {
            duration_s: 20.0,
            realisation: Realisation::Fixed(0),
            seed: None,
            ground: vec![("pga_g", 0.5)],
            processing: Processing::default(),
            f_ref_hz: 50.0,
        };
        let model = ModelParams::default();
        let target = quake::generated(&exc, &model, 7, 0).unwrap();
        let settings = IterationSettings {
            max_iterations: 6,
            goal: 0.01,
            ..Default::default()
        };
        let out = iterate_on_model(&model, &Solver::default(), &target, &settings, 1, |r| {
            eprintln!("{r:?}")
        })
        .unwrap();
        let rows = &out.rows;
        assert!(rows[0].rms_error_ratio > 0.2, "{rows:?}");
        // The kept drive is the best iteration's (a last update that raised the error is not).
        let best = rows
            .iter()
            .min_by(|a, b| a.rms_error_ratio.total_cmp(&b.rms_error_ratio))
            .unwrap();
        let first_under = rows.iter().find(|r| r.rms_error_ratio <= 0.05).unwrap();
        assert!(first_under.iteration <= 6, "{rows:?}");
        let again = rms_ratio_in(&out.achieved, &target.a, Some(target.window));
        assert!((again - best.rms_error_ratio).abs() < 1e-12, "{again}");
    }
}
