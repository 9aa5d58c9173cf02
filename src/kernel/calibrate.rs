//! Calibration loops for the benchmark: what this machine can do at best for this kernel.
//!
//! One right-hand-side evaluation per lane costs 9 square roots (8 in the four orifice terms —
//! two per term, since sq(Δp) = Δp/(Δp²+p_tr²)^¼ — and 1 for |v|^½) and 6 divisions (4 in the
//! orifice terms, 2 for β/V1, β/V2). On x86 both run on the one divide/square-root unit, which
//! is therefore the bound. [`sqrt_div_mix`] runs exactly that mix, with enough independent
//! operations per lane that it is throughput-bound, on the same lanes and instruction set as the
//! kernel: its rate is the machine's limit for the kernel. [`add_chain`] measures the clock
//! (a dependent chain of one-cycle integer operations), to convert rates into cycles.

use super::LANES;

#[inline(always)]
fn mix_body(iters: usize, seed: f64) -> f64 {
    let mut x = [0.0f64; LANES];
    for (l, v) in x.iter_mut().enumerate() {
        *v = seed + 0.01 * l as f64;
    }
    const C: [f64; 9] = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5];
    for _ in 0..iters {
        for v in x.iter_mut() {
            let a = *v;
            let mut s = 0.0;
            for c in C {
                s += (a + c).sqrt();
            }
            let mut d = 0.0;
            for c in &C[..6] {
                d += (a + 0.25) / (a + c);
            }
            *v = (s + d) * (1.0 / 20.0);
        }
    }
    x.iter().sum()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn mix_avx2(iters: usize, seed: f64) -> f64 {
    mix_body(iters, seed)
}

/// Runs `iters` iterations of 9 square roots and 6 divisions on each of [`LANES`] lanes; returns
/// a checksum (so the work cannot be optimised away). Lane-evaluations = iters × LANES.
pub fn sqrt_div_mix(iters: usize, seed: f64) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if super::simulate::Isa::detected() == "avx2" {
        // SAFETY: the CPU reports AVX2 and FMA.
        return unsafe { mix_avx2(iters, seed) };
    }
    mix_body(iters, seed)
}

/// A dependent chain of 2·iters one-cycle integer operations (add, rotate); returns a checksum.
pub fn add_chain(iters: usize, seed: u64) -> u64 {
    let mut a = seed;
    let b = std::hint::black_box(0x9e37_79b9_7f4a_7c15u64);
    for _ in 0..iters {
        a = a.wrapping_add(b).rotate_left(7);
    }
    a
}

#[cfg(test)]
mod tests {
    #[test]
    fn loops_compute_something() {
        let a = super::sqrt_div_mix(100, 1.0);
        assert!(a.is_finite() && a > 0.0);
        assert_ne!(super::add_chain(1000, 1), super::add_chain(1001, 1));
    }
}
