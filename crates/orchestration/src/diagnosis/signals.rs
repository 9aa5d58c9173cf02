//! The plain evidence in the signals: what the residual (measured − model, the starting model run
//! as each test was driven) shows before any candidate is fitted.
//!
//! - **Offsets.** Per test and channel, the residual's mean m. It is reported when it is
//!   [`OFFSET_Z`] standard errors of the noise from zero (σ/√n, σ the channel's noise estimated
//!   from the data), makes at least [`OFFSET_SHARE`] of the residual's mean square, and is steady:
//!   the means of the window's two halves differ by less than [`OFFSET_STEADY`] of m (a drift or a
//!   slow misfit is not an offset). The same offset in every test that has the channel is a
//!   constant of the set-up (a sensor's zero, a preload); one in some tests only, a change between
//!   tests. A displacement offset is also read against the tracked reference: the steady part of
//!   feedback − reference, measured and in the model (the loop's own steady error), from a
//!   least-squares fit of it by a constant and the reference's x_r, v_r, a_r ([`loop_errors`]).
//!   A valve's null bias, a steady loss of oil (external leakage: the valve must stay open to
//!   make it up) or a steady force shows as feedback the loop holds off the reference by more
//!   than the model's loop does.
//! - **Spectral lines.** Per test and channel, the periodogram of the residual under a Hann window
//!   (zero-padded to a power of two, [`crate::fourier`]). A bin is a line where it is a local
//!   maximum standing [`LINE_RATIO`] times above the median of its neighbours (±[`LINE_SPAN`]
//!   resolutions, its own main lobe left out: a local floor, so a residual that is not white
//!   does not make lines), it is as narrow as the window makes a sinusoid (at ±[`LINE_WIDTH`]
//!   resolutions its power is below [`LINE_SKIRT`] of the peak's: a resonance, a specimen's mode
//!   in a record's residual, is as wide as its damping and is not a line), the sinusoid it
//!   implies carries at least [`LINE_SHARE`] of the
//!   residual's mean square, and, for a sine test, it is not a harmonic k·f₀ of the excitation
//!   (nor below three resolutions: drift); a higher harmonic (k > [`HARMONIC_ALWAYS`]) standing
//!   [`HARMONIC_STANDS`] times above its neighbours k ± 1, k ± 2 is a line that sits on a
//!   harmonic, not the excitation's ([`is_excitation_harmonic`]). Its amplitude is
//!   2|X_k|/Σw (the Hann window's coherent gain), its frequency the peak refined by a parabola
//!   through the log-power of the three bins around it. Lines at one frequency in several tests
//!   (within the coarser resolution) are one line, and so are lines of sine tests at one ratio
//!   f/f₀ to each test's f₀ ([`merge_locked`]): *fixed* in frequency when the sine tests' f₀
//!   differ and the line does not move, *locked* to the excitation when f/f₀ is the same in every
//!   sine test that has it.
//! - **A channel's gain.** Per test and channel, the least-squares gain g of the residual on the
//!   model's own channel, both less their means (an offset beside it does not hide it): the
//!   channel reads (1 + g) times the model's. It is reported where g·y explains at least
//!   [`GAIN_SHARE`] of the residual's mean square about its mean, stands [`OFFSET_Z`] standard
//!   errors of the noise from zero, and no other channel of the test shows a gain of its sign
//!   over [`GAIN_ALONE`] of it: a sensor's calibration scales its one channel, while a plant
//!   that moves more moves every channel. An offset of a channel with a gain is read in the
//!   residual the gain leaves.
//! - **Tests that differ.** Per test, the weighted misfit the fit minimises (√(χ²/dof), about 1
//!   at the noise). When some tests are above [`TEST_CARRIES`] and others at most
//!   [`TEST_CLEAN`], the residual is in some tests only: the set-up changed between them, or an
//!   effect acts in some tests only.
//!
//! [chosen: the thresholds below; each says why.]

use crate::diagnosis::compare::ComparedTest;
use crate::fourier;
use faer::prelude::*;
use faer::Mat;
use std::f64::consts::PI;

/// An offset is reported at this many standard errors of the noise from zero. [chosen: 5; the
/// residual is not white, so a smaller multiple of a white-noise error is too easy to reach.]
pub const OFFSET_Z: f64 = 5.0;
/// … when it makes at least this share of the residual's mean square. [chosen: a fifth: an
/// offset that is a sliver of the misfit is not its cause.]
pub const OFFSET_SHARE: f64 = 0.2;
/// … and the two halves' means differ by less than this share of it. [chosen: a quarter.]
pub const OFFSET_STEADY: f64 = 0.25;
/// A periodogram bin is a line at this many times the median of its neighbours. [chosen: 40.
/// Under a Hann window a bin's power over the local median is, for noise or a smooth residual,
/// exponential with median 1, so 40 is exceeded with probability e^(−40 ln 2) ≈ 1e-12 per bin.]
pub const LINE_RATIO: f64 = 40.0;
/// The neighbours of a bin whose median is its local floor: ± this many resolutions (1/T).
/// [chosen: 40; wide enough that a line's own lobe is a small part of it.]
pub const LINE_SPAN: f64 = 40.0;
/// A line is as narrow as the window: at this many resolutions from its peak … [chosen: 3, just
/// beyond the Hann window's main lobe (±2)]
pub const LINE_WIDTH: f64 = 3.0;
/// … its power is below this share of the peak's. [chosen: 1 %. A sinusoid's Hann spectrum is
/// below −31 dB (8e-4) there wherever it falls between bins; a resonance of damping ζ at f, with
/// a record of T s, keeps 1/(1 + (3/(2ζfT))²) of its peak: 0.4 at 1.4 Hz, ζ 5 %, 35 s.]
pub const LINE_SKIRT: f64 = 0.01;
/// A line is reported when its sinusoid carries this share of the residual's mean square.
/// [chosen: 0.5 %: a line smaller than that changes nothing a fit could see.]
pub const LINE_SHARE: f64 = 0.005;
/// Harmonics of a sine test's excitation up to this order are never lines of their own.
/// [chosen: 3; the fundamental's misfit is the largest part of most residuals, and a nonlinearity
/// of the plant puts its share of the motion in the 2nd and 3rd.]
pub const HARMONIC_ALWAYS: f64 = 3.0;
/// A higher harmonic is a line of its own when its power is this many times that of each of its
/// neighbours h ± 1, h ± 2. [chosen: 10 (3.2× in amplitude): a nonlinearity's harmonics change
/// smoothly with their order, the odd ones of a friction as 1/h, 1.1× in power from one to the
/// next at h = 20.]
pub const HARMONIC_STANDS: f64 = 10.0;
/// A test carries the residual above this misfit (√(χ²/dof)). [chosen: 5, the issue's "many
/// times its noise".]
pub const TEST_CARRIES: f64 = 5.0;
/// A test is at the noise at or below this misfit. [chosen: 1.5, the diagnosis's NOISE_FACTOR.]
pub const TEST_CLEAN: f64 = 1.5;

/// A channel's gain is reported where it explains this share of the residual's mean square about
/// its mean. [chosen: 0.8. A load cell reading 6 % high beside 1 % noise leaves 97 %; a plant
/// effect leaves a residual that is not one channel scaled (a lag, harmonics, a resonance).]
pub const GAIN_SHARE: f64 = 0.8;
/// … and the test's other channels show no gain of its sign over this share of it. [chosen: a
/// quarter: a motion the plant changes by a factor changes every channel alike, while two
/// sensors' calibrations need not agree.]
pub const GAIN_ALONE: f64 = 0.25;

/// Offsets and lines smaller than this share of the measured channel's rms are not reported:
/// [docs/model.md §4: the model's numerical floor, 1e-4 of the signal's rms. The model's own
/// output compared with itself leaves residuals at that level, with narrow peaks of resampling
/// error that are not evidence of anything.]
pub const SIGNAL_FLOOR: f64 = 1e-4;

/// The channels' names and units.
pub const CHANNELS: [(&str, &str); 3] = [
    ("acceleration", "m/s2"),
    ("displacement", "m"),
    ("force", "N"),
];

/// A steady difference between measurement and model in one test and channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Offset {
    pub test: usize,
    pub channel: usize,
    /// Mean of measured − model, in the channel's unit.
    pub value: f64,
    /// The same in standard errors of the noise.
    pub z: f64,
    /// Its share of the residual's mean square.
    pub share: f64,
    /// The displacement's: the steady part of the feedback less the tracked reference, measured
    /// and the model's (the loop's steady error), m ([`loop_errors`]).
    pub loop_error: Option<[f64; 2]>,
}

/// A channel that reads a constant factor times the model's in one test.
#[derive(Debug, Clone, PartialEq)]
pub struct Gain {
    pub test: usize,
    pub channel: usize,
    /// g: the channel reads (1 + g) times the model's.
    pub gain: f64,
    /// g in standard errors of the noise.
    pub z: f64,
    /// Its share of the residual's mean square about its mean.
    pub share: f64,
}

/// A spectral line of the residual in one test and channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Hit {
    pub test: usize,
    pub channel: usize,
    pub freq_hz: f64,
    /// Amplitude of the sinusoid, in the channel's unit.
    pub amplitude: f64,
    /// Its share of the residual's mean square.
    pub share: f64,
}

/// A spectral line, over the tests that show it.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    pub freq_hz: f64,
    pub hits: Vec<Hit>,
    /// f/f₀ where every sine test that shows it has the same ratio (and there are two sine tests
    /// or more of different f₀).
    pub locked: Option<f64>,
    /// Whether it stays at one frequency across sine tests of different f₀.
    pub fixed: bool,
}

/// Tests with their misfit √(χ²/dof): (test, misfit).
pub type Misfits = Vec<(usize, f64)>;

/// What the signals show.
#[derive(Debug, Clone, Default)]
pub struct Signals {
    pub offsets: Vec<Offset>,
    pub gains: Vec<Gain>,
    pub lines: Vec<Line>,
    /// Tests above [`TEST_CARRIES`] and tests at most [`TEST_CLEAN`] (√(χ²/dof)), when both are
    /// there.
    pub split: Option<(Misfits, Misfits)>,
    /// The tests between the split's (above [`TEST_CLEAN`], at most [`TEST_CARRIES`]).
    pub between: Misfits,
    /// The term read off the signals (its form) with which the tests split, where they split
    /// only once it is fitted (an offset in every test).
    pub split_after: Option<String>,
    /// The tests' names, for the sentences.
    pub names: Vec<String>,
}

/// The residual measured − model of channel `c` of a compared test (None without the channel).
pub(crate) fn residual(t: &ComparedTest, c: usize) -> Option<Vec<f64>> {
    let m = &t.test.measured;
    let (x, y): (&[f64], &[f64]) = match c {
        0 => (&m.accel, &t.accel_model),
        1 => (&m.disp, &t.disp_model),
        _ => (m.force.as_deref()?, &t.force_model),
    };
    Some(x.iter().zip(y).map(|(a, b)| a - b).collect())
}

/// The model's channel `c` of a compared test (None where the file lacks it).
fn model_channel(t: &ComparedTest, c: usize) -> Option<&[f64]> {
    match c {
        0 => Some(&t.accel_model),
        1 => Some(&t.disp_model),
        _ => t
            .test
            .measured
            .force
            .as_ref()
            .map(|_| t.force_model.as_slice()),
    }
}

/// The least-squares factor g of channel `c`'s residual on the model's channel, both less their
/// means, with Σ(y − ȳ)² and Σ(e − ē)²; None without the channel or its variation.
fn factor(t: &ComparedTest, c: usize) -> Option<(f64, f64, f64)> {
    let (e, y) = (residual(t, c)?, model_channel(t, c)?);
    let n = e.len().min(y.len());
    if n < 8 {
        return None;
    }
    let mean = |v: &[f64]| v[..n].iter().sum::<f64>() / n as f64;
    let (me, my) = (mean(&e), mean(y));
    let (mut ey, mut yy, mut ee) = (0.0, 0.0, 0.0);
    for (a, b) in e[..n].iter().zip(&y[..n]) {
        let (a, b) = (a - me, b - my);
        (ey, yy, ee) = (ey + a * b, yy + b * b, ee + a * a);
    }
    (yy > 0.0 && ee > 0.0).then(|| (ey / yy, yy, ee))
}

/// The gain of channel `c` of test `t` ([`Gain`], test and channel set), where its residual is
/// one; `sigma` the channel's noise.
fn gain(t: &ComparedTest, c: usize, sigma: f64) -> Option<Gain> {
    let (g, yy, ee) = factor(t, c).filter(|_| sigma > 0.0)?;
    let (share, z) = (g * g * yy / ee, g * yy.sqrt() / sigma);
    let big = g.abs() >= SIGNAL_FLOOR && z.abs() >= OFFSET_Z;
    (big && share >= GAIN_SHARE).then_some(Gain {
        test: 0,
        channel: c,
        gain: g,
        z,
        share,
    })
}

/// The gains of test `t`'s channels that no other channel shares ([`GAIN_ALONE`]: another's
/// factor of the same sign and over that share of it), test index `i`.
fn gains_of(t: &ComparedTest, i: usize, sigma: &[f64; 3]) -> Vec<Gain> {
    let other = |c: usize| factor(t, c).map_or(0.0, |f| f.0);
    (0..3)
        .filter_map(|c| gain(t, c, sigma[c]))
        .filter(|g| {
            let mut others = (0..3).filter(|&o| o != g.channel).map(other);
            others.all(|o| o * g.gain <= 0.0 || o.abs() <= GAIN_ALONE * g.gain.abs())
        })
        .map(|g| Gain { test: i, ..g })
        .collect()
}

/// The rms of the measured channel `c` of a compared test (0 without it).
fn measured_rms(t: &ComparedTest, c: usize) -> f64 {
    let m = &t.test.measured;
    let x: &[f64] = match c {
        0 => &m.accel,
        1 => &m.disp,
        _ => m.force.as_deref().unwrap_or(&[]),
    };
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// The signals' evidence of the compared tests (the starting model), with each test's noise σ
/// per channel (NaN or 0 where unknown) and misfit √(χ²/dof) per test.
pub fn read(compared: &[ComparedTest], sigma: &[[f64; 3]], misfit: &[f64]) -> Signals {
    let mut offsets = Vec::new();
    let mut hits = Vec::new();
    let mut gains = Vec::new();
    for (i, t) in compared.iter().enumerate() {
        let own = gains_of(t, i, &sigma[i]);
        for c in 0..3 {
            let Some(mut e) = residual(t, c) else {
                continue;
            };
            // An offset beside a gain is read in what the gain leaves.
            if let (Some(g), Some(y)) = (own.iter().find(|g| g.channel == c), model_channel(t, c)) {
                e.iter_mut().zip(y).for_each(|(e, y)| *e -= g.gain * y);
            }
            let floor = SIGNAL_FLOOR * measured_rms(t, c);
            if let Some(o) = offset(&e, sigma[i][c]).filter(|o| o.value.abs() >= floor) {
                offsets.push(Offset {
                    test: i,
                    channel: c,
                    loop_error: (c == 1).then(|| loop_errors(t)),
                    ..o
                });
            }
            let rate = t.test.samples.rate_hz;
            let f0 = t.test.samples.fundamental_hz;
            let lines = lines_of(&e, rate, f0, true).into_iter();
            hits.extend(lines.filter(|h| h.amplitude >= floor).map(|h| Hit {
                test: i,
                channel: c,
                ..h
            }));
        }
        gains.extend(own);
    }
    let f0: Vec<Option<f64>> = compared
        .iter()
        .map(|t| t.test.samples.fundamental_hz)
        .collect();
    let res: Vec<f64> = compared
        .iter()
        .map(|t| t.test.samples.rate_hz / t.test.samples.len().max(1) as f64)
        .collect();
    Signals {
        offsets,
        gains,
        lines: group_lines(hits, &f0, &res),
        split: split(misfit),
        between: between(misfit),
        split_after: None,
        names: compared.iter().map(|t| t.test.name.clone()).collect(),
    }
}

/// The steady part of the displacement less the tracked reference over a compared test's
/// samples, measured and the model's: the constant of its least-squares fit by a constant and
/// the reference's x_r, v_r and a_r (the loop's lag and gain error of the motion taken out, which
/// over a window of partial cycles would leave a mean of its own).
fn loop_errors(t: &ComparedTest) -> [f64; 2] {
    let s = &t.test.samples;
    let n = s.len();
    let a = Mat::<f64>::from_fn(n, 4, |i, j| match j {
        0 => 1.0,
        1 => s.ref_x[i],
        2 => s.ref_v[i],
        _ => s.ref_a[i],
    });
    let qr = a.qr();
    let steady = |y: &[f64]| {
        let b = Mat::<f64>::from_fn(n, 1, |i, _| y[i] - s.ref_x[i]);
        qr.solve_lstsq(&b)[(0, 0)]
    };
    [steady(&t.test.measured.disp), steady(&t.disp_model)]
}

/// The offset of the residual `e` (test and channel left 0), if it is one; `sigma` the noise.
fn offset(e: &[f64], sigma: f64) -> Option<Offset> {
    let n = e.len();
    if n < 8 || !(sigma > 0.0) {
        return None;
    }
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let m = mean(e);
    let ms = e.iter().map(|v| v * v).sum::<f64>() / n as f64;
    let (a, b) = (mean(&e[..n / 2]), mean(&e[n / 2..]));
    let z = m / (sigma / (n as f64).sqrt());
    let share = m * m / ms;
    let steady = (a - b).abs() < OFFSET_STEADY * m.abs();
    (z.abs() >= OFFSET_Z && share >= OFFSET_SHARE && steady).then_some(Offset {
        test: 0,
        channel: 0,
        value: m,
        z,
        share,
        loop_error: None,
    })
}

/// The frequencies of the spectral lines of `e` sampled at `rate` Hz whose amplitude is at least
/// `floor` ([`lines_of`]); `f0` a sine test's frequency, whose harmonics are not lines.
/// They need not be as narrow as the window ([`narrow`]).
pub(crate) fn line_frequencies(e: &[f64], rate: f64, f0: Option<f64>, floor: f64) -> Vec<f64> {
    let lines = lines_of(e, rate, f0, false).into_iter();
    lines
        .filter(|h| h.amplitude >= floor)
        .map(|h| h.freq_hz)
        .collect()
}

/// The spectral lines of the residual `e` sampled at `rate` Hz (test and channel left 0); `f0`
/// a sine test's frequency, whose harmonics are not lines.
fn lines_of(e: &[f64], rate: f64, f0: Option<f64>, narrow_only: bool) -> Vec<Hit> {
    let n = e.len();
    if n < 64 {
        return Vec::new();
    }
    let hann = |j: usize| (PI * (j as f64 + 0.5) / n as f64).sin().powi(2);
    let sum_w: f64 = (0..n).map(hann).sum();
    let (p, n_fft) = fourier::power_windowed(e, hann);
    let ms = e.iter().map(|v| v * v).sum::<f64>() / n as f64;
    let pad = n_fft as f64 / n as f64;
    let span = (LINE_SPAN * pad).round() as usize;
    let lobe = (3.0 * pad).ceil() as usize;
    let df = rate / n_fft as f64;
    let resolution = rate / n as f64;
    let mut out = Vec::new();
    for k in (lobe + 1)..p.len().saturating_sub(1) {
        if !(p[k] > p[k - 1] && p[k] >= p[k + 1]) {
            continue;
        }
        let f = refined(&p, k) * df;
        if f < 3.0 * resolution || is_excitation_harmonic(&p, k, f, f0, resolution, df) {
            continue;
        }
        let wide = narrow_only && !narrow(&p, k, pad);
        if p[k] < LINE_RATIO * local_median(&p, k, span, lobe) || wide {
            continue;
        }
        let amplitude = amplitude_at(e, f / rate, &hann, sum_w);
        // (The window's estimate may exceed the whole by a little where the line is all.)
        let share = (0.5 * amplitude * amplitude / ms).min(1.0);
        if share >= LINE_SHARE {
            out.push(Hit {
                test: 0,
                channel: 0,
                freq_hz: f,
                amplitude,
                share,
            });
        }
    }
    out
}

/// The least-squares sine and cosine of `e` at `tau` (s) at frequency `f` (Hz).
pub(crate) fn projection(e: &[f64], tau: &[f64], f: f64) -> (f64, f64) {
    let (mut ss, mut sc, mut cc, mut es, mut ec) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (x, t) in e.iter().zip(tau) {
        let (s, c) = (2.0 * PI * f * t).sin_cos();
        (ss, sc, cc) = (ss + s * s, sc + s * c, cc + c * c);
        (es, ec) = (es + x * s, ec + x * c);
    }
    let det = ss * cc - sc * sc;
    if !(det.abs() > 0.0) {
        return (0.0, 0.0);
    }
    ((es * cc - ec * sc) / det, (ec * ss - es * sc) / det)
}

/// The frequency within half a resolution (1/T) of `f` at which the least-squares sinusoid of
/// `e` at `tau` is largest (golden-section search): the line's frequency to a small share of a
/// resolution, which a term written with a fixed frequency needs (a frequency off by ε
/// resolutions turns its phase by 2πε over the window).
pub fn refined_frequency(e: &[f64], tau: &[f64], f: f64, rate_hz: f64) -> f64 {
    let half = 0.5 * rate_hz / e.len().max(1) as f64;
    let power = |f: f64| {
        let (s, c) = projection(e, tau, f);
        s * s + c * c
    };
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (f - half, f + half);
    for _ in 0..40 {
        let (x1, x2) = (b - g * (b - a), a + g * (b - a));
        if power(x1) >= power(x2) {
            b = x2;
        } else {
            a = x1;
        }
    }
    0.5 * (a + b)
}

/// Whether the peak at bin k is as narrow as the window makes a sinusoid: at ±[`LINE_WIDTH`]
/// resolutions (`pad` bins each) its power has fallen below [`LINE_SKIRT`] of the peak on both
/// sides. A resonance driven by a broadband motion (a specimen's mode in a record's residual) is
/// a peak too, but as wide as its damping: 2ζf is several resolutions for any record of useful
/// length.
fn narrow(p: &[f64], k: usize, pad: f64) -> bool {
    let off = (LINE_WIDTH * pad).round() as usize;
    k >= off && k + off < p.len() && p[k - off].max(p[k + off]) < LINE_SKIRT * p[k]
}

/// Whether the peak at bin k of `p` (frequency `f`, `df` Hz a bin) is a harmonic of the sine
/// `f0`'s excitation rather than a line of its own: it lies within half a resolution of a
/// harmonic h·f₀ (a sine test's window holds whole cycles, so its harmonics fall on bins and a
/// harmonic's refined peak is at its bin; a line between harmonics is not), and either h is at
/// most [`HARMONIC_ALWAYS`] or its power is below [`HARMONIC_STANDS`] times the largest of the
/// harmonics h ± 1 and h ± 2. A nonlinearity's harmonics change smoothly with their order (a
/// friction's fall as 1/h), so one that stands alone over its neighbours is a line that happens
/// to sit on a harmonic: a 48 Hz hum in a 2 Hz test, mains in a 1 Hz one.
fn is_excitation_harmonic(
    p: &[f64],
    k: usize,
    f: f64,
    f0: Option<f64>,
    resolution: f64,
    df: f64,
) -> bool {
    let Some(f0) = f0 else { return false };
    let h = (f / f0).round().max(1.0);
    if (f - h * f0).abs() > 0.5 * resolution {
        return false;
    }
    if h <= HARMONIC_ALWAYS || f0 < 1.5 * resolution {
        return true;
    }
    // The bins within a quarter resolution of a harmonic (its own bin where the FFT is not
    // padded: the next is in the main lobe of whatever stands at the harmonic).
    let w = (0.25 * resolution / df).floor() as usize;
    let power_near = |j: f64| {
        let b = (j * f0 / df).round() as usize;
        let hi = (b + w).min(p.len() - 1);
        (b.saturating_sub(w)..=hi).map(|i| p[i]).fold(0.0, f64::max)
    };
    let neighbours = [-2.0, -1.0, 1.0, 2.0]
        .map(|d| power_near(h + d))
        .into_iter()
        .fold(0.0, f64::max);
    p[k] < HARMONIC_STANDS * neighbours
}

/// The amplitude of the sinusoid at `f` cycles per sample in `e` under the window `w` (of sum
/// `sum_w`): 2|Σ w_j e_j e^(−2πi f j)|/Σw, the DFT at the frequency itself (no scalloping).
fn amplitude_at(e: &[f64], f: f64, w: &dyn Fn(usize) -> f64, sum_w: f64) -> f64 {
    let (mut re, mut im) = (0.0, 0.0);
    for (j, x) in e.iter().enumerate() {
        let (s, c) = (2.0 * PI * f * j as f64).sin_cos();
        re += w(j) * x * c;
        im -= w(j) * x * s;
    }
    2.0 * re.hypot(im) / sum_w
}

/// The median of `p` over k ± `span` without k ± `lobe`.
fn local_median(p: &[f64], k: usize, span: usize, lobe: usize) -> f64 {
    let lo = k.saturating_sub(span);
    let hi = (k + span).min(p.len() - 1);
    let mut v: Vec<f64> = (lo..=hi)
        .filter(|&j| j + lobe < k || j > k + lobe)
        .map(|j| p[j])
        .collect();
    if v.is_empty() {
        return f64::INFINITY;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// The peak bin k refined by a parabola through the log-power of k − 1, k, k + 1.
fn refined(p: &[f64], k: usize) -> f64 {
    let (a, b, c) = (
        p[k - 1].max(1e-300).ln(),
        p[k].max(1e-300).ln(),
        p[k + 1].max(1e-300).ln(),
    );
    let den = a - 2.0 * b + c;
    let d = if den < 0.0 { 0.5 * (a - c) / den } else { 0.0 };
    k as f64 + d.clamp(-0.5, 0.5)
}

/// The hits grouped into lines (a hit joins a line within the coarser of their tests'
/// resolutions, twice), largest share first; `f0` each test's sine frequency, `res` its
/// resolution (Hz).
fn group_lines(mut hits: Vec<Hit>, f0: &[Option<f64>], res: &[f64]) -> Vec<Line> {
    hits.sort_by(|a, b| b.share.total_cmp(&a.share));
    let mut lines: Vec<Line> = Vec::new();
    for h in hits {
        let near = lines.iter_mut().find(|l| {
            let r = l
                .hits
                .iter()
                .map(|x| res[x.test])
                .fold(res[h.test], f64::max);
            (l.freq_hz - h.freq_hz).abs() <= 2.0 * r
        });
        match near {
            Some(l) => l.hits.push(h),
            None => lines.push(Line {
                freq_hz: h.freq_hz,
                hits: vec![h],
                locked: None,
                fixed: false,
            }),
        }
    }
    let mut lines = merge_locked(lines, f0, res);
    for l in &mut lines {
        classify(l, f0);
    }
    lines
}

/// Lines seen in sine tests only, at one ratio to each test's f₀, merged into one: a line locked
/// to the excitation moves with it, so grouping by frequency splits it over tests of different
/// f₀. Two lines merge when their mean ratios f/f₀ agree within the coarser of their tests'
/// resolutions over f₀, twice.
fn merge_locked(lines: Vec<Line>, f0: &[Option<f64>], res: &[f64]) -> Vec<Line> {
    // The line's ratio and its tolerance; None where a hit is not a sine test's or the hits'
    // ratios differ (a line at one frequency over tests of different f₀).
    let ratio = |l: &Line| -> Option<(f64, f64)> {
        let (mut lo, mut hi, mut tol) = (f64::INFINITY, 0.0f64, 0.0f64);
        for h in &l.hits {
            let f = f0[h.test]?;
            (lo, hi) = (lo.min(h.freq_hz / f), hi.max(h.freq_hz / f));
            tol = tol.max(2.0 * res[h.test] / f);
        }
        (hi - lo <= tol).then_some((0.5 * (lo + hi), tol))
    };
    let mut out: Vec<Line> = Vec::new();
    for l in lines {
        let same = |o: &&mut Line| match (ratio(o), ratio(&l)) {
            (Some((a, ta)), Some((b, tb))) => (a - b).abs() <= ta.max(tb),
            _ => false,
        };
        match out.iter_mut().find(same) {
            Some(o) => o.hits.extend(l.hits),
            None => out.push(l),
        }
    }
    out
}

/// Whether a line stays at one frequency or moves with the excitation, over its sine tests.
fn classify(l: &mut Line, f0: &[Option<f64>]) {
    let sines: Vec<(f64, f64)> = l
        .hits
        .iter()
        .filter_map(|h| f0[h.test].map(|f| (h.freq_hz, f)))
        .collect();
    let f0s: Vec<f64> = sines.iter().map(|s| s.1).collect();
    let spread = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        hi / lo - 1.0
    };
    if f0s.len() < 2 || spread(&f0s) < 0.05 {
        return;
    }
    let freqs: Vec<f64> = sines.iter().map(|s| s.0).collect();
    let ratios: Vec<f64> = sines.iter().map(|s| s.0 / s.1).collect();
    l.fixed = spread(&freqs) < 0.01;
    if !l.fixed && spread(&ratios) < 0.01 {
        l.locked = Some(ratios.iter().sum::<f64>() / ratios.len() as f64);
    }
}

/// The tests above [`TEST_CARRIES`] and those at most [`TEST_CLEAN`], when both are there.
/// The tests whose misfit `misfit` (√(χ²/dof)) is above [`TEST_CLEAN`] and at most
/// [`TEST_CARRIES`]: above their noise, short of carrying the residual.
pub(crate) fn between(misfit: &[f64]) -> Misfits {
    (misfit.iter().enumerate())
        .filter(|(_, &m)| m > TEST_CLEAN && m <= TEST_CARRIES)
        .map(|(i, &m)| (i, m))
        .collect()
}

pub(crate) fn split(misfit: &[f64]) -> Option<(Misfits, Misfits)> {
    let pick = |keep: &dyn Fn(f64) -> bool| -> Vec<(usize, f64)> {
        misfit
            .iter()
            .enumerate()
            .filter(|(_, &m)| keep(m))
            .map(|(i, &m)| (i, m))
            .collect()
    };
    let carry = pick(&|m| m > TEST_CARRIES);
    let clean = pick(&|m| m <= TEST_CLEAN);
    (!carry.is_empty() && !clean.is_empty()).then_some((carry, clean))
}

impl Signals {
    /// The evidence in plain words, one sentence per finding, each with its numbers.
    pub fn sentences(&self) -> Vec<String> {
        let mut out = self.offset_sentences();
        out.extend(self.gain_sentences());
        out.extend(self.lines.iter().map(|l| self.line_sentence(l)));
        out.extend(self.split_sentence());
        out
    }

    /// Whether the signals show anything.
    pub fn is_empty(&self) -> bool {
        self.offsets.is_empty()
            && self.gains.is_empty()
            && self.lines.is_empty()
            && self.split.is_none()
    }

    fn gain_sentences(&self) -> Vec<String> {
        (0..3)
            .filter_map(|c| {
                let g: Vec<&Gain> = self.gains.iter().filter(|g| g.channel == c).collect();
                g.first()?;
                let (lo, hi) = bounds(g.iter().map(|g| 1.0 + g.gain));
                let what = match hi - lo > 0.1 * (hi - 1.0).abs().max((lo - 1.0).abs()) {
                    true => format!("{lo:.4} to {hi:.4}"),
                    false => format!("{:.4}", 1.0 + g.iter().map(|g| g.gain).sum::<f64>() / g.len() as f64),
                };
                let which = if g.len() == self.names.len() {
                    format!("in every test ({} of {})", g.len(), self.names.len())
                } else {
                    format!("in {} only", self.list(g.iter().map(|g| g.test)))
                };
                let share = g.iter().map(|g| g.share).fold(0.0, f64::max);
                let z = g.iter().map(|g| g.z.abs()).fold(0.0, f64::max);
                Some(format!(
                    "the {} reads {what} times the model's {which}, while the other channels show no such factor (up to {z:.0} noise errors and {:.0} % of that residual about its mean): a sensor's calibration, or a load only that channel sees",
                    CHANNELS[c].0,
                    100.0 * share
                ))
            })
            .collect()
    }

    fn offset_sentences(&self) -> Vec<String> {
        (0..3)
            .filter_map(|c| {
                let o: Vec<&Offset> = self.offsets.iter().filter(|o| o.channel == c).collect();
                let first = o.first()?;
                let (name, unit) = CHANNELS[c];
                let values: Vec<f64> = o.iter().map(|o| o.value).collect();
                let same_sign = values.iter().all(|v| v.signum() == first.value.signum());
                let (lo, hi) = values.iter().fold((f64::INFINITY, 0.0f64), |(a, b), v| {
                    (a.min(v.abs()), b.max(v.abs()))
                });
                let share = o.iter().map(|o| o.share).fold(0.0, f64::max);
                let z = o.iter().map(|o| o.z.abs()).fold(0.0, f64::max);
                let which = if o.len() == self.names.len() {
                    format!("in every test ({} of {})", o.len(), self.names.len())
                } else {
                    format!("in {} only", self.list(o.iter().map(|o| o.test)))
                };
                let what = if same_sign && hi <= 1.25 * lo {
                    format!("{:+.3e} {unit}", values.iter().sum::<f64>() / values.len() as f64)
                } else {
                    let (min, max) = bounds(values.iter().copied());
                    format!("{min:+.2e} to {max:+.2e} {unit}")
                };
                Some(format!(
                    "a steady offset of the {name} (measured - model) of {what} {which}, up to {z:.0} noise errors and {:.0} % of that residual{}",
                    100.0 * share,
                    loop_sentence(&o)
                ))
            })
            .collect()
    }

    fn line_sentence(&self, l: &Line) -> String {
        let mut channels: Vec<usize> = l.hits.iter().map(|h| h.channel).collect();
        channels.sort_unstable();
        channels.dedup();
        let ch: Vec<&str> = channels.iter().map(|&c| CHANNELS[c].0).collect();
        let mut tests: Vec<usize> = l.hits.iter().map(|h| h.test).collect();
        tests.sort_unstable();
        tests.dedup();
        let amp: Vec<String> = channels
            .iter()
            .map(|&c| {
                let a = (l.hits.iter().filter(|h| h.channel == c))
                    .map(|h| h.amplitude)
                    .fold(0.0, f64::max);
                format!("{a:.2e} {}", CHANNELS[c].1)
            })
            .collect();
        let share = l.hits.iter().map(|h| h.share).fold(0.0, f64::max);
        let kind = match (l.locked, l.fixed) {
            (Some(r), _) => format!("locked to the excitation at {r:.3} f0"),
            (None, true) => "at one frequency whatever the excitation's".to_string(),
            _ => "not a harmonic of the excitation".to_string(),
        };
        let (lo, hi) = bounds(l.hits.iter().map(|h| h.freq_hz));
        let at = match hi - lo > 0.005 * hi {
            true => format!("{lo:.2} to {hi:.2}"),
            false => format!("{:.2}", l.freq_hz),
        };
        format!(
            "a spectral line at {at} Hz in the {} ({} of {} tests: {}; amplitude up to {}, {:.0} % of that residual; {kind})",
            join_and(&ch),
            tests.len(),
            self.names.len(),
            self.list(tests.iter().copied()),
            amp.join(", "),
            100.0 * share
        )
    }

    /// "the residual is in some tests only: …" where it is ([`Signals::split`]).
    pub fn split_sentence(&self) -> Option<String> {
        let (carry, clean) = self.split.as_ref()?;
        let show = |v: &[(usize, f64)]| -> String {
            v.iter()
                .map(|&(t, m)| format!("{} {m:.1}x", self.names[t]))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let once = (self.split_after.as_ref())
            .map_or(String::new(), |t| format!(" once the term {t} is fitted"));
        let between = match self.between.is_empty() {
            true => String::new(),
            false => format!(" and, less, {}", show(&self.between)),
        };
        Some(format!(
            "the residual is in some tests only{once}: {} (misfit over noise){between}, while {} {} at the noise: the set-up changed between them, or an effect acts in those tests only",
            show(carry),
            show(clean),
            if clean.len() == 1 { "is" } else { "are" }
        ))
    }

    /// "a, b and c" of the tests' names.
    pub fn list(&self, tests: impl Iterator<Item = usize>) -> String {
        let v: Vec<&str> = tests.map(|t| self.names[t].as_str()).collect();
        join_and(&v)
    }
}

/// The displacement offsets' reading against the reference: how much further the loop holds the
/// measured feedback off the tracked reference than the model's loop holds the model's (its
/// steady error), then the two readings; empty for another channel. In mm: the model's own
/// steady error is a few hundredths of a millimetre.
fn loop_sentence(o: &[&Offset]) -> String {
    let errors: Vec<[f64; 2]> = o.iter().filter_map(|o| o.loop_error).collect();
    if errors.is_empty() {
        return String::new();
    }
    let range = |v: Vec<f64>| {
        let (lo, hi) = bounds(v.iter().copied());
        match hi - lo > 0.25 * hi.abs().max(lo.abs()) {
            true => format!("{:+.3} to {:+.3} mm", 1e3 * lo, 1e3 * hi),
            false => format!("{:+.3} mm", 0.5e3 * (lo + hi)),
        }
    };
    let beyond = range(errors.iter().map(|e| e[0] - e[1]).collect());
    let measured = range(errors.iter().map(|e| e[0]).collect());
    let model = range(errors.iter().map(|e| e[1]).collect());
    format!(
        "; the loop holds the feedback {beyond} off the tracked reference beyond the model's own steady error (feedback - reference: measured {measured}, model {model}): a valve's null bias, a steady loss of oil from the chambers (external leakage) or a steady force the loop leaves as an error, or a recorded feedback whose zero is not the loop's"
    )
}

/// The least and the greatest of `v` ((∞, −∞) when empty).
pub(crate) fn bounds(v: impl IntoIterator<Item = f64>) -> (f64, f64) {
    (v.into_iter()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    })
}

/// "a, b and c".
pub(crate) fn join_and(v: &[&str]) -> String {
    match v {
        [] => String::new(),
        [a] => a.to_string(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic white noise of standard deviation `sd`: a hash of `j` made uniform, then
    /// Gaussian by Box–Muller.
    fn noise(j: usize, sd: f64) -> f64 {
        let u = |k: u64| {
            let mut x = k.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03;
            x ^= x >> 31;
            x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x ^= x >> 29;
            ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (u(2 * j as u64), u(2 * j as u64 + 1));
        sd * (-2.0 * a.ln()).sqrt() * (2.0 * PI * b).cos()
    }

    #[test]
    fn a_line_is_found_with_its_frequency_and_amplitude() {
        let rate = 1024.0;
        let e: Vec<f64> = (0..4096)
            .map(|j| {
                let t = j as f64 / rate;
                0.1 * (2.0 * PI * 37.3 * t + 0.4).sin() + noise(j, 0.02)
            })
            .collect();
        let hits = lines_of(&e, rate, Some(3.0), true);
        assert_eq!(hits.len(), 1, "{hits:?}");
        assert!((hits[0].freq_hz - 37.3).abs() < 0.05, "{hits:?}");
        assert!((hits[0].amplitude - 0.1).abs() < 0.01, "{hits:?}");
    }

    #[test]
    fn a_resonance_driven_by_noise_is_not_a_line() {
        // White noise through a mode at 1.4 Hz, 5 % damping (semi-implicit Euler at 1024 Hz),
        // 35 s: its response is a peak in the spectrum, but as wide as its damping.
        let (rate, w, zeta) = (1024.0, 2.0 * PI * 1.4, 0.05);
        let dt = 1.0 / rate;
        let (mut x, mut v) = (0.0, 0.0);
        let e: Vec<f64> = (0..35 * 1024)
            .map(|j| {
                v += dt * (noise(j, 50.0) - 2.0 * zeta * w * v - w * w * x);
                x += dt * v;
                x
            })
            .collect();
        let peak = lines_of(&e, rate, None, true);
        assert!(peak.is_empty(), "{peak:?}");
    }

    #[test]
    fn harmonics_of_the_excitation_are_not_lines() {
        let rate = 1024.0;
        let e: Vec<f64> = (0..4096)
            .map(|j| {
                let t = j as f64 / rate;
                0.1 * (2.0 * PI * 9.0 * t).sin() + noise(j, 0.02)
            })
            .collect();
        assert!(lines_of(&e, rate, Some(3.0), true).is_empty());
        assert_eq!(lines_of(&e, rate, None, true).len(), 1);
    }

    /// A 48 Hz hum in a 2 Hz sine test sits on its 24th harmonic, over a friction's odd
    /// harmonics falling as 1/k: the hum is a line, the friction's harmonics are not.
    #[test]
    fn a_line_on_a_high_harmonic_is_a_line_and_a_smooth_distortion_is_not() {
        let (rate, f0) = (1024.0, 2.0);
        let friction = |t: f64| -> f64 {
            (1..40)
                .step_by(2)
                .map(|k| 0.3 / k as f64 * (2.0 * PI * k as f64 * f0 * t).sin())
                .sum()
        };
        let e: Vec<f64> = (0..8192)
            .map(|j| {
                let t = j as f64 / rate;
                friction(t) + 0.1 * (2.0 * PI * 48.0 * t + 0.4).sin() + noise(j, 0.02)
            })
            .collect();
        let hits = lines_of(&e, rate, Some(f0), true);
        assert_eq!(hits.len(), 1, "{hits:?}");
        assert!((hits[0].freq_hz - 48.0).abs() < 0.05, "{hits:?}");
        assert!((hits[0].amplitude - 0.1).abs() < 0.01, "{hits:?}");
        let e: Vec<f64> = (0..8192).map(|j| friction(j as f64 / rate)).collect();
        assert!(lines_of(&e, rate, Some(f0), true).is_empty());
    }

    #[test]
    fn a_steady_offset_is_found_and_a_drift_is_not() {
        let steady: Vec<f64> = (0..2000).map(|j| 1e-3 + noise(j, 1e-5)).collect();
        let o = offset(&steady, 1e-5).unwrap();
        assert!((o.value - 1e-3).abs() < 1e-6 && o.share > 0.99, "{o:?}");
        let drift: Vec<f64> = (0..2000).map(|j| 1e-6 * j as f64).collect();
        assert_eq!(offset(&drift, 1e-5), None);
    }

    /// A line at 3.1 f₀ in sine tests of 1, 2 and 3 Hz is one line, locked to the excitation;
    /// a hum at 59.96 Hz in the same tests is another, at one frequency.
    #[test]
    fn a_line_that_moves_with_the_excitation_is_one_line() {
        let f0 = [Some(1.0), Some(2.0), Some(3.0)];
        let res = [0.01; 3];
        let hit = |test: usize, freq_hz: f64, share: f64| Hit {
            test,
            channel: 0,
            freq_hz,
            amplitude: 1.0,
            share,
        };
        let hits = vec![
            hit(0, 3.1, 0.3),
            hit(1, 6.2, 0.2),
            hit(2, 9.3 + 0.004, 0.1),
            hit(0, 59.96, 0.05),
            hit(1, 59.96, 0.04),
            hit(2, 59.965, 0.03),
        ];
        let lines = group_lines(hits, &f0, &res);
        assert_eq!(lines.len(), 2, "{lines:?}");
        let locked = lines.iter().find(|l| l.locked.is_some()).unwrap();
        assert_eq!(locked.hits.len(), 3, "{locked:?}");
        assert!((locked.locked.unwrap() - 3.1).abs() < 1e-3, "{locked:?}");
        let hum = lines.iter().find(|l| l.fixed).unwrap();
        assert_eq!(hum.hits.len(), 3, "{hum:?}");
        let names = ["a", "b", "c"].map(String::from).to_vec();
        let s = Signals {
            lines: vec![locked.clone()],
            names,
            ..Default::default()
        };
        let sentence = s.line_sentence(locked);
        assert!(
            sentence.contains("at 3.10 to 9.30 Hz") && sentence.contains("at 3.100 f0"),
            "{sentence}"
        );
    }

    /// An offset of either sign over the tests is stated with its signs.
    #[test]
    fn offsets_of_both_signs_keep_their_signs() {
        let off = |test: usize, value: f64| Offset {
            test,
            channel: 1,
            value,
            z: 10.0,
            share: 0.5,
            loop_error: Some([value + 1e-5, 1e-5]),
        };
        let s = Signals {
            offsets: vec![off(0, -2e-4), off(1, 3e-4)],
            names: ["a", "b"].map(String::from).to_vec(),
            ..Default::default()
        };
        let said = s.offset_sentences().join("");
        assert!(said.contains("-2.00e-4 to +3.00e-4 m"), "{said}");
        assert!(
            said.contains("the loop holds the feedback -0.200 to +0.300 mm off the tracked reference beyond the model's own steady error (feedback - reference: measured -0.190 to +0.310 mm, model +0.010 mm)"),
            "{said}"
        );
    }

    #[test]
    fn tests_split_only_when_some_are_at_the_noise() {
        let s = split(&[12.0, 1.1, 0.9, 30.0]).unwrap();
        assert_eq!(s.0, vec![(0, 12.0), (3, 30.0)]);
        assert_eq!(s.1, vec![(1, 1.1), (2, 0.9)]);
        assert_eq!(split(&[12.0, 3.0, 30.0]), None);
    }

    /// The refined frequency and the projection recover a sinusoid in noise.
    #[test]
    fn a_line_s_frequency_and_phase_are_recovered() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let noise = Normal::new(0.0, 1.0).unwrap();
        let rate = 256.0;
        let tau: Vec<f64> = (0..4096).map(|i| 0.3 + i as f64 / rate).collect();
        let (f, s, c) = (37.3123, 0.8, -1.9);
        let e: Vec<f64> = (tau.iter())
            .map(|t| {
                let w = 2.0 * PI * f * t;
                s * w.sin() + c * w.cos() + noise.sample(&mut rng)
            })
            .collect();
        let got = refined_frequency(&e, &tau, 37.30, rate);
        // The Cramér–Rao bound for f: √(6/(SNR·N³))/(π/rate): about 2e-4 Hz here.
        assert!((got - f).abs() < 2e-3, "{got}");
        // The sine and cosine at t = 0 turn with the frequency's error; the amplitude does not.
        let (s1, c1) = projection(&e, &tau, got);
        let a = f64::hypot(s, c);
        assert!((s1.hypot(c1) - a).abs() < 0.05 * a, "{s1} {c1}");
    }
}
