//! Effect `supply`: supply pressure dynamics. A pressure-compensated pump delivers
//! Q_p = q_pump·clamp((P_S − P_s)/dp_band, 0, 1) into an accumulator of capacitance c_acc, and the
//! valves draw Q from it: c_acc dP_s/dt = Q_p − Q; the valves see P_s. Its signature: when the
//! draw of a test exceeds the pump, the supply droops, more at large amplitude, and the envelope
//! of the acceleration sinks from cycle to cycle.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, PlantView, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "supply pressure",
    summary: "supply pressure droop: a pump of limited flow and an accumulator",
    params: Params::FIELDS,
    // The pump's band shapes the droop with the flow and the capacitance: a band of 2.5 MPa
    // held at 1 MPa was fitted as a pump 15 % short and an accumulator 70 % large, beside a
    // flow-gain curve that made up the rest (issue 51).
    stages: &[Stage::free(&["q_pump", "c_acc", "dp_band"])],
};

params! {
    /// Effect `supply`: supply pressure dynamics. A pressure-compensated pump delivers
    /// Q_p = q_pump·clamp((P_S − P_s)/dp_band, 0, 1) into an accumulator of capacitance c_acc;
    /// the valves draw Q from it: c_acc dP_s/dt = Q_p − Q. The valves see P_s instead of P_S.
    pub struct Params {
        q_pump: "m³/s", "m3_per_s", 0.2, Range::gt(0.0), Chosen,
            "Pump flow at full stroke [chosen: below the peak draw of large tests, so accumulators carry the peaks].";
        c_acc: "m³/Pa", "m3_per_pa", 3.5e-8, Range::gt(0.0), Chosen,
            "Accumulator capacitance V_gas/(n·P) [chosen: 1 m³ of gas at 20.7 MPa, n = 1.4].";
        dp_band: "Pa", "pa", 1.0e6, Range::gt(0.0), Chosen,
            "Pressure band over which the pump goes from no flow to full flow [chosen].";
    }
}

pub struct Supply<const N: usize> {
    on: [f64; N],
    /// Nominal supply pressure P_S (also the initial state), Pa.
    pub p_s0: [f64; N],
    q_pump: [f64; N],
    inv_c: [f64; N],
    inv_band: [f64; N],
}

impl<const N: usize> LibraryEffect<N> for Supply<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        Supply {
            on: super::lane_mask::<N, Self>(&p),
            p_s0: p.map(|m| m.servovalve().p_s),
            q_pump: p.map(|m| Params::of(m).q_pump),
            inv_c: p.map(|m| 1.0 / Params::of(m).c_acc),
            inv_band: p.map(|m| 1.0 / Params::of(m).dp_band),
        }
    }
}

impl<const N: usize> Supply<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 5] {
        [
            self.on[l],
            self.p_s0[l],
            self.q_pump[l],
            self.inv_c[l],
            self.inv_band[l],
        ]
    }
}

impl<const N: usize> Effect<N> for Supply<N> {
    /// The supply pressure P_s the valves see, Pa.
    type State = [[f64; N]; 1];

    fn initial_state(&self) -> Self::State {
        [self.p_s0]
    }

    #[inline(always)]
    fn supply(&self, c: hook::Supply, s: &Self::State) -> f64 {
        c.p_s + self.on[c.lane] * (s[0][c.lane] - c.p_s)
    }

    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        for l in 0..N {
            let q_p =
                self.q_pump[l] * ((self.p_s0[l] - s[0][l]) * self.inv_band[l]).clamp(0.0, 1.0);
            // Off: the state is held at P_S (derivative 0), so it never drifts.
            ds[0][l] = self.on[l] * (q_p - plant.q_supply[l]) * self.inv_c[l];
        }
    }
}
