//! Effect `leakage`: internal leakage across the piston q_i = c_int (P1 − P2) (from chamber 1
//! into chamber 2) and external leakage q_e = c_ext·P from each chamber to drain. Its signature:
//! a flow loss proportional to the load pressure, so a lower amplitude ratio and a phase lead
//! that are largest where the force is (low frequency, large amplitude); neutral when off
//! (both coefficients 0).

use crate::kernel::params::ModelParams;

pub struct Leakage<const N: usize> {
    c_int: [f64; N],
    c_ext: [f64; N],
}

impl<const N: usize> Leakage<N> {
    pub fn new(p: [&ModelParams; N]) -> Self {
        let on = |m: &ModelParams| super::switch(m, "leakage");
        Leakage { c_int: p.map(|m| on(m) * m.leakage.c_int), c_ext: p.map(|m| on(m) * m.leakage.c_ext) }
    }

    /// Net (into chamber 1, out of chamber 2) from the valve flows `q`.
    #[inline(always)]
    pub fn flows(&self, l: usize, q: (f64, f64), p1: f64, p2: f64) -> (f64, f64) {
        let cross = self.c_int[l] * (p1 - p2);
        (q.0 - cross - self.c_ext[l] * p1, q.1 - cross + self.c_ext[l] * p2)
    }
}
