//! The TVC's feedforward stage (docs/model.md §2): the reference's displacement, velocity,
//! acceleration and jerk through the leads L_d, L_v, L_a, L_j, each normalised by its rated
//! maximum and scaled to the 10 V command.

use super::RefState;

/// One lane's feedforward gains.
#[derive(Debug, Clone, Copy)]
pub struct Feedforward {
    /// 10·L_d/D_max, V/m.
    pub c_d: f64,
    /// 10·L_v/V_max, V/(m/s).
    pub c_v: f64,
    /// 10·L_a/A_max, V/(m/s²).
    pub c_a: f64,
    /// 10·L_j/J_max, V/(m/s³).
    pub c_j: f64,
}

impl Feedforward {
    /// The command `u` (V) with the four leads' terms added, in the order d, v, a, j (the order
    /// the CUDA kernel and the peers sum in, so that the rounding is the same).
    #[inline(always)]
    pub fn add(&self, u: f64, r: &RefState) -> f64 {
        u + self.c_d * r.x + self.c_v * r.v + self.c_a * r.a + self.c_j * r.j
    }
}
