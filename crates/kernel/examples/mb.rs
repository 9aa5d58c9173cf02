use vshake_kernel::expr::Program;
fn main() {
    let p = Program::compile(
        "-tanh(v / v_eps) * (f_c + (f_s - f_c) * exp(-(v / v_s)^2))",
        &["y", "v", "t"],
        &["f_c", "f_s", "v_s", "v_eps"],
    )
    .unwrap();
    let params = [5000.0, 8000.0, 0.01, 1e-3];
    let n = 20_000_000;
    let t = std::time::Instant::now();
    let mut acc = 0.0;
    for i in 0..n {
        let v = (i as f64) * 1e-9 - 0.01;
        acc += p.eval(std::hint::black_box(&[0.0, v, 0.0]), &params);
    }
    let e = t.elapsed().as_secs_f64();
    println!("interp {:.1} ns/eval {acc}", e / n as f64 * 1e9);
    let t = std::time::Instant::now();
    let mut acc = 0.0;
    let (f_c, df, ivs, ie) = (5000.0f64, 3000.0f64, 100.0f64, 1000.0f64);
    for i in 0..n {
        let v: f64 = std::hint::black_box((i as f64) * 1e-9 - 0.01);
        let r = v * ivs;
        acc += -(v * ie).tanh() * (f_c + df * (-r * r).exp());
    }
    let e = t.elapsed().as_secs_f64();
    println!("native {:.1} ns/eval {acc}", e / n as f64 * 1e9);
}
