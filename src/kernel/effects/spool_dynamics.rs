//! Effect `spool_dynamics`: the spool follows its command through a second-order lag,
//! ẍ_s = ω²(x_c − x_s) − 2ζω ẋ_s, ω = 2π·freq_hz. Its signature: a phase lag that grows with
//! frequency, and a smaller amplitude ratio at higher frequencies.

use super::PlantView;
use crate::kernel::params::ModelParams;
use crate::kernel::N_ACT;

/// State indices in [`super::EffectSet`]: position of actuator i's spool at 2i, velocity at 2i+1.
pub const X: [usize; N_ACT] = [0, 2];
pub const V: [usize; N_ACT] = [1, 3];

pub struct SpoolDynamics<const N: usize> {
    /// 1 where the effect is on, 0 where it is off.
    on: [f64; N],
    w2: [f64; N],
    two_zw: [f64; N],
}

impl<const N: usize> SpoolDynamics<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        let w = p.map(|m| 2.0 * std::f64::consts::PI * m.spool_dynamics.freq_hz);
        SpoolDynamics {
            on: super::lane_mask(&p, "spool_dynamics"),
            w2: w.map(|w| w * w),
            two_zw: std::array::from_fn(|l| 2.0 * p[l].spool_dynamics.zeta * w[l]),
        }
    }

    #[inline(always)]
    pub fn spool<const S: usize>(&self, l: usize, act: usize, x_c: f64, s: &[[f64; N]; S]) -> f64 {
        x_c + self.on[l] * (s[X[act]][l] - x_c)
    }

    #[inline(always)]
    pub fn derivs<const S: usize>(&self, plant: &PlantView<'_, N>, s: &[[f64; N]; S], ds: &mut [[f64; N]; S]) {
        for act in 0..N_ACT {
            for l in 0..N {
                ds[X[act]][l] = s[V[act]][l];
                ds[V[act]][l] = self.w2[l] * (plant.x_c[l] - s[X[act]][l]) - self.two_zw[l] * s[V[act]][l];
            }
        }
    }
}
