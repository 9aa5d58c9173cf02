//! Effect `seal_friction`: actuator seal friction with a Stribeck term,
//! F = −tanh(v/v_eps)·(f_c + (f_s − f_c)·exp(−(v/v_s)²)) − sigma·v. Its signature: a force step at
//! every velocity reversal, so relative odd harmonics (h3) that are largest at small amplitude,
//! and a residual concentrated near velocity reversal; neutral when off (forces 0).

use crate::kernel::params::ModelParams;

pub struct SealFriction<const N: usize> {
    f_c: [f64; N],
    df: [f64; N],
    inv_vs: [f64; N],
    sigma: [f64; N],
    inv_eps: [f64; N],
}

impl<const N: usize> SealFriction<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        let on = |m: &ModelParams| super::switch(m, "seal_friction");
        SealFriction {
            f_c: p.map(|m| on(m) * m.seal_friction.f_c),
            df: p.map(|m| on(m) * (m.seal_friction.f_s - m.seal_friction.f_c)),
            inv_vs: p.map(|m| 1.0 / m.seal_friction.v_s),
            sigma: p.map(|m| on(m) * m.seal_friction.sigma),
            inv_eps: p.map(|m| 1.0 / m.seal_friction.v_eps),
        }
    }

    /// Friction force on the platen, N.
    #[inline(always)]
    pub fn force(&self, l: usize, v: f64) -> f64 {
        let r = v * self.inv_vs[l];
        -(v * self.inv_eps[l]).tanh() * (self.f_c[l] + self.df[l] * (-r * r).exp()) - self.sigma[l] * v
    }
}
