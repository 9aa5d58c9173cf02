//! The TVC's notch stage (docs/model.md §2): five notch filters in series on the command,
//!
//! ```text
//! N(s) = (s² + 2ζ_z ω0 s + ω0²)/(s² + 2ζ_p ω0 s + ω0²),   ζ_p = B/(2 f0),   ζ_z = ζ_p·10^(−depth/20)
//! ```
//!
//! each discretised by Tustin with pre-warping at f0. A notch of depth 0 dB is given the identity
//! coefficients [1, 0, 0, 0, 0] (its Tustin form would equal them only up to rounding), so that it
//! passes its input through bit for bit.

use crate::params::ControllerParams;

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

/// One lane's five notches.
#[derive(Debug, Clone, Copy)]
pub struct Notches {
    pub q: [Biquad; 5],
    /// Which notches are the [`IDENTITY`] (depth 0), found once so that a tick need not compare.
    pub identity: [bool; 5],
}

/// The notches' transposed direct-form II states.
pub type NotchMemory = [[f64; 2]; 5];

impl Notches {
    /// The controller's five notches at its rate.
    pub fn new(p: &ControllerParams) -> Self {
        let q = p.notches().map(|(f0, bw, depth)| {
            if depth == 0.0 {
                // Exactly the identity (the Tustin form would equal it up to rounding).
                IDENTITY
            } else {
                notch_coefficients(f0, bw, depth, p.f_s)
            }
        });
        Notches {
            q,
            identity: q.map(|q| q == IDENTITY),
        }
    }

    /// The command `u` (V) through the five notches in series.
    #[inline(always)]
    pub fn apply(&self, m: &mut NotchMemory, mut u: f64) -> f64 {
        for ((q, s), &identity) in self.q.iter().zip(m.iter_mut()).zip(&self.identity) {
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
        u
    }
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
    }
}
