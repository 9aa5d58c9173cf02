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
//! README's effects table).

use super::PlantView;
use crate::kernel::params::ModelParams;

/// Number of first-order stages.
pub const STAGES: usize = 4;
/// State indices in [`super::EffectSet`]: the outputs of the stages, the last is the delayed command.
pub const D: [usize; STAGES] = [5, 6, 7, 8];

pub struct TransportDelay<const N: usize> {
    on: [f64; N],
    /// STAGES/τ per lane, 1/s (a lane that is off still runs the chain, at the default τ, unused).
    rate: [f64; N],
}

impl<const N: usize> TransportDelay<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        let default_tau = crate::kernel::params::TransportDelayParams::default().tau;
        TransportDelay {
            on: super::lane_mask(&p, "transport_delay"),
            rate: p.map(|m| STAGES as f64 / if m.effects.transport_delay { m.transport_delay.tau } else { default_tau }),
        }
    }

    /// The delayed command of lane `l` (the command itself where the effect is off).
    #[inline(always)]
    pub fn delayed<const S: usize>(&self, l: usize, x_c: f64, s: &[[f64; N]; S]) -> f64 {
        x_c + self.on[l] * (s[D[STAGES - 1]][l] - x_c)
    }

    #[inline(always)]
    pub fn derivs<const S: usize>(&self, plant: &PlantView<'_, N>, s: &[[f64; N]; S], ds: &mut [[f64; N]; S]) {
        for l in 0..N {
            let mut input = plant.x_c[l];
            for &d in &D {
                ds[d][l] = self.rate[l] * (input - s[d][l]);
                input = s[d][l];
            }
        }
    }
}
