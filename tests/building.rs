//! The shear building (`building` effect): its modes against the closed form, a linear building
//! against the modal specimen of its modes, a yielding one against the bilinear law's bounds, and
//! its channels in a time history. The independent check against OpenSees is CI's
//! (`tests/opensees_building.py`).

use vshake::kernel::effects::building::{self, Mode};
use vshake::kernel::excitation::{Reference, Sine};
use vshake::kernel::params::{EffectId, ModelParams};
use vshake::orchestration::runs::single::{run_one, History};

/// A 3-storey building of 30 t floors and 24 MN/m storeys, storey law `law`.
fn building_model(law: f64) -> ModelParams {
    let mut p = ModelParams::default();
    *p.effects.get_mut(EffectId::Building) = true;
    p.effect_params.building.law = law;
    p
}

/// A sine of `amp_g` at `f` Hz, 6 s with a 1 s taper, at the controller's rate.
fn sine(f: f64, amp_g: f64) -> Reference {
    Sine {
        freq_hz: f,
        amp_m: Sine::amp_from_g(amp_g, f),
        taper_s: 1.0,
        duration_s: 6.0,
        window_cycles: None,
    }
    .reference(1024.0)
}

fn history(model: &ModelParams, reference: &Reference) -> History {
    let mut h = History::with_capacity(reference.len());
    let r = run_one(model, reference, &Default::default(), &mut h).unwrap();
    assert_eq!(
        r.status,
        vshake::kernel::simulate::LaneStatus::Ok,
        "the run fails"
    );
    h
}

fn peak(v: &[f64]) -> f64 {
    worst(v.iter().map(|x| x.abs()))
}

/// The largest of 0 and `values`, NaN if any is NaN (`f64::max` would drop it and hide a failed
/// run).
fn worst(values: impl Iterator<Item = f64>) -> f64 {
    largest(0.0, values)
}

/// The largest of `start` and `values`, NaN if any is NaN.
fn largest(start: f64, values: impl Iterator<Item = f64>) -> f64 {
    values.fold(start, |m, x| {
        if x.is_nan() || m.is_nan() {
            f64::NAN
        } else {
            m.max(x)
        }
    })
}

/// The largest |a − b| over the samples, NaN if any is NaN.
fn worst_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    worst(a.iter().zip(b).map(|(x, y)| (x - y).abs()))
}

/// A uniform shear building's modes: ω² = λ k/m with λ the eigenvalues of the tridiagonal
/// [2 −1; −1 2 −1; −1 1] (for 3 storeys 0.19806, 1.55496, 3.24698: 4 sin²((2j−1)π/14)), and the
/// effective masses add up to the building's mass.
#[test]
fn a_uniform_buildings_modes_are_the_closed_form() {
    let (m, k) = (30e3, 24e6);
    let modes: Vec<Mode> = building::modes(&[(m, k, 1.0); 3]);
    for (j, mode) in modes.iter().enumerate() {
        let lambda = 4.0
            * ((2 * j + 1) as f64 * std::f64::consts::PI / 14.0)
                .sin()
                .powi(2);
        let f = (lambda * k / m).sqrt() / (2.0 * std::f64::consts::PI);
        assert!(
            (mode.freq_hz - f).abs() < 1e-12 * f,
            "mode {}: {} against {f} Hz",
            j + 1,
            mode.freq_hz
        );
    }
    let total: f64 = modes.iter().map(|m| m.mass).sum();
    assert!((total - 3.0 * m).abs() < 1e-9 * m, "{total}");
    // The first mode's shape rises up the building: 0.445, 0.802, 1.
    let s = &modes[0].shape;
    assert!((s[0] - 0.445042).abs() < 1e-6 && (s[1] - 0.801938).abs() < 1e-6 && s[2] == 1.0);
}

/// With every storey linear, the building is the modal specimen of its three modes (their
/// frequencies, effective masses and the damping ζ_j = ζ f_j/f_1 of stiffness-proportional
/// damping): the same platen acceleration to the integrator's accuracy, at the building's first
/// mode where the two interact most.
#[test]
fn a_linear_building_is_the_modal_specimen_of_its_modes() {
    let b = building_model(0.0);
    let q = &b.effect_params.building;
    let modes = building::modes(&building::storeys(q));
    let zeta = q.zeta;
    let mut s = ModelParams::default();
    *s.effects.get_mut(EffectId::Specimen) = true;
    let sp = &mut s.effect_params.specimen;
    let f1 = modes[0].freq_hz;
    (sp.m1, sp.f1, sp.zeta1) = (modes[0].mass, f1, zeta);
    (sp.m2, sp.f2, sp.zeta2) = (
        modes[1].mass,
        modes[1].freq_hz,
        zeta * modes[1].freq_hz / f1,
    );
    (sp.m3, sp.f3, sp.zeta3) = (
        modes[2].mass,
        modes[2].freq_hz,
        zeta * modes[2].freq_hz / f1,
    );
    let reference = sine(f1, 0.3);
    let (hb, hs) = (history(&b, &reference), history(&s, &reference));
    let (ab, a_s) = (
        hb.channel("accel_mps2").unwrap(),
        hs.channel("accel_mps2").unwrap(),
    );
    let gap = worst_diff(ab, a_s);
    let scale = peak(a_s);
    assert!(scale > 1.0, "the run moves: {scale}");
    assert!(
        gap <= 1e-6 * scale,
        "building vs modal specimen: {gap:e} of {scale} m/s²"
    );
    // The base shear is the specimen's: the building's mass times its absolute accelerations.
    let shear = hb.channel("base_shear_n").unwrap();
    let inertia: Vec<f64> = (0..shear.len())
        .map(|t| {
            (1..=3)
                .map(|i| 30e3 * hb.channel(&format!("floor_accel_{i}_mps2")).unwrap()[t])
                .sum::<f64>()
        })
        .collect();
    let off = worst(shear.iter().zip(&inertia).map(|(v, f)| (v + f).abs()));
    assert!(
        off <= 1e-9 * peak(shear),
        "V_1 = -sum m_i a_i: {off:e} of {}",
        peak(shear)
    );
}

/// A bilinear building driven past its yield: the first storey's force stays on the bilinear
/// law's lines (|R| ≤ (1 − α) F_y + α k |d|, reaching F_y), its drift passes the yield drift, and
/// more than half the storey's work ∫R dd is dissipated (not stored) at the end. The same
/// building linear stores and returns its energy: its work is k d²/2 at every tick.
#[test]
fn a_yielding_storey_follows_the_bilinear_law_and_dissipates() {
    let reference = sine(2.0, 0.5);
    let h = history(&building_model(1.0), &reference);
    let q = building_model(1.0).effect_params.building;
    let (k, fy, alpha) = (q.k1, q.fy1, q.alpha);
    let d = h.channel("drift_1_m").unwrap();
    let r = h.channel("storey_force_1_n").unwrap();
    let over = largest(
        f64::MIN,
        d.iter()
            .zip(r)
            .map(|(d, r)| r.abs() - ((1.0 - alpha) * fy + alpha * k * d.abs())),
    );
    assert!(over <= 1e-6 * fy, "beyond the yield line by {over} N");
    assert!(peak(r) >= fy, "the storey yields: peak {} N", peak(r));
    assert!(peak(d) > 2.0 * fy / k, "ductility {}", peak(d) * k / fy);
    let energy = |h: &History| *h.channel("energy_1_j").unwrap().last().unwrap();
    let dissipated = energy(&h);
    // What the storey stores at the end: α k d²/2 and the hysteretic spring's r²/(2k) (1 − α),
    // with r = (R − α k d)/(1 − α).
    let (d_end, r_end) = (*d.last().unwrap(), *r.last().unwrap());
    let r_h = (r_end - alpha * k * d_end) / (1.0 - alpha);
    let stored = 0.5 * alpha * k * d_end * d_end + (1.0 - alpha) * r_h * r_h / (2.0 * k);
    assert!(
        dissipated - stored > 0.5 * dissipated,
        "work {dissipated} J, of which {stored} J stored at the end"
    );
    // Linear, the storey's work is its elastic energy k d²/2 at every tick.
    let lin = history(&building_model(0.0), &reference);
    let (d, w) = (
        lin.channel("drift_1_m").unwrap(),
        lin.channel("energy_1_j").unwrap(),
    );
    let top = worst(w.iter().copied());
    let off = worst(d.iter().zip(w).map(|(d, w)| (w - 0.5 * k * d * d).abs()));
    assert!(
        off <= 1e-6 * top,
        "linear: work - k d²/2 = {off:e} of {top} J"
    );
}

/// A Bouc–Wen storey with a sharp yield (n = 25) is close to the bilinear one.
#[test]
fn a_sharp_bouc_wen_storey_approaches_the_bilinear_one() {
    let reference = sine(2.0, 0.5);
    let bilinear = history(&building_model(1.0), &reference);
    let mut m = building_model(2.0);
    m.effect_params.building.bw_n = 25.0;
    let bw = history(&m, &reference);
    let (a, b) = (
        bilinear.channel("drift_1_m").unwrap(),
        bw.channel("drift_1_m").unwrap(),
    );
    let diff = worst_diff(a, b);
    assert!(diff < 0.05 * peak(a), "{diff} of {}", peak(a));
}

/// A count of storeys or a law that is not a whole number is refused by name.
#[test]
fn a_fractional_count_of_storeys_is_refused() {
    let mut m = building_model(1.0);
    m.effect_params.building.storeys = 2.5;
    let e = m.validate().unwrap_err();
    assert!(
        e.iter()
            .any(|i| i.path == "building.storeys" && i.message.contains("whole")),
        "{e:?}"
    );
}

/// A study or a tuning that varies a storey's parameter above the building's storeys is refused,
/// naming the variable and the count; with the count varied too, or the storey present, it is not.
#[test]
fn a_variable_of_a_storey_the_building_lacks_is_refused() {
    use vshake::orchestration::study::problem::StudySpec;
    let study = |storeys: &str, vars: &[(&str, f64, f64)]| {
        let mut t = String::from("[study]\nname = \"s\"\nsamples = 4\n");
        for (name, low, high) in vars {
            t += &format!("[[variables]]\nname = \"{name}\"\ndistribution = \"uniform\"\nlow = {low}\nhigh = {high}\n");
        }
        t += "[[excitations]]\nname = \"s\"\nkind = \"sine\"\nfreq_hz = 3.0\namp_g = 0.5\nduration_s = 4.0\n";
        t += &format!("[model.building]\nstoreys = {storeys}\n");
        StudySpec::from_toml(&t, "s.toml")
    };
    let e = study("3", &[("building.k5", 1e7, 2e7)])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("variables[0].name: building.k5 is storey 5's, but the building has 3 storeys"),
        "{e}"
    );
    let e = study("2", &[("building.fy3", 1e5, 2e5)])
        .unwrap_err()
        .to_string();
    assert!(e.contains("building.fy3 is storey 3's"), "{e}");
    study("5", &[("building.k5", 1e7, 2e7)]).unwrap();
    study("3", &[("building.m3", 2e4, 4e4)]).unwrap();
    // The count of storeys takes whole numbers: a uniform one is refused, a list is not.
    let e = study(
        "3",
        &[("building.k5", 1e7, 2e7), ("building.storeys", 3.0, 6.0)],
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("variables[1].distribution: building.storeys takes whole numbers only"),
        "{e}"
    );
    let listed = |values: &str| {
        let mut t = String::from("[study]\nname = \"s\"\nsamples = 4\n");
        t += &format!("[[variables]]\nname = \"building.storeys\"\ndistribution = \"list\"\nvalues = {values}\n");
        t += "[[variables]]\nname = \"building.k5\"\ndistribution = \"uniform\"\nlow = 1e7\nhigh = 2e7\n";
        t += "[[excitations]]\nname = \"s\"\nkind = \"sine\"\nfreq_hz = 3.0\namp_g = 0.5\nduration_s = 4.0\n";
        t += "[model.building]\nstoreys = 3\n";
        StudySpec::from_toml(&t, "s.toml")
    };
    listed("[3, 5, 6]").unwrap();
    let e = listed("[3, 4.5]").unwrap_err().to_string();
    assert!(e.contains("every value must be one"), "{e}");
}

/// The specimen's metrics (`peak_drift_ratio`, `peak_base_shear_n`, `ductility_demand`,
/// `hysteretic_energy_j`) are the peaks of the building's own channels over the run and the
/// storeys' work less what they hold at its end; the same in a batch beside a lane without a
/// building, where they are NaN; and a linear building dissipates nothing.
#[test]
fn the_specimen_metrics_are_the_peaks_of_its_channels() {
    let reference = sine(2.0, 0.5);
    let model = building_model(1.0);
    let mut h = History::with_capacity(reference.len());
    let m = run_one(&model, &reference, &Default::default(), &mut h)
        .unwrap()
        .metrics;
    let q = model.effect_params.building.clone();
    let storey = [(q.k1, q.fy1), (q.k2, q.fy2), (q.k3, q.fy3)];
    let ch = |name: String| h.channel(&name).unwrap().to_vec();
    let drifts: Vec<Vec<f64>> = (1..=3).map(|i| ch(format!("drift_{i}_m"))).collect();
    let drift = worst(drifts.iter().map(|d| peak(d)));
    let ductility = worst(
        drifts
            .iter()
            .zip(storey)
            .map(|(d, (k, fy))| peak(d) * k / fy),
    );
    let held = |i: usize, (k, _): (f64, f64)| {
        let (d, r) = (
            *drifts[i].last().unwrap(),
            *ch(format!("storey_force_{}_n", i + 1)).last().unwrap(),
        );
        let r_h = (r - q.alpha * k * d) / (1.0 - q.alpha);
        0.5 * q.alpha * k * d * d + (1.0 - q.alpha) * r_h * r_h / (2.0 * k)
    };
    let energy: f64 = (0..3)
        .map(|i| ch(format!("energy_{}_j", i + 1)).last().unwrap() - held(i, storey[i]))
        .sum();
    let close = |got: f64, want: f64, what: &str| {
        let rel = (got - want).abs() / want.abs();
        assert!(rel <= 1e-9, "{what}: {got} against {want} ({rel:e})");
    };
    close(m.peak_drift_ratio, drift / q.height, "peak drift ratio");
    close(
        m.peak_base_shear_n,
        peak(&ch("base_shear_n".into())),
        "peak base shear",
    );
    close(m.ductility_demand, ductility, "ductility demand");
    close(m.hysteretic_energy_j, energy, "dissipated energy");
    assert!(
        m.ductility_demand > 1.5 && m.hysteretic_energy_j > 100.0,
        "{m:?}"
    );

    // In a batch beside a bare lane: the same bits, and NaN where there is no building.
    let bare = ModelParams::default();
    let solver = Default::default();
    let got =
        vshake::orchestration::runs::single::run_group(&[&model, &bare], &[&reference], &solver)
            .unwrap();
    assert_eq!(got[0].metrics.bits(), m.bits());
    let names = vshake::kernel::metrics::Metrics::SPECIMEN;
    let bare_cols = got[1].metrics.columns();
    for (n, v) in bare_cols.iter().filter(|(n, _)| names.contains(n)) {
        assert!(v.is_nan(), "{n} = {v} without a building");
    }
    assert_eq!(bare_cols.len(), m.columns().len());

    // Linear storeys hold all their work: nothing dissipated, to rounding.
    let mut h = History::with_capacity(reference.len());
    let lin = run_one(&building_model(0.0), &reference, &solver, &mut h).unwrap();
    let work: f64 = (1..=3)
        .map(|i| worst(h.channel(&format!("energy_{i}_j")).unwrap().iter().copied()))
        .sum();
    assert!(
        lin.metrics.ductility_demand.is_nan(),
        "linear storeys have no yield"
    );
    let e = lin.metrics.hysteretic_energy_j;
    assert!(
        e.abs() <= 1e-9 * work,
        "linear: {e} J dissipated of {work} J of work"
    );
}
