//! Rigid platen (docs/model.md §3):
//!
//! ```text
//! M dv/dt = F − K y − (C |v|^α + μ) z,   dy/dt = v
//! ```
//!
//! F is the total actuator force, K the hold-down stiffness, C|v|^α the viscous term and μ the
//! Coulomb force, both shaped by the friction variable z of [`crate::friction`].
//! |v|^α is a type parameter ([`Damping`]): α = 0.5 (the paper's value) uses a square root,
//! other exponents `powf`; the choice is made once per batch.

use super::lanes::{Pack, Simd};

/// Per-lane platen coefficients.
#[derive(Debug, Clone, Copy)]
pub struct PlatenLane {
    pub inv_m: f64,
    pub k: f64,
    pub c: f64,
    pub alpha: f64,
    pub mu: f64,
}

crate::lanes::soa!(PlatenLane => PlatenSoa { inv_m, k, c, alpha, mu });

/// How |v|^α is evaluated.
pub trait Damping: Copy + Send + Sync + 'static {
    /// The published law (α = ½): the kernel's vector builds are made for it, for the other only
    /// on the bare plant's full batches (`crate::builds`).
    const USUAL: bool = false;

    fn pow(v_abs: f64, alpha: f64) -> f64;

    /// [`Damping::pow`] in every lane.
    #[inline(always)]
    fn pow_lanes<S: Simd, const G: usize>(v_abs: Pack<S, G>, alpha: Pack<S, G>) -> Pack<S, G> {
        lane_by_lane::<Self, S, G>(v_abs, alpha)
    }
}

/// [`Damping::pow`] taken in each lane in turn.
#[inline(always)]
fn lane_by_lane<D: Damping, S: Simd, const G: usize>(
    v_abs: Pack<S, G>,
    alpha: Pack<S, G>,
) -> Pack<S, G> {
    let mut r = v_abs;
    let (mut v, mut a) = ([0.0; 16], [0.0; 16]);
    for g in 0..G {
        v_abs.0[g].store(&mut v);
        alpha.0[g].store(&mut a);
        for i in 0..S::LANES {
            v[i] = D::pow(v[i], a[i]);
        }
        r.0[g] = S::load(&v);
    }
    r
}

/// α = 0.5 for every lane: |v|^α = √|v|.
#[derive(Debug, Clone, Copy, Default)]
pub struct SqrtDamping;
impl Damping for SqrtDamping {
    const USUAL: bool = true;
    #[inline(always)]
    fn pow(v_abs: f64, _alpha: f64) -> f64 {
        v_abs.sqrt()
    }
    #[inline(always)]
    fn pow_lanes<S: Simd, const G: usize>(v_abs: Pack<S, G>, _alpha: Pack<S, G>) -> Pack<S, G> {
        v_abs.sqrt()
    }
}

/// Any α: |v|^α = powf, lane by lane. A lane with α = 0.5 still takes the square root, so its
/// result does not depend on its batch neighbours, and where every lane has α = 0.5 the roots
/// are taken in vector registers: the same bits as [`SqrtDamping`] (the kernel's builds for the
/// rarer configurations take this law for both, `crate::builds`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PowDamping;
impl Damping for PowDamping {
    #[inline(always)]
    fn pow(v_abs: f64, alpha: f64) -> f64 {
        if alpha == 0.5 {
            v_abs.sqrt()
        } else {
            v_abs.powf(alpha)
        }
    }

    #[inline(always)]
    fn pow_lanes<S: Simd, const G: usize>(v_abs: Pack<S, G>, alpha: Pack<S, G>) -> Pack<S, G> {
        let mut a = [0.0; 16];
        let mut every_half = true;
        for g in 0..G {
            alpha.0[g].store(&mut a);
            every_half &= a[..S::LANES].iter().all(|&a| a == 0.5);
        }
        if every_half {
            v_abs.sqrt()
        } else {
            lane_by_lane::<Self, S, G>(v_abs, alpha)
        }
    }
}

/// Platen acceleration dv/dt for actuator force `f` plus any external force `f_ext`.
#[inline(always)]
pub fn accel<D: Damping>(c: &PlatenLane, f: f64, f_ext: f64, y: f64, v: f64, z: f64) -> f64 {
    (f + f_ext - c.k * y - (c.c * D::pow(v.abs(), c.alpha) + c.mu) * z) * c.inv_m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accel_balances_forces() {
        // Worked by hand: F − k·y − (c·|v|^α + μ)·z over m, with y = 0.01 m, v = 0.25 m/s, z = 1:
        // (1e6 − 12 660 − (41 000·0.5 + 7 597)) / 144 000 = 959 243 / 144 000.
        let c = PlatenLane {
            inv_m: 1.0 / 144e3,
            k: 1.266e6,
            c: 0.041e6,
            alpha: 0.5,
            mu: 7597.0,
        };
        let a = accel::<SqrtDamping>(&c, 1e6, 0.0, 0.01, 0.25, 1.0);
        assert!((a - 959_243.0 / 144e3).abs() < 1e-12, "{a}");
        // The general law at α = ½ is the square root.
        assert_eq!(accel::<PowDamping>(&c, 1e6, 0.0, 0.01, 0.25, 1.0), a);
        // α = 0.6, moving back (v < 0, z = −½), an external force: 0.36^0.6 = 0.541728270868…
        // (e^(0.6·ln 0.36)), so (1 020 000 + 25 320 + (41 000·0.5417282709 + 7 597)·0.5) / 144 000
        // = 1 060 224.03 / 144 000 = 7.36267 m/s².
        let c = PlatenLane { alpha: 0.6, ..c };
        let b = accel::<PowDamping>(&c, 1e6, 2e4, -0.02, -0.36, -0.5);
        assert!((b - 7.362_666_177_450_024).abs() < 1e-12, "{b}");
    }
}
