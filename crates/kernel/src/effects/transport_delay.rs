//! Effect `transport_delay`: a delay τ between the controller's command and the spool (pilot
//! stages, driver electronics, digital I/O). Its signature: a phase lag −ω·τ that grows in
//! proportion to frequency, with no change of amplitude.
//!
//! A pure delay has no finite state, and the kernel's states are ODE states, so the delay is
//! realised as a chain of [`STAGES`] equal first-order lags of τ/STAGES each (an Erlang delay):
//! smooth (no feed-through of the held command's steps, unlike a Padé all-pass), stable for RK4 at
//! the default step down to τ = 0.5 ms (eigenvalue −STAGES/τ, h·λ ≈ −1), and close to a pure
//! delay at table frequencies: phase −STAGES·atan(ωτ/STAGES) = −ωτ·(1 − (ωτ)²/(3·STAGES²) + …),
//! magnitude (1 + (ωτ/STAGES)²)^(−STAGES/2) ≈ 1 − (ωτ)²/(2·STAGES) — at 6 Hz and τ = 2 ms the
//! phase is within 0.01 % of −ωτ and the magnitude within 0.02 % of 1 (a choice; documented in the
//! docs/guide.md's effects table).

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, PlantView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "valve dynamics",
    summary: "a pure delay between the valve command and the spool",
    params: Params::FIELDS,
    stages: &[Stage {
        label: "",
        free: &["tau"],
        // [chosen] Starts a fit scans for `tau` (a lag a whole period off a harmonic fits it as well).
        scan: Some(("tau", &[0.5e-3, 1.0e-3, 2.0e-3, 4.0e-3, 8.0e-3, 15.0e-3])),
        size: None,
        shape: None,
        start: &[],
    }],
};

params! {
    /// Effect `transport_delay`: a pure delay τ between the controller's command and the spool
    /// (pilot stages, driver electronics, digital I/O), before the spool dynamics if those are on.
    pub struct Params {
        tau: "s", "s", 2.0e-3, Range::closed(0.5e-3, 20.0e-3), Chosen,
            "Delay between the valve command and the spool [chosen: 2 ms; realised as 4 equal first-order lags, see the effect's doc].";
    }
}

/// Number of first-order stages.
pub const STAGES: usize = 4;

pub struct TransportDelay<const N: usize> {
    on: [f64; N],
    /// STAGES/τ per lane, 1/s (a lane that is off still runs the chain, at the default τ, unused).
    rate: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for TransportDelay<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        let default_tau = Params::default().tau;
        TransportDelay {
            on,
            rate: std::array::from_fn(|l| {
                STAGES as f64
                    / if on[l] > 0.0 {
                        Params::of(p[l]).tau
                    } else {
                        default_tau
                    }
            }),
        }
    }
}

impl<const N: usize> TransportDelay<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 2] {
        [self.on[l], self.rate[l]]
    }
}

impl<const N: usize> Effect<N> for TransportDelay<N> {
    /// The outputs of the stages; the last is the delayed command.
    type State = [[f64; N]; STAGES];
    /// It moves the spool itself: a spool LVDT reads the opening.
    const MOVES_SPOOL: bool = true;

    fn initial_state(&self) -> Self::State {
        [[0.0; N]; STAGES]
    }

    /// The delayed command of lane `l` (the command itself where the effect is off).
    #[inline(always)]
    fn opening(&self, c: hook::Opening, s: &Self::State) -> f64 {
        c.x + self.on[c.lane] * (s[STAGES - 1][c.lane] - c.x)
    }

    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        for l in 0..N {
            let mut input = plant.x_c[l];
            for d in 0..STAGES {
                ds[d][l] = self.rate[l] * (input - s[d][l]);
                input = s[d][l];
            }
        }
    }
}
