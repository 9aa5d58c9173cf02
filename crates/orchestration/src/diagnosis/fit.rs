//! Fitting: nonlinear least squares of model parameters against a campaign of measured tests.
//!
//! **Features.** A fit does not match raw time histories (noise, and the window's start, would
//! dominate); it matches features that average noise out, computed on the file's own samples
//! (the model interpolated there, [`vshake_kernel::resample`]):
//! - a sine test, per channel (acceleration, displacement, force where the file has it), over
//!   the analysis window, model minus measured: the complex harmonics k = 1…9 (those below the
//!   file's Nyquist frequency), by least squares ([`crate::diagnosis::projector::Projector`], built once per
//!   test); the mean (displacement and force: a static offset, e.g. of a leaking loop; the
//!   accelerometer's mean is its bias, not physics); and the *remainder* (I − P)(model −
//!   measured)/σ at each sample, what neither the mean nor the harmonics hold (an oscillation at
//!   another frequency, harmonics above the 9th, an envelope that drifts). Without the last two a fit could
//!   lower χ² while leaving a static offset or a limit cycle that the time-domain residual shows;
//!   with them χ² is the time-domain χ² of the window, split into its parts;
//! - a record test: the residual of each channel at every sample of the window. There are no
//!   harmonics to average the noise into, and any summary (block means, a band of the spectrum)
//!   hides part of the residual a user sees: block means of 1/64 s pass nothing above 32 Hz, so
//!   a fit could lower their χ² while raising the residual's rms. With every sample, χ² is the
//!   time-domain χ² of the window (Σ e²/σ², channel by channel), which falls exactly when each
//!   channel's residual rms falls; the evidence by frequency band is its split by Parseval
//!   ([`crate::fourier::band_energy`]).
//!
//! Each feature is divided by its noise standard deviation, so the sum of squares χ² is a
//! chi-square when the model is right. The noise of a channel is estimated from the measured data
//! itself ([`noise_sigma`]):
//! - a sine test: the residual of a least-squares fit of every harmonic of the test's frequency
//!   up to 0.45 of the file's rate (at most 60), a quadratic trend, a linearly drifting
//!   fundamental and a sinusoid at each spectral line between the harmonics
//!   ([`crate::diagnosis::signals`]; a hum is a signal, which left in σ would hide itself from
//!   χ²), over the window: σ² = RSS/(n − p). It holds at any sample rate (third
//!   differences, which keep (2πf/R)³ of a smooth signal, do not at 256 Hz);
//! - a record test: the level of the spectrum's top band, 0.4 to 0.5 of the rate
//!   ([`crate::fourier::noise_sigma`]): the motion is band-limited, the sensors' noise is not
//!   (third differences, σ = rms(Δ³x)/√20, keep (2πf/R)³ of the motion and overstate it at the
//!   rates where a table's broadband motion reaches 50 Hz; they remain the fallback for a record
//!   too short for the band to hold 16 bins).
//!
//! Both are floored at [`NUMERICAL_FLOOR`] of the channel's rms: a channel recorded without
//! noise (a synthetic force) is still only as exact as the model is, and a weight beyond that
//! would make its standard errors claim a precision no implementation of the model has. A
//! harmonic of white noise over W samples has σ·√(2/W) per component, a mean σ/√W, a sample σ;
//! the remainder's square has W − p degrees of freedom (p functions fitted), so a model right to
//! the noise leaves χ² ≈ n, the features' degrees of freedom ([`Problem::dof`]).
//! Campaign channel weights multiply.
//!
//! **Solver.** Levenberg–Marquardt on u, the free parameters in scaled coordinates (log of the
//! ratio to the start for a positive parameter, else the change over the start's magnitude),
//! clamped to each parameter's valid range. The Jacobian comes from forward differences (step
//! 1e-3 in u); the base point, the perturbed points and the trial steps of one iteration are lanes
//! of one batch on the lane kernel, and the tests run in parallel. Linear algebra by faer.
//! Standard errors: Cov(u) = s²·(JᵀJ)⁻¹ with s² = max(1, χ²/(n − p)) (inflated when the model
//! still misfits), checked along each parameter by direct evaluation ([`profiled`]: never smaller
//! than χ²'s own curvature where it rises by 4s²), mapped to the parameters' units.

use crate::measured::aligned::{wrap_deg, AlignedTest, Samples};
use crate::measured::campaign::Weights;
use faer::prelude::*;
use faer::Mat;
use rayon::prelude::*;
use vshake_kernel::excitation::Reference;
use vshake_kernel::params::{EffectId, ModelParams, ParamInfo};
use vshake_kernel::resample::{ch, Resampler};
use vshake_kernel::simulate::{LaneResult, LaneStatus, Solver};
use vshake_kernel::EFFECT_LANES as LANES;

/// Forward-difference step in the scaled coordinates.
const H: f64 = 1e-3;

/// The least noise σ a channel is given, as a share of its rms [chosen: 1e-4, the numerical floor
/// of the model against data made by another implementation of it, or at another sample rate:
/// the round trips of tests/roundtrip.rs agree to that order, 1e-4 of the rms at 500 Hz].
pub const NUMERICAL_FLOOR: f64 = 1e-4;

/// Which channel a feature comes from.
pub const CHANNELS: [&str; 3] = ["accel", "disp", "force"];

/// [`FeatureInfo::harmonic`] of a sine test's mean (displacement and force).
pub const MEAN: usize = 100;
/// [`FeatureInfo::harmonic`] of a sine test's remainder: the part of the residual that neither
/// the mean nor the harmonics hold.
pub const REMAINDER: usize = 101;

/// What one feature is: its test, channel (index into [`CHANNELS`]) and harmonic (0 for a sample,
/// [`MEAN`], [`REMAINDER`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeatureInfo {
    pub test: usize,
    pub channel: usize,
    pub harmonic: usize,
}

/// One measured test, prepared for fitting.
pub struct TestData {
    pub name: String,
    /// The test's model (campaign model with its overrides); free parameters are set on it.
    pub model: ModelParams,
    /// The effects the campaign switches off in this test by name (`enabled = false`): a fit
    /// that adds one leaves it off here ([`as_switched`]).
    pub off: Vec<EffectId>,
    /// The model's drive at the controller's ticks.
    pub drive: Reference,
    /// The compared samples (the analysis window in the file).
    pub samples: Samples,
    /// Measured channels at the samples: acceleration, displacement, force (if the file has it).
    pub measured: [Option<Vec<f64>>; 3],
    pub weights: Weights,
    /// Noise standard deviation per channel, estimated from the data.
    pub sigma: [f64; 3],
    /// Measured features (unweighted) and each one's standard deviation × 1/weight.
    meas: Vec<f64>,
    scale: Vec<f64>,
    info: Vec<FeatureInfo>,
    /// The harmonic projector of the samples (sine tests), built once.
    proj: Option<crate::diagnosis::projector::Projector>,
    /// Degrees of freedom of the features ([`TestData::dof`]).
    dof: f64,
    /// The same, per channel (acceleration, displacement, force).
    dof_ch: [f64; 3],
}

fn rms_slice(v: &[f64]) -> f64 {
    (v.iter().map(|a| a * a).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// σ of white noise in `x` from its third differences, floored at [`NUMERICAL_FLOOR`] of its rms.
pub(crate) fn noise_sigma_differences(x: &[f64]) -> f64 {
    let d3: Vec<f64> = x
        .windows(4)
        .map(|w| w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0])
        .collect();
    (rms_slice(&d3) / 20f64.sqrt())
        .max(NUMERICAL_FLOOR * rms_slice(x))
        .max(f64::MIN_POSITIVE)
}

/// σ of white noise in `x` sampled at model times `tau` at `rate_hz`: see the module docs. With
/// a fundamental `f`, the residual of the periodic fit; without, third differences.
pub fn noise_sigma(x: &[f64], tau: &[f64], rate_hz: f64, f: Option<f64>) -> f64 {
    let Some(f) = f else {
        return crate::fourier::noise_sigma(x)
            .unwrap_or_else(|| noise_sigma_differences(x))
            .max(NUMERICAL_FLOOR * rms_slice(x))
            .max(f64::MIN_POSITIVE);
    };
    let n = x.len();
    let k_max = ((0.45 * rate_hz / f).floor() as usize).min(60);
    let p = 2 * k_max + 5;
    if k_max == 0 || n < p + 20 {
        return noise_sigma_differences(x);
    }
    let floor = NUMERICAL_FLOOR * rms_slice(x);
    let r = periodic_residual(x, tau, f, k_max, &[]);
    // Spectral lines between the harmonics are a signal (a hum, a ripple), not noise: fitted
    // with the harmonics, they do not raise σ and hide themselves from χ². (Not required to be
    // as narrow as the window: the harmonics' own fit leaves a spur beside a line it leaks into.)
    let lines: Vec<f64> =
        (crate::diagnosis::signals::line_frequencies(&r, rate_hz, Some(f), floor))
            .into_iter()
            .map(|fl| crate::diagnosis::signals::refined_frequency(&r, tau, fl, rate_hz))
            .collect();
    let r = match lines.len() {
        0 => r,
        _ => periodic_residual(x, tau, f, k_max, &lines),
    };
    let p = p + 2 * lines.len();
    let rss: f64 = r.iter().map(|v| v * v).sum();
    (rss / n.saturating_sub(p).max(1) as f64)
        .sqrt()
        .max(floor)
        .max(f64::MIN_POSITIVE)
}

/// σ of channel `c`'s noise in `x` ([`noise_sigma`]). A tracked reference's derivatives are only
/// as exact as the record lets them be (docs/model.md §4): their estimated error over a_r's rms,
/// `accel_floor`, is a floor of the acceleration's and the force's (the inertia's share) noise
/// over their rms; the displacement's is below its own.
fn channel_sigma(x: &[f64], s: &Samples, c: usize, accel_floor: f64) -> f64 {
    let sigma = noise_sigma(x, &s.tau, s.rate_hz, s.fundamental_hz);
    match c {
        1 => sigma,
        _ => sigma.max(accel_floor * rms_slice(x)),
    }
}

/// The floor a tracked record sets on each channel (acceleration, displacement, force; their
/// units): the rms, at the samples `tau`, of the channels of `model` run on the drive plus
/// [`Reference::record_error`] less those run on the drive. The model's reference is the record,
/// its noise and its printed digits included, and its derivatives filtered at a corner that
/// takes some of its content off, while the table tracked the reference before the noise was
/// added, with its true derivatives (docs/model.md §4). Six broadband tests whose `ref_disp_m`
/// was written to 6 significant digits, nothing hidden: the force's χ²/dof 0.25 to 1.5 with this
/// floor (and the corner chosen from the record's noise read per sample). Zero where the
/// reference is exact, or a run fails.
pub fn reference_floor(model: &ModelParams, drive: &Reference, tau: &[f64]) -> [f64; 3] {
    if drive.record_error.is_empty() || tau.is_empty() {
        return [0.0; 3];
    }
    let mut noisy = drive.clone();
    for (k, s) in drive.record_error.iter().enumerate().take(drive.len()) {
        noisy.x[k] += s[0];
        noisy.v[k] += s[1];
        noisy.a[k] += s[2];
        noisy.j[k] += s[3];
    }
    let refs: [&Reference; LANES] = std::array::from_fn(|l| if l == 0 { drive } else { &noisy });
    let mut rs = Resampler::<LANES>::new(tau);
    let solver = Solver::default();
    let ran = vshake_kernel::builds::run_effect_lanes(&[model, model], &refs, &solver, &mut rs);
    match ran {
        Ok(r) if r[..2].iter().all(|r| r.status == LaneStatus::Ok) => {
            [ch::ACCEL, ch::DISP, ch::FORCE].map(|c| {
                let lanes = rs.lanes(c);
                rms_of(lanes[0].iter().zip(&lanes[1]).map(|(a, b)| b - a))
            })
        }
        _ => [0.0; 3],
    }
}

/// The residual of the least-squares fit to `x` at `tau` of the harmonics 1…`k_max` of `f`, a
/// quadratic trend, a linearly drifting fundamental and a sinusoid at each of `lines` (Hz).
fn periodic_residual(x: &[f64], tau: &[f64], f: f64, k_max: usize, lines: &[f64]) -> Vec<f64> {
    let n = x.len();
    let p = 2 * k_max + 5;
    let (t0, t1) = (tau[0], tau[n - 1]);
    let (mid, half) = (0.5 * (t0 + t1), (0.5 * (t1 - t0)).max(f64::MIN_POSITIVE));
    let turn = |c: f64| 2.0 * std::f64::consts::PI * (c - c.floor());
    let a = Mat::<f64>::from_fn(n, p + 2 * lines.len(), |i, j| {
        let s = (tau[i] - mid) / half;
        let th = |k: usize| turn(f * tau[i] * k as f64);
        match j {
            0 => 1.0,
            1 => s,
            2 => s * s,
            3 => s * th(1).cos(),
            4 => s * th(1).sin(),
            j if j >= p => {
                let w = turn(lines[(j - p) / 2] * tau[i]);
                if (j - p).is_multiple_of(2) {
                    w.cos()
                } else {
                    w.sin()
                }
            }
            _ => {
                let k = (j - 5) / 2 + 1;
                if (j - 5) % 2 == 0 {
                    th(k).cos()
                } else {
                    th(k).sin()
                }
            }
        }
    });
    let b = Mat::<f64>::from_fn(n, 1, |i, _| x[i]);
    let coef = a.qr().solve_lstsq(&b);
    let fitted = &a * &coef;
    (0..n).map(|i| x[i] - fitted[(i, 0)]).collect()
}

/// The unweighted linear features of channel `c` at the samples `s`: the harmonics below the
/// Nyquist frequency and, for displacement and force, the mean (a sine, `proj` of the samples);
/// or every sample (a record).
fn channel_features(
    proj: Option<&crate::diagnosis::projector::Projector>,
    c: usize,
    x: &[f64],
) -> Vec<f64> {
    match proj {
        Some(p) => {
            let h = p.apply(x);
            let mut f: Vec<f64> = h[..p.n_harm()].iter().flat_map(|c| [c.0, c.1]).collect();
            if c != 0 {
                f.push(p.mean(x));
            }
            f
        }
        None => x.to_vec(),
    }
}

impl TestData {
    /// Prepares a measured test aligned to the model.
    pub fn new(t: &AlignedTest) -> Self {
        let m = &t.measured;
        let floor = reference_floor(&t.model, &t.drive, &t.samples.tau);
        Self::from_parts(
            t.name.clone(),
            t.model.clone(),
            t.drive.clone(),
            t.samples.clone(),
            [Some(m.accel.clone()), Some(m.disp.clone()), m.force.clone()],
            (t.weights, floor),
        )
        .switched_off(t.off.clone())
    }

    /// The test with the effects its campaign switches off by name ([`TestData::off`]).
    pub fn switched_off(self, off: Vec<EffectId>) -> Self {
        TestData { off, ..self }
    }

    /// Prepares a test from its parts: the measured features, the noise estimate (each channel's,
    /// with the floor its record's resolution sets, `floor`: [`reference_floor`]) and the feature
    /// scales.
    pub(crate) fn from_parts(
        name: String,
        model: ModelParams,
        drive: Reference,
        samples: Samples,
        measured: [Option<Vec<f64>>; 3],
        (weights, floor): (Weights, [f64; 3]),
    ) -> Self {
        let w = [weights.accel, weights.disp, weights.force];
        let proj = samples
            .fundamental_hz
            .map(|f| crate::diagnosis::projector::Projector::new(&samples.tau, f, samples.n_harm));
        let mut t = TestData {
            name,
            model,
            off: Vec::new(),
            drive,
            samples,
            measured,
            weights,
            sigma: [f64::NAN; 3],
            meas: Vec::new(),
            scale: Vec::new(),
            info: Vec::new(),
            proj,
            dof: 0.0,
            dof_ch: [0.0; 3],
        };
        let sine = t.samples.fundamental_hz.is_some();
        let n = t.samples.len();
        for c in 0..3 {
            let Some(x) = &t.measured[c] else { continue };
            if w[c] <= 0.0 {
                continue;
            }
            let sigma = channel_sigma(x, &t.samples, c, t.drive.accel_floor).hypot(floor[c]);
            t.sigma[c] = sigma;
            let fs = channel_features(t.proj.as_ref(), c, x);
            let sd = if sine {
                sigma * (2.0 / n as f64).sqrt()
            } else {
                sigma
            };
            let n_harm = t.proj.as_ref().map_or(0, |p| 2 * p.n_harm());
            for (i, v) in fs.iter().enumerate() {
                t.meas.push(*v);
                let (scale, harmonic) = match () {
                    _ if !sine => (sd, 0),
                    _ if i < n_harm => (sd, i / 2 + 1),
                    // The mean of white noise over n samples: σ/√n.
                    _ => (sigma / (n as f64).sqrt(), MEAN),
                };
                t.scale.push(scale / w[c]);
                t.info.push(FeatureInfo {
                    test: 0,
                    channel: c,
                    harmonic,
                });
                t.dof_ch[c] += 1.0;
            }
            t.push_remainder(c, sigma / w[c]);
        }
        t.dof = t.dof_ch.iter().sum();
        t
    }

    /// A sine test's remainder features of channel `c`, each of scale `scale` (its σ over its
    /// weight): (I − P)(model − measured)/σ at each sample (measured value 0), whose sum of
    /// squares is a χ² of n − p degrees of freedom for a model right to the noise. Each sample a
    /// feature, not their norm alone: a parameter that acts through the remainder (a line between
    /// the harmonics, a mode above the 9th) then has its full curvature in JᵀJ, where one norm
    /// per channel gave it rank one (a 0.1 m/s² line at 37.3 Hz in 1–8 Hz tests, its sine in the
    /// first test: 9.2e-2 ± 3.3e-2 m/s² from the norm, ± 8.0e-4 from the samples, σ√(2/n) for
    /// its noise; the tutorial's seal friction converges in 4 iterations, not 15). None for a
    /// record test.
    fn push_remainder(&mut self, c: usize, scale: f64) {
        let Some(p) = &self.proj else { return };
        let n = self.samples.len();
        for _ in 0..n {
            self.meas.push(0.0);
            self.scale.push(scale);
            self.info.push(FeatureInfo {
                test: 0,
                channel: c,
                harmonic: REMAINDER,
            });
        }
        self.dof_ch[c] += n.saturating_sub(p.n_functions()) as f64;
    }

    /// The χ² a model right to the noise leaves in this test's features (their degrees of freedom).
    pub fn dof(&self) -> f64 {
        self.dof
    }

    /// Number of features of this test.
    pub fn len(&self) -> usize {
        self.meas.len()
    }
    pub fn is_empty(&self) -> bool {
        self.meas.is_empty()
    }
}

/// The model evaluated at one parameter set, over the campaign.
#[derive(Debug, Clone)]
pub struct Eval {
    /// Weighted residual features (model − measured)/σ, all tests in order; empty on failure.
    pub r: Vec<f64>,
    /// Per test and channel (acceleration, displacement, force): rms of the residual over rms
    /// of the measurement, over the analysis window (NaN where the file lacks the channel).
    pub rms: Vec<[f64; 3]>,
    /// Why the model failed in some test, if it did.
    pub failure: Option<String>,
}

impl Eval {
    /// The residual rms of test `t`, over its channels.
    pub fn test_rms(&self, t: usize) -> f64 {
        rms_of(self.rms[t].iter().copied())
    }
    /// The residual rms of channel `c` over the tests (NaN where no test has it).
    pub(crate) fn channel_rms(&self, c: usize) -> f64 {
        let v: Vec<f64> = self
            .rms
            .iter()
            .map(|r| r[c])
            .filter(|x| !x.is_nan())
            .collect();
        if v.is_empty() {
            f64::NAN
        } else {
            rms_of(v.into_iter())
        }
    }
    /// The campaign's residual rms: over every test and channel.
    pub fn residual_rms(&self) -> f64 {
        rms_of(self.rms.iter().flat_map(|r| r.iter().copied()))
    }
    pub fn chi2(&self) -> f64 {
        if self.failure.is_some() {
            f64::INFINITY
        } else {
            self.r.iter().map(|v| v * v).sum()
        }
    }
}

fn rms_of(v: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0);
    for x in v.filter(|x| !x.is_nan()) {
        s += x * x;
        n += 1;
    }
    (s / n.max(1) as f64).sqrt()
}

/// A campaign prepared for fitting.
pub struct Problem {
    pub tests: Vec<TestData>,
    /// The integrator's settings for every evaluation.
    pub solver: Solver,
    /// Told the number of model runs (test × parameter set) each time a group of them finishes,
    /// from any thread: the shell's progress display.
    pub progress: Option<std::sync::Arc<dyn Fn(usize) + Send + Sync>>,
}

/// One lane's weighted residual features and rms residuals, or why its run failed.
type Lane = Result<(Vec<f64>, [f64; 3]), String>;

impl TestData {
    /// [`TestData::lane_features`] of the lanes `runs` of a run resampled at the test's samples.
    fn lanes_features(&self, rs: &Resampler<LANES>, runs: &[LaneResult]) -> Vec<Lane> {
        let model_ch = [ch::ACCEL, ch::DISP, ch::FORCE].map(|c| rs.lanes(c));
        (runs.iter().enumerate())
            .map(|(l, r)| match r.status {
                LaneStatus::Failed { time_s, reason } => Err(format!(
                    "test {:?}: the model failed at t = {time_s:.4} s: {reason}",
                    self.name
                )),
                LaneStatus::Ok => Ok(self.lane_features(model_ch.each_ref().map(|c| &c[l][..]))),
            })
            .collect()
    }

    /// The weighted residual features of lane `l` of a run resampled at the test's samples, and
    /// the rms residual / rms measured of each channel (acceleration, displacement, force).
    fn lane_features(&self, model_ch: [&[f64]; 3]) -> (Vec<f64>, [f64; 3]) {
        let mut r = Vec::with_capacity(self.len());
        let mut at = 0;
        for c in 0..3 {
            // The channels with features: measured and weighted (σ set).
            if self.measured[c].is_none() || !(self.sigma[c] > 0.0) {
                continue;
            }
            let push = |v: f64| {
                r.push((v - self.meas[at]) / self.scale[at]);
                at += 1;
            };
            match &self.proj {
                Some(p) => channel_features(Some(p), c, model_ch[c])
                    .into_iter()
                    .for_each(push),
                None => model_ch[c].iter().copied().for_each(push),
            }
            if let (Some(p), Some(x)) = (&self.proj, &self.measured[c]) {
                let e: Vec<f64> = model_ch[c].iter().zip(x).map(|(a, b)| a - b).collect();
                for v in p.remainder(&e) {
                    r.push(v / self.scale[at]);
                    at += 1;
                }
            }
        }
        let rms: [f64; 3] = std::array::from_fn(|c| match &self.measured[c] {
            Some(x) => {
                let num: f64 = x
                    .iter()
                    .zip(model_ch[c])
                    .map(|(a, b)| (b - a).powi(2))
                    .sum();
                let den: f64 = x.iter().map(|a| a * a).sum();
                (num / den).sqrt()
            }
            None => f64::NAN,
        });
        (r, rms)
    }
}

impl Problem {
    pub fn new(mut tests: Vec<TestData>) -> Self {
        for (i, t) in tests.iter_mut().enumerate() {
            for f in &mut t.info {
                f.test = i;
            }
        }
        Problem {
            tests,
            solver: Solver::default(),
            progress: None,
        }
    }

    /// The χ² a model right to the noise leaves: the features' degrees of freedom.
    pub fn dof(&self) -> f64 {
        self.tests.iter().map(|t| t.dof()).sum()
    }

    /// The residual rms a model right to the noise would leave: over every test and channel, the
    /// estimated noise σ over the measurement's rms (the floor of [`Eval::residual_rms`]).
    pub fn noise_rms(&self) -> f64 {
        rms_of(self.tests.iter().flat_map(|t| {
            (0..3).map(move |c| match &t.measured[c] {
                Some(x) if t.sigma[c] > 0.0 => t.sigma[c] / rms_slice(x),
                _ => f64::NAN,
            })
        }))
    }

    /// [`Problem::noise_rms`] of one channel (0 acceleration, 1 displacement, 2 force): over the
    /// tests that have it; NaN where none does.
    pub(crate) fn channel_noise_rms(&self, c: usize) -> f64 {
        let v: Vec<f64> = (self.tests.iter())
            .filter_map(|t| match &t.measured[c] {
                Some(x) if t.sigma[c] > 0.0 => Some(t.sigma[c] / rms_slice(x)),
                _ => None,
            })
            .collect();
        if v.is_empty() {
            f64::NAN
        } else {
            rms_of(v.into_iter())
        }
    }

    /// Per test: the phase of the acceleration's fundamental, model minus measured, in degrees,
    /// under the evaluation `e` (NaN for a record test or a failed evaluation). Evidence of a
    /// lag: a missing lag shows as a phase error that grows with frequency.
    pub fn fundamental_phase_error(&self, e: &Eval) -> Vec<f64> {
        let mut at = 0;
        self.tests
            .iter()
            .map(|t| {
                let start = at;
                at += t.len();
                // The acceleration's features come first in a test: H1 is features 0 (re) and 1 (im).
                let first = t.info.first().copied();
                if e.failure.is_some()
                    || t.samples.fundamental_hz.is_none()
                    || first.map(|f| f.channel) != Some(0)
                {
                    return f64::NAN;
                }
                let (mr, mi) = (t.meas[0], t.meas[1]);
                let (xr, xi) = (
                    mr + e.r[start] * t.scale[0],
                    mi + e.r[start + 1] * t.scale[1],
                );
                wrap_deg((xi.atan2(xr) - mi.atan2(mr)).to_degrees())
            })
            .collect()
    }

    /// The weighted misfit the fit minimises, per test and channel (acceleration, displacement,
    /// force): χ² over its degrees of freedom, about 1 for a model right to the noise (NaN where
    /// the test has no features of the channel, or the evaluation failed).
    pub fn chi2_table(&self, e: &Eval) -> Vec<[f64; 3]> {
        chi2_per_channel(&self.features(), e, &self.dof_table())
    }

    /// Per test, the degrees of freedom of each channel's features (acceleration, displacement,
    /// force): the χ² a model right to the noise leaves in them.
    pub fn dof_table(&self) -> Vec<[f64; 3]> {
        self.tests.iter().map(|t| t.dof_ch).collect()
    }

    /// Per test, √(χ²/dof) over its channels: the residual in units of its noise (about 1 at
    /// the noise; NaN where the evaluation failed).
    pub fn test_misfit(&self, e: &Eval) -> Vec<f64> {
        let mut sum = vec![0.0; self.tests.len()];
        for (f, r) in self.features().iter().zip(&e.r) {
            sum[f.test] += r * r;
        }
        (self.tests.iter().zip(sum))
            .map(|(t, s)| match e.failure {
                None if t.dof > 0.0 => (s / t.dof).sqrt(),
                _ => f64::NAN,
            })
            .collect()
    }

    /// What each feature is, all tests in order.
    pub fn features(&self) -> Vec<FeatureInfo> {
        self.tests
            .iter()
            .flat_map(|t| t.info.iter().copied())
            .collect()
    }

    /// Evaluates `sets(test)` — one model per parameter set for each test — in batches of
    /// [`LANES`] lanes, the tests in parallel.
    pub fn evaluate(
        &self,
        n_sets: usize,
        set: &(dyn Fn(usize, usize, &ModelParams) -> ModelParams + Sync),
    ) -> Vec<Eval> {
        let chunks: Vec<(usize, usize)> = (0..self.tests.len())
            .flat_map(|t| (0..n_sets.div_ceil(LANES)).map(move |c| (t, c)))
            .collect();
        // Per (test, chunk): per lane, the weighted features and rms, or a failure.
        let done: Vec<Vec<Lane>> = chunks
            .par_iter()
            .map(|&(ti, c)| {
                let t = &self.tests[ti];
                let lo = c * LANES;
                let hi = (lo + LANES).min(n_sets);
                let models: Vec<ModelParams> = (lo..hi).map(|k| set(k, ti, &t.model)).collect();
                let refs: Vec<&ModelParams> = models.iter().collect();
                if let Some(bad) = models.iter().find_map(|m| m.validate().err()) {
                    let msg = bad
                        .iter()
                        .map(|i| i.to_string())
                        .collect::<Vec<_>>()
                        .join("; ");
                    return vec![Err(format!("test {:?}: {msg}", t.name)); hi - lo];
                }
                let mut rs = Resampler::<LANES>::new(&t.samples.tau);
                let res = match crate::runs::single::run_lanes_single(
                    &refs,
                    &t.drive,
                    &self.solver,
                    &mut rs,
                ) {
                    Ok(r) => r,
                    Err(e) => return vec![Err(format!("test {:?}: {e}", t.name)); hi - lo],
                };
                if let Some(p) = &self.progress {
                    p(hi - lo);
                }
                t.lanes_features(&rs, &res[..hi - lo])
            })
            .collect();
        (0..n_sets)
            .map(|k| {
                let mut e = Eval {
                    r: Vec::new(),
                    rms: Vec::new(),
                    failure: None,
                };
                for (i, &(_, c)) in chunks.iter().enumerate() {
                    if k / LANES != c {
                        continue;
                    }
                    match &done[i][k % LANES] {
                        Ok((r, rms)) => {
                            e.r.extend_from_slice(r);
                            e.rms.push(*rms);
                        }
                        Err(m) => {
                            e.failure.get_or_insert_with(|| m.clone());
                            e.rms.push([f64::NAN; 3]);
                        }
                    }
                }
                if e.failure.is_some() {
                    e.r.clear();
                }
                e
            })
            .collect()
    }
}

/// A free parameter: its registry row and the start value.
#[derive(Clone, Copy)]
pub struct Free {
    pub info: &'static ParamInfo,
    pub start: f64,
    /// Scaled by log (a positive parameter) or linearly.
    pub log: bool,
    /// The tests it is set in, a bit each ([`ALL_TESTS`]: every one): an effect fitted to a
    /// group of tests is on in those alone (a specimen on the table for some tests).
    pub tests: u64,
}

/// [`Free::tests`] of a parameter set in every test.
pub const ALL_TESTS: u64 = u64::MAX;

/// Most tests a group may be made of ([`Free::tests`]: one bit each).
pub const GROUP_TESTS: usize = 64;

impl Free {
    pub fn new(info: &'static ParamInfo, start: f64) -> Self {
        Free {
            info,
            start,
            log: start > 0.0 && info.range.lo >= 0.0,
            tests: ALL_TESTS,
        }
    }
    /// The same parameter (in the same tests) started at `start`.
    pub fn at(&self, start: f64) -> Self {
        Free {
            tests: self.tests,
            ..Free::new(self.info, start)
        }
    }
    /// The same parameter set in the tests `group` alone (indices below [`GROUP_TESTS`]).
    pub fn in_tests(&self, group: &[usize]) -> Self {
        let tests = group.iter().fold(0u64, |m, &t| m | 1u64 << t);
        Free { tests, ..*self }
    }
    /// Whether it is set in test `test`.
    pub fn applies(&self, test: usize) -> bool {
        self.tests == ALL_TESTS || (test < GROUP_TESTS && self.tests >> test & 1 == 1)
    }
    /// The parameter's value at scaled coordinate u, inside its valid range.
    pub fn value(&self, u: f64) -> f64 {
        let u = if u.is_finite() { u } else { 0.0 };
        let v = if self.log {
            self.start * u.exp()
        } else {
            self.start + u * self.start.abs().max(1.0)
        };
        // Inside the valid range (an open end is kept a relative 1e-12 away).
        let r = self.info.range;
        let lo = if !r.lo.is_finite() {
            f64::MIN
        } else if r.lo_inclusive {
            r.lo
        } else {
            r.lo + r.lo.abs() * 1e-12 + f64::MIN_POSITIVE
        };
        let hi = if !r.hi.is_finite() {
            f64::MAX
        } else if r.hi_inclusive {
            r.hi
        } else {
            r.hi - r.hi.abs() * 1e-12 - f64::MIN_POSITIVE
        };
        v.clamp(lo, hi)
    }
    /// The scaled coordinate of `value` (the inverse of [`Free::value`] inside the range).
    pub(crate) fn u_of(&self, value: f64) -> f64 {
        if self.log {
            (value / self.start).ln()
        } else {
            (value - self.start) / self.start.abs().max(1.0)
        }
    }
    /// d value / d u at u.
    pub fn slope(&self, u: f64) -> f64 {
        if self.log {
            self.value(u)
        } else {
            self.start.abs().max(1.0)
        }
    }
}

/// Sets the free parameters at `u` on `model`, test `test`'s (switching on the effects they
/// belong to; those set in other tests only left as they are).
pub fn apply(test: usize, model: &ModelParams, free: &[Free], u: &[f64]) -> ModelParams {
    with_values(
        test,
        model,
        free,
        free.iter().zip(u).map(|(f, &x)| f.value(x)),
    )
}

/// `model` with the parameters `free` at the values `estimate` (in their units), their effects
/// switched on, every parameter set whatever its tests: a fit's model file, whatever start its
/// scaled coordinates are relative to.
pub fn apply_estimates(model: &ModelParams, free: &[Free], estimate: &[f64]) -> ModelParams {
    let every: Vec<Free> = (free.iter())
        .map(|f| Free {
            tests: ALL_TESTS,
            ..*f
        })
        .collect();
    with_values(0, model, &every, estimate.iter().copied())
}

/// [`apply_estimates`] on test `test`'s model: the parameters set in other tests only left as
/// they are.
pub fn apply_estimates_in(
    test: usize,
    model: &ModelParams,
    free: &[Free],
    estimate: &[f64],
) -> ModelParams {
    with_values(test, model, free, estimate.iter().copied())
}

/// `free` with each effect's parameters set in the tests the campaign has it in: those whose
/// models have it on where some do (a specimen on the table for some tests), else every test (an
/// effect a fit adds), less those whose model table switches it off by name (`enabled = false`).
/// Fails naming the effect where that leaves no test, or more than [`GROUP_TESTS`] to tell apart.
pub fn as_switched(problem: &Problem, free: &[Free]) -> Result<Vec<Free>, String> {
    let mut out = free.to_vec();
    let n = problem.tests.len();
    for f in out.iter_mut() {
        let Some(e) = f.info.component.effect() else {
            continue;
        };
        let on = |t: usize| problem.tests[t].model.effects.get(e);
        let some_on = (0..n).any(on);
        let tests: Vec<usize> = (0..n)
            .filter(|&t| (on(t) || !some_on) && !problem.tests[t].off.contains(&e))
            .collect();
        if tests.len() == n {
            continue;
        }
        if tests.is_empty() {
            return Err(format!("{}: the campaign switches it off (`enabled = false`) in every test: nothing to fit it to", e.name()));
        }
        if n > GROUP_TESTS {
            return Err(format!("{}: the campaign has it in {} of its {n} tests; a fit tells at most {GROUP_TESTS} tests apart (split the campaign)", e.name(), tests.len()));
        }
        *f = f.in_tests(&tests);
    }
    Ok(out)
}

/// `model` (test `test`'s) with the parameters `free` set in it at `values` (in their units),
/// their effects switched on; no allocation beyond the model's clone (a batch makes one per
/// lane).
fn with_values(
    test: usize,
    model: &ModelParams,
    free: &[Free],
    values: impl Iterator<Item = f64>,
) -> ModelParams {
    let mut m = model.clone();
    for (f, v) in free.iter().zip(values) {
        if !f.applies(test) {
            continue;
        }
        if let Some(e) = f.info.component.effect() {
            *m.effects.get_mut(e) = true;
        }
        f.info.set(&mut m, v);
    }
    m
}

/// `free` with the start of the parameter `scan` names (its path, `effect.name`) moved to the
/// one of its values (or its own start) at which the model, the other parameters at their
/// starts, has the lowest χ²: one batch of evaluations. A resonance's frequency or a lag makes χ²
/// non-convex in the parameter, and Levenberg–Marquardt from a start in another valley stays
/// there. Values outside the parameter's range are skipped; without a scan, or when `free` lacks
/// the parameter, `free` as it is. Where `shape` names a parameter of `free`, every value is also
/// tried with it at each of its values. Where `sizing` names a size of `free` ([`Sizing`]), each
/// value is scored at the sizes that fit best to first order ([`first_order_sizes`]), and the
/// sizes start at the best value's.
pub fn scanned(
    problem: &Problem,
    free: &[Free],
    scan: Option<(&str, &[f64])>,
    sizing: &Sizing,
    shape: Option<(&str, &[f64])>,
) -> Vec<Free> {
    let at = |n: &str| free.iter().position(|f| f.info.path() == n);
    let Some((i, values)) = scan.and_then(|(n, v)| Some((at(n)?, v))) else {
        return free.to_vec();
    };
    let shaped = shape.and_then(|(n, v)| Some((at(n)?, v)));
    let f = free[i];
    let shapes: Vec<Option<f64>> = std::iter::once(None)
        .chain(shaped.iter().flat_map(|(_, v)| v.iter().map(|&x| Some(x))))
        .collect();
    let points: Vec<(f64, Option<f64>)> = (shapes.iter())
        .flat_map(|&s| {
            std::iter::once(f.start)
                .chain(values.iter().copied().filter(|&v| f.info.range.contains(v)))
                .map(move |v| (v, s))
        })
        .collect();
    // The scaled coordinates of point k: the scanned parameter and the shape at its values.
    let u_at = |k: usize| {
        let mut u = vec![0.0; free.len()];
        u[i] = f.u_of(points[k].0);
        if let (Some(x), Some((h, _))) = (points[k].1, shaped) {
            u[h] = free[h].u_of(x);
        }
        u
    };
    let (best, sizes) = match sizing.size.as_deref().and_then(at) {
        Some(j) => sized_best(problem, free, (j, sizing), points.len(), &u_at),
        None => {
            let ev = problem.evaluate(points.len(), &|k, t, m| apply(t, m, free, &u_at(k)));
            (lowest(&ev), Vec::new())
        }
    };
    let mut out = free.to_vec();
    out[i] = f.at(points[best].0);
    if let (Some(x), Some((h, _))) = (points[best].1, shaped) {
        out[h] = free[h].at(x);
    }
    for (q, v) in sizes {
        out[q] = free[q].at(v);
    }
    out
}

/// What a scan sizes: the parameter a stage's signature grows in proportion to (a mode's mass;
/// 0, the stage absent), and those of the effect's earlier stages that may give way to it (the
/// first mode's mass, fitted where it stood in for both modes).
#[derive(Debug, Clone, Default)]
pub struct Sizing {
    pub size: Option<String>,
    pub give: Vec<String>,
}

/// The index of the lowest χ² of `ev` (0 where it is empty).
fn lowest(ev: &[Eval]) -> usize {
    (0..ev.len())
        .min_by(|&a, &b| ev[a].chi2().total_cmp(&ev[b].chi2()))
        .unwrap_or(0)
}

/// Relative step of an earlier stage's size for its signature, to first order [chosen: a
/// quarter: far above the integrator's round-off, small beside the sizes the scan moves].
const GIVE_STEP: f64 = 0.25;

/// The best of `n` points (`u_at`, their scaled coordinates) of a sized scan, and the values
/// of its sizes (index in `free`, value): each point's sizes (the size at `j`, those of
/// `sizing.give` beside it) fitted to first order against the model with the stage absent (the
/// size 0, the other parameters at their starts), then each point run at its sizes, a large
/// effect not being linear in its size.
fn sized_best(
    problem: &Problem,
    free: &[Free],
    (j, sizing): (usize, &Sizing),
    n: usize,
    u_at: &(dyn Fn(usize) -> Vec<f64> + Sync),
) -> (usize, Vec<(usize, f64)>) {
    let give: Vec<usize> = (sizing.give.iter())
        .filter_map(|g| free.iter().position(|f| &f.info.path() == g))
        .collect();
    // The stage absent, then the same with each earlier size a step larger.
    let absent = |g: Option<usize>| -> Vec<f64> {
        (free.iter().enumerate())
            .map(|(q, f)| match q {
                q if q == j => 0.0,
                q if Some(q) == g => f.start * (1.0 + GIVE_STEP),
                _ => f.start,
            })
            .collect()
    };
    let ev = problem.evaluate(n + 1 + give.len(), &|k, t, m| match k.checked_sub(n) {
        None => apply(t, m, free, &u_at(k)),
        Some(0) => with_values(t, m, free, absent(None).into_iter()),
        Some(c) => with_values(t, m, free, absent(Some(give[c - 1])).into_iter()),
    });
    let (points, without) = ev.split_at(n);
    let cols: Vec<&Eval> = without[1..].iter().collect();
    let at_sizes = |k: usize| {
        let (a, b) = first_order_sizes(&without[0], &points[k], &cols);
        let mut u = u_at(k);
        u[j] = free[j].u_of(free[j].start * a);
        for (&g, b) in give.iter().zip(b) {
            u[g] = free[g].u_of(free[g].start * (1.0 + b * GIVE_STEP));
        }
        u
    };
    let sized: Vec<Vec<f64>> = (0..n).map(at_sizes).collect();
    let again = problem.evaluate(n, &|k, t, m| apply(t, m, free, &sized[k]));
    let best = lowest(&again);
    let sizes = (std::iter::once(j).chain(give))
        .map(|q| (q, free[q].value(sized[best][q])))
        .collect();
    (best, sizes)
}

/// Most a first-order size moves its parameter from its start, either way: a size fitted far
/// beyond its start is a linearisation too far to trust. [chosen: 16]
const SIZE_REACH: f64 = 16.0;

/// The factors of the first-order fit of `with`'s difference from `without` (a stage at its
/// start size against its absence) and of the differences `give` make (an earlier stage's size
/// a [`GIVE_STEP`] larger), scaled by the factors that minimise the χ²: the size's factor
/// (within 1/[`SIZE_REACH`] to [`SIZE_REACH`]) and the earlier sizes' in steps (their sizes kept
/// within the same reach). 1 and none where a run failed or the signature is nil.
fn first_order_sizes(without: &Eval, with: &Eval, give: &[&Eval]) -> (f64, Vec<f64>) {
    let failed = |e: &Eval| e.failure.is_some() || e.r.len() != without.r.len();
    if failed(without) || failed(with) || give.iter().any(|e| failed(e)) {
        return (1.0, vec![0.0; give.len()]);
    }
    let diff = |e: &Eval| -> Vec<f64> { e.r.iter().zip(&without.r).map(|(a, b)| a - b).collect() };
    let cols: Vec<Vec<f64>> = std::iter::once(with)
        .chain(give.iter().copied())
        .map(diff)
        .collect();
    if !(cols[0].iter().map(|x| x * x).sum::<f64>() > 0.0) {
        return (1.0, vec![0.0; give.len()]);
    }
    let neg: Vec<f64> = without.r.iter().map(|r| -r).collect();
    let (a, g) = normal(&cols, &neg);
    let x = solve(&a, &g);
    let size = x[0].clamp(1.0 / SIZE_REACH, SIZE_REACH);
    // With the size held inside its reach, the earlier sizes refitted to what it leaves.
    let left: Vec<f64> = (neg.iter().zip(&cols[0]))
        .map(|(r, d)| r - size * d)
        .collect();
    let steps = match give.len() {
        0 => Vec::new(),
        _ => {
            let (a, g) = normal(&cols[1..], &left);
            solve(&a, &g)
        }
    };
    let reach = |b: f64| {
        let lo = (1.0 / SIZE_REACH - 1.0) / GIVE_STEP;
        b.clamp(lo, (SIZE_REACH - 1.0) / GIVE_STEP)
    };
    (size, steps.into_iter().map(reach).collect())
}

/// The outcome of a fit.
#[derive(Debug, Clone)]
pub struct FitResult {
    pub estimate: Vec<f64>,
    /// Standard errors in the parameters' units.
    pub se: Vec<f64>,
    /// Standard errors in the scaled coordinates.
    pub se_u: Vec<f64>,
    /// Whether the fit was checked along each parameter ([`FitResult::profile`]); else its
    /// standard errors are Gauss–Newton's.
    pub profiled: bool,
    /// Correlation matrix of the estimates.
    pub corr: Vec<Vec<f64>>,
    /// Scaled coordinates of the estimate.
    pub u: Vec<f64>,
    pub before: Eval,
    pub after: Eval,
    /// Degrees of freedom of the features: the χ² of a model right to the noise.
    pub n: usize,
    pub iterations: usize,
    pub converged: bool,
}

impl FitResult {
    pub fn chi2_before(&self) -> f64 {
        self.before.chi2()
    }
    pub fn chi2_after(&self) -> f64 {
        self.after.chi2()
    }
}

/// The weighted misfit of `e` per test and channel: χ² over `dof`, the channels' degrees of
/// freedom per test (NaN where a test has no features of the channel, or the evaluation failed);
/// `features` say where each of `e`'s weighted residuals belongs.
pub fn chi2_per_channel(features: &[FeatureInfo], e: &Eval, dof: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut sum = vec![[0.0; 3]; dof.len()];
    for (f, r) in features.iter().zip(&e.r) {
        sum[f.test][f.channel] += r * r;
    }
    let failed = e.failure.is_some();
    (dof.iter().zip(sum))
        .map(|(d, s)| {
            std::array::from_fn(|c| match d[c] {
                d if d > 0.0 && !failed => s[c] / d,
                _ => f64::NAN,
            })
        })
        .collect()
}

/// Solves the small square system `a x = b` (least squares by QR, which also copes with a
/// singular `a`).
fn solve(a: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let p = b.len();
    let m = Mat::<f64>::from_fn(p, p, |i, j| a[i][j]);
    let rhs = Mat::<f64>::from_fn(p, 1, |i, _| b[i]);
    let x = m.qr().solve_lstsq(&rhs);
    (0..p).map(|i| x[(i, 0)]).collect()
}

/// JᵀJ and Jᵀr of the columns `j` (one per parameter) and residual `r`.
fn normal(j: &[Vec<f64>], r: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let p = j.len();
    let a = (0..p)
        .map(|i| {
            (0..p)
                .map(|k| j[i].iter().zip(&j[k]).map(|(x, y)| x * y).sum())
                .collect()
        })
        .collect();
    let g = (0..p)
        .map(|i| j[i].iter().zip(r).map(|(x, y)| x * y).sum())
        .collect();
    (a, g)
}

/// Evaluates each point of `points` with its forward-difference neighbours (one batch of lanes
/// when it fits): per point, its evaluation and the Jacobian columns there, or `None` where the
/// point or a neighbour fails.
fn with_jacobian(
    problem: &Problem,
    free: &[Free],
    points: &[Vec<f64>],
) -> Vec<(Eval, Option<Vec<Vec<f64>>>)> {
    let p = free.len();
    let mut sets = Vec::with_capacity(points.len() * (p + 1));
    for u in points {
        sets.push(u.clone());
        for i in 0..p {
            let mut v = u.clone();
            v[i] += H;
            sets.push(v);
        }
    }
    let ev = problem.evaluate(sets.len(), &|k, t, m| apply(t, m, free, &sets[k]));
    ev.chunks(p + 1)
        .map(|c| {
            let base = c[0].clone();
            if base.failure.is_some() || c[1..].iter().any(|e| e.failure.is_some()) {
                return (base, None);
            }
            let cols = c[1..]
                .iter()
                .map(|e| e.r.iter().zip(&base.r).map(|(a, b)| (a - b) / H).collect())
                .collect();
            (base, Some(cols))
        })
        .collect()
}

/// Lanes the fitter plans its trials for: the batch width it was tuned with, fixed so that a
/// change of the kernel's batch width ([`vshake_kernel::EFFECT_LANES`]) does not change a fit's
/// path.
const TRIAL_LANES: usize = 8;

/// The damping factors tried at once in an iteration, around λ, as many as fit in
/// [`TRIAL_LANES`].
fn lambdas(lambda: f64, p: usize) -> Vec<f64> {
    match (TRIAL_LANES / (p + 1)).clamp(1, 4) {
        1 => vec![lambda],
        2 => vec![lambda / 10.0, lambda * 10.0],
        3 => vec![lambda / 10.0, lambda, lambda * 10.0],
        _ => vec![lambda / 10.0, lambda, lambda * 10.0, lambda * 100.0],
    }
}

/// Levenberg–Marquardt over the free parameters, from their start values; setting a parameter
/// switches its effect on. "Before" is each test's model as given.
///
/// Each iteration is one batch: the trial steps for a few damping factors, each with its
/// forward-difference neighbours, so the Jacobian at the accepted step comes with it. It stops
/// when χ² falls by less than 1e-3 + 1e-4·χ² (a thousandth of a standard deviation squared at the
/// noise level; a ten-thousandth of a misfit's χ²), or no step lowers χ².
/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq)]
pub enum FitError {
    /// The model fails (or its parameters are invalid) at the starting point: the reason, with
    /// its test.
    Start(String),
    /// A parameter step of 1e-3 from the start makes the model fail, so there is no Jacobian.
    NoJacobian,
}

impl std::fmt::Display for FitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FitError::Start(why) => f.write_str(why),
            FitError::NoJacobian => {
                f.write_str("a parameter step of 1e-3 from the start makes the model fail")
            }
        }
    }
}

impl std::error::Error for FitError {}

pub fn fit(problem: &Problem, free: &[Free], max_iter: usize) -> Result<FitResult, FitError> {
    fit_from(
        problem,
        free,
        max_iter,
        problem.evaluate(1, &|_, _, m| m.clone()).remove(0),
    )
}

/// [`fit`], given the evaluation of the models as given (a diagnosis evaluates it once for every
/// candidate), without the check along each parameter ([`FitResult::profile`]): its standard
/// errors are Gauss–Newton's. Levenberg–Marquardt: each iteration tries several damping factors
/// at once ([`lambdas`]) and keeps the best step that lowers χ².
///
/// A fit that cannot matter stops early: after [`SCREEN_ITER`] iterations, when χ² would stay
/// above `reach` even if it fell at [`PACE_MARGIN`] times its last iteration's pace in every
/// iteration left (a diagnosis's candidate that cannot explain enough to be significant;
/// `f64::INFINITY`: never). It is then not converged.
pub(crate) fn fit_unprofiled(
    problem: &Problem,
    free: &[Free],
    max_iter: usize,
    before: Eval,
    reach: f64,
) -> Result<FitResult, FitError> {
    let p = free.len();
    let mut u = vec![0.0; p];
    let (mut at, j0) = with_jacobian(problem, free, std::slice::from_ref(&u)).remove(0);
    if let Some(f) = &at.failure {
        return Err(FitError::Start(f.clone()));
    }
    let mut j = j0.ok_or(FitError::NoJacobian)?;
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    for it in 0..max_iter {
        iterations = it + 1;
        let chi2 = at.chi2();
        let (a, g) = normal(&j, &at.r);
        let lams = lambdas(lambda, p);
        let trials: Vec<Vec<f64>> = lams
            .iter()
            .map(|&l| damped_step(&a, &g, l, &u, free))
            .collect();
        let ev = with_jacobian(problem, free, &trials);
        let best = (0..ev.len())
            .filter(|&k| ev[k].1.is_some())
            .min_by(|&x, &y| ev[x].0.chi2().total_cmp(&ev[y].0.chi2()));
        match best {
            Some(b) if ev[b].0.chi2() < chi2 => {
                let new = ev[b].0.chi2();
                let step: f64 = trials[b]
                    .iter()
                    .zip(&u)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f64::max);
                u = trials[b].clone();
                lambda = lams[b].max(1e-9);
                (at, j) = (ev[b].0.clone(), ev[b].1.clone().expect("filtered"));
                if chi2 - new < 1e-2 + 1e-6 * chi2 || step < 1e-8 {
                    converged = true;
                    break;
                }
                if it + 1 >= SCREEN_ITER && out_of_reach(chi2, new, max_iter - it - 1, reach) {
                    break;
                }
            }
            _ => {
                lambda = lams[lams.len() - 1] * 10.0;
                if lambda > 1e10 {
                    // No step lowers χ²: u is a minimum (to the precision of the features).
                    converged = true;
                    break;
                }
            }
        }
    }
    let n = problem.dof().round() as usize;
    let (se_gn, corr) = uncertainty(&j, &at, n);
    let mut r = FitResult {
        estimate: Vec::new(),
        se: Vec::new(),
        se_u: se_gn,
        corr,
        u,
        before,
        after: at,
        n,
        iterations,
        converged,
        profiled: false,
    };
    r.set_values(free);
    Ok(r)
}

/// Iterations a fit makes before it may stop as out of reach ([`fit_unprofiled`]). [chosen: a
/// candidate that matters takes most of its share in its first few iterations.]
pub const SCREEN_ITER: usize = 6;

/// How much faster than its last iteration's pace a fit is allowed to fall in each iteration
/// left before it is called out of reach. [chosen: 3; Levenberg–Marquardt's steps lengthen as
/// its damping falls, but not threefold an iteration for the rest of a fit.]
pub const PACE_MARGIN: f64 = 3.0;

/// Whether a fit whose χ² fell from `chi2` to `new` in its last iteration stays above `reach`
/// after `left` more at [`PACE_MARGIN`] times that pace.
fn out_of_reach(chi2: f64, new: f64, left: usize, reach: f64) -> bool {
    new - PACE_MARGIN * left as f64 * (chi2 - new) > reach
}

impl FitResult {
    /// The estimates and standard errors in the parameters' units, from `u` and `se_u`.
    fn set_values(&mut self, free: &[Free]) {
        self.estimate = free.iter().zip(&self.u).map(|(f, &x)| f.value(x)).collect();
        self.se = (free.iter().zip(&self.u).zip(&self.se_u))
            .map(|((f, &x), s)| f.slope(x) * s)
            .collect();
    }

    /// The fit checked along each parameter by direct evaluation ([`profiled`]): its standard
    /// errors where χ² is not smooth, its estimate where a probe finds a lower χ². Once.
    pub(crate) fn profile(mut self, problem: &Problem, free: &[Free]) -> FitResult {
        if self.profiled {
            return self;
        }
        let p = free.len();
        let s2 = (self.after.chi2() / self.n.saturating_sub(p).max(1) as f64).max(1.0);
        let (u, after, se_u) = profiled(problem, free, self.u, self.after, self.se_u, s2);
        (self.u, self.after, self.se_u, self.profiled) = (u, after, se_u, true);
        self.set_values(free);
        self
    }
}

/// [`fit_from`] checked along each parameter ([`FitResult::profile`]).
pub(crate) fn fit_from(
    problem: &Problem,
    free: &[Free],
    max_iter: usize,
    before: Eval,
) -> Result<FitResult, FitError> {
    fit_unprofiled(problem, free, max_iter, before, f64::INFINITY).map(|r| r.profile(problem, free))
}

/// The point a damped Gauss–Newton step with factor `l` reaches from `u`, on the normal
/// equations `a`·d = −`g`.
fn damped_step(a: &[Vec<f64>], g: &[f64], l: f64, u: &[f64], free: &[Free]) -> Vec<f64> {
    let p = u.len();
    let dmax = (0..p).map(|i| a[i][i]).fold(0.0, f64::max);
    let mut al = a.to_vec();
    for i in 0..p {
        al[i][i] += l * a[i][i].max(1e-12 * dmax) + f64::MIN_POSITIVE;
    }
    let d = solve(&al, &g.iter().map(|x| -x).collect::<Vec<_>>());
    u.iter()
        .zip(&d)
        .zip(free)
        .enumerate()
        .map(|(i, ((x, dx), f))| {
            // A parameter the features do not see (zero column) does not move.
            let dx = if dx.is_finite() && a[i][i] > 0.0 {
                dx.clamp(-2.0, 2.0)
            } else {
                0.0
            };
            // Keep u where the clamp to the valid range puts the value.
            f.u_of(f.value(x + dx))
        })
        .collect()
}

/// Rounds of [`profiled`] at most (each one batch of 2 evaluations per parameter).
const PROFILE_ROUNDS: usize = 12;

/// The fit checked along each parameter by direct evaluation: χ² at u ± δ, from δ = 2 standard
/// errors ([`first_probe`]) up (×4 a round), until both sides rise by at least 4·s² (the
/// conditional 2σ bound). A side lower than u by [`MOVE_SHARE`]·s² or more moves the estimate
/// there. The standard error is then the larger of the Gauss–Newton one and δ·√(s²/Δχ²), with
/// Δχ² the mean rise of the two sides ([`curvature`]: the smaller where one side stays below
/// 4·s²; where that side does not rise at all, the error is `inf`), the curvature χ² has at that
/// scale: where the model is not smooth (a friction law's stick and slip, a clamp), χ² is rough
/// at the scale of a forward-difference step, its jumps inflate JᵀJ, and the Gauss–Newton errors
/// claim a precision the χ² surface does not have (a noise-free channel's jumps of 40 σ at a step
/// of 1e-3: a standard error 45× too small). On a smooth χ² both agree.
fn profiled(
    problem: &Problem,
    free: &[Free],
    mut u: Vec<f64>,
    mut at: Eval,
    mut se: Vec<f64>,
    s2: f64,
) -> (Vec<f64>, Eval, Vec<f64>) {
    let p = free.len();
    let mut delta: Vec<Option<f64>> = se.iter().map(|&s| Some(first_probe(s))).collect();
    for _ in 0..PROFILE_ROUNDS {
        let probes: Vec<(usize, Vec<f64>)> = (0..p)
            .filter_map(|i| delta[i].map(|d| (i, d)))
            .flat_map(|(i, d)| [-d, d].map(|s| (i, probe(free, &u, i, s))))
            .collect();
        if probes.is_empty() {
            break;
        }
        let ev = problem.evaluate(probes.len(), &|k, t, m| apply(t, m, free, &probes[k].1));
        let chi0 = at.chi2();
        let best = (0..ev.len()).min_by(|&a, &b| ev[a].chi2().total_cmp(&ev[b].chi2()));
        // A lower side moves the estimate only where it is lower by a share of s² that matters:
        // smaller ones (rounding, the roughness of a stick-slip law) would use up the rounds in
        // moves of no consequence and leave the probes unsettled.
        let lower = chi0 - (1e-9 * chi0).max(MOVE_SHARE * s2);
        if let Some(b) = best.filter(|&b| ev[b].chi2() < lower) {
            (u, at) = (probes[b].1.clone(), ev[b].clone());
            continue;
        }
        for (k, pair) in ev.chunks(2).enumerate() {
            let (i, d) = (probes[2 * k].0, delta[probes[2 * k].0].unwrap_or(0.0));
            let rise = [0, 1].map(|s| rise_of(&probes[2 * k + s].1, &u, &pair[s], chi0));
            if rise.iter().all(|r| *r >= 4.0 * s2) || d > 2.0 {
                if let Some(curv) = curvature(rise, s2) {
                    // No rise at all on a side: the tests do not bound the parameter there.
                    let wide = if curv > 0.0 {
                        d * (s2 / curv).sqrt()
                    } else {
                        f64::INFINITY
                    };
                    se[i] = se[i].max(wide);
                }
                delta[i] = None;
            } else {
                delta[i] = Some(4.0 * d);
            }
        }
    }
    // Not settled within the rounds: χ² rose by less than 4·s² within the last δ/4 tried.
    for (s, d) in se.iter_mut().zip(&delta) {
        if let Some(d) = d {
            *s = s.max(d / 8.0);
        }
    }
    (u, at, se)
}

/// The rise of χ² that gives a parameter's curvature from the `rise` of its two probes (infinite
/// where the range stops one): their mean where both sides rose by 4·s² or more; else the side
/// that did not, since the features do not bound the parameter that way (a storey's yield force
/// above the largest force it carries: χ² is flat there, and the error is infinite).
fn curvature(rise: [f64; 2], s2: f64) -> Option<f64> {
    let finite: Vec<f64> = rise.into_iter().filter(|r| r.is_finite()).collect();
    if finite.is_empty() {
        None
    } else if finite.iter().all(|&r| r >= 4.0 * s2) {
        Some(finite.iter().sum::<f64>() / finite.len() as f64)
    } else {
        Some(finite.iter().copied().fold(f64::INFINITY, f64::min))
    }
}

/// The share of s² by which a probe must lower χ² to move the estimate in [`profiled`]: a move
/// smaller than this shifts the estimate by under a tenth of its standard error.
const MOVE_SHARE: f64 = 0.01;

/// The smallest first probe of [`profiled`] in u (a relative 1e-6 of a log-scaled value). Below
/// it the features' rounding is felt; above it a smooth χ² still gives its curvature, since a
/// quadratic's rise over δ² is the same at every δ. A Gauss–Newton error that is not a number
/// (a singular JᵀJ: a parameter the features do not see) starts there too.
const MIN_PROBE: f64 = 1e-6;

/// The first probe of [`profiled`] for a Gauss–Newton standard error `se` (in u): 2 `se`, at
/// least [`MIN_PROBE`].
fn first_probe(se: f64) -> f64 {
    if (2.0 * se).is_finite() {
        (2.0 * se).max(MIN_PROBE)
    } else {
        MIN_PROBE
    }
}

/// `u` with parameter `i` moved by `d`, kept inside its valid range.
fn probe(free: &[Free], u: &[f64], i: usize, d: f64) -> Vec<f64> {
    let mut v = u.to_vec();
    v[i] = free[i].u_of(free[i].value(u[i] + d));
    v
}

/// How much χ² rises from `chi0` at the probe `v` of `u`: infinite where the range stops the
/// probe (no side there) or the model fails.
fn rise_of(v: &[f64], u: &[f64], e: &Eval, chi0: f64) -> f64 {
    if v == u || e.failure.is_some() {
        f64::INFINITY
    } else {
        e.chi2() - chi0
    }
}

/// The standard errors of u and their correlations at the fit: (JᵀJ)⁻¹ scaled by the reduced
/// χ² (at least 1), for `n` features.
fn uncertainty(j: &[Vec<f64>], after: &Eval, n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let (a, _) = normal(j, &after.r);
    let p = a.len();
    let s2 = if n > p {
        (after.chi2() / (n - p) as f64).max(1.0)
    } else {
        1.0
    };
    let inv = seen_inverse(&a);
    let cov = |i: usize, k: usize| s2 * inv[k][i];
    let se_u: Vec<f64> = (0..p).map(|i| cov(i, i).max(0.0).sqrt()).collect();
    let corr = (0..p)
        .map(|i| {
            (0..p)
                .map(|k| correlation(cov(i, k), se_u[i], se_u[k], i == k))
                .collect()
        })
        .collect();
    (se_u, corr)
}

/// (JᵀJ)⁻¹ over the parameters the features see (a column of J that is zero, e.g. the yield
/// force of a storey that never yields, would make JᵀJ singular and every error a number of
/// nothing); an unseen parameter's row and column are 0, its error left to [`profiled`].
fn seen_inverse(a: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let p = a.len();
    let dmax = (0..p).map(|i| a[i][i]).fold(0.0, f64::max);
    let seen: Vec<usize> = (0..p).filter(|&i| a[i][i] > 1e-24 * dmax).collect();
    let sub: Vec<Vec<f64>> = seen
        .iter()
        .map(|&i| seen.iter().map(|&k| a[i][k]).collect())
        .collect();
    let mut inv = vec![vec![0.0; p]; p];
    for (c, &k) in seen.iter().enumerate() {
        let e: Vec<f64> = (0..seen.len())
            .map(|i| f64::from(u8::from(i == c)))
            .collect();
        for (x, &i) in solve(&sub, &e).into_iter().zip(&seen) {
            inv[k][i] = x;
        }
    }
    inv
}

/// The correlation of a covariance `c` between errors `si` and `sk` (1 on the diagonal, 0 where
/// an error is 0).
fn correlation(c: f64, si: f64, sk: f64, diagonal: bool) -> f64 {
    if diagonal {
        1.0
    } else if si > 0.0 && sk > 0.0 {
        c / (si * sk)
    } else {
        0.0
    }
}

/// [`FeatureInfo::harmonic`] of a record's residual in octave band `b` of
/// [`crate::fourier::octave_edges`], in [`grouped`]: `BAND + b`.
pub const BAND: usize = 200;

/// χ² contributions grouped by (test, harmonic) — what a candidate explains. A record test's
/// samples (harmonic 0; `rates_hz` per test) are split by octave band (Parseval,
/// [`crate::fourier::band_energy`]): key `BAND + b`.
pub fn grouped(
    features: &[FeatureInfo],
    rates_hz: &[f64],
    r: &[f64],
) -> std::collections::BTreeMap<(usize, usize), f64> {
    let mut g = std::collections::BTreeMap::new();
    let mut i = 0;
    while i < features.len().min(r.len()) {
        let f = features[i];
        if f.harmonic != 0 {
            *g.entry((f.test, f.harmonic)).or_insert(0.0) += r[i] * r[i];
            i += 1;
            continue;
        }
        // One channel's samples of a record test: a contiguous run.
        let end = i + features[i..].iter().take_while(|&&h| h == f).count();
        let edges = crate::fourier::octave_edges(rates_hz[f.test]);
        let e = crate::fourier::band_energy(&r[i..end], rates_hz[f.test], &edges);
        for (b, v) in e.into_iter().enumerate() {
            *g.entry((f.test, BAND + b)).or_insert(0.0) += v;
        }
        i = end;
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runs::single::run_sampled;
    use vshake_kernel::excitation::Record;

    /// The first-order sizes are the least-squares factors of the stage's and the earlier
    /// stages' signatures, and the size is held inside its reach with the earlier ones refitted.
    #[test]
    fn first_order_sizes_give_way_jointly() {
        let eval = |r: Vec<f64>| Eval {
            r,
            rms: Vec::new(),
            failure: None,
        };
        let d = [1.0, 0.5, -0.3, 0.2, 0.0];
        let c = [0.1, -0.4, 0.6, 0.0, 0.3];
        // The residual the stage (2x its start) and an earlier size (1.5 steps) would remove.
        let r0: Vec<f64> = (0..5).map(|i| -(2.0 * d[i] + 1.5 * c[i])).collect();
        let shifted = |x: &[f64; 5]| eval((0..5).map(|i| r0[i] + x[i]).collect());
        let (without, with, give) = (eval(r0.clone()), shifted(&d), shifted(&c));
        let (a, b) = first_order_sizes(&without, &with, &[&give]);
        assert!(
            (a - 2.0).abs() < 1e-12 && (b[0] - 1.5).abs() < 1e-12,
            "{a} {b:?}"
        );
        // Alone, the size takes what it can of both.
        let (alone, none) = first_order_sizes(&without, &with, &[]);
        let dd: f64 = d.iter().map(|x| x * x).sum();
        let rd: f64 = r0.iter().zip(&d).map(|(r, x)| r * x).sum();
        assert!(
            (alone + rd / dd).abs() < 1e-12 && none.is_empty(),
            "{alone}"
        );
        // Past its reach, the size is held at it and the earlier size takes the rest.
        let far: Vec<f64> = (0..5).map(|i| -(20.0 * d[i] + 1.5 * c[i])).collect();
        let at = |x: &[f64; 5]| eval((0..5).map(|i| far[i] + x[i]).collect());
        let (a, b) = first_order_sizes(&eval(far.clone()), &at(&d), &[&at(&c)]);
        let left: Vec<f64> = (0..5).map(|i| -far[i] - SIZE_REACH * d[i]).collect();
        let cc: f64 = c.iter().map(|x| x * x).sum();
        let lc: f64 = left.iter().zip(&c).map(|(l, x)| l * x).sum();
        assert_eq!(a, SIZE_REACH);
        assert!((b[0] - lc / cc).abs() < 1e-12, "{b:?}");
    }

    /// A sine test's noise σ is the noise's, not a hum's: a line between the harmonics (near one
    /// of them, or in a short window) is fitted out with them.
    #[test]
    fn a_hum_is_not_noise() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let noise = Normal::new(0.0, 0.02).unwrap();
        let rate = 1024.0;
        for (f0, n) in [
            (1.0, 4096),
            (2.0, 4096),
            (3.0, 3072),
            (6.0, 2048),
            (8.0, 1024),
        ] {
            let tau: Vec<f64> = (0..n).map(|i| 1.0 + i as f64 / rate).collect();
            let w = |f: f64, t: f64| (2.0 * std::f64::consts::PI * f * t).sin();
            let x: Vec<f64> = (tau.iter())
                .map(|&t| 3.0 * w(f0, t) + 0.1 * w(37.3, t + 0.01) + noise.sample(&mut rng))
                .collect();
            let s = noise_sigma(&x, &tau, rate, Some(f0));
            // Without the line σ would be √(0.02² + 0.1²/2) = 0.073.
            assert!((s - 0.02).abs() < 0.002, "f0 {f0}: σ {s}");
        }
    }

    /// A record test (time-domain features) with a hidden baseline-parameter change: the fit of that
    /// parameter from its default finds it, within its standard error's reach.
    #[test]
    fn a_record_campaign_recovers_a_baseline_parameter() {
        // A 3 s record: a 1.5 Hz and a 4 Hz component, tapered in.
        let n = 301;
        let time_s: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
        let disp_m: Vec<f64> = time_s
            .iter()
            .map(|t| {
                (t / 1.0).min(1.0)
                    * (0.02 * (2.0 * std::f64::consts::PI * 1.5 * t).sin()
                        + 0.004 * (2.0 * std::f64::consts::PI * 4.0 * t).sin())
            })
            .collect();
        let mut reference = Record {
            time_s,
            disp_m,
            f_ref_hz: 50.0,
            signal: vshake_kernel::excitation::Signal::Command,
        }
        .reference(1024.0);
        // ComparedTest at 500 Hz, every sample of the record's span.
        let tau: Vec<f64> = (0..1500).map(|i| i as f64 / 500.0).collect();
        reference.hold_to((tau[tau.len() - 1] * 1024.0) as usize + 2);
        let mut truth = ModelParams::default();
        truth.servovalve.kv *= 0.96;
        let (res, rs) = run_sampled(&truth, &reference, &Solver::default(), &tau).unwrap();
        assert_eq!(res.status, LaneStatus::Ok);
        let ch = |c: usize| Some(rs.channel(c, 0));
        let at = |v: &[f64]| {
            tau.iter()
                .map(|&t| reference.at_time(v, t))
                .collect::<Vec<f64>>()
        };
        let samples = Samples {
            rate_hz: 500.0,
            time: tau.clone(),
            ref_x: at(&reference.x),
            ref_v: at(&reference.v),
            ref_a: at(&reference.a),
            tau,
            fundamental_hz: None,
            n_harm: 0,
        };
        let test = TestData::from_parts(
            "rec".into(),
            ModelParams::default(),
            reference,
            samples,
            [ch(ch::ACCEL), ch(ch::DISP), ch(ch::FORCE)],
            (Weights::default(), [0.0; 3]),
        );
        assert!(
            test.samples.fundamental_hz.is_none() && test.len() == 3 * 1500,
            "time-domain features: {}",
            test.len()
        );
        let problem = Problem::new(vec![test]);
        let info = ModelParams::lookup("servovalve.kv").unwrap();
        let free = [Free::new(info, ModelParams::default().servovalve.kv)];
        let r = fit(&problem, &free, 30).unwrap();
        assert!(r.converged);
        let want = truth.servovalve.kv;
        // Noise-free data: the estimate is the truth to the fit's convergence.
        assert!(
            (r.estimate[0] - want).abs() < 1e-6 * want,
            "{} vs {want}",
            r.estimate[0]
        );
        assert!(r.chi2_after() < 1e-6 * r.chi2_before());
        assert!(r.after.residual_rms() < 1e-3 * r.before.residual_rms());
    }

    /// The periodic-fit noise estimate finds white noise on a distorted, drifting sine at any
    /// rate, where third differences overstate it at low rates.
    #[test]
    fn noise_is_estimated_at_low_sample_rates() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = chacha20::ChaCha8Rng::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.02).unwrap();
        for rate in [256.0, 1024.0] {
            let f = 8.0;
            let tau: Vec<f64> = (0..(4.0 * rate) as usize)
                .map(|i| 1.0 + i as f64 / rate)
                .collect();
            let w = 2.0 * std::f64::consts::PI * f;
            let x: Vec<f64> = tau
                .iter()
                .map(|t| {
                    10.0 * (1.0 + 0.01 * t) * (w * t).sin()
                        + 0.3 * (3.0 * w * t + 0.4).sin()
                        + 0.05 * (9.0 * w * t).cos()
                        + noise.sample(&mut rng)
                })
                .collect();
            let s = noise_sigma(&x, &tau, rate, Some(f));
            assert!((s / 0.02 - 1.0).abs() < 0.08, "{rate} Hz: {s}");
            if rate == 256.0 {
                // Third differences keep (2π·8/256)³ of the 10 m/s² fundamental and amplify the
                // 72 Hz harmonic (2·sin(π·72/256))³ = 3.8 times: nearly twice the noise.
                assert!(
                    noise_sigma_differences(&x) > 1.5 * 0.02,
                    "{}",
                    noise_sigma_differences(&x)
                );
            }
        }
    }
}
