//! Effect `hold_down`: hold-down strut stiffness nonlinearity, F = −k3·y³ on top of the linear
//! −K·y of the baseline. Its signature: odd harmonics and a changed amplitude ratio where the
//! displacement is large (low frequency, large amplitude), nothing at small displacement.

use crate::kernel::params::ModelParams;

pub struct HoldDown<const N: usize> {
    k3: [f64; N],
}

impl<const N: usize> HoldDown<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        HoldDown { k3: p.map(|m| if m.effects.hold_down { m.hold_down.k3 } else { 0.0 }) }
    }

    /// Force of the cubic term on the platen, N.
    #[inline(always)]
    pub fn force(&self, l: usize, y: f64) -> f64 {
        -self.k3[l] * y * y * y
    }
}
