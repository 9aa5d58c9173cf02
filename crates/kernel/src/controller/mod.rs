//! Three-variable controller (TVC) replica, discrete at f_s with a zero-order hold (docs/model.md §2).
//!
//! At each tick t_k = k/f_s, from the plant state at t_k, the TVC's stages, one type each:
//!
//! ```text
//! u = 10·G_d (x_r − x)/D_max                                        feedback (`feedback`)
//!   + 10·[L_d x_r/D_max + L_v v_r/V_max + L_a a_r/A_max + L_j j_r/J_max]   feedforward (`feedforward`)
//!   + 10·G_f F_hp/F_max                                             force stabilisation (`force_stabilisation`)
//! u → compensators (the effects' `command` hook, docs/model.md §8)
//!   → five notch filters in series (`notches`) → clamp ±u_lim → spool command x_c = k_sp·u, held to t_{k+1}
//! ```
//!
//! The reference generator is [`crate::excitation::Reference`]: its four states x_r, v_r, a_r, j_r
//! at the tick ([`RefState`]). The sum is taken in the order above, term by term, as the CUDA
//! kernel and the peers take it, so that its rounding is theirs. Every stage always runs, so the
//! tick has no branch on configuration.

pub mod feedback;
pub mod feedforward;
pub mod force_stabilisation;
pub mod notches;

use feedback::Feedback;
use feedforward::Feedforward;
use force_stabilisation::{ForceMemory, ForceStabilisation};
use notches::{NotchMemory, Notches};

use super::params::ControllerParams;

/// Per-lane controller coefficients: each stage's, the clamp and the spool's gain.
#[derive(Debug, Clone, Copy)]
pub struct ControllerLane {
    pub feedback: Feedback,
    pub feedforward: Feedforward,
    pub force: ForceStabilisation,
    pub notches: Notches,
    /// The command's limit ±u_lim, V.
    pub u_lim: f64,
    /// Spool displacement per volt, m/V.
    pub k_sp: f64,
}

impl ControllerLane {
    pub fn new(p: &ControllerParams, u_lim: f64, k_sp: f64) -> Self {
        let [c_fb, c_d, c_v, c_a, c_j, c_f] = p.gains();
        ControllerLane {
            feedback: Feedback { c_fb },
            feedforward: Feedforward { c_d, c_v, c_a, c_j },
            force: ForceStabilisation::new(c_f, p.f_s, p.f_hp),
            notches: Notches::new(p),
            u_lim,
            k_sp,
        }
    }
}

/// Per-lane controller memory.
#[derive(Debug, Clone, Copy, Default)]
pub struct ControllerMemory {
    pub force: ForceMemory,
    pub notch: NotchMemory,
}

impl ControllerMemory {
    /// Memory before the first tick: F[−1] = F[0], F_hp[−1] = 0.
    pub fn new(f0: f64) -> Self {
        ControllerMemory {
            force: ForceMemory {
                f_prev: f0,
                f_hp: 0.0,
            },
            notch: NotchMemory::default(),
        }
    }
}

/// Reference states at one tick (of one lane; usually every lane shares them).
#[derive(Debug, Clone, Copy, Default)]
pub struct RefState {
    pub x: f64,
    pub v: f64,
    pub a: f64,
    pub j: f64,
}

/// One controller tick: returns the clamped valve command u (V). The spool command is k_sp·u.
#[inline(always)]
pub fn tick(c: &ControllerLane, m: &mut ControllerMemory, r: &RefState, x: f64, f: f64) -> f64 {
    let u = sum(c, m, r, x, f);
    shape(c, m, u)
}

/// The TVC's sum at a tick (V): feedback, feedforward, then the force stabilisation (its
/// high-pass stepped). A compensator (docs/model.md §8) changes it before [`shape`].
#[inline(always)]
pub fn sum(c: &ControllerLane, m: &mut ControllerMemory, r: &RefState, x: f64, f: f64) -> f64 {
    let u = c.feedback.term(r, x);
    let u = c.feedforward.add(u, r);
    c.force.add(&mut m.force, u, f)
}

/// The command `u` through the five notches in series, then clamped to ±u_lim (V).
#[inline(always)]
pub fn shape(c: &ControllerLane, m: &mut ControllerMemory, u: f64) -> f64 {
    c.notches.apply(&mut m.notch, u).clamp(-c.u_lim, c.u_lim)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Notches at depth 0 are the identity, to the bit: a tick is the feedback's term alone.
    #[test]
    fn notches_at_depth_0_pass_the_sum_to_the_bit() {
        let p = ControllerParams::default();
        let c = ControllerLane::new(&p, 10.0, 1.905e-3);
        let mut m = ControllerMemory::new(0.0);
        let r = RefState {
            x: 0.0123,
            ..Default::default()
        };
        let u = tick(&c, &mut m, &r, 0.0, 0.0);
        assert_eq!(u, c.feedback.c_fb * 0.0123);
    }

    /// The sum of the stages is the TVC's formula with its terms in order, to the bit.
    #[test]
    fn the_stages_sum_to_the_tvc_formula() {
        let p = ControllerParams::default();
        let [c_fb, c_d, c_v, c_a, c_j, c_f] = p.gains();
        let c = ControllerLane::new(&p, 10.0, 1.905e-3);
        let mut m = ControllerMemory::new(1e5);
        let r = RefState {
            x: 0.0123,
            v: -0.31,
            a: 4.7,
            j: -250.0,
        };
        let (x, f) = (0.011, 3.2e5);
        let f_hp = c.force.hp_b * (f - 1e5);
        let want = c_fb * (r.x - x) + c_d * r.x + c_v * r.v + c_a * r.a + c_j * r.j + c_f * f_hp;
        assert_eq!(sum(&c, &mut m, &r, x, f), want);
        assert_eq!(m.force.f_prev, f);
    }

    #[test]
    fn force_high_pass_removes_a_constant_force() {
        let p = ControllerParams::default();
        let c = ControllerLane::new(&p, 10.0, 1.905e-3);
        let mut m = ControllerMemory::new(0.0);
        let r = RefState::default();
        let mut u = 0.0;
        for _ in 0..(20.0 * p.f_s) as usize {
            u = tick(&c, &mut m, &r, 0.0, 1e6);
        }
        assert!(u.abs() < 1e-6, "{u}");
        // The first tick sees a step and passes it with gain hp_b·c_f.
        let mut m = ControllerMemory::new(0.0);
        let u0 = tick(&c, &mut m, &r, 0.0, 1e6);
        assert!((u0 - c.force.c_f * c.force.hp_b * 1e6).abs() < 1e-9);
    }
}
