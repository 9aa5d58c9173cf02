//! The TVC's force stabilisation stage (docs/model.md §2): the actuators' force F through a
//! high-pass s/(s + ω_hp), discretised by Tustin, and the gain G_f/F_max scaled to the 10 V
//! command (the dynamic force feedback that damps the oil column's resonance):
//!
//! ```text
//! F_hp[k] = (2f_s (F[k] − F[k−1]) + (2f_s − ω_hp) F_hp[k−1]) / (2f_s + ω_hp)
//! ```
//!
//! with F[−1] = F[0] and F_hp[−1] = 0.

/// One lane's force stabilisation.
#[derive(Debug, Clone, Copy)]
pub struct ForceStabilisation {
    /// 10·G_f/F_max, V/N.
    pub c_f: f64,
    /// The high-pass: F_hp = hp_b·(F − F_prev) + hp_a·F_hp_prev.
    pub hp_b: f64,
    pub hp_a: f64,
}

/// What the stage keeps from tick to tick.
#[derive(Debug, Clone, Copy, Default)]
pub struct ForceMemory {
    /// The force at the last tick, N.
    pub f_prev: f64,
    /// The high-passed force at the last tick, N.
    pub f_hp: f64,
}

impl ForceStabilisation {
    /// The stage at the controller rate `f_s` (Hz) with the high-pass corner `f_hp` (Hz) and
    /// the gain `c_f` (V/N).
    pub fn new(c_f: f64, f_s: f64, f_hp: f64) -> Self {
        let two_fs = 2.0 * f_s;
        let w_hp = 2.0 * std::f64::consts::PI * f_hp;
        ForceStabilisation {
            c_f,
            hp_b: two_fs / (two_fs + w_hp),
            hp_a: (two_fs - w_hp) / (two_fs + w_hp),
        }
    }

    /// The command `u` (V) with the force's term added, the high-pass stepped to the force `f`
    /// (N) of this tick.
    #[inline(always)]
    pub fn add(&self, m: &mut ForceMemory, u: f64, f: f64) -> f64 {
        m.f_hp = self.hp_b * (f - m.f_prev) + self.hp_a * m.f_hp;
        m.f_prev = f;
        u + self.c_f * m.f_hp
    }
}
