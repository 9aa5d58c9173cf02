//! Three-variable controller (TVC) replica, discrete at f_s with a zero-order hold (docs/model.md §2).
//!
//! At each tick t_k = k/f_s, from the plant state at t_k:
//!
//! ```text
//! F_hp[k] = (2f_s (F[k] − F[k−1]) + (2f_s − ω_hp) F_hp[k−1]) / (2f_s + ω_hp)   (Tustin of s/(s+ω_hp))
//! u = 10·[ G_d (x_r − x)/D_max + L_d x_r/D_max + L_v v_r/V_max + L_a a_r/A_max + L_j j_r/J_max
//!          + G_f F_hp/F_max ]
//! u → five notch filters in series → clamp ±u_lim → spool command x_c = k_sp·u, held to t_{k+1}
//! ```
//!
//! with F[−1] = F[0] and F_hp[−1] = 0. Notch i is N(s) = (s² + 2ζ_z ω0 s + ω0²)/(s² + 2ζ_p ω0 s + ω0²),
//! ζ_p = B/(2 f0), ζ_z = ζ_p·10^(−depth/20), discretised by Tustin with pre-warping at f0. A notch
//! of depth 0 dB is given the identity coefficients [1, 0, 0, 0, 0] (its Tustin form would equal
//! them only up to rounding), so it passes its input through bit for bit; all five always run, so
//! the tick has no branch on configuration.

use super::params::ControllerParams;

/// Normalised biquad coefficients [b0, b1, b2, a1, a2] (a0 = 1).
pub type Biquad = [f64; 5];

/// A notch at depth 0: exactly the identity (b0 = 1, the rest 0).
pub const IDENTITY: Biquad = [1.0, 0.0, 0.0, 0.0, 0.0];

/// Tustin (pre-warped at f0) coefficients of notch (f0 Hz, bandwidth Hz, depth dB) at rate f_s.
pub(crate) fn notch_coefficients(f0: f64, bw: f64, depth_db: f64, f_s: f64) -> Biquad {
    let w0 = 2.0 * std::f64::consts::PI * f0;
    let zeta_p = bw / (2.0 * f0);
    let zeta_z = zeta_p * 10f64.powf(-depth_db / 20.0);
    let c = w0 / (w0 / (2.0 * f_s)).tan();
    let poly = |zeta: f64| {
        [
            c * c + 2.0 * zeta * w0 * c + w0 * w0,
            2.0 * (w0 * w0 - c * c),
            c * c - 2.0 * zeta * w0 * c + w0 * w0,
        ]
    };
    let b = poly(zeta_z);
    let a = poly(zeta_p);
    [
        b[0] / a[0],
        b[1] / a[0],
        b[2] / a[0],
        a[1] / a[0],
        a[2] / a[0],
    ]
}

/// Per-lane controller coefficients (gains folded with the 10 V scale and the normalisations).
#[derive(Debug, Clone, Copy)]
pub struct ControllerLane {
    /// 10·G_d/D_max, V/m.
    pub c_fb: f64,
    /// 10·L_d/D_max, V/m.
    pub c_d: f64,
    /// 10·L_v/V_max, V/(m/s).
    pub c_v: f64,
    /// 10·L_a/A_max, V/(m/s²).
    pub c_a: f64,
    /// 10·L_j/J_max, V/(m/s³).
    pub c_j: f64,
    /// 10·G_f/F_max, V/N.
    pub c_f: f64,
    /// High-pass: F_hp = hp_b·(F − F_prev) + hp_a·F_hp_prev.
    pub hp_b: f64,
    pub hp_a: f64,
    pub notches: [Biquad; 5],
    /// Which notches are the [`IDENTITY`] (depth 0), found once so that a tick need not compare.
    pub identity: [bool; 5],
    pub u_lim: f64,
    pub k_sp: f64,
}

impl ControllerLane {
    pub fn new(p: &ControllerParams, u_lim: f64, k_sp: f64) -> Self {
        let two_fs = 2.0 * p.f_s;
        let w_hp = 2.0 * std::f64::consts::PI * p.f_hp;
        let notches = p.notches().map(|(f0, bw, depth)| {
            if depth == 0.0 {
                // Exactly the identity (the Tustin form would equal it up to rounding).
                IDENTITY
            } else {
                notch_coefficients(f0, bw, depth, p.f_s)
            }
        });
        let [c_fb, c_d, c_v, c_a, c_j, c_f] = p.gains();
        ControllerLane {
            c_fb,
            c_d,
            c_v,
            c_a,
            c_j,
            c_f,
            hp_b: two_fs / (two_fs + w_hp),
            hp_a: (two_fs - w_hp) / (two_fs + w_hp),
            notches,
            identity: notches.map(|q| q == IDENTITY),
            u_lim,
            k_sp,
        }
    }
}

/// Per-lane controller memory.
#[derive(Debug, Clone, Copy, Default)]
pub struct ControllerMemory {
    pub f_prev: f64,
    pub f_hp: f64,
    /// Transposed direct-form II states of the notches.
    pub notch: [[f64; 2]; 5],
}

impl ControllerMemory {
    /// Memory before the first tick: F[−1] = F[0], F_hp[−1] = 0.
    pub fn new(f0: f64) -> Self {
        ControllerMemory {
            f_prev: f0,
            ..Default::default()
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

/// The TVC's sum at a tick (V): the force high-pass updated, then the gains. A compensator
/// (docs/model.md §8) changes it before [`shape`].
#[inline(always)]
pub fn sum(c: &ControllerLane, m: &mut ControllerMemory, r: &RefState, x: f64, f: f64) -> f64 {
    m.f_hp = c.hp_b * (f - m.f_prev) + c.hp_a * m.f_hp;
    m.f_prev = f;
    c.c_fb * (r.x - x) + c.c_d * r.x + c.c_v * r.v + c.c_a * r.a + c.c_j * r.j + c.c_f * m.f_hp
}

/// The command `u` through the five notches in series, then clamped to ±u_lim (V).
#[inline(always)]
pub fn shape(c: &ControllerLane, m: &mut ControllerMemory, mut u: f64) -> f64 {
    for ((q, s), &identity) in c.notches.iter().zip(m.notch.iter_mut()).zip(&c.identity) {
        if identity {
            // Its states stay +0 while u is finite, so y = 1·u + 0 = u + 0 (the same bits).
            u += 0.0;
            continue;
        }
        let y = q[0] * u + s[0];
        s[0] = q[1] * u - q[3] * y + s[1];
        s[1] = q[2] * u - q[4] * y;
        u = y;
    }
    u.clamp(-c.u_lim, c.u_lim)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gain_at(q: &Biquad, f: f64, f_s: f64) -> f64 {
        let w = 2.0 * std::f64::consts::PI * f / f_s;
        let (c1, s1) = (w.cos(), -w.sin());
        let (c2, s2) = ((2.0 * w).cos(), -(2.0 * w).sin());
        let num = (q[0] + q[1] * c1 + q[2] * c2, q[1] * s1 + q[2] * s2);
        let den = (1.0 + q[3] * c1 + q[4] * c2, q[3] * s1 + q[4] * s2);
        (num.0.hypot(num.1)) / (den.0.hypot(den.1))
    }

    #[test]
    fn notch_has_its_depth_at_f0_and_unit_gain_far_away() {
        let q = notch_coefficients(40.0, 8.0, 20.0, 1024.0);
        assert!(
            (gain_at(&q, 40.0, 1024.0) - 0.1).abs() < 1e-9,
            "pre-warping puts the depth at f0"
        );
        assert!((gain_at(&q, 1.0, 1024.0) - 1.0).abs() < 1e-3);
        // Depth 0 is the identity, to the bit.
        let p = ControllerParams::default();
        let c = ControllerLane::new(&p, 10.0, 1.905e-3);
        let mut m = ControllerMemory::new(0.0);
        let r = RefState {
            x: 0.0123,
            ..Default::default()
        };
        let u = tick(&c, &mut m, &r, 0.0, 0.0);
        assert_eq!(u, c.c_fb * 0.0123);
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
        assert!((u0 - c.c_f * c.hp_b * 1e6).abs() < 1e-9);
    }
}
