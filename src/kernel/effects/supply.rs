//! Effect `supply`: supply pressure dynamics. A pressure-compensated pump delivers
//! Q_p = q_pump·clamp((P_S − P_s)/dp_band, 0, 1) into an accumulator of capacitance c_acc, and the
//! valves draw Q from it: c_acc dP_s/dt = Q_p − Q; the valves see P_s. Its signature: when the
//! draw of a test exceeds the pump, the supply droops, more at large amplitude, and the envelope
//! of the acceleration sinks from cycle to cycle.

use super::PlantView;
use crate::kernel::params::ModelParams;

/// State index of the supply pressure in [`super::EffectSet`].
pub const PS: usize = 4;

pub struct Supply<const N: usize> {
    on: [f64; N],
    /// Nominal supply pressure P_S (also the initial state), Pa.
    pub p_s0: [f64; N],
    q_pump: [f64; N],
    inv_c: [f64; N],
    inv_band: [f64; N],
}

impl<const N: usize> Supply<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        Supply {
            on: super::lane_mask(&p, "supply"),
            p_s0: p.map(|m| m.servovalve.p_s),
            q_pump: p.map(|m| m.supply.q_pump),
            inv_c: p.map(|m| 1.0 / m.supply.c_acc),
            inv_band: p.map(|m| 1.0 / m.supply.dp_band),
        }
    }

    #[inline(always)]
    pub fn supply<const S: usize>(&self, l: usize, p_s: f64, s: &[[f64; N]; S]) -> f64 {
        p_s + self.on[l] * (s[PS][l] - p_s)
    }

    #[inline(always)]
    pub fn derivs<const S: usize>(&self, plant: &PlantView<'_, N>, s: &[[f64; N]; S], ds: &mut [[f64; N]; S]) {
        for l in 0..N {
            let q_p = self.q_pump[l] * ((self.p_s0[l] - s[PS][l]) * self.inv_band[l]).clamp(0.0, 1.0);
            // Off: the state is held at P_S (derivative 0), so it never drifts.
            ds[PS][l] = self.on[l] * (q_p - plant.q_supply[l]) * self.inv_c[l];
        }
    }
}
