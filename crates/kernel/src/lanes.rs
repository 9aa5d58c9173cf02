//! Explicit lane vectors for the kernel's hot path: [`Pack`] holds G registers of four f64
//! lanes, and every operation is issued on all G registers before the next operation. The G
//! chains are independent, so their latencies overlap (a Newton step of the orifice law is five
//! dependent operations; one register's chain alone would leave the pipes mostly idle).
//!
//! A register is a [`Simd`]: [`Avx`] (an AVX2 register, chosen at run time when the CPU has
//! it) or [`Portable`] (four f64, which LLVM maps onto whatever the target has). Every operation
//! is the scalar IEEE operation applied lane by lane, in the order the scalar code does it, so a
//! lane's bits do not depend on the choice: no fused multiply-add, no reassociation, no
//! approximate instructions.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Generates a structure-of-arrays twin of a per-lane coefficient struct.
macro_rules! soa {
    ($Scalar:ident => $Soa:ident { $($f:ident),* $(,)? }) => {
        #[doc = concat!("The structure-of-arrays twin of [`", stringify!($Scalar), "`], one array per coefficient.")]
        #[derive(Debug, Clone, Copy)]
        pub struct $Soa<const N: usize> { $(pub $f: [f64; N],)* }
        impl<const N: usize> $Soa<N> {
            #[inline(always)]
            pub fn lane(&self, l: usize) -> $Scalar { $Scalar { $($f: self.$f[l],)* } }
            pub(crate) fn from_lanes(c: &[$Scalar; N]) -> Self { $Soa { $($f: std::array::from_fn(|l| c[l].$f),)* } }
        }
    };
}
pub(crate) use soa;

/// Seed of [`inv_fourth_root`]: the bits of s^(−¼) are about `FOURTH_ROOT_SEED − bits(s)/4`
/// (the exponent field divided by −4, the mantissa approximated linearly). This constant
/// minimises the seed's largest relative error, 3.1 % [found numerically over four octaves].
pub(crate) const FOURTH_ROOT_SEED: u64 = 0x4feb_0c0b_ba5e_3540;

/// s^(−¼) for a positive normal s, to within 2 ulp, with multiplications and additions only.
///
/// A seed from the bits of s (3.1 %) and four Newton steps on y⁻⁴ = s,
/// y ← y·(5 − s·y⁴)/4, each squaring the relative error (times 2.5): 3.1e-2, 2.5e-3, 1.6e-5,
/// 6.2e-10, then rounding. It replaces two square roots and a division, which share the one
/// divide/square-root unit, with 26 operations on the multiply and add pipes; the kernel has
/// spare room there and none on the divider. Integer and IEEE operations only, with no fused
/// multiply-add, so every build and every CPU gives the same bits.
#[inline(always)]
pub fn inv_fourth_root(s: f64) -> f64 {
    let mut y = f64::from_bits(FOURTH_ROOT_SEED.wrapping_sub(s.to_bits() >> 2));
    for _ in 0..4 {
        let y2 = y * y;
        y *= 1.25 - 0.25 * s * (y2 * y2);
    }
    y
}

/// One register of f64 lanes.
pub trait Simd: Copy {
    /// Lanes per register.
    const LANES: usize;
    /// Lanes where a comparison holds.
    type Mask: Copy;
    fn splat(x: f64) -> Self;
    /// Lanes `a[0..LANES]`.
    fn load(a: &[f64]) -> Self;
    /// Writes the lanes to `a[0..LANES]`.
    fn store(self, a: &mut [f64]);
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    fn neg(self) -> Self;
    fn abs(self) -> Self;
    fn sqrt(self) -> Self;
    /// `self > o` (false where either is NaN).
    fn gt(self, o: Self) -> Self::Mask;
    /// `a` where `m` holds, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// `f64::from_bits(c − bits(self) >> 2)` in every lane (the seed of a fourth root).
    fn seed(self, c: u64) -> Self;
}

/// Lanes of a portable register.
pub const WIDTH: usize = 4;

/// Four f64 lanes in plain arrays: the portable register.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Portable(pub [f64; WIDTH]);

impl Portable {
    #[inline(always)]
    fn map(mut self, f: impl Fn(f64) -> f64) -> Self {
        for x in &mut self.0 {
            *x = f(*x);
        }
        self
    }

    #[inline(always)]
    fn zip(mut self, o: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        for (x, y) in self.0.iter_mut().zip(o.0) {
            *x = f(*x, y);
        }
        self
    }
}

impl Simd for Portable {
    const LANES: usize = WIDTH;
    type Mask = [bool; WIDTH];
    #[inline(always)]
    fn splat(x: f64) -> Self {
        Portable([x; WIDTH])
    }
    #[inline(always)]
    fn load(a: &[f64]) -> Self {
        let mut r = [0.0; WIDTH];
        r.copy_from_slice(&a[..WIDTH]);
        Portable(r)
    }
    #[inline(always)]
    fn store(self, a: &mut [f64]) {
        a[..WIDTH].copy_from_slice(&self.0);
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self.zip(o, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self.zip(o, |a, b| a * b)
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        self.zip(o, |a, b| a / b)
    }
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|a| -a)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        self.map(f64::abs)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f64::sqrt)
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Self::Mask {
        let mut m = [false; WIDTH];
        for i in 0..WIDTH {
            m[i] = self.0[i] > o.0[i];
        }
        m
    }
    #[inline(always)]
    fn select(m: Self::Mask, mut a: Self, b: Self) -> Self {
        for i in 0..WIDTH {
            if !m[i] {
                a.0[i] = b.0[i];
            }
        }
        a
    }
    #[inline(always)]
    fn seed(self, c: u64) -> Self {
        self.map(|s| f64::from_bits(c.wrapping_sub(s.to_bits() >> 2)))
    }
}

/// Which register type a kernel build uses (the `SIMD` parameter of `simulate::integrate`).
pub(crate) const PORTABLE: u8 = 0;
/// [`Avx`]: the kernel build for CPUs with AVX2 and FMA.
pub(crate) const AVX2: u8 = 1;
/// [`Avx512`]: the kernel build for CPUs with AVX-512 F and VL as well.
pub(crate) const AVX512: u8 = 2;

#[cfg(target_arch = "x86_64")]
pub(crate) use avx::{Avx, Avx512};

#[cfg(target_arch = "x86_64")]
mod avx {
    //! SAFETY (every `unsafe` block of this module): the intrinsics need AVX and AVX2 ([`Avx`])
    //! or AVX-512 F ([`Avx512`]), and a value of either type exists only in code that runs on a
    //! CPU that has them. The kernel names [`Avx`] only in `simulate::integrate_avx2` and
    //! [`Avx512`] only in `simulate::integrate_avx512`, which `Isa::detected` guards; their
    //! operations are inlined there, where the features are enabled.
    use super::Simd;
    use std::arch::x86_64::*;

    /// An AVX2 register of four f64.
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct Avx(__m256d);

    /// An AVX-512 register of eight f64.
    #[derive(Debug, Clone, Copy)]
    pub(crate) struct Avx512(__m512d);

    impl Simd for Avx {
        const LANES: usize = 4;
        type Mask = __m256d;
        #[inline(always)]
        fn splat(x: f64) -> Self {
            Avx(unsafe { _mm256_set1_pd(x) })
        }
        #[inline(always)]
        fn load(a: &[f64]) -> Self {
            let a = &a[..Self::LANES];
            Avx(unsafe { _mm256_loadu_pd(a.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, a: &mut [f64]) {
            let a = &mut a[..Self::LANES];
            unsafe { _mm256_storeu_pd(a.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            Avx(unsafe { _mm256_add_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            Avx(unsafe { _mm256_sub_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            Avx(unsafe { _mm256_mul_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            Avx(unsafe { _mm256_div_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn neg(self) -> Self {
            Avx(unsafe { _mm256_xor_pd(self.0, _mm256_set1_pd(-0.0)) })
        }
        #[inline(always)]
        fn abs(self) -> Self {
            Avx(unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), self.0) })
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            Avx(unsafe { _mm256_sqrt_pd(self.0) })
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self::Mask {
            unsafe { _mm256_cmp_pd::<_CMP_GT_OQ>(self.0, o.0) }
        }
        #[inline(always)]
        fn select(m: Self::Mask, a: Self, b: Self) -> Self {
            Avx(unsafe { _mm256_blendv_pd(b.0, a.0, m) })
        }
        #[inline(always)]
        fn seed(self, c: u64) -> Self {
            Avx(unsafe {
                let bits = _mm256_srli_epi64::<2>(_mm256_castpd_si256(self.0));
                _mm256_castsi256_pd(_mm256_sub_epi64(_mm256_set1_epi64x(c as i64), bits))
            })
        }
    }

    impl Simd for Avx512 {
        const LANES: usize = 8;
        type Mask = __mmask8;
        #[inline(always)]
        fn splat(x: f64) -> Self {
            Avx512(unsafe { _mm512_set1_pd(x) })
        }
        #[inline(always)]
        fn load(a: &[f64]) -> Self {
            let a = &a[..Self::LANES];
            Avx512(unsafe { _mm512_loadu_pd(a.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, a: &mut [f64]) {
            let a = &mut a[..Self::LANES];
            unsafe { _mm512_storeu_pd(a.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            Avx512(unsafe { _mm512_add_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            Avx512(unsafe { _mm512_sub_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            Avx512(unsafe { _mm512_mul_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            Avx512(unsafe { _mm512_div_pd(self.0, o.0) })
        }
        #[inline(always)]
        fn neg(self) -> Self {
            Avx512(unsafe {
                let sign = _mm512_set1_epi64(i64::MIN);
                _mm512_castsi512_pd(_mm512_xor_si512(_mm512_castpd_si512(self.0), sign))
            })
        }
        #[inline(always)]
        fn abs(self) -> Self {
            Avx512(unsafe { _mm512_abs_pd(self.0) })
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            Avx512(unsafe { _mm512_sqrt_pd(self.0) })
        }
        #[inline(always)]
        fn gt(self, o: Self) -> Self::Mask {
            unsafe { _mm512_cmp_pd_mask::<_CMP_GT_OQ>(self.0, o.0) }
        }
        #[inline(always)]
        fn select(m: Self::Mask, a: Self, b: Self) -> Self {
            Avx512(unsafe { _mm512_mask_blend_pd(m, b.0, a.0) })
        }
        #[inline(always)]
        fn seed(self, c: u64) -> Self {
            Avx512(unsafe {
                let bits = _mm512_srli_epi64::<2>(_mm512_castpd_si512(self.0));
                _mm512_castsi512_pd(_mm512_sub_epi64(_mm512_set1_epi64(c as i64), bits))
            })
        }
    }
}

/// `G` registers of `S`: lanes `l0 .. l0 + G·S::LANES` of a batch, operated on together.
#[derive(Debug, Clone, Copy)]
pub struct Pack<S, const G: usize>(pub [S; G]);

/// Lanes where a comparison holds, per register.
#[derive(Debug, Clone, Copy)]
pub struct PackMask<S: Simd, const G: usize>([S::Mask; G]);

impl<S: Simd, const G: usize> Pack<S, G> {
    #[inline(always)]
    fn map(mut self, f: impl Fn(S) -> S) -> Self {
        for x in &mut self.0 {
            *x = f(*x);
        }
        self
    }

    #[inline(always)]
    fn zip(mut self, o: Self, f: impl Fn(S, S) -> S) -> Self {
        for (x, y) in self.0.iter_mut().zip(o.0) {
            *x = f(*x, y);
        }
        self
    }

    #[inline(always)]
    pub fn splat(x: f64) -> Self {
        Pack([S::splat(x); G])
    }

    /// Lanes `l0 .. l0 + G·S::LANES` of `a`.
    #[inline(always)]
    pub fn load(a: &[f64], l0: usize) -> Self {
        let mut r = [S::splat(0.0); G];
        for (g, x) in r.iter_mut().enumerate() {
            *x = S::load(&a[l0 + S::LANES * g..]);
        }
        Pack(r)
    }

    /// Writes the lanes to `a[l0 .. l0 + G·S::LANES]`.
    #[inline(always)]
    pub fn store(self, a: &mut [f64], l0: usize) {
        for (g, x) in self.0.iter().enumerate() {
            x.store(&mut a[l0 + S::LANES * g..]);
        }
    }

    #[inline(always)]
    pub fn abs(self) -> Self {
        self.map(S::abs)
    }

    #[inline(always)]
    pub fn sqrt(self) -> Self {
        self.map(S::sqrt)
    }

    /// Lanes where `self > o` (false where either is NaN).
    #[inline(always)]
    pub fn gt(self, o: Self) -> PackMask<S, G> {
        let mut m = [S::splat(0.0).gt(S::splat(0.0)); G];
        for g in 0..G {
            m[g] = self.0[g].gt(o.0[g]);
        }
        PackMask(m)
    }

    /// Lanes where `self < o` (false where either is NaN).
    #[inline(always)]
    pub fn lt(self, o: Self) -> PackMask<S, G> {
        o.gt(self)
    }

    /// [`inv_fourth_root`] of `a` and `b` in every lane, the two
    /// chains interleaved: the same seed and Newton steps.
    #[inline(always)]
    pub fn inv_fourth_roots(a: Self, b: Self) -> (Self, Self) {
        use crate::lanes::FOURTH_ROOT_SEED as C;
        let quarter = Self::splat(0.25);
        let (sa, sb) = (quarter * a, quarter * b);
        let (mut ya, mut yb) = (a.map(|s| s.seed(C)), b.map(|s| s.seed(C)));
        let five_quarters = Self::splat(1.25);
        for _ in 0..4 {
            let (a2, b2) = (ya * ya, yb * yb);
            ya = ya * (five_quarters - sa * (a2 * a2));
            yb = yb * (five_quarters - sb * (b2 * b2));
        }
        (ya, yb)
    }
}

impl<S: Simd, const G: usize> PackMask<S, G> {
    /// `a` where the mask holds, else `b`.
    #[inline(always)]
    pub fn select(self, mut a: Pack<S, G>, b: Pack<S, G>) -> Pack<S, G> {
        for g in 0..G {
            a.0[g] = S::select(self.0[g], a.0[g], b.0[g]);
        }
        a
    }
}

macro_rules! binary {
    ($Op:ident, $op:ident) => {
        impl<S: Simd, const G: usize> $Op for Pack<S, G> {
            type Output = Self;
            #[inline(always)]
            fn $op(self, o: Self) -> Self {
                self.zip(o, S::$op)
            }
        }
    };
}
binary!(Add, add);
binary!(Sub, sub);
binary!(Mul, mul);
binary!(Div, div);

impl<S: Simd, const G: usize> Neg for Pack<S, G> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(S::neg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pack's result and the scalar operation it should equal, lane by lane.
    type Case<S> = (Pack<S, 2>, fn(f64, f64) -> f64);

    /// Each operation of a register gives the scalar operation's bits, lane by lane.
    fn same_bits<S: Simd>() {
        let a8 = [1e10, 3.7e14, 2.0e-300, -5.5e300, 0.0, -0.0, f64::NAN, 7.25];
        let b8 = [3.0, -1e-3, 2.0e-300, 1.5, -0.0, 0.0, 1.0, f64::NAN];
        let (a, b): ([f64; 16], [f64; 16]) = (
            std::array::from_fn(|i| if i < 8 { a8[i] } else { -1.5 * b8[i - 8] }),
            std::array::from_fn(|i| if i < 8 { b8[i] } else { 0.75 * a8[15 - i] }),
        );
        let n = 2 * S::LANES;
        let (pa, pb) = (Pack::<S, 2>::load(&a, 0), Pack::<S, 2>::load(&b, 0));
        let (ra, rb) = Pack::inv_fourth_roots(pa.abs(), pb.abs());
        let ops: [Case<S>; 10] = [
            (pa + pb, |x, y| x + y),
            (pa - pb, |x, y| x - y),
            (pa * pb, |x, y| x * y),
            (pa / pb, |x, y| x / y),
            (-pa, |x, _| -x),
            (pa.abs().sqrt(), |x, _| x.abs().sqrt()),
            (pa.gt(pb).select(pa, pb), |x, y| if x > y { x } else { y }),
            (pa.lt(pb).select(pa, pb), |x, y| if x < y { x } else { y }),
            (ra, |x, _| inv_fourth_root(x.abs())),
            (rb, |_, y| inv_fourth_root(y.abs())),
        ];
        for (k, (got, want)) in ops.into_iter().enumerate() {
            let mut out = [0.0; 16];
            got.store(&mut out, 0);
            for i in 0..n {
                let w = want(a[i], b[i]);
                // The bits, signed zeros included; a NaN's payload is not specified by Rust (and
                // the compiler may fold the scalar side), so any NaN matches a NaN.
                let same = out[i].to_bits() == w.to_bits() || (out[i].is_nan() && w.is_nan());
                assert!(same, "operation {k}, lane {i}: {} vs {w}", out[i]);
            }
        }
    }

    #[test]
    fn every_register_gives_the_scalar_bits() {
        same_bits::<Portable>();
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") {
            same_bits::<Avx>();
        }
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx512f") {
            same_bits::<Avx512>();
        }
    }
}
