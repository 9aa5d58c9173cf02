use std::time::Instant;
use vshake::kernel::{effects::Baseline, excitation::Sine, params::*, simulate::*};
fn bench<const N: usize>(reps: usize) -> f64 {
    let p = ModelParams::default();
    let sets: Vec<&ModelParams> = (0..N).map(|_| &p).collect();
    let lp = LaneParams::<N>::new(&sets).unwrap();
    let r = Sine { freq_hz: 3.0, amp_m: Sine::amp_from_g(1.73, 3.0), taper_s: 1.0, duration_s: 3.0, window_cycles: Some(4) }.reference(1024.0);
    let t = Instant::now();
    for _ in 0..reps { std::hint::black_box(run(&lp, &Baseline, &r, &Solver::default(), &mut NoObserver).unwrap()); }
    let wall = t.elapsed().as_secs_f64();
    let sim = 3.0 * (N * reps) as f64;
    let rhs = (N * reps) as f64 * 3072.0 * 8.0 * 4.0;
    println!("N={N}: {:.0} sim-s/wall-s; {:.1} ns per lane-RHS; {:.0} cycles @2.45GHz", sim / wall, wall / rhs * 1e9, wall / rhs * 2.45e9);
    sim / wall
}
fn main() {
    bench::<1>(40); bench::<4>(10); bench::<8>(10); bench::<16>(5);
}
