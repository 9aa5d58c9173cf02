//! What this machine can do at best for the model: the rates of its arithmetic units on the
//! kernel's lanes and instruction set, and the model's minimal operation count. Together they
//! give `study bench`'s limit, the throughput of an ideal program that does only the arithmetic
//! the model needs, perfectly scheduled.
//!
//! **The count** ([`MINIMAL`]) is of the model, not of this kernel: one right-hand-side
//! evaluation of one lane, with the two actuators identical (one equivalent actuator), lane
//! constants and the per-tick land selection hoisted, and each nonlinear function charged at its
//! cheapest form:
//!
//! | term | mul/add | divide | sqrt | (·)^−¼ |
//! |---|---|---|---|---|
//! | chamber volumes V1 = c1 + A1·y, V2 = c2 − A2·y | 4 | | | |
//! | β/V1, β/V2 | | 2 | | |
//! | orifice Δp (lands chosen per tick), Δp² + p_tr² | 6 | | | |
//! | (Δp² + p_tr²)^−¼ | | | | 2 |
//! | flows (k·x)·Δp·r | 4 | | | |
//! | pressure rates β/V·(q − A·v) | 6 | | | |
//! | force 2·(A1·P1 − A2·P2) | 4 | | | |
//! | platen: F − K·y − (C·√\|v\| + μ)·z, ·1/M | 8 | | 1 | |
//! | friction: (v/Y)·(1 − z²·b(z·v)) | 8 | | | |
//! | RK4: stage states (3 × 5 states × 2) and the update (5 × 6), per stage | 15 | | | |
//! | **per evaluation** | **55** | **2** | **1** | **2** |
//!
//! Per tick and lane, outside the evaluations ([`TICK_OPS`]): the controller (force, high-pass,
//! six feedback and feed-forward terms, clamp, spool gain: 23; the notches are identities at their
//! default depth and cost nothing), the guard (10 compares) and, in the analysis window, the
//! metrics (errors, squares, peak, nine harmonics of the acceleration and one of the
//! displacement: 50).
//!
//! A (·)^−¼ costs either two square roots and a division on the divide/square-root unit or
//! [`FOURTH_ROOT_FLOPS`] multiplications and additions (a seed and four Newton steps); the limit
//! takes whichever split of the two between the units is faster. The divide/square-root unit
//! and the multiply/add pipes work in parallel, so an evaluation takes the longer of the two.

/// Lanes of every rate loop: two AVX2 registers per chain, which with the chains below keeps
/// every unit busy without spilling registers. Fixed, so the rates are the machine's and do not
/// follow the kernel's batch width.
const LANES: usize = 8;
use crate::kernel::simulate::Isa;
use std::hint::black_box;

/// An operation count per lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpCount {
    /// Multiplications, additions, subtractions, compares and selects.
    pub flops: f64,
    pub divs: f64,
    pub sqrts: f64,
    /// (·)^−¼ evaluations (either unit; see the module doc).
    pub fourth_roots: f64,
}

/// One right-hand-side evaluation of one lane (the table of the module doc).
pub const MINIMAL: OpCount = OpCount {
    flops: 55.0,
    divs: 2.0,
    sqrts: 1.0,
    fourth_roots: 2.0,
};

/// Per tick and lane outside the evaluations: controller 23, guard 10.
pub const TICK_OPS: f64 = 33.0;

/// Per tick and lane in the analysis window: the metrics' running sums.
pub const WINDOW_OPS: f64 = 50.0;

/// Multiplications and additions of a (·)^−¼ by seed and Newton steps: the square and the seed's
/// integer operations (4), then four steps of y·(5/4 − (s/4)·y⁴) (5 each, s/4 once: 22).
pub const FOURTH_ROOT_FLOPS: f64 = 26.0;

/// Measured rates of one thread, in lane-operations per second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rates {
    /// Independent multiplications and additions (1:1).
    pub flops: f64,
    pub divs: f64,
    pub sqrts: f64,
}

impl Rates {
    /// Seconds per lane for `n` of `op` on the divide/square-root unit and on the mul/add pipes,
    /// with `k` of the fourth roots on the divider and the rest by Newton steps.
    fn seconds(&self, op: &OpCount, k: f64) -> (f64, f64) {
        let divider = (op.divs + k) / self.divs + 2.0 * k / self.sqrts + op.sqrts / self.sqrts;
        let pipes = (op.flops + (op.fourth_roots - k) * FOURTH_ROOT_FLOPS) / self.flops;
        (divider, pipes)
    }

    /// Seconds per lane of one evaluation by the best split of the fourth roots.
    pub(crate) fn rhs_seconds(&self, op: &OpCount) -> f64 {
        (0..=op.fourth_roots as usize)
            .map(|k| {
                let (d, p) = self.seconds(op, k as f64);
                d.max(p)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The limit in simulated seconds per wall second of one thread: `rhs_per_tick` evaluations
    /// and the tick's own work, `window_share` of the ticks in the analysis window, at `f_s`.
    pub fn limit(&self, rhs_per_tick: f64, window_share: f64, f_s: f64) -> f64 {
        let tick = rhs_per_tick * self.rhs_seconds(&MINIMAL)
            + (TICK_OPS + window_share * WINDOW_OPS) / self.flops;
        1.0 / (f_s * tick)
    }
}

/// Independent chains per lane for the divider loops: enough to cover its latency.
const CHAINS: usize = 4;

/// Chains of multiplications and of additions per lane in the mul/add loop: with 8 lanes, 3 of
/// each keep 6 vectors of each in flight (two pipes of each, 3 cycles' latency) in 12 registers.
const MUL_CHAINS: usize = 3;

/// Independent multiplications and additions, in separate chains (`MUL_CHAINS` of each per lane)
/// so that neither unit waits on the other's latency; `a` is 1 at run time (opaque to the
/// compiler), so the values stay normal however long the loop runs.
#[inline(always)]
fn flop_body(iters: usize, a: f64, b: f64) -> f64 {
    let mut m = [[1.5f64; LANES]; MUL_CHAINS];
    let mut s = [[0.5f64; LANES]; MUL_CHAINS];
    for _ in 0..iters {
        for (mc, sc) in m.iter_mut().zip(s.iter_mut()) {
            for l in 0..LANES {
                mc[l] *= a;
                sc[l] += b;
            }
        }
    }
    m.iter().flatten().chain(s.iter().flatten()).sum()
}

#[inline(always)]
fn sqrt_body(iters: usize, c: f64) -> f64 {
    let mut x = [[2.0f64; LANES]; CHAINS];
    for _ in 0..iters {
        for r in x.iter_mut() {
            for v in r.iter_mut() {
                *v = (*v + c).sqrt();
            }
        }
    }
    x.iter().flatten().sum()
}

#[inline(always)]
fn div_body(iters: usize, c: f64) -> f64 {
    let mut x = [[2.0f64; LANES]; CHAINS];
    for _ in 0..iters {
        for r in x.iter_mut() {
            for v in r.iter_mut() {
                *v = c / (*v + c);
            }
        }
    }
    x.iter().flatten().sum()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn flop_avx2(iters: usize, a: f64, b: f64) -> f64 {
    flop_body(iters, a, b)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sqrt_avx2(iters: usize, c: f64) -> f64 {
    sqrt_body(iters, c)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn div_avx2(iters: usize, c: f64) -> f64 {
    div_body(iters, c)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
unsafe fn flop_avx512(iters: usize, a: f64, b: f64) -> f64 {
    flop_body(iters, a, b)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
unsafe fn sqrt_avx512(iters: usize, c: f64) -> f64 {
    sqrt_body(iters, c)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
unsafe fn div_avx512(iters: usize, c: f64) -> f64 {
    div_body(iters, c)
}

/// The instruction sets the kernel has builds for and this CPU runs, widest last.
fn isas() -> Vec<Isa> {
    [Isa::Portable, Isa::Avx2, Isa::Avx512]
        .into_iter()
        .filter(|&i| i <= Isa::detected())
        .collect()
}

/// The best of `f`'s rates over the instruction sets of [`isas`] from AVX2 up (the portable
/// build where the CPU has neither): the machine's rate, whichever encoding reaches it.
fn best(f: impl Fn(Isa) -> f64) -> f64 {
    let all = isas();
    let wide: Vec<Isa> = all.iter().copied().filter(|&i| i >= Isa::Avx2).collect();
    let pick = if wide.is_empty() { all } else { wide };
    pick.into_iter().map(f).fold(0.0, f64::max)
}

/// Lane-operations per second of `f`, which does `ops_per_iter` of them per iteration, run for
/// about `secs`.
fn rate(secs: f64, ops_per_iter: f64, f: impl Fn(usize) -> f64) -> f64 {
    let probe = 10_000;
    let t = std::time::Instant::now();
    black_box(f(black_box(probe)));
    let iters =
        ((secs / t.elapsed().as_secs_f64().max(1e-7)) * probe as f64).max(probe as f64) as usize;
    let t = std::time::Instant::now();
    black_box(f(black_box(iters)));
    iters as f64 * ops_per_iter / t.elapsed().as_secs_f64()
}

/// Measures the three rates on the kernel's lanes and instruction set, about `secs` each.
pub fn rates(secs: f64) -> Rates {
    let per_iter = (CHAINS * LANES) as f64;
    let (a, b) = (black_box(1.0), black_box(1e-3));
    Rates {
        // SAFETY (every call below): `best` only asks for instruction sets the CPU reports.
        flops: best(|isa| {
            rate(secs, (2 * MUL_CHAINS * LANES) as f64, |n| match isa {
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 => unsafe { flop_avx512(n, a, b) },
                #[cfg(target_arch = "x86_64")]
                Isa::Avx2 => unsafe { flop_avx2(n, a, b) },
                _ => flop_body(n, a, b),
            })
        }),
        sqrts: best(|isa| {
            rate(secs, per_iter, |n| match isa {
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 => unsafe { sqrt_avx512(n, b) },
                #[cfg(target_arch = "x86_64")]
                Isa::Avx2 => unsafe { sqrt_avx2(n, b) },
                _ => sqrt_body(n, b),
            })
        }),
        divs: best(|isa| {
            rate(secs, per_iter, |n| match isa {
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 => unsafe { div_avx512(n, b) },
                #[cfg(target_arch = "x86_64")]
                Isa::Avx2 => unsafe { div_avx2(n, b) },
                _ => div_body(n, b),
            })
        }),
    }
}

/// A dependent chain of 2·iters one-cycle integer operations (add, rotate): the clock, to turn
/// rates into cycles. Returns a checksum.
pub(crate) fn add_chain(iters: usize, seed: u64) -> u64 {
    let mut a = seed;
    let b = black_box(0x9e37_79b9_7f4a_7c15u64);
    for _ in 0..iters {
        a = a.wrapping_add(b).rotate_left(7);
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The limit follows the slower unit and picks the faster split of the fourth roots.
    #[test]
    fn the_limit_takes_the_slower_unit_and_the_best_split() {
        // A machine whose divider is free: both fourth roots go to it, the pipes bound the time.
        let r = Rates {
            flops: 1e9,
            divs: 1e12,
            sqrts: 1e12,
        };
        assert!((r.rhs_seconds(&MINIMAL) - MINIMAL.flops / 1e9).abs() < 1e-12);
        // A machine whose divider is slow: the fourth roots go to the pipes.
        let r = Rates {
            flops: 1e9,
            divs: 1e6,
            sqrts: 1e6,
        };
        let pipes = (MINIMAL.flops + 2.0 * FOURTH_ROOT_FLOPS) / 1e9;
        let divider = 3.0 / 1e6;
        assert!((r.rhs_seconds(&MINIMAL) - pipes.max(divider)).abs() < 1e-15);
        // Sixteen evaluations and the tick's work at 1024 Hz.
        let lim = r.limit(16.0, 0.5, 1024.0);
        assert!(
            (lim - 1.0 / (1024.0 * (16.0 * pipes.max(divider) + (TICK_OPS + 25.0) / 1e9))).abs()
                < 1e-9 * lim
        );
    }

    /// The timed loops do the work their rates count, and their AVX2 builds the same work; no
    /// timing here (`study bench` measures the rates, where a busy machine cannot fail a test).
    #[test]
    fn the_timed_loops_compute_what_they_count() {
        let (c, n) = (1e-3f64, (CHAINS * LANES) as f64);
        // 1.5 · 1^i and 0.5 + i·b per chain and lane.
        let flops = (MUL_CHAINS * LANES) as f64 * (1.5 + 0.5 + 100.0 * 0.25);
        assert_eq!(flop_body(100, 1.0, 0.25), flops);
        // x ← √(x + c) and x ← c / (x + c) converge to their fixed points.
        let root = (1.0 + (1.0 + 4.0 * c).sqrt()) / 2.0;
        assert!((sqrt_body(200, c) / n - root).abs() < 1e-12);
        let quotient = (-c + (c * c + 4.0 * c).sqrt()) / 2.0;
        assert!((div_body(4000, c) / n - quotient).abs() < 1e-12);
        // The clock's chain is one add and one rotate per iteration, not folded away.
        let k = 0x9e37_79b9_7f4a_7c15u64;
        assert_eq!(
            add_chain(1000, 1),
            add_chain(999, 1).wrapping_add(k).rotate_left(7)
        );
        #[cfg(target_arch = "x86_64")]
        if Isa::detected() >= Isa::Avx2 {
            // SAFETY: the CPU reports AVX2 and FMA.
            unsafe {
                assert_eq!(
                    flop_avx2(100, 1.0, 0.25).to_bits(),
                    flop_body(100, 1.0, 0.25).to_bits()
                );
                assert_eq!(sqrt_avx2(200, c).to_bits(), sqrt_body(200, c).to_bits());
                assert_eq!(div_avx2(400, c).to_bits(), div_body(400, c).to_bits());
            }
        }
        #[cfg(target_arch = "x86_64")]
        if Isa::detected() >= Isa::Avx512 {
            // SAFETY: the CPU reports AVX-512 F and VL.
            unsafe {
                assert_eq!(
                    flop_avx512(100, 1.0, 0.25).to_bits(),
                    flop_body(100, 1.0, 0.25).to_bits()
                );
                assert_eq!(sqrt_avx512(200, c).to_bits(), sqrt_body(200, c).to_bits());
                assert_eq!(div_avx512(400, c).to_bits(), div_body(400, c).to_bits());
            }
        }
    }
}
