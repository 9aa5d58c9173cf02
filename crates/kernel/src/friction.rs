//! Viscoplastic friction law of the platen bearings (docs/model.md §3):
//!
//! ```text
//! dz/dt = (v/Y) · (1 − z² [κ + (1−κ) sign(z v)])
//! ```
//!
//! z ∈ [−1, 1] scales the dissipative force (C|v|^α + μ)·z of [`crate::platen`].
//! With z·v > 0 the bracket is 1 (loading towards |z| = 1); with z·v < 0 it is 2κ − 1 (unloading);
//! sign(0) = 0 gives κ. The branches are selects, evaluated for every lane.

/// Per-lane friction-law coefficients.
#[derive(Debug, Clone, Copy)]
pub struct FrictionLane {
    /// 1/Y, 1/m.
    pub inv_y: f64,
    /// κ (bracket when z·v = 0).
    pub kappa: f64,
    /// 2κ − 1 (bracket when z·v < 0).
    pub kappa_neg: f64,
}

crate::lanes::soa!(FrictionLane => FrictionSoa { inv_y, kappa, kappa_neg });

/// dz/dt of the friction law.
#[inline(always)]
pub(crate) fn dz_dt(c: &FrictionLane, v: f64, z: f64) -> f64 {
    let zv = z * v;
    let bracket = if zv > 0.0 {
        1.0
    } else if zv < 0.0 {
        c.kappa_neg
    } else {
        c.kappa
    };
    v * c.inv_y * (1.0 - z * z * bracket)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturates_at_one_while_loading() {
        let c = FrictionLane {
            inv_y: 1.0 / 2e-4,
            kappa: 0.5,
            kappa_neg: 0.0,
        };
        assert_eq!(dz_dt(&c, 0.3, 1.0), 0.0);
        assert_eq!(dz_dt(&c, -0.3, -1.0), 0.0);
        // Unloading with κ = 0.5: the bracket is 0, z moves at v/Y.
        assert!((dz_dt(&c, -0.3, 1.0) - (-0.3 / 2e-4)).abs() < 1e-9);
        // At rest nothing moves.
        assert_eq!(dz_dt(&c, 0.0, 0.7), 0.0);
    }
}
