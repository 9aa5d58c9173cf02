//! Excitations: the reference states (x_r, v_r, a_r, j_r) at every controller tick (docs/model.md §4).
//!
//! They are computed once, before a run, into a [`Reference`] that every lane of a batch shares,
//! so the tick loop reads arrays and never branches on the excitation kind.
//!
//! - **sine**: x_r = X·e(t)·sin(2πft), e = ½(1 − cos(πt/T_taper)) for t < T_taper, else 1;
//!   v_r, a_r, j_r are the exact derivatives (product rule with e's derivatives).
//! - **record**, by what it is ([`Signal`]):
//!   - a *command* (a drive file, a ground motion): linearly interpolated to the ticks, then a
//!     discrete 4th-order critically damped state-variable filter H(s) = ω⁴/(s+ω)⁴, ω = 2π f_ref,
//!     whose four states are (x_r, v_r, a_r, j_r) [chosen: all four reference states come from
//!     the filter so they are mutually consistent; the filter is discretised exactly for a
//!     zero-order-held input (matrix exponential), and starts at rest at the first record value];
//!     causal like a controller's generator, so x_r lags the record (4/ω at low frequency);
//!   - the tracked *reference* (what a data-acquisition system records): x_r is the record
//!     itself, by the cubic through the four nearest samples between them; v_r, a_r, j_r are the
//!     derivatives of the record through a zero-phase filter, the 4th-order Butterworth run
//!     backward then forward, |H|² = 1/(1 + (f/f_d)⁸), at four times the ticks' rate; its corner
//!     f_d is chosen per record from 1 to 3 × f_ref by the least estimated error of a_r
//!     ([`Record::derivative_corner_hz`]) [each pass is exact for an input linear between its
//!     steps, the input first corrected by −Δ²/12, so the derivatives of a smooth record are right
//!     to O((ωT)⁴)]; no lag.

use super::expm::expm;
use super::spectrum::SpectrumSpec;
use std::f64::consts::PI;

/// Reference states at every tick, plus what the metrics need to know about them.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// Controller rate, Hz.
    pub f_s: f64,
    pub x: Vec<f64>,
    pub v: Vec<f64>,
    pub a: Vec<f64>,
    pub j: Vec<f64>,
    /// The reference displacement command before any filter (a sine: x_r itself; a record: the
    /// record interpolated to the ticks), m — what a controller log calls the reference.
    pub command: Vec<f64>,
    /// Ticks of the analysis window, [start, end).
    pub window: (usize, usize),
    /// Fundamental frequency for the harmonic metrics, Hz (`None` for records).
    pub fundamental_hz: Option<f64>,
    /// What moves the spool: the controller (the default) or a measured column (open loop).
    pub drive: Drive,
    /// The response spectrum the metrics take, with the target's PSA (of `a` over the window),
    /// m/s² ([`Reference::with_spectrum`]); `None`: no spectral metrics.
    pub spectrum: Option<(SpectrumSpec, Vec<f64>)>,
    /// The estimated rms error of a_r over a_r's rms: a tracked reference's derivatives,
    /// [`Record::derivative_corner_hz`]; 0 where the states are exact.
    pub accel_floor: f64,
    /// What a tracked reference could equally be off by: (x, v, a, j) at each tick of its
    /// record's noise drawn once more ([`Record::noise_samples`]: a DAQ's bits, its printed
    /// digits), plus the content its derivatives' corner takes off, estimated against the
    /// highest corner ([`Record::derivative_corner_hz`]). How far the reference plus this
    /// moves the model's channels is the floor the record sets on any comparison: the table
    /// tracked the reference before the noise was added, and its true derivatives. Empty where
    /// the states are exact (a sine, a generated motion) or made by the causal generator
    /// (`signal = "command"`).
    pub record_error: Vec<[f64; 4]>,
}

/// What moves the spool.
///
/// Open loop drives the plant with a measured column instead of the controller, to separate
/// the plant's error from the controller's. The reference still gives the analysis window and
/// the phase reference of the metrics.
#[derive(Debug, Clone, Default, PartialEq)]
pub enum Drive {
    /// The three-variable controller closes the loop (docs/model.md §3).
    #[default]
    ClosedLoop,
    /// A valve command per tick, V: clamped to ±u_lim like the controller's output, then
    /// x_c = k_sp·u goes through the valve effects (delay, spool dynamics) as usual.
    ValveCommand(Vec<f64>),
    /// A spool position per tick, m; the spool command held over [t_k, t_{k+1}) is the mean of
    /// the samples at t_k and t_{k+1} (the measured spool moves continuously). A measured spool already
    /// contains the valve's own dynamics, so the caller switches the delay and spool-dynamics
    /// effects off for this drive.
    Spool(Vec<f64>),
}

impl Reference {
    /// An empty reference with room for `n` ticks; the window is every tick until set.
    fn with_capacity(f_s: f64, n: usize, fundamental_hz: Option<f64>) -> Self {
        Reference {
            f_s,
            x: Vec::with_capacity(n),
            v: Vec::with_capacity(n),
            a: Vec::with_capacity(n),
            j: Vec::with_capacity(n),
            command: Vec::with_capacity(n),
            window: (0, n),
            fundamental_hz,
            drive: Drive::ClosedLoop,
            spectrum: None,
            accel_floor: 0.0,
            record_error: Vec::new(),
        }
    }

    /// A reference from its states (x, v, a, j) at every tick (the command is x); the window is
    /// every tick, no fundamental.
    pub fn from_states(f_s: f64, states: &[[f64; 4]]) -> Self {
        let mut r = Reference::with_capacity(f_s, states.len(), None);
        states.iter().for_each(|s| r.push(*s, s[0]));
        r
    }

    /// Appends one tick: the states (x, v, a, j) and the command.
    fn push(&mut self, s: [f64; 4], command: f64) {
        self.x.push(s[0]);
        self.v.push(s[1]);
        self.a.push(s[2]);
        self.j.push(s[3]);
        self.command.push(command);
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
    /// Time of tick k, s.
    pub fn time(&self, k: usize) -> f64 {
        k as f64 / self.f_s
    }

    /// The same reference with a response spectrum: the target's PSA is the spectrum of `a` over
    /// the window.
    pub fn with_spectrum(mut self, spec: SpectrumSpec) -> Self {
        let (w0, w1) = self.window;
        let target = super::spectrum::psa(&self.a[w0..w1], 1.0 / self.f_s, &spec);
        self.spectrum = Some((spec, target));
        self
    }

    /// Peaks over the window: (max |x_r|, max |v_r|, max |a_r|).
    pub fn peaks(&self) -> (f64, f64, f64) {
        let (w0, w1) = self.window;
        let peak = |v: &[f64]| v[w0..w1].iter().fold(0.0f64, |m, x| m.max(x.abs()));
        (peak(&self.x), peak(&self.v), peak(&self.a))
    }

    /// Keeps the first `n` ticks (the window is clipped to them).
    pub fn truncate(&mut self, n: usize) {
        for v in [
            &mut self.x,
            &mut self.v,
            &mut self.a,
            &mut self.j,
            &mut self.command,
        ] {
            v.truncate(n);
        }
        self.window = (self.window.0.min(n), self.window.1.min(n));
    }

    /// Lengthens the reference to `n` ticks by holding its last tick (states and command). A
    /// run needs a tick beyond the last time it is sampled at ([`super::resample::Resampler`]);
    /// a held tick at the end changes nothing before it.
    pub fn hold_to(&mut self, n: usize) {
        while !self.is_empty() && self.len() < n {
            let k = self.len() - 1;
            let (s, c) = (
                [self.x[k], self.v[k], self.a[k], self.j[k]],
                self.command[k],
            );
            self.push(s, c);
        }
    }

    /// Channel `values` (one per tick) at time `t`, by the cubic through the four nearest ticks
    /// (held beyond the ends).
    pub fn at_time(&self, values: &[f64], t: f64) -> f64 {
        let p = t * self.f_s;
        let n = values.len();
        if n == 0 {
            return f64::NAN;
        }
        let k = p.floor();
        if p == k && (k as usize) < n {
            return values[k as usize];
        }
        if n < 4 || p <= 0.0 || p >= (n - 1) as f64 {
            return values[(p.round().max(0.0) as usize).min(n - 1)];
        }
        let j0 = (k as usize).saturating_sub(1).min(n - 4);
        (0..4)
            .map(|i| {
                let xi = (j0 + i) as f64;
                let w: f64 = (0..4)
                    .filter(|&q| q != i)
                    .map(|q| (p - (j0 + q) as f64) / (xi - (j0 + q) as f64))
                    .product();
                w * values[j0 + i]
            })
            .sum()
    }
}

/// Sine excitation (docs/model.md §4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sine {
    /// Frequency f, Hz.
    pub freq_hz: f64,
    /// Displacement amplitude X, m (from g: X = a·g/(2πf)²).
    pub amp_m: f64,
    /// Half-cosine taper-in time, s (0 = none). Default 1 s.
    pub taper_s: f64,
    /// Run length, s: ticks k = 0 … round(duration·f_s) − 1.
    pub duration_s: f64,
    /// Whole cycles in the analysis window (ending at the last tick); `None` = every whole cycle
    /// after T_taper + 1 s.
    pub window_cycles: Option<u32>,
}

impl Sine {
    /// Displacement amplitude for an acceleration amplitude in g.
    pub fn amp_from_g(amp_g: f64, freq_hz: f64) -> f64 {
        amp_g * super::params::G / (2.0 * PI * freq_hz).powi(2)
    }

    /// Number of whole cycles in the default window.
    pub fn default_cycles(&self) -> u32 {
        ((self.duration_s - self.taper_s - 1.0) * self.freq_hz)
            .floor()
            .max(0.0) as u32
    }

    /// Reference states at time t.
    pub fn states(&self, t: f64) -> [f64; 4] {
        let w = 2.0 * PI * self.freq_hz;
        let (s, c) = (w * t).sin_cos();
        let sd = [s, w * c, -w * w * s, -w * w * w * c];
        let ed = taper(t, self.taper_s);
        let x = self.amp_m;
        [
            x * ed[0] * sd[0],
            x * (ed[1] * sd[0] + ed[0] * sd[1]),
            x * (ed[2] * sd[0] + 2.0 * ed[1] * sd[1] + ed[0] * sd[2]),
            x * (ed[3] * sd[0] + 3.0 * ed[2] * sd[1] + 3.0 * ed[1] * sd[2] + ed[0] * sd[3]),
        ]
    }

    /// Reference displacement x_r at time t (0 before the start, t < 0), m.
    pub fn displacement(&self, t: f64) -> f64 {
        if t < 0.0 {
            return 0.0;
        }
        let e = if t < self.taper_s {
            0.5 * (1.0 - (PI * t / self.taper_s).cos())
        } else {
            1.0
        };
        self.amp_m * e * (2.0 * PI * self.freq_hz * t).sin()
    }

    /// The reference at controller rate f_s.
    pub fn reference(&self, f_s: f64) -> Reference {
        let n = (self.duration_s * f_s).round() as usize;
        let mut r = Reference::with_capacity(f_s, n, Some(self.freq_hz));
        for k in 0..n {
            let s = self.states(k as f64 / f_s);
            r.push(s, s[0]);
        }
        let cycles = self.window_cycles.unwrap_or_else(|| self.default_cycles());
        let len = ((cycles as f64) * f_s / self.freq_hz).round() as usize;
        r.window = (n.saturating_sub(len), n);
        r
    }
}

/// Sampled displacement record (docs/model.md §4).
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Sample times, s (strictly increasing).
    pub time_s: Vec<f64>,
    /// Displacement, m.
    pub disp_m: Vec<f64>,
    /// Corner of the reference filter, Hz. Default 50 Hz.
    pub f_ref_hz: f64,
    /// What the record is: a command (the causal generator) or the tracked reference.
    pub signal: Signal,
}

impl Record {
    /// The reference at controller rate f_s, ticks from the first to the last record time.
    ///
    /// Panics if the record has fewer than two samples or times that do not increase; the
    /// orchestration layer validates records (with file, column and row) before they get here.
    pub fn reference(&self, f_s: f64) -> Reference {
        assert!(self.time_s.len() >= 2 && self.time_s.len() == self.disp_m.len());
        let span = self.time_s[self.time_s.len() - 1] - self.time_s[0];
        let n = (span * f_s).floor() as usize + 1;
        match self.signal {
            Signal::Command => self.generated(f_s, n),
            Signal::Reference => self.tracked(f_s, n),
        }
    }

    /// `signal = "reference"`: x_r is the record (the cubic through the nearest samples between
    /// them), v_r, a_r and j_r its zero-phase derivatives ([`zero_phase_derivatives`]).
    fn tracked(&self, f_s: f64, n: usize) -> Reference {
        let u = cubic_at_ticks(&self.time_s, &self.disp_m, f_s, n);
        let d = self.derivatives(f_s, n);
        let mut r = Reference::with_capacity(f_s, n, None);
        for (k, s) in d.states.iter().enumerate() {
            r.push([u[k], s[1], s[2], s[3]], u[k]);
        }
        r.accel_floor = d.floor;
        let noise = self.noise_realisation(f_s, n, d.corner_hz);
        r.record_error = match (noise.is_empty(), d.loss.is_empty()) {
            (true, _) => d.loss,
            (_, true) => noise,
            _ => (noise.iter().zip(&d.loss))
                .map(|(a, b)| std::array::from_fn(|i| a[i] + b[i]))
                .collect(),
        };
        r
    }

    /// [`Reference::record_error`]: the record's noise drawn once more ([`Record::noise_samples`]),
    /// made into states as [`Record::tracked`] makes the record's: the cubic at the ticks for x,
    /// the zero-phase derivatives at `corner_hz` for v, a and j. Empty where there is none.
    fn noise_realisation(&self, f_s: f64, n: usize, corner_hz: f64) -> Vec<[f64; 4]> {
        let Some(e) = self.noise_samples() else {
            return Vec::new();
        };
        let fine = OVERSAMPLING as f64 * f_s;
        let u = cubic_at_ticks(&self.time_s, &e, fine, OVERSAMPLING * (n - 1) + 1);
        let x = cubic_at_ticks(&self.time_s, &e, f_s, n);
        let d = zero_phase_derivatives(&u, 2.0 * PI * corner_hz, 1.0 / fine);
        (d.into_iter().step_by(OVERSAMPLING).zip(x))
            .map(|(s, x)| [x, s[1], s[2], s[3]])
            .collect()
    }

    /// The record's noise drawn once more, a value per sample (a fixed pseudo-random sequence,
    /// [`Record::noise_scales`]'s law); none where the record has none.
    fn noise_samples(&self) -> Option<Vec<f64>> {
        let (scale, rounding) = self.noise_scales()?;
        let draw = |i: usize| match rounding {
            true => uniform(2 * i as u64) - 0.5,
            false => gaussian(i as u64),
        };
        Some(scale.iter().enumerate().map(|(i, s)| s * draw(i)).collect())
    }

    /// The record's noise, per sample: its scale, and whether it is rounding (uniform over the
    /// scale, a step) or white (Gaussian of σ the scale). Where its values read as printed to a
    /// fixed number of significant digits or of decimals ([`printed_steps`]) and that rounding
    /// makes at least half of the white noise's σ, the rounding: each value's step follows its
    /// level (white noise of the same σ moved a broadband test's force 2–3 times less than
    /// rounding to 6 significant digits did). Else white noise of the σ of [`white_sigma`], block
    /// by block of at least [`NOISE_BLOCK`] samples (the record's level may change). None where
    /// both are 0, or not finite.
    fn noise_scales(&self) -> Option<(Vec<f64>, bool)> {
        let x = &self.disp_m;
        let block = x.len().div_ceil((x.len() / NOISE_BLOCK).max(1));
        let sigma: Vec<f64> = x.chunks(block).map(white_sigma).collect();
        if !sigma.iter().all(|s| s.is_finite()) {
            return None;
        }
        let rms = |v: &[f64]| (v.iter().map(|a| a * a).sum::<f64>() / v.len().max(1) as f64).sqrt();
        if let Some(q) = printed_steps(x) {
            if rms(&q) / 12f64.sqrt() >= 0.5 * rms(&sigma) && rms(&q) > 0.0 {
                return Some((q, true));
            }
        }
        if !sigma.iter().any(|s| *s > 0.0) {
            return None;
        }
        Some(((0..x.len()).map(|i| sigma[i / block]).collect(), false))
    }

    /// σ of the record's noise over its samples, m ([`Record::noise_scales`]: a rounding's
    /// step over √12); 0 where it has none. A window over the whole record (the top band's
    /// estimate) weighs its middle, where a motion's strong part and its coarsest rounding are:
    /// 1.4 times the rounding's σ of a record written to 6 significant digits.
    fn noise_level(&self) -> f64 {
        let Some((scale, rounding)) = self.noise_scales() else {
            return 0.0;
        };
        let per = if rounding { 12f64.sqrt() } else { 1.0 };
        let ms = scale.iter().map(|s| (s / per).powi(2)).sum::<f64>() / scale.len() as f64;
        ms.sqrt()
    }

    /// The corner of a tracked reference's derivatives, Hz (docs/model.md §4): of
    /// [`DERIVATIVE_CORNERS`] × f_ref (those up to f_s/4 and 1/2.5 of the record's rate), the
    /// one whose a_r has the least estimated error, the record's content the corner takes off
    /// (against the highest corner's a_r) plus the record's noise it lets through.
    pub fn derivative_corner_hz(&self, f_s: f64) -> f64 {
        let n = ((self.time_s[self.time_s.len() - 1] - self.time_s[0]) * f_s).floor() as usize + 1;
        self.derivatives(f_s, n).corner_hz
    }

    /// [`Record::derivative_corner_hz`], the derivatives there at `n` ticks and their estimated
    /// error. The filters run at [`OVERSAMPLING`] times the controller's rate, on the record's
    /// cubic there: at the ticks' own rate each pass's linear interpolation has a kink at every
    /// tick, whose images at the tick rate a corner above f_s/20 passes into a_r (4.6e-4 of a
    /// multisine's a_r at 125 Hz).
    fn derivatives(&self, f_s: f64, n: usize) -> Derivatives {
        let rate = self.sample_rate();
        let cap = (f_s / 4.0).min(rate / 2.5);
        let corners: Vec<f64> = DERIVATIVE_CORNERS
            .iter()
            .map(|k| k * self.f_ref_hz)
            .filter(|&c| c <= self.f_ref_hz || c <= cap)
            .collect();
        let fine = OVERSAMPLING as f64 * f_s;
        let u = cubic_at_ticks(&self.time_s, &self.disp_m, fine, OVERSAMPLING * (n - 1) + 1);
        let at = |c: f64| -> Vec<[f64; 4]> {
            let d = zero_phase_derivatives(&u, 2.0 * PI * c, 1.0 / fine);
            d.into_iter().step_by(OVERSAMPLING).collect()
        };
        let accels: Vec<Vec<f64>> = corners
            .iter()
            .map(|&c| at(c).iter().map(|s| s[2]).collect())
            .collect();
        let sigma = self.noise_level();
        let noise =
            |c: f64, minus: Option<f64>| noise_in_accel(sigma, rate.min(f_s) / 2.0, c, minus);
        // The content corner i takes off against corner j (i < j), noise apart.
        let taken = |i: usize, j: usize| {
            (mean_square_apart(&accels[i], &accels[j]) - noise(corners[i], Some(corners[j])))
                .max(0.0)
        };
        let top = corners.len() - 1;
        let best = (0..=top)
            .map(|i| {
                (
                    if i < top { taken(i, top) } else { 0.0 } + noise(corners[i], None),
                    i,
                )
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(top, |(_, i)| i);
        // The best corner's own loss, from its difference with a neighbour: for content well
        // below both corners the filter takes (f/c)⁸ off, so corner c' < c takes ((c/c')⁸ − 1)
        // times c's loss more, and c'' > c ((1 − (c/c'')⁸) times c's loss less.
        let loss = match (best, top) {
            (_, 0) => 0.0,
            (0, _) => taken(0, 1) / (1.0 - (corners[0] / corners[1]).powi(8)).powi(2),
            (b, _) => taken(b - 1, b) / ((corners[b] / corners[b - 1]).powi(8) - 1.0).powi(2),
        };
        let rms = (accels[best].iter().map(|a| a * a).sum::<f64>() / n.max(1) as f64).sqrt();
        let states = at(corners[best]);
        let loss_states = match best == top {
            true => Vec::new(),
            false => {
                let share = 1.0 - (corners[best] / corners[top]).powi(8);
                let d = scaled_difference(&at(corners[top]), &states, share);
                // Sized to the content alone: the difference also holds the noise the highest
                // corner lets through beyond this one's.
                let ms = d.iter().map(|s| s[2] * s[2]).sum::<f64>() / n.max(1) as f64;
                let content = taken(best, top) / (share * share);
                let k = if ms > 0.0 {
                    (content / ms).sqrt().min(1.0)
                } else {
                    0.0
                };
                d.into_iter().map(|s| s.map(|v| v * k)).collect()
            }
        };
        Derivatives {
            corner_hz: corners[best],
            states,
            floor: ((loss + noise(corners[best], None)).sqrt() / rms).min(1.0),
            loss: loss_states,
        }
    }

    /// The record's sample rate, Hz: its samples over its span.
    fn sample_rate(&self) -> f64 {
        let span = self.time_s[self.time_s.len() - 1] - self.time_s[0];
        (self.time_s.len() - 1) as f64 / span
    }

    /// `signal = "command"`: the record, linear between samples, through the causal
    /// state-variable filter (docs/model.md §4), exact for the record's linear interpolant.
    fn generated(&self, f_s: f64, n: usize) -> Reference {
        let t0 = self.time_s[0];
        let (phi, g0, g1) = foh_filter(CRITICAL4, 2.0 * PI * self.f_ref_hz, 1.0 / f_s);
        let mut r = Reference::with_capacity(f_s, n, None);
        let mut s = [self.disp_m[0], 0.0, 0.0, 0.0];
        let mut i = 0;
        let mut u_at = |k: usize| {
            let t = t0 + k as f64 / f_s;
            while i + 2 < self.time_s.len() && self.time_s[i + 1] <= t {
                i += 1;
            }
            let (ta, tb) = (self.time_s[i], self.time_s[i + 1]);
            let w = ((t - ta) / (tb - ta)).clamp(0.0, 1.0);
            self.disp_m[i] + w * (self.disp_m[i + 1] - self.disp_m[i])
        };
        let mut u = u_at(0);
        for k in 0..n {
            r.push(s, u);
            let next = u_at(k + 1);
            s = std::array::from_fn(|row| {
                (0..4).map(|c| phi[row][c] * s[c]).sum::<f64>() + g0[row] * u + g1[row] * (next - u)
            });
            u = next;
        }
        r
    }
}

/// What a record is, which decides how its four reference states are made (docs/model.md §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Signal {
    /// The command into the controller's reference generator (a drive file, a ground motion fed
    /// to the table): the states of the causal 4th-order state-variable filter, lag included.
    #[default]
    Command,
    /// The reference the controller tracked (what a data-acquisition system records): x_r is the
    /// record itself; v_r, a_r, j_r its derivatives by a zero-phase filter, with no lag.
    Reference,
}

impl Signal {
    /// Its name in a spec (`signal = "reference"`).
    pub fn name(self) -> &'static str {
        match self {
            Signal::Command => "command",
            Signal::Reference => "reference",
        }
    }
}

/// Coefficients c₁, c₂, c₃ of the 4th-order Butterworth polynomial s⁴ + c₃s³ + c₂s² + c₁s + 1
/// (unit corner): (s² + 2cos(π/8)s + 1)(s² + 2cos(3π/8)s + 1).
const BUTTERWORTH4: [f64; 3] = [
    2.613_125_929_752_753,
    3.414_213_562_373_095,
    2.613_125_929_752_753,
];

/// σ of white noise in `x`, m: the median power of the Hann-windowed spectrum of its second
/// differences in the top band, 0.4 to 0.5 of its rate, where a reference the controller's
/// generator made holds next to nothing, over the differences' gain there (as
/// `fourier::noise_sigma` in the orchestration layer, at 64 bins by a direct transform); third
/// differences (σ = rms(Δ³x)/√20, an upper bound) for fewer than 1280 samples, too few for the
/// band to hold 64 bins.
fn white_sigma(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 1280 {
        let d3 = x
            .windows(4)
            .map(|w| (w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0]).powi(2));
        return (d3.sum::<f64>() / n.saturating_sub(3).max(1) as f64 / 20.0).sqrt();
    }
    // Second differences: the window's leakage of a strong slow motion into the top band (a
    // 2048-sample block of a broadband record read 1e-10 m there, its noise 1e-14 m) falls by
    // (2 sin(πf/R))² at the motion's f; the noise's power in the band is then divided by the
    // differences' gain (2 sin(πk/n))⁴ bin by bin.
    let x: Vec<f64> = x.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect();
    let n = x.len();
    let hann: Vec<f64> = (0..n)
        .map(|j| (PI * (j as f64 + 0.5) / n as f64).sin().powi(2))
        .collect();
    let sum_w2: f64 = hann.iter().map(|w| w * w).sum();
    let turn: Vec<(f64, f64)> = (0..n)
        .map(|j| (2.0 * PI * j as f64 / n as f64).sin_cos())
        .collect();
    let mut power: Vec<f64> = (0..64)
        .map(|m| {
            let k = (n as f64 * (0.4 + 0.1 * (m as f64 + 0.5) / 64.0)) as usize;
            let (mut re, mut im) = (0.0, 0.0);
            for j in 0..n {
                let (s, c) = turn[(j * k) % n];
                re += x[j] * hann[j] * c;
                im -= x[j] * hann[j] * s;
            }
            let gain = (2.0 * (PI * k as f64 / n as f64).sin()).powi(4);
            (re * re + im * im) / gain
        })
        .collect();
    power.sort_by(f64::total_cmp);
    (power[32] / (2f64.ln() * sum_w2)).sqrt()
}

/// The fewest samples of a record whose noise σ [`Reference::record_error`] estimates apart (the
/// record split into equal blocks of at least this many, or taken whole) [chosen: 2048,
/// 2 s at 1024 Hz: long enough for the top band's 64 bins of [`white_sigma`], short enough to
/// follow a resolution that changes with the record's level].
const NOISE_BLOCK: usize = 2048;

/// The `i`-th of a fixed sequence of numbers uniform on (0, 1): SplitMix64's `i`-th output.
fn uniform(i: u64) -> f64 {
    let z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 + 0.5 / (1u64 << 53) as f64
}

/// The `i`-th of a fixed sequence of standard normal numbers: [`uniform`]'s 2i-th and
/// (2i + 1)-th, by Box–Muller.
fn gaussian(i: u64) -> f64 {
    let (u1, u2) = (uniform(2 * i), uniform(2 * i + 1));
    (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
}

/// The most digits [`printed_steps`] looks for [chosen: 12; a value that needs more was not
/// printed for a file, or its rounding is far below any table's noise].
const MOST_DIGITS: usize = 12;

/// Each value's rounding step where every value of `x` reads back exactly from a fixed number
/// of significant digits (`%.6g`: a step of 10^(⌊log10 |v|⌋ − 5), 0 at 0) or of decimals
/// (`%.6f`: 1e-6), up to [`MOST_DIGITS`]: the fewest that every value needs; of the two, the
/// one of larger steps (a value printed to 6 decimals also reads back from a few more
/// significant digits, but was rounded at 1e-6). None where the values need more digits (a
/// record computed in binary, never printed).
fn printed_steps(x: &[f64]) -> Option<Vec<f64>> {
    let fits_sig = |v: f64, d: usize| format!("{:.*e}", d - 1, v).parse::<f64>() == Ok(v);
    let fits_dec = |v: f64, k: usize| format!("{v:.k$}").parse::<f64>() == Ok(v);
    if !x.iter().any(|v| *v != 0.0) {
        return None;
    }
    let fewest = |fits: &dyn Fn(f64, usize) -> bool, from: usize| {
        (x.iter().filter(|v| **v != 0.0))
            .try_fold(from, |d, &v| (d..=MOST_DIGITS).find(|&k| fits(v, k)))
    };
    let sig = fewest(&fits_sig, 1).map(|d| {
        x.iter()
            .map(|v| match *v == 0.0 {
                true => 0.0,
                false => 10f64.powi(v.abs().log10().floor() as i32 + 1 - d as i32),
            })
            .collect::<Vec<f64>>()
    });
    let dec = fewest(&fits_dec, 0).map(|k| vec![10f64.powi(-(k as i32)); x.len()]);
    let mean = |q: &Vec<f64>| q.iter().sum::<f64>() / q.len().max(1) as f64;
    match (sig, dec) {
        (Some(s), Some(d)) => Some(if mean(&s) >= mean(&d) { s } else { d }),
        (s, d) => s.or(d),
    }
}

/// The record's values at `n` ticks from its first time, by the cubic through the four nearest
/// samples (the end samples held beyond the ends).
fn cubic_at_ticks(time_s: &[f64], values: &[f64], f_s: f64, n: usize) -> Vec<f64> {
    let m = time_s.len();
    let t0 = time_s[0];
    let mut i = 0;
    (0..n)
        .map(|k| {
            let t = t0 + k as f64 / f_s;
            while i + 2 < m && time_s[i + 1] <= t {
                i += 1;
            }
            let j0 = i.saturating_sub(1).min(m.saturating_sub(4));
            let nodes = (j0..(j0 + 4).min(m)).collect::<Vec<_>>();
            if nodes.len() < 4 || t <= t0 || t >= time_s[m - 1] {
                // Two samples, or beyond an end: linear, held outside.
                let w = ((t - time_s[i]) / (time_s[i + 1] - time_s[i])).clamp(0.0, 1.0);
                return values[i] + w * (values[i + 1] - values[i]);
            }
            nodes
                .iter()
                .map(|&a| {
                    let w: f64 = nodes
                        .iter()
                        .filter(|&&b| b != a)
                        .map(|&b| (t - time_s[b]) / (time_s[a] - time_s[b]))
                        .product();
                    w * values[a]
                })
                .sum()
        })
        .collect()
}

/// Exact discretisation, for an input linear between ticks (first-order hold), of the 4th-order
/// filter 1/P(s/ω), P(s) = s⁴ + c₃s³ + c₂s² + c₁s + 1 with `c` = [c₁, c₂, c₃], in the states
/// (y, ẏ, ÿ, y⃛): s[k+1] = Φ s[k] + Γ₀ u[k] + Γ₁ (u[k+1] − u[k]).
pub(crate) fn foh_filter(c: [f64; 3], w: f64, dt: f64) -> ([[f64; 4]; 4], [f64; 4], [f64; 4]) {
    // Scaled states ξ_i = y⁽ⁱ⁾/ωⁱ: ξ' = ω·(companion) ξ + ω·e4·u; augmented with u and its
    // change per tick d (u(τ) = u_k + d·τ/dt).
    let mut m = [[0.0f64; 6]; 6];
    for i in 0..3 {
        m[i][i + 1] = w * dt;
    }
    let coef = [1.0, c[0], c[1], c[2]];
    for k in 0..4 {
        m[3][k] = -coef[k] * w * dt;
    }
    m[3][4] = w * dt;
    m[4][5] = 1.0;
    let e = expm(&m);
    let mut phi = [[0.0; 4]; 4];
    let (mut g0, mut g1) = ([0.0; 4], [0.0; 4]);
    for r in 0..4 {
        let up = w.powi(r as i32);
        for k in 0..4 {
            phi[r][k] = e[r][k] * up / w.powi(k as i32);
        }
        g0[r] = e[r][4] * up;
        g1[r] = e[r][5] * up;
    }
    (phi, g0, g1)
}

/// A tracked reference's derivatives ([`Record::derivative_corner_hz`]).
struct Derivatives {
    /// The corner they were filtered at, Hz.
    corner_hz: f64,
    /// (x, v, a, j) at every tick (x filtered too; the reference takes the record's).
    states: Vec<[f64; 4]>,
    /// The estimated rms error of a over its rms: the content the corner takes off, and the
    /// record's noise it lets through.
    floor: f64,
    /// The content the corner takes off, at every tick (v, a, j; x 0): the highest corner's
    /// states less its own, over 1 − (corner / highest)⁸ (for content well below both, the
    /// share of its own loss the highest corner does not take), scaled down to the content's
    /// estimated mean square (the difference also holds the noise the highest corner lets
    /// through beyond its own). Empty where the corner is the highest.
    loss: Vec<[f64; 4]>,
}

/// (a − b) / `factor` in v, a and j, x left at 0: a loss of the derivatives' content.
fn scaled_difference(a: &[[f64; 4]], b: &[[f64; 4]], factor: f64) -> Vec<[f64; 4]> {
    (a.iter().zip(b))
        .map(|(a, b)| {
            [
                0.0,
                (a[1] - b[1]) / factor,
                (a[2] - b[2]) / factor,
                (a[3] - b[3]) / factor,
            ]
        })
        .collect()
}

/// The mean square of `a − b`.
fn mean_square_apart(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q).powi(2)).sum::<f64>() / a.len().max(1) as f64
}

/// The corners tried for a tracked reference's derivatives, in units of f_ref [chosen: from
/// f_ref, the contract's corner, to 3 f_ref, where the zero-phase filter takes (1/3)⁸ = 1.5e-4 off
/// the content at f_ref and the generator that made the reference has left (1 + 3²)⁻² = 1 % of
/// its command; higher corners raise j_r's error on a 1024 Hz record (6.8e-4 of a multisine's
/// peak at 4 f_ref against 1.6e-4 at 3 f_ref). The model's own 35 s stochastic run read back:
/// acceleration residual 1.1e-2 at f_ref, 1.2e-4 at 3 f_ref].
pub const DERIVATIVE_CORNERS: [f64; 6] = [1.0, 1.25, 1.5, 2.0, 2.5, 3.0];

/// How many times the controller's rate a tracked reference's derivatives are filtered at.
const OVERSAMPLING: usize = 4;

/// The variance of white noise of σ `sigma` (m), spread evenly over [0, `band`] Hz, in the
/// acceleration the zero-phase filter of corner `c` derives from it, m²/s⁴; with `minus`, in the
/// difference from the acceleration at that corner.
fn noise_in_accel(sigma: f64, band: f64, c: f64, minus: Option<f64>) -> f64 {
    let h = |f: f64, c: f64| 1.0 / (1.0 + (f / c).powi(8));
    let steps = 2000;
    let df = band / steps as f64;
    let integral: f64 = (0..steps)
        .map(|i| {
            let f = (i as f64 + 0.5) * df;
            let g = h(f, c) - minus.map_or(0.0, |m| h(f, m));
            (2.0 * PI * f).powi(4) * g * g * df
        })
        .sum();
    sigma * sigma / band * integral
}

/// Coefficients of the critically damped (s + 1)⁴ of the command's state-variable filter.
pub const CRITICAL4: [f64; 3] = [4.0, 6.0, 4.0];

/// One pass of the filter over `u` (every tick), from rest at u[0]: the states at every tick.
fn butterworth_pass(u: &[f64], w: f64, dt: f64) -> Vec<[f64; 4]> {
    let (phi, g0, g1) = foh_filter(BUTTERWORTH4, w, dt);
    // The first-order hold takes (ωT)²/12 off a smooth input's amplitude at ω; the input is
    // first corrected by the inverse, u − Δ²u/12, so the pass is exact to O((ωT)⁴).
    let n = u.len();
    let at = |k: isize| u[k.clamp(0, n as isize - 1) as usize];
    let p: Vec<f64> = (0..n as isize)
        .map(|k| at(k) - (at(k + 1) - 2.0 * at(k) + at(k - 1)) / 12.0)
        .collect();
    let mut s = [p[0], 0.0, 0.0, 0.0];
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        out.push(s);
        if k + 1 < n {
            let (uk, du) = (p[k], p[k + 1] - p[k]);
            s = std::array::from_fn(|r| {
                (0..4).map(|c| phi[r][c] * s[c]).sum::<f64>() + g0[r] * uk + g1[r] * du
            });
        }
    }
    out
}

/// The derivatives (v, a, j) of `u` (every tick) by the zero-phase filter |B(jω/ω_c)|⁻² — the
/// Butterworth filter run backward, then forward — so without lag: the forward pass's states.
///
/// A record may end (or start) in motion, where a filter run from rest would ring. Each end is
/// therefore extended, over [`pad_len`] ticks, by the parabola that fits the last 10 ms (at least
/// 8 ticks) by least squares [chosen: it carries the end's velocity and acceleration on, while
/// a fit over more than a few ticks keeps a recorded reference's quantisation out of it]; the
/// filter runs over the extended record, and the pads are dropped.
pub fn zero_phase_derivatives(u: &[f64], w: f64, dt: f64) -> Vec<[f64; 4]> {
    let pad = pad_len(w, dt).min(u.len());
    let fit = ((0.01 / dt).round() as usize).clamp(8, u.len().max(1));
    let head: Vec<f64> = {
        let rev: Vec<f64> = u.iter().rev().copied().collect();
        let mut h = extrapolate(&rev, fit, pad);
        h.reverse();
        h
    };
    let tail = extrapolate(u, fit, pad);
    let mut rev: Vec<f64> = head.iter().chain(u).chain(&tail).rev().copied().collect();
    let back = butterworth_pass(&rev, w, dt);
    rev.clear();
    rev.extend(back.iter().rev().map(|s| s[0]));
    let mut out = butterworth_pass(&rev, w, dt);
    out.truncate(head.len() + u.len());
    out.drain(..head.len());
    out
}

/// Ticks by which a record is extended at each end for the zero-phase filter: ten time constants
/// 1/ω of the filter (its impulse response is below 1e-4 of its peak there).
fn pad_len(w: f64, dt: f64) -> usize {
    (10.0 / (w * dt)).ceil() as usize
}

/// `pad` values after the end of `u`, on the parabola fitted by least squares to its last `fit`
/// values (a line or the last value when there are fewer).
fn extrapolate(u: &[f64], fit: usize, pad: usize) -> Vec<f64> {
    let n = u.len();
    let m = fit.min(n);
    if m < 3 {
        return vec![*u.last().unwrap_or(&0.0); pad];
    }
    // Least squares in the tick offset s from the last value (s = 0, −1, …, −(m − 1)).
    let (mut a, mut b) = ([[0.0f64; 3]; 3], [0.0f64; 3]);
    for k in 0..m {
        let s = -(k as f64);
        let basis = [1.0, s, s * s];
        for i in 0..3 {
            b[i] += basis[i] * u[n - 1 - k];
            for j in 0..3 {
                a[i][j] += basis[i] * basis[j];
            }
        }
    }
    let c = solve3(a, b);
    (1..=pad)
        .map(|k| {
            let s = k as f64;
            c[0] + c[1] * s + c[2] * s * s
        })
        .collect()
}

/// The solution of a 3×3 system by Cramer's rule (the normal equations of a parabola's fit).
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> [f64; 3] {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    std::array::from_fn(|col| {
        let mut m = a;
        for r in 0..3 {
            m[r][col] = b[r];
        }
        det(m) / d
    })
}

/// The taper (1 − cos(πt/T))/2 rising over `taper_s` = T and its first three derivatives at `t`
/// (1 and zeros from T on): the envelope a sine starts under.
pub fn taper(t: f64, taper_s: f64) -> [f64; 4] {
    if t >= taper_s {
        return [1.0, 0.0, 0.0, 0.0];
    }
    let p = PI / taper_s;
    let (ps, pc) = (p * t).sin_cos();
    [
        0.5 * (1.0 - pc),
        0.5 * p * ps,
        0.5 * p * p * pc,
        -0.5 * p * p * p * ps,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tracked record's noise, once more (`record_error`'s x): for a record holding white noise of
    /// σ = 2e-6 m in its second half only (a resolution that follows the record's level), the
    /// realisation's x has that σ there, within the estimate's 10 %, and none in the quiet first
    /// half; a record without noise gives none (under 1e-3 of that σ); and the realisation is
    /// not the record's own noise (their correlation is near 0).
    #[test]
    fn a_records_noise_is_drawn_once_more_where_it_is() {
        let rate = 1024.0;
        let n = 8 * 2048;
        let time_s: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
        let smooth: Vec<f64> = (time_s.iter())
            .map(|t| 0.02 * (2.0 * PI * 1.3 * t).sin())
            .collect();
        let noise: Vec<f64> = (0..n)
            .map(|i| {
                if i < n / 2 {
                    0.0
                } else {
                    2e-6 * gaussian(1_000_003 + i as u64)
                }
            })
            .collect();
        let noisy: Vec<f64> = smooth.iter().zip(&noise).map(|(a, b)| a + b).collect();
        let record = |disp_m: Vec<f64>| Record {
            time_s: time_s.clone(),
            disp_m,
            f_ref_hz: 50.0,
            signal: Signal::Reference,
        };
        let r = record(noisy).reference(rate);
        let rms =
            |v: &[[f64; 4]]| (v.iter().map(|s| s[0] * s[0]).sum::<f64>() / v.len() as f64).sqrt();
        let (first, second) = r.record_error.split_at(r.record_error.len() / 2);
        assert!((rms(second) / 2e-6 - 1.0).abs() < 0.1, "{:e}", rms(second));
        assert!(rms(&first[..first.len() - 64]) < 2e-8, "{:e}", rms(first));
        let dot: f64 = (second.iter().zip(&noise[n / 2..]))
            .map(|(a, b)| a[0] * b)
            .sum();
        let corr = dot / (rms(second) * 2e-6 * second.len() as f64);
        assert!(
            corr.abs() < 0.05,
            "correlated with the record's own noise: {corr}"
        );
        let clean = record(smooth).reference(rate);
        assert!(
            rms(&clean.record_error) < 2e-9,
            "{:e}",
            rms(&clean.record_error)
        );
    }

    /// A record printed to 5 significant digits is drawn again as its rounding: each value's
    /// error within half its step (10^(⌊log10 |v|⌋ − 4)), of the rms a uniform error over the
    /// steps has; one printed to 6 decimals has steps of 1e-6; one never printed, or all zero,
    /// has none.
    #[test]
    fn a_records_printed_digits_are_drawn_as_its_rounding() {
        let rate = 1024.0;
        let time_s: Vec<f64> = (0..8192).map(|i| i as f64 / rate).collect();
        let exact: Vec<f64> = (time_s.iter())
            .map(|t| 0.03 * (2.0 * PI * 1.1 * t).sin() + 0.004 * (2.0 * PI * 4.7 * t).sin())
            .collect();
        let printed = |f: &dyn Fn(f64) -> String| -> Vec<f64> {
            exact.iter().map(|v| f(*v).parse().unwrap()).collect()
        };
        let five = printed(&|v| format!("{v:.4e}"));
        let step = |v: f64| match v == 0.0 {
            true => 0.0,
            false => 10f64.powi(v.abs().log10().floor() as i32 - 4),
        };
        let r = Record {
            time_s: time_s.clone(),
            disp_m: five.clone(),
            f_ref_hz: 50.0,
            signal: Signal::Reference,
        }
        .reference(rate);
        let e: Vec<f64> = r.record_error.iter().map(|s| s[0]).collect();
        assert_eq!(e.len(), five.len());
        for (i, (e, v)) in e.iter().zip(&five).enumerate() {
            assert!(
                e.abs() <= 0.5 * step(*v) * (1.0 + 1e-9),
                "row {i}: {e:e} for {v}"
            );
        }
        let rms = |v: &mut dyn Iterator<Item = f64>| {
            let (s, n) = v.fold((0.0, 0.0), |(s, n), x| (s + x * x, n + 1.0));
            (s / n).sqrt()
        };
        let want = rms(&mut five.iter().map(|v| step(*v))) / 12f64.sqrt();
        let got = rms(&mut e.iter().copied());
        assert!((got / want - 1.0).abs() < 0.1, "{got:e} against {want:e}");
        let six_decimals = printed_steps(&printed(&|v| format!("{v:.6}"))).unwrap();
        assert!(six_decimals.iter().all(|q| *q == 1e-6));
        assert!(printed_steps(&exact).is_none());
        assert!(printed_steps(&[0.0; 16]).is_none());
    }

    /// What a tracked reference could be off by (`record_error`) is the size of what it is off
    /// by: a record of a 1.1 Hz motion with a 41 Hz component, each with white noise of 0.1 µm
    /// (a corner between f_ref and the highest, whose a_r loses some of the 41 Hz) or 10 µm
    /// (f_ref: noise and loss): the rms of record_error's a from 0.8 to 2 times the rms of a_r
    /// less the true acceleration, away from the ends (measured: 1.27 and 1.70; the content
    /// lost is estimated against the highest corner, so the estimate errs large, a floor on the
    /// safe side; the unscaled difference was 13 times the error at 10 µm).
    #[test]
    fn a_tracked_references_error_is_estimated_to_its_size() {
        let rate = 1024.0;
        let n = (20.0 * rate) as usize;
        let w = [2.0 * PI * 1.1, 2.0 * PI * 41.0];
        let time_s: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
        let x = |t: f64| 0.05 * (w[0] * t).sin() + 1e-5 * (w[1] * t).sin();
        let a =
            |t: f64| -0.05 * w[0] * w[0] * (w[0] * t).sin() - 1e-5 * w[1] * w[1] * (w[1] * t).sin();
        for (sd, seed) in [(1e-7, 7_000_000u64), (1e-5, 9_000_000)] {
            let disp_m = (time_s.iter().enumerate())
                .map(|(i, t)| x(*t) + sd * gaussian(seed + i as u64))
                .collect();
            let r = Record {
                time_s: time_s.clone(),
                disp_m,
                f_ref_hz: 50.0,
                signal: Signal::Reference,
            }
            .reference(rate);
            let mid = 2048..n - 2048;
            let rms = |v: &mut dyn Iterator<Item = f64>| {
                let (s, m) = v.fold((0.0, 0.0), |(s, m), x| (s + x * x, m + 1.0));
                (s / m).sqrt()
            };
            let actual = rms(&mut mid.clone().map(|k| r.a[k] - a(k as f64 / rate)));
            let estimated = rms(&mut mid.map(|k| r.record_error[k][2]));
            let ratio = estimated / actual;
            assert!(
                ratio > 0.8 && ratio < 2.0,
                "σ {sd:e}: {estimated:e} against {actual:e}"
            );
        }
    }

    /// The extension after a record's end lies on the parabola through its last values: exactly
    /// where they are a parabola, with three values (the fewest that fit one) or more.
    #[test]
    fn the_extension_continues_a_parabola() {
        let u: Vec<f64> = (0..8)
            .map(|k| 0.5 * (k as f64 - 2.0).powi(2) - 3.0)
            .collect();
        let next = |k: usize| 0.5 * (k as f64 - 2.0).powi(2) - 3.0;
        for fit in [3, 5, 8] {
            let e = extrapolate(&u, fit, 3);
            for (i, got) in e.iter().enumerate() {
                let want = next(8 + i);
                assert!(
                    (got - want).abs() < 1e-9,
                    "fit {fit}, {i}: {got} against {want}"
                );
            }
        }
        // Fewer than three values: the last one, held.
        assert_eq!(extrapolate(&u[..2], 5, 2), vec![u[1]; 2]);
    }

    /// The peaks are the largest magnitudes inside the window, of x, v and a in that order: a
    /// 3 Hz sine's amplitude, ω times it and ω² times it (the window holds whole cycles of the
    /// untapered sine; a tick need not fall on a crest, hence the 1e-3).
    #[test]
    fn peaks_are_the_window_maxima_of_each_state() {
        let amp = 0.05;
        let r = Sine {
            freq_hz: 3.0,
            amp_m: amp,
            taper_s: 1.0,
            duration_s: 3.0,
            window_cycles: Some(4),
        }
        .reference(1024.0);
        let w = 2.0 * std::f64::consts::PI * 3.0;
        let (x, v, a) = r.peaks();
        for (got, want) in [(x, amp), (v, amp * w), (a, amp * w * w)] {
            assert!((got / want - 1.0).abs() < 1e-3, "{got} against {want}");
            assert!(got <= want * (1.0 + 1e-12), "{got} beyond {want}");
        }
        // The taper (outside the window) is never counted: a spike there changes nothing.
        let mut spiked = r.clone();
        spiked.a[0] = 1e6;
        assert_eq!(spiked.peaks(), (x, v, a));
    }

    #[test]
    fn sine_derivatives_are_consistent() {
        let s = Sine {
            freq_hz: 3.0,
            amp_m: 0.05,
            taper_s: 1.0,
            duration_s: 3.0,
            window_cycles: Some(4),
        };
        for &t in &[0.1, 0.5, 0.999, 1.5, 2.2] {
            let h = 1e-6;
            let (p, m) = (s.states(t + h), s.states(t - h));
            let c = s.states(t);
            for d in 0..3 {
                let fd = (p[d] - m[d]) / (2.0 * h);
                assert!(
                    (fd - c[d + 1]).abs() <= 1e-5 * (1.0 + c[d + 1].abs()),
                    "t={t} d={d}: {fd} vs {}",
                    c[d + 1]
                );
            }
        }
        let r = s.reference(1024.0);
        assert_eq!(r.len(), 3072);
        assert_eq!(r.window, (3072 - 1365, 3072));
        assert_eq!(s.default_cycles(), 3);
        assert!((Sine::amp_from_g(1.73, 3.0) - 0.047749).abs() < 1e-6);
    }

    #[test]
    fn svf_tracks_a_ramp_with_exact_derivatives() {
        // A ramp of 0.1 m/s: after the transient, v_r = 0.1, a_r = j_r = 0, x_r lags by 4/ω
        // (the filter is exact for an input linear between ticks: no ripple, no extra lag).
        let f_s = 1024.0;
        let t: Vec<f64> = (0..=2048).map(|k| k as f64 / f_s).collect();
        let d: Vec<f64> = t.iter().map(|t| 0.1 * t).collect();
        let rec = Record {
            time_s: t,
            disp_m: d,
            f_ref_hz: 50.0,
            signal: Signal::Command,
        };
        let r = rec.reference(f_s);
        assert_eq!(r.len(), 2049);
        let k = 2000;
        // The transient decays as (ωt)³e^{−ωt}/6 of the ramp: 2e-123 by t = 1.95 s; what is
        // left is rounding.
        assert!((r.v[k] - 0.1).abs() < 1e-12, "{}", r.v[k]);
        assert!(
            r.a[k].abs() < 1e-9 && r.j[k].abs() < 1e-6,
            "a {} j {}",
            r.a[k],
            r.j[k]
        );
        let lag = 4.0 / (2.0 * PI * 50.0);
        let expected = 0.1 * (k as f64 / f_s - lag);
        assert!(
            (r.x[k] - expected).abs() < 1e-12,
            "{} vs {expected}",
            r.x[k]
        );
    }

    #[test]
    fn svf_dc_gain_is_one() {
        let (phi, g0, _) = foh_filter(CRITICAL4, 2.0 * PI * 50.0, 1.0 / 1024.0);
        // Fixed point for u = 1 is x = 1, other states 0.
        let s = [1.0, 0.0, 0.0, 0.0];
        for r in 0..4 {
            let next = (0..4).map(|c| phi[r][c] * s[c]).sum::<f64>() + g0[r];
            assert!((next - s[r]).abs() < 1e-9, "row {r}: {next}");
        }
    }

    /// `signal = "reference"`: x_r is the record, and its derivatives by the zero-phase filter
    /// are those of the signal, with no lag, at the controller's rate and at a DAQ's 500 and
    /// 256 Hz (a multisine of 1.3, 7 and 15 Hz; the first and last 2 s, where the filter starts,
    /// left out).
    #[test]
    fn a_tracked_reference_has_the_record_and_its_derivatives() {
        let comps = [(0.04, 1.3, 0.2), (0.004, 7.0, 1.0), (0.0008, 15.0, 2.0)];
        let exact = |t: f64| -> [f64; 4] {
            let mut s = [0.0; 4];
            for (a, f, p) in comps {
                let w = 2.0 * PI * f;
                let (sn, cs) = (w * t + p).sin_cos();
                s = [
                    s[0] + a * sn,
                    s[1] + a * w * cs,
                    s[2] - a * w * w * sn,
                    s[3] - a * w.powi(3) * cs,
                ];
            }
            s
        };
        // Largest error over the largest value, of x, v, a, j: measured 0, 1.5e-7, 3.4e-6,
        // 1.6e-4 at 1024 Hz and 6.2e-7, 2.8e-6, 1.0e-5, 2.1e-4 at 500 Hz (corner 150 Hz);
        // 9.5e-6, 4.0e-5, 1.3e-4, 4.8e-4 at 256 Hz (corner 100 Hz, the highest below 1/2.5 of
        // the rate).
        for (rate, bound) in [
            (1024.0, [1e-15, 1e-6, 1e-5, 4e-4]),
            (500.0, [2e-6, 1e-5, 3e-5, 5e-4]),
            (256.0, [2e-5, 1e-4, 3e-4, 1e-3]),
        ] {
            let n = (20.0 * rate) as usize;
            let time_s: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
            let disp_m: Vec<f64> = time_s.iter().map(|&t| exact(t)[0]).collect();
            let rec = Record {
                time_s,
                disp_m,
                f_ref_hz: 50.0,
                signal: Signal::Reference,
            };
            let r = rec.reference(1024.0);
            let (mut err, mut mag) = ([0.0f64; 4], [0.0f64; 4]);
            for k in 2048..(r.len() - 2048) {
                let e = exact(k as f64 / 1024.0);
                for (d, got) in [r.x[k], r.v[k], r.a[k], r.j[k]].into_iter().enumerate() {
                    err[d] = err[d].max((got - e[d]).abs());
                    mag[d] = mag[d].max(e[d].abs());
                }
            }
            for d in 0..4 {
                assert!(
                    err[d] <= bound[d] * mag[d],
                    "{rate} Hz, state {d}: {}",
                    err[d] / mag[d]
                );
            }
            assert_eq!(r.command, r.x);
        }
    }

    /// The derivatives' corner: the highest tried for a clean record (3 f_ref), f_ref for one
    /// whose noise (10 µm, a 16-bit reference over ±0.3 m) would swamp a higher corner's a_r, and
    /// in between for 0.1 µm; at 256 Hz only corners up to 1/2.5 of the rate are tried.
    #[test]
    fn the_derivatives_corner_follows_the_records_noise() {
        let rate = 1024.0;
        let n = (20.0 * rate) as usize;
        let mut state = 12345u64;
        let mut gauss = move || {
            let mut u = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            (-2.0 * u().ln()).sqrt() * (2.0 * PI * u()).cos()
        };
        let clean: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / rate;
                0.05 * (2.0 * PI * 1.1 * t).sin() + 1e-5 * (2.0 * PI * 41.0 * t).sin()
            })
            .collect();
        let corner = |sd: f64, rate: f64, gauss: &mut dyn FnMut() -> f64| {
            let step = (1024.0 / rate) as usize;
            let disp_m: Vec<f64> = clean
                .iter()
                .step_by(step)
                .map(|x| x + sd * gauss())
                .collect();
            let time_s = (0..disp_m.len()).map(|i| i as f64 / rate).collect();
            let rec = Record {
                time_s,
                disp_m,
                f_ref_hz: 50.0,
                signal: Signal::Reference,
            };
            rec.derivative_corner_hz(1024.0)
        };
        assert_eq!(corner(0.0, rate, &mut gauss), 150.0);
        assert_eq!(corner(1e-5, rate, &mut gauss), 50.0);
        let between = corner(1e-7, rate, &mut gauss);
        assert!(between > 50.0 && between < 150.0, "{between}");
        assert_eq!(corner(0.0, 256.0, &mut gauss), 100.0);
    }
}
