//! Effect `harmonic_cancellation`: adaptive harmonic cancellation (AHC) in the controller
//! (docs/model.md §8), not a physical effect of the plant. The servo-valve's square-root orifice
//! law distorts a sine's motion with odd harmonics (the seed paper's THD_odd). AHC adapts, for
//! each odd harmonic k = 3, 5, 7, 9 of the reference's frequency, the sine and cosine
//! coefficients of a cancelling displacement added to the reference, by LMS from the k-th
//! harmonic of the displacement error (demodulated and low-passed: a band filter at k·f) through
//! a model of the plant's phase at k·f, until that harmonic of the error is zero (the MTS 469D's
//! adaptive harmonic cancellation; the algorithm is the canceller of `adaptive.rs`):
//!
//! ```text
//! per k:  E_k ← E_k + λ·(2e·e^{−jkθ} − E_k),   D_k ← D_k + μ·e^{jkωτ}·E_k (|D_k| ≤ authority·A),
//!         u ← u + Σ_k Re{F(jkω)·D_k·e^{jkθ}}
//! ```
//!
//! with θ, ω and A the reference's phase, frequency and amplitude read from its four states, e
//! the displacement error, F the TVC's reference path and τ the plant model's delay; each
//! harmonic's correction is capped (the maximum authority) and all are held from `freeze_s` on.
//! Where the reference is not a sine it neither adapts nor acts. Its 16 states (D_k and E_k of
//! the four harmonics) change at the ticks only.

use super::adaptive::{cancel, Phase, Settings};
use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: super::COMPENSATION,
    summary: "adaptive harmonic cancellation: the 3rd to 9th harmonics cancelled by LMS",
    params: Params::FIELDS,
    stages: &[Stage::free(&["gain"])],
};

/// The harmonics cancelled.
pub const HARMONICS: [usize; 4] = [3, 5, 7, 9];

/// The time-history channels of each harmonic's cancelling displacement |D_k| (m): the authority
/// it uses, against its cap authority·A.
pub const CORRECTIONS: [&str; 4] = ["ahc_d3_m", "ahc_d5_m", "ahc_d7_m", "ahc_d9_m"];

params! {
    /// Effect `harmonic_cancellation`: a canceller per odd harmonic (3rd to 9th) adapted by LMS
    /// through a model of the plant's phase (docs/model.md §8).
    pub struct Params {
        gain: "1/s", "per_s", 2.0, Range::open_closed(0.0, 100.0), Chosen,
            "Adaptation rate g of each harmonic: its error falls as e^(−g·t) where the plant model is right [chosen: settled within a few seconds].";
        band_hz: "Hz", "hz", 0.5, Range::open_closed(0.0, 1000.0), Chosen,
            "Corner B of each band filter's low-pass after demodulation [chosen: below the spacing of a sine's harmonics, even ones included, down to a 1 Hz fundamental (at 2 Hz the neighbours passed at 1 Hz and the cancellers oscillated), above the rate g/2π; tests/compensation.rs, 1-10 Hz].";
        delay_s: "s", "s", 2.8e-3, Range::closed(0.0, 1.0), Chosen,
            "The plant model's delay τ: the closed loop's phase at k·ω taken as −k·ω·τ [chosen: measured, the published model's loop from reference to feedback lags as a delay of 2.6–2.9 ms at 12–40 Hz (−11° to −39°), and leads by under 15° below 5 Hz, within the 90° the LMS allows; tests/compensation.rs prints it].";
        authority: "1", "ratio", 0.05, Range::open_closed(0.0, 10.0), Chosen,
            "Largest correction of each harmonic as a fraction of the reference's amplitude [chosen: 5 %, some times the distortion of the seed's SP09].";
        freeze_s: "s", "s", 0.0, Range::ge(0.0), Chosen,
            "Time from which the corrections are held, adapted no more (0: adapts to the end) [chosen].";
    }
}

pub struct HarmonicCancellation<const N: usize> {
    set: [Settings; N],
}

impl<const N: usize> LibraryEffect<N> for HarmonicCancellation<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        HarmonicCancellation {
            set: std::array::from_fn(|l| {
                let q = Params::of(p[l]);
                let values = [q.gain, q.band_hz, q.delay_s, q.authority, q.freeze_s];
                Settings::new(on[l] != 0.0, values, p[l].controller())
            }),
        }
    }
}

impl<const N: usize> HarmonicCancellation<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 6] {
        self.set[l].lane()
    }
}

impl<const N: usize> Effect<N> for HarmonicCancellation<N> {
    /// Per harmonic (3, 5, 7, 9): D (real, imaginary), then E (real, imaginary).
    type State = [[f64; N]; 16];

    fn initial_state(&self) -> Self::State {
        [[0.0; N]; 16]
    }

    /// Each harmonic's correction |D_k| ([`CORRECTIONS`]), where the lane has it on.
    fn responses(&self, lane: usize, s: &Self::State, out: &mut dyn FnMut(&'static str, f64)) {
        if self.set[lane].on != 0.0 {
            for (h, name) in CORRECTIONS.iter().enumerate() {
                out(name, s[4 * h][lane].hypot(s[4 * h + 1][lane]));
            }
        }
    }

    /// The TVC's command plus the four harmonics' corrections, adapted at this tick.
    #[inline(always)]
    fn command(&self, c: hook::Command, s: &mut Self::State) -> f64 {
        let (l, set) = (c.lane, &self.set[c.lane]);
        // An off lane (or a reference that is not a sine) passes the command untouched.
        if set.on == 0.0 {
            return c.u;
        }
        let Some(ph) = Phase::of(c.r) else {
            return c.u;
        };
        let e = c.r[0] - c.x;
        let mut sum = 0.0;
        for (h, &k) in HARMONICS.iter().enumerate() {
            let [d_re, d_im, e_re, e_im] = &mut s[4 * h..4 * h + 4] else {
                unreachable!("four states per harmonic")
            };
            let st = [&mut d_re[l], &mut d_im[l], &mut e_re[l], &mut e_im[l]];
            sum += cancel(set, k, &ph, e, c.t, st);
        }
        c.u + sum
    }
}
