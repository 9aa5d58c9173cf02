//! The bare plant's right-hand side (no effect, one equivalent actuator) for every lane of a
//! batch in one [`Pack`] of registers: the design-exploration path, where the time goes.
//!
//! It does the operations of the general right-hand side (`simulate::rhs`) with every hook at its
//! identity, in the same order, lane by lane, so it gives the same bits (the kernel's tests run
//! both on the same states). What only an effect reads (the flows, the actuators' force) is
//! computed only for an effect that leaves the hydraulics alone ([`Hydraulics`]): a force on the
//! platen (a specimen, a building) or a measurement chain, whose batches then run the plant here.

use super::lane_params::LaneParams;
use super::lanes::{Pack, Portable, Simd, AVX2, AVX512};
use super::platen::Damping;
use super::servovalve::FlowLaw;
use super::state::idx::*;
use super::state::NP;

/// Whether [`rhs`] takes a batch of `n` lanes in the build `SIMD`: whole registers, at most four
/// (one pack of every lane, whose chains then overlap).
pub(crate) const fn fits<const SIMD: u8>(n: usize) -> bool {
    let width = match SIMD {
        AVX512 => 8,
        _ => 4,
    };
    n.is_multiple_of(width) && n / width >= 1 && n / width <= 4
}

/// What an effect's derivatives read of the plant besides its states and derivatives
/// (`effects::PlantView`), one actuator standing for both: for an effect that leaves the
/// hydraulics alone, computed with the plant here.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hydraulics<const N: usize> {
    /// Valve flow into chamber 1 of each actuator, m³/s.
    pub q1: [f64; N],
    /// Valve flow out of chamber 2 of each actuator, m³/s.
    pub q2: [f64; N],
    /// Flow drawn from the supply by both valves, m³/s.
    pub q_supply: [f64; N],
    /// Force of both actuators on the platen, N.
    pub f_act: [f64; N],
}

impl<const N: usize> Default for Hydraulics<N> {
    fn default() -> Self {
        Hydraulics {
            q1: [0.0; N],
            q2: [0.0; N],
            q_supply: [0.0; N],
            f_act: [0.0; N],
        }
    }
}

/// The plant's derivatives `ds` at state `s` and held spool command `x_c`, every lane, in the
/// registers of the build `SIMD` ([`super::lanes::PORTABLE`], [`AVX2`], [`AVX512`]: the
/// caller runs on a CPU that has the instructions). The batch [`fits`]. `f_ext`: the effects'
/// force on the platen per lane, N (none: the bare plant); `out`: where the flows and the force
/// go for the effects' derivatives.
#[inline(always)]
pub(crate) fn rhs<const N: usize, const SIMD: u8, Q: FlowLaw, D: Damping>(
    lp: &LaneParams<N>,
    x_c: &[f64; N],
    s: &[[f64; N]; NP],
    ds: &mut [[f64; N]; NP],
    f_ext: Option<&[f64; N]>,
    out: Option<&mut Hydraulics<N>>,
) {
    #[cfg(target_arch = "x86_64")]
    match SIMD {
        AVX2 => return registers::<N, super::lanes::Avx, Q, D>(lp, x_c, s, ds, f_ext, out),
        AVX512 => return registers::<N, super::lanes::Avx512, Q, D>(lp, x_c, s, ds, f_ext, out),
        _ => {}
    }
    registers::<N, Portable, Q, D>(lp, x_c, s, ds, f_ext, out)
}

/// [`rhs`] in registers of `S`.
#[inline(always)]
fn registers<const N: usize, S: Simd, Q: FlowLaw, D: Damping>(
    lp: &LaneParams<N>,
    x_c: &[f64; N],
    s: &[[f64; N]; NP],
    ds: &mut [[f64; N]; NP],
    f_ext: Option<&[f64; N]>,
    out: Option<&mut Hydraulics<N>>,
) {
    match N / S::LANES {
        1 => pack::<N, S, 1, Q, D>(lp, x_c, s, ds, f_ext, out),
        2 => pack::<N, S, 2, Q, D>(lp, x_c, s, ds, f_ext, out),
        3 => pack::<N, S, 3, Q, D>(lp, x_c, s, ds, f_ext, out),
        _ => pack::<N, S, 4, Q, D>(lp, x_c, s, ds, f_ext, out),
    }
}

/// [`rhs`] in one pack of `G` registers.
#[inline(always)]
fn pack<const N: usize, S: Simd, const G: usize, Q: FlowLaw, D: Damping>(
    lp: &LaneParams<N>,
    x_c: &[f64; N],
    s: &[[f64; N]; NP],
    ds: &mut [[f64; N]; NP],
    f_ext: Option<&[f64; N]>,
    out: Option<&mut Hydraulics<N>>,
) {
    let ld = |a: &[f64; N]| Pack::<S, G>::load(a, 0);
    let (zero, one) = (Pack::splat(0.0), Pack::splat(1.0));
    let (y, v, z) = (ld(&s[Y]), ld(&s[VEL]), ld(&s[Z]));
    let (p1, p2) = (ld(&s[P1[0]]), ld(&s[P2[0]]));
    // β/V of the two chambers at the stroke y (`actuator::stiffness_factors`).
    let act = &lp.act;
    let (a1, a2, l, beta) = (ld(&act.a1), ld(&act.a2), ld(&act.l), ld(&act.beta));
    let b1 = beta / (a1 * (l + y) + ld(&act.vd1));
    let b2 = beta / (a2 * (l - y) + ld(&act.vd2));
    let x = ld(x_c);
    let (q1, q2) = Q::flows_lanes(&lp.valve, 0, [x, p1, p2, ld(&lp.p_s)]);
    // `actuator::pressure_rates`, the same for the second actuator.
    let d1 = b1 * (q1 - a1 * v);
    let d2 = b2 * (a2 * v - q2);
    for i in 0..2 {
        d1.store(&mut ds[P1[i]], 0);
        d2.store(&mut ds[P2[i]], 0);
    }
    // The force of one actuator (`actuator::force`, summed from 0), doubled.
    let f = zero + (p1 * a1 - p2 * a2);
    let f = f + f;
    if let Some(out) = out {
        q1.store(&mut out.q1, 0);
        q2.store(&mut out.q2, 0);
        // The supply flow as `simulate::rhs_general` sums it: 0 + (q1 or -q2), doubled.
        let qs = zero + x.gt(zero).select(q1, -q2);
        (qs + qs).store(&mut out.q_supply, 0);
        f.store(&mut out.f_act, 0);
    }
    // `platen::accel`, with the effects' force or none.
    let f_ext = f_ext.map_or(zero, ld);
    let pl = &lp.platen;
    let damping = ld(&pl.c) * D::pow_lanes(v.abs(), ld(&pl.alpha)) + ld(&pl.mu);
    let accel = (f + f_ext - ld(&pl.k) * y - damping * z) * ld(&pl.inv_m);
    accel.store(&mut ds[VEL], 0);
    v.store(&mut ds[Y], 0);
    // `friction::dz_dt`.
    let fr = &lp.friction;
    let zv = z * v;
    let bracket = zv.lt(zero).select(ld(&fr.kappa_neg), ld(&fr.kappa));
    let bracket = zv.gt(zero).select(one, bracket);
    let dz = v * ld(&fr.inv_y) * (one - z * z * bracket);
    dz.store(&mut ds[Z], 0);
}
