//! Effect `asymmetry`: port/valve asymmetry. The valve flows of extension (flow into the cap
//! side, x > 0) are scaled by `extend_gain` against those of retraction, and actuator 2's valves
//! by `act2_gain` against actuator 1's. Its signature: even harmonics (h2) and a shifted
//! displacement, from a table that extends and retracts differently.

use crate::kernel::params::ModelParams;

pub struct Asymmetry<const N: usize> {
    extend: [f64; N],
    act2: [f64; N],
}

impl<const N: usize> Asymmetry<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        let on = |m: &ModelParams| super::switch(m, "asymmetry");
        // Off: both gains exactly 1.
        Asymmetry {
            extend: p.map(|m| 1.0 + on(m) * (m.asymmetry.extend_gain - 1.0)),
            act2: p.map(|m| 1.0 + on(m) * (m.asymmetry.act2_gain - 1.0)),
        }
    }

    /// Valve flows of actuator `act`, scaled.
    #[inline(always)]
    pub fn flows(&self, l: usize, act: usize, q: (f64, f64)) -> (f64, f64) {
        let g = (if q.0 > 0.0 { self.extend[l] } else { 1.0 }) * (if act == 1 { self.act2[l] } else { 1.0 });
        (g * q.0, g * q.1)
    }
}
