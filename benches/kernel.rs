//! Criterion benchmarks of the lane kernel: one 3 s run of the 3 Hz, 1.73 g reference case
//! (RK4, 4 substeps per 1024 Hz tick: converged, see tests/reference.rs), as the scalar path
//! (1 lane), the batch kernel (8 lanes) on one thread, and two batches on two threads.
//! Throughput is reported in simulated seconds (criterion's "elements" = simulated seconds).
//!
//!   cargo bench --bench kernel
//!
//! `study bench` prints the same figures with cycles per lane per right-hand-side evaluation and
//! the machine's limit, and gates CI on their ratios.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use vshake::kernel::effects::Baseline;
use vshake::kernel::excitation::Sine;
use vshake::kernel::params::ModelParams;
use vshake::kernel::simulate::{self, LaneParams, NoObserver, Solver};
use vshake::kernel::LANES;

fn kernel(c: &mut Criterion) {
    let p = ModelParams::default();
    let r = Sine {
        freq_hz: 3.0,
        amp_m: Sine::amp_from_g(1.73, 3.0),
        taper_s: 1.0,
        duration_s: 3.0,
        window_cycles: Some(4),
    }
    .reference(1024.0);
    let solver = Solver::default();
    let lp1 = LaneParams::<1>::new(&[&p]).unwrap();
    let sets: Vec<&ModelParams> = (0..LANES).map(|_| &p).collect();
    let lp8 = LaneParams::<LANES>::new(&sets).unwrap();
    let mut g = c.benchmark_group("kernel_3s_sine");
    g.sample_size(10);
    g.throughput(Throughput::Elements(3));
    g.bench_function("scalar_1_lane", |b| {
        b.iter(|| simulate::run(&lp1, &Baseline, &r, &solver, &mut NoObserver).unwrap())
    });
    g.throughput(Throughput::Elements(3 * LANES as u64));
    g.bench_function("batch_8_lanes_1_thread", |b| {
        b.iter(|| simulate::run(&lp8, &Baseline, &r, &solver, &mut NoObserver).unwrap())
    });
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    g.throughput(Throughput::Elements(2 * 3 * LANES as u64));
    g.bench_function("batch_8_lanes_2_threads", |b| {
        b.iter(|| {
            pool.install(|| {
                (0..2)
                    .into_par_iter()
                    .map(|_| {
                        simulate::run(&lp8, &Baseline, &r, &solver, &mut NoObserver).unwrap()[0]
                            .metrics
                            .amp_ratio
                    })
                    .sum::<f64>()
            })
        })
    });
    g.finish();
}

criterion_group!(benches, kernel);
criterion_main!(benches);
