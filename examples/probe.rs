use vshake::kernel::{excitation::Sine, params::*, simulate::*, effects::Baseline};
fn main() {
    for &g in &[1.73, 3.20] {
        let mut base = None;
        for &sub in &[128usize, 1, 2, 3, 4, 6, 8, 16, 32] {
            let p = ModelParams::default();
            let sine = Sine { freq_hz: 3.0, amp_m: Sine::amp_from_g(g, 3.0), taper_s: 1.0, duration_s: 3.0, window_cycles: Some(4) };
            let r = sine.reference(1024.0);
            let lp = LaneParams::<1>::new(&[&p]).unwrap();
            let res = run(&lp, &Baseline, &r, &Solver { substeps: sub }, &mut NoObserver).unwrap();
            let m = res[0].metrics;
            let v = [m.amp_ratio, m.phase_err_deg, m.h(2), m.h(3), m.h(5), m.h(7), m.h(9), m.thd_odd];
            if base.is_none() { base = Some(v); }
            let b = base.unwrap();
            let rel: Vec<String> = v.iter().zip(b.iter()).map(|(x, y)| format!("{:.1e}", ((x - y) / y).abs())).collect();
            println!("{g} sub={sub:3} ratio={:.7} phase={:+.6} h3={:.7} h9={:.7} relerr vs 128: {:?} {:?}", m.amp_ratio, m.phase_err_deg, m.h(3), m.h(9), rel, res[0].status);
        }
    }
}
