//! The TVC's feedback stage (docs/model.md §2): the displacement error through the gain G_d,
//! 10·G_d·(x_r − x)/D_max volts. It starts the command's sum.

use super::RefState;

/// One lane's feedback gain.
#[derive(Debug, Clone, Copy)]
pub struct Feedback {
    /// 10·G_d/D_max, V/m.
    pub c_fb: f64,
}

impl Feedback {
    /// The command's first term (V) for the reference `r` and the feedback displacement `x` (m).
    #[inline(always)]
    pub fn term(&self, r: &RefState, x: f64) -> f64 {
        self.c_fb * (r.x - x)
    }
}
