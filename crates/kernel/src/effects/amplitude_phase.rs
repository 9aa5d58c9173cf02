//! Effect `amplitude_phase`: amplitude/phase control (APC) in the controller (docs/model.md §8),
//! not a physical effect of the plant. On a sine or a slow sweep the TVC leaves the fundamental
//! of the feedback a little off the reference's, in amplitude and in phase. APC adapts a
//! correction at the fundamental, the sine and cosine coefficients of a displacement added to the
//! reference, by LMS from the fundamental of the displacement error, until that error's
//! fundamental is zero: the amplitude ratio 1 and the phase 0 (the MTS 469D's amplitude/phase
//! control; the algorithm is the canceller of `adaptive.rs` at k = 1):
//!
//! ```text
//! E ← E + λ·(2e·e^{−jθ} − E),   D ← D + μ·e^{jωτ}·E (|D| ≤ authority·A),   u ← u + Re{F(jω)·D·e^{jθ}}
//! ```
//!
//! with θ, ω and A the reference's phase, frequency and amplitude read from its four states, e
//! the displacement error, F the TVC's reference path and τ the plant model's delay. Where the
//! reference is not a sine (at rest, a broadband record) it neither adapts nor acts. Its four
//! states (D and E, each a phasor) change at the ticks only.

use super::adaptive::{cancel, Phase, Settings};
use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: super::COMPENSATION,
    summary: "amplitude/phase control: the fundamental's amplitude and phase adapted by LMS",
    params: Params::FIELDS,
    stages: &[Stage::free(&["gain"])],
};

/// The time-history channel of the correction's size |D| (m): the authority it uses, against its
/// cap authority·A.
pub const CORRECTION: &str = "apc_d_m";

params! {
    /// Effect `amplitude_phase`: the fundamental's correction adapted by LMS on its sine and
    /// cosine coefficients (docs/model.md §8).
    pub struct Params {
        gain: "1/s", "per_s", 2.0, Range::open_closed(0.0, 100.0), Chosen,
            "Adaptation rate g: the error's fundamental falls as e^(−g·t) where the plant model is right [chosen: settled within about 2 s, slower than the band filter].";
        band_hz: "Hz", "hz", 5.0, Range::open_closed(0.0, 1000.0), Chosen,
            "Corner B of the band filter's low-pass after demodulation [chosen: above the rate g/2π; what it passes at twice the fundamental is the remaining error, which vanishes as it adapts].";
        delay_s: "s", "s", 2.8e-3, Range::closed(0.0, 1.0), Chosen,
            "The plant model's delay τ: the closed loop's phase at ω taken as −ω·τ [chosen: measured, the published model's loop from reference to feedback lags as a delay of 2.6–2.9 ms at 12–40 Hz (−11° to −39°), and leads by under 15° below 5 Hz, within the 90° the LMS allows; tests/compensation.rs prints it].";
        authority: "1", "ratio", 1.0, Range::open_closed(0.0, 10.0), Chosen,
            "Largest correction as a fraction of the reference's amplitude [chosen: the motion itself; the published model's TVC alone follows 62 % of a 1 Hz sine (0.5 g), which needs 0.62 of it].";
        freeze_s: "s", "s", 0.0, Range::ge(0.0), Chosen,
            "Time from which the correction is held, adapted no more (0: adapts to the end) [chosen].";
    }
}

pub struct AmplitudePhase<const N: usize> {
    set: [Settings; N],
}

impl<const N: usize> LibraryEffect<N> for AmplitudePhase<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        AmplitudePhase {
            set: std::array::from_fn(|l| {
                let q = Params::of(p[l]);
                let values = [q.gain, q.band_hz, q.delay_s, q.authority, q.freeze_s];
                Settings::new(on[l] != 0.0, values, p[l].controller())
            }),
        }
    }
}

impl<const N: usize> AmplitudePhase<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 6] {
        self.set[l].lane()
    }
}

impl<const N: usize> Effect<N> for AmplitudePhase<N> {
    /// D (real, imaginary), then E (real, imaginary).
    type State = [[f64; N]; 4];

    fn initial_state(&self) -> Self::State {
        [[0.0; N]; 4]
    }

    /// The correction's size |D| at the fundamental ([`CORRECTION`]), where the lane has it on.
    fn responses(&self, lane: usize, s: &Self::State, out: &mut dyn FnMut(&'static str, f64)) {
        if self.set[lane].on != 0.0 {
            out(CORRECTION, s[0][lane].hypot(s[1][lane]));
        }
    }

    /// The TVC's command plus the correction at the fundamental, adapted at this tick.
    #[inline(always)]
    fn command(&self, c: hook::Command, s: &mut Self::State) -> f64 {
        let (l, set) = (c.lane, &self.set[c.lane]);
        // An off lane (or a reference that is not a sine) passes the command untouched: the
        // canceller's trigonometry is the tick's dearest arithmetic, not to be paid for nothing.
        if set.on == 0.0 {
            return c.u;
        }
        let Some(ph) = Phase::of(c.r) else {
            return c.u;
        };
        let [d_re, d_im, e_re, e_im] = s;
        let st = [&mut d_re[l], &mut d_im[l], &mut e_re[l], &mut e_im[l]];
        c.u + cancel(set, 1, &ph, c.r[0] - c.x, c.t, st)
    }
}
