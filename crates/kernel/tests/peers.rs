//! The kernel pinned to an independent implementation inside `cargo test` (the kernel's own
//! tests, so that a change of the kernel is tested without building the shell): the NumPy peer's
//! metrics (benches/peers/numpy_peer.py, a transcription of docs/model.md that shares no code
//! with vshake), committed in tests/fixtures/numpy_peer_metrics.csv by
//! benches/peers/make_fixture.py, for 16 gain sets at 0.5, 1.73 and 3.20 g of the 3 Hz reference
//! sine, RK4 with 4 substeps. Every metric agrees to 1e-9 relative to max(|value|, 1) (a phase in
//! degrees), and a run the peer stops the kernel fails too. A change of any plant constant by
//! 0.01 % moves some metric by far more than that (`a_small_change_of_beta_is_caught`).

use vshake_kernel::effects::expression::Hook;
use vshake_kernel::effects::{effect_set, Baseline, EffectId};
use vshake_kernel::param_table::Range;
use vshake_kernel::params::ModelParams;
use vshake_kernel::simulate::{
    self, LaneParams, LaneResult, LaneStatus, NoObserver, Observer, Solver, TickView,
};

const TOLERANCE: f64 = 1e-9;

/// `VSHAKE_PEERS_EVERY=k`: every k-th case of each fixture only (each effect's defaults always),
/// for benches/mutants.sh, which runs these tests once per mutant at opt-level 0; 1 (all) else.
fn every() -> usize {
    std::env::var("VSHAKE_PEERS_EVERY").map_or(1, |k| {
        k.parse()
            .ok()
            .filter(|&k| k >= 1)
            .unwrap_or_else(|| panic!("VSHAKE_PEERS_EVERY={k}: a whole number >= 1"))
    })
}

/// A fixture of the workspace's tests/fixtures (the peers' output, shared with the shell's tests).
fn fixture(name: &str) -> String {
    format!("{}/../../tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// A CSV file as the peers write it (a header, plain fields: no quotes, no commas inside a field),
/// read without a CSV crate, which the kernel does not depend on. Every row has the header's width.
fn read_csv(path: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let mut lines = text.lines().filter(|l| !l.is_empty());
    let split = |l: &str| l.split(',').map(str::to_string).collect::<Vec<_>>();
    let header = split(lines.next().unwrap_or_else(|| panic!("{path}: empty")));
    let rows: Vec<Vec<String>> = lines.map(split).collect();
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), header.len(), "{path}, row {}: its width", i + 2);
    }
    (header, rows)
}

/// The reference test's 3 Hz sine at `amp_g` (1 s tapers, 3 s, the 4-cycle window), at 1024 Hz:
/// what the peers run (tests/common's `reference_sine`).
fn reference_sine(amp_g: f64) -> vshake_kernel::excitation::Reference {
    use vshake_kernel::excitation::Sine;
    Sine {
        freq_hz: 3.0,
        amp_m: Sine::amp_from_g(amp_g, 3.0),
        taper_s: 1.0,
        duration_s: 3.0,
        window_cycles: Some(4),
    }
    .reference(1024.0)
}

struct Case {
    amp_g: f64,
    gains: Vec<(String, f64)>,
    metrics: Vec<(String, f64)>,
}

fn cases() -> Vec<Case> {
    cases_in("numpy_peer_metrics.csv")
}

/// The cases of a fixture whose columns are the amplitude, parameter paths, then the metrics
/// (from `amp_ratio` on).
fn cases_in(name: &str) -> Vec<Case> {
    let (header, rows) = read_csv(&fixture(name));
    let split = header.iter().position(|h| h == "amp_ratio").unwrap();
    rows.iter()
        .map(|rec| {
            let v: Vec<f64> = rec.iter().map(|x| x.parse().unwrap()).collect();
            let named = |range: std::ops::Range<usize>| {
                range.map(|i| (header[i].clone(), v[i])).collect::<Vec<_>>()
            };
            Case {
                amp_g: v[0],
                gains: named(1..split),
                metrics: named(split..header.len()),
            }
        })
        .collect()
}

fn run(case: &Case, base: &ModelParams) -> LaneResult {
    let mut model = base.clone();
    for (path, v) in &case.gains {
        ModelParams::lookup(path)
            .unwrap_or_else(|| panic!("{path}: not a parameter"))
            .set(&mut model, *v);
    }
    let lp = LaneParams::<1>::new(&[&model]).unwrap();
    let solver = Solver { substeps: 4 };
    let [r] = simulate::run(
        &lp,
        &Baseline,
        &reference_sine(case.amp_g),
        &solver,
        &mut NoObserver,
    )
    .unwrap();
    r
}

/// The largest deviation of `r`'s metrics from the case's, relative to max(|value|, 1), with
/// the metric's name; infinite when one run failed and the other did not.
fn deviation(case: &Case, r: &LaneResult) -> (f64, String) {
    // A run the peer stops has every metric NaN; a metric NaN by definition (the ductility of
    // linear storeys) must be NaN in the kernel too.
    let failed = case
        .metrics
        .iter()
        .all(|(n, v)| v.is_nan() || FORCE.contains(&n.as_str()));
    if failed || r.status != LaneStatus::Ok {
        let agree = failed && matches!(r.status, LaneStatus::Failed { .. });
        return (if agree { 0.0 } else { f64::INFINITY }, "status".into());
    }
    let ours = r.metrics.columns();
    case.metrics
        .iter()
        .filter(|(name, _)| !FORCE.contains(&name.as_str()))
        .map(|(name, want)| {
            let got = ours.iter().find(|(n, _)| n == name).unwrap().1;
            if want.is_nan() {
                return (if got.is_nan() { 0.0 } else { f64::INFINITY }, name.clone());
            }
            // A NaN on one side is the largest deviation, never dropped by the fold.
            let d = (got - want).abs() / want.abs().max(1.0);
            (if d.is_nan() { f64::INFINITY } else { d }, name.clone())
        })
        .fold((0.0, String::new()), |a, b| if b.0 > a.0 { b } else { a })
}

/// Every case of fixture `file` (`rows` of them; every k-th where VSHAKE_PEERS_EVERY thins) run
/// from the defaults with the case's parameters: every metric within [`TOLERANCE`] of the peer's.
fn agrees_with(file: &str, rows: usize) {
    let cases = cases_in(file);
    assert_eq!(cases.len(), rows, "{file}: its rows");
    let base = ModelParams::default();
    let mut worst = (0.0f64, String::new());
    for (i, case) in cases.iter().enumerate().step_by(every()) {
        let (d, name) = deviation(case, &run(case, &base));
        assert!(
            d <= TOLERANCE,
            "{file} row {} ({} g): {name} deviates by {d:e} from the NumPy peer",
            i + 2,
            case.amp_g
        );
        if d > worst.0 {
            worst = (d, format!("row {} {name}", i + 2));
        }
    }
    println!(
        "{file}: largest deviation from the NumPy peer {:e} ({})",
        worst.0, worst.1
    );
}

/// The gain sets (16 sets x 3 amplitudes).
#[test]
fn the_kernel_agrees_with_the_numpy_peer_to_1e_9() {
    agrees_with("numpy_peer_metrics.csv", 48);
}

/// The plant away from its defaults (benches/peers/make_plant_fixture.py): 24 random sets of every
/// constant the peer models (valve, actuators with dead volumes, platen, friction, the
/// controller's scalings; a third of the runs clamp the command) at 0.5 and 1.73 g, default
/// gains: every metric within 1e-9 of the peer's. A term that vanishes at the defaults (the dead
/// volumes) is pinned here, not by the gain sets.
#[test]
fn the_plant_agrees_with_the_numpy_peer_away_from_its_defaults() {
    agrees_with("numpy_peer_plant.csv", 48);
}

/// The pin can fail: β (the oil's bulk modulus) 0.1 % and 0.01 % off its default moves a metric
/// of the reference case far beyond the tolerance.
#[test]
fn a_small_change_of_beta_is_caught() {
    let cases = cases();
    for change in [1e-3, 1e-4] {
        let mut model = ModelParams::default();
        model.actuator.beta *= 1.0 + change;
        let (d, name) = deviation(&cases[16], &run(&cases[16], &model));
        assert!(
            d > 100.0 * TOLERANCE,
            "β x (1 + {change}) moved the metrics by only {d:e} ({name})"
        );
    }
}

/// One case of tests/fixtures/numpy_peer_effects.csv: an effect, its parameters, the peer's
/// metrics.
struct EffectCase {
    effect: String,
    amp_g: f64,
    params: Vec<(String, f64)>,
    case: Case,
}

/// The committed fixture, or the file `VSHAKE_PEER_EFFECTS` names (CI's step regenerates it with
/// the peer and runs this test on what the peer printed).
fn effect_cases() -> Vec<EffectCase> {
    let path =
        std::env::var("VSHAKE_PEER_EFFECTS").unwrap_or_else(|_| fixture("numpy_peer_effects.csv"));
    effect_cases_in(&path)
}

/// The cases of a fixture of effects (an effect, an amplitude, its parameters, the metrics).
fn effect_cases_in(path: &str) -> Vec<EffectCase> {
    let (header, rows) = read_csv(path);
    rows.iter()
        .map(|rec| {
            let params = rec[2]
                .split(';')
                .filter(|kv| !kv.is_empty())
                .map(|kv| {
                    let (k, v) = kv.split_once('=').unwrap();
                    (k.to_string(), v.parse().unwrap())
                })
                .collect();
            // An empty cell: a metric the effect does not have (the building's, elsewhere).
            let metrics = (3..header.len())
                .filter(|&i| !rec[i].is_empty())
                .map(|i| (header[i].clone(), rec[i].parse().unwrap()))
                .collect();
            let amp_g = rec[1].parse().unwrap();
            EffectCase {
                effect: rec[0].to_string(),
                amp_g,
                params,
                case: Case {
                    amp_g,
                    gains: Vec::new(),
                    metrics,
                },
            }
        })
        .collect()
}

/// The recorded actuator force's projections on the reference's acceleration and velocity over
/// the analysis window: Σ f a_r / Σ a_r² (kg) and Σ f v_r / Σ v_r² (N·s/m), phase-sensitive.
struct ForceProjections {
    window: (usize, usize),
    sums: [f64; 4],
}

impl Observer<1> for ForceProjections {
    fn tick(&mut self, view: &TickView<'_, 1>) {
        if (self.window.0..self.window.1).contains(&view.k) {
            let (f, a, v) = (view.f[0], view.r.a, view.r.v);
            self.sums[0] += f * a;
            self.sums[1] += a * a;
            self.sums[2] += f * v;
            self.sums[3] += v * v;
        }
    }
}

/// The kernel with the case's effect switched on and its parameters set (default gains), and the
/// recorded actuator force's projections ([`ForceProjections`]: what the force sensor changes).
fn run_effect(c: &EffectCase) -> (LaneResult, [f64; 2]) {
    let mut model = ModelParams::default();
    if let Some(scenario) = c.effect.strip_prefix("expression:") {
        write_expressions(&mut model, scenario, &c.params);
    } else {
        *model.effects.get_mut(EffectId::parse(&c.effect).unwrap()) = true;
        for (path, v) in &c.params {
            ModelParams::lookup(path)
                .unwrap_or_else(|| panic!("{path}: not a parameter"))
                .set(&mut model, *v);
        }
    }
    let lp = LaneParams::<1>::new(&[&model]).unwrap();
    let set = effect_set::<1>(&[&model]);
    let solver = Solver { substeps: 4 };
    let reference = reference_sine(c.amp_g);
    let mut obs = ForceProjections {
        window: reference.window,
        sums: [0.0; 4],
    };
    let [r] = simulate::run(&lp, &set, &reference, &solver, &mut obs).unwrap();
    let s = obs.sums;
    assert!(s[1] > 0.0 && s[3] > 0.0, "no tick in the window");
    (r, [s[0] / s[1], s[2] / s[3]])
}

/// The expression fixture's scenarios (the peer's tests/fixtures/numpy_peer_expressions.tsv, or
/// the `.tsv` beside the file `VSHAKE_PEER_EXPRESSIONS` names): (scenario, hook, source).
fn expression_sources() -> Vec<(String, String, String)> {
    let path = expressions_fixture().replace(".csv", ".tsv");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let rows: Vec<_> = (text.lines())
        .map(|l| match l.split('\t').collect::<Vec<_>>()[..] {
            [s, h, src] => (s.to_string(), h.to_string(), src.to_string()),
            _ => panic!("{path}: {l:?} is not scenario, hook and source"),
        })
        .collect();
    assert!(!rows.is_empty(), "{path}: no expression");
    rows
}

/// The expression fixture: the committed one, or the file `VSHAKE_PEER_EXPRESSIONS` names (CI's
/// step makes it again with the peer).
fn expressions_fixture() -> String {
    std::env::var("VSHAKE_PEER_EXPRESSIONS")
        .unwrap_or_else(|_| fixture("numpy_peer_expressions.csv"))
}

/// Effect `expression` switched on in `model` with the scenario's expressions, each named
/// parameter (`expression.NAME`) named at its value, as a model file's `[model.expression]` does.
fn write_expressions(model: &mut ModelParams, scenario: &str, params: &[(String, f64)]) {
    *model
        .effects
        .get_mut(EffectId::parse("expression").unwrap()) = true;
    for (path, v) in params {
        let name = path.strip_prefix("expression.").unwrap();
        model
            .name_expression_param(name, "-", Range::any(), *v)
            .unwrap_or_else(|e| panic!("{path}: {e}"));
    }
    let sources = expression_sources();
    for (_, hook, source) in sources.iter().filter(|r| r.0 == scenario) {
        let hook = Hook::parse(hook).unwrap_or_else(|| panic!("{hook}: not a hook"));
        (model.expression.set(hook, source)).unwrap_or_else(|e| panic!("{source}: {e:?}"));
    }
}

/// The columns of the recorded force ([`ForceProjections`]), not kernel metrics.
const FORCE: [&str; 2] = ["force_a_kg", "force_v_n_s_per_m"];

/// [`deviation`] over the metrics and the recorded force's projections.
fn effect_deviation(c: &EffectCase, (r, force): &(LaneResult, [f64; 2])) -> (f64, String) {
    let mut worst = deviation(&c.case, r);
    if r.status != LaneStatus::Ok {
        return worst;
    }
    for (name, got) in FORCE.iter().zip(force) {
        let want = c.case.metrics.iter().find(|(n, _)| n == name).unwrap().1;
        let d = (got - want).abs() / want.abs().max(1.0);
        let d = if d.is_nan() { f64::INFINITY } else { d };
        if d > worst.0 {
            worst = (d, name.to_string());
        }
    }
    worst
}

/// The library's effects that benches/peers/effects.py transcribes.
const LIBRARY: [&str; 21] = [
    "transport_delay",
    "spool_dynamics",
    "flow_saturation",
    "flow_gain",
    "asymmetry",
    "leakage",
    "supply",
    "seal_friction",
    "compressibility",
    "bulk_curve",
    "reaction_mass",
    "hold_down",
    "specimen",
    "accel_sensor",
    "disp_sensor",
    "force_sensor",
    "building",
    "valve_compensator",
    "amplitude_phase",
    "harmonic_cancellation",
    "adaptive_inverse",
];

/// Each case (its fixture row's index, the case) run by the kernel: every metric within
/// [`TOLERANCE`] of the peer's. Per effect, in order: its name, its cases run and the largest
/// deviation.
fn each_agrees(cases: &[(usize, &EffectCase)]) -> Vec<(String, usize, f64)> {
    let mut per_effect: Vec<(String, usize, f64)> = Vec::new();
    for &(i, c) in cases {
        let (d, name) = effect_deviation(c, &run_effect(c));
        assert!(
            d <= TOLERANCE,
            "row {} ({}, {:?}): {name} deviates by {d:e} from the NumPy peer",
            i + 2,
            c.effect,
            c.params
        );
        match per_effect.iter_mut().find(|(e, ..)| *e == c.effect) {
            Some((_, n, worst)) => (*n, *worst) = (*n + 1, worst.max(d)),
            None => per_effect.push((c.effect.clone(), 1, d)),
        }
    }
    per_effect
}

/// Every library effect (benches/peers/effects.py), 50 random parameter sets each away from the defaults and one at the documented defaults (the kernel's
/// own: a changed default fails): every metric within 1e-9 of the peer's.
#[test]
fn each_effect_agrees_with_the_numpy_peer_to_1e_9() {
    let all = effect_cases();
    // Each effect's k-th sets and its last row (the defaults), where VSHAKE_PEERS_EVERY thins.
    let cases: Vec<(usize, &EffectCase)> = all
        .iter()
        .enumerate()
        .filter(|&(i, c)| {
            let last = all.get(i + 1).is_none_or(|n| n.effect != c.effect);
            i % every() == 0 || last
        })
        .collect();
    let per_effect = each_agrees(&cases);
    for (effect, n, worst) in &per_effect {
        println!("{effect}: {n} sets, largest deviation {worst:e}");
        assert!(*n >= 51 / every(), "{effect}: {n} sets");
        // The last set is the documented defaults, the kernel's own (no parameter set).
        let last = cases
            .iter()
            .rev()
            .find(|c| c.1.effect == *effect)
            .unwrap()
            .1;
        assert!(last.params.is_empty(), "{effect}: no row at the defaults");
    }
    // Every effect of the library this peer was written for; an effect added since (the guide's
    // tutorial adds one) has no peer yet, and is named.
    let peered: Vec<&str> = per_effect.iter().map(|(e, ..)| e.as_str()).collect();
    for effect in LIBRARY {
        assert!(
            peered.contains(&effect),
            "{effect}: no row in the peer's fixture"
        );
    }
    let new: Vec<&str> = EffectId::ALL
        .iter()
        .map(|e| e.name())
        // `expression` has its own fixture (`each_expression_agrees_with_the_numpy_peer_to_1e_9`).
        .filter(|e| !peered.contains(e) && *e != "expression")
        .collect();
    if !new.is_empty() {
        println!("effects without a peer (added after it was written): {new:?}");
    }
}

/// Effect `expression` (physics a model file writes, no rebuild) against the NumPy peer
/// (benches/peers/make_expression_fixture.py: the documented language under Python's grammar and
/// NumPy's functions): 50 random parameter sets of each scenario, whose expressions give every
/// hook and use every function, and the effect on with no expression (the baseline's metrics):
/// every metric and the recorded force within 1e-9 of the peer's.
#[test]
fn each_expression_agrees_with_the_numpy_peer_to_1e_9() {
    let all = effect_cases_in(&expressions_fixture());
    // Every k-th set where VSHAKE_PEERS_EVERY thins, and the neutral row.
    let cases: Vec<(usize, &EffectCase)> = (all.iter().enumerate())
        .filter(|&(i, c)| i % every() == 0 || c.params.is_empty())
        .collect();
    let per_scenario = each_agrees(&cases);
    for (scenario, n, worst) in &per_scenario {
        println!("{scenario}: {n} sets, largest deviation {worst:e}");
        let want = if *scenario == "expression:none" {
            1
        } else {
            50 / every()
        };
        assert!(*n >= want, "{scenario}: {n} sets");
    }
    assert!(per_scenario.iter().any(|s| s.0 == "expression:none"));
    let sources = expression_sources();
    for hook in Hook::ALL {
        assert!(
            sources.iter().any(|r| r.1 == hook.key()),
            "{}: no scenario gives it an expression",
            hook.key()
        );
    }
    for (f, _) in vshake_kernel::expr::FUNCTIONS {
        assert!(
            sources.iter().any(|r| calls(&r.2, f)),
            "{f}: no expression calls it"
        );
    }
}

/// Whether expression `source` calls function `f` (`f(` not inside a longer name: `atan(` is no
/// call of `tan`).
fn calls(source: &str, f: &str) -> bool {
    let call = format!("{f}(");
    source.match_indices(&call).any(|(i, _)| {
        let before = source[..i].chars().next_back();
        !before.is_some_and(|c| c.is_alphanumeric() || c == '_')
    })
}

/// Whether parameter `path` changes anything in the set `params`: not a mode that is absent (zero
/// mass), a count or a law (whole numbers), a storey above the building, the Bouc–Wen constants
/// of another law, or α and the yield forces of linear storeys (R = k d whatever they are).
fn applies(params: &[(String, f64)], path: &str) -> bool {
    let get = |name: &str| params.iter().find(|(p, _)| p == name).map(|(_, v)| *v);
    if let Some(mode) = path
        .strip_prefix("specimen.")
        .and_then(|n| n.chars().last())
    {
        return get(&format!("specimen.m{mode}")) != Some(0.0);
    }
    // The inverse's fit reaches the run only through its copy into the inverse in use.
    if ["memory_s", "weight_hz", "freeze_s"]
        .map(|n| format!("adaptive_inverse.{n}"))
        .contains(&path.to_string())
    {
        return get("adaptive_inverse.copy_s").is_some_and(|c| c > 0.0);
    }
    let Some(name) = path.strip_prefix("building.") else {
        return true;
    };
    let (storeys, law) = (
        get("building.storeys").unwrap(),
        get("building.law").unwrap(),
    );
    let storey: Option<f64> = ["m", "k", "fy"]
        .iter()
        .find_map(|pre| name.strip_prefix(pre)?.parse().ok());
    match name {
        "storeys" | "law" => false,
        "alpha" => law != 0.0,
        _ if name.starts_with("bw_") => law == 2.0,
        _ if name.starts_with("fy") && law == 0.0 => false,
        _ => storey.is_none_or(|i| i <= storeys),
    }
}

/// Whether parameter `path` is a compensator's setting that changes some runs only: a cap, a
/// freeze time, the adaptive inverse's fit and its copy.
fn acts_in_some_runs(path: &str) -> bool {
    let fit = ["memory_s", "weight_hz", "copy_s"].map(|n| format!("adaptive_inverse.{n}"));
    path.ends_with(".authority") || path.ends_with(".freeze_s") || fit.contains(&path.to_string())
}

/// The effects' pin can fail: a 1 % change of any parameter of any effect the peer has (here,
/// the first set's each; a compensator's setting that acts in some runs only, in the first set
/// where it acts), or its force's or flow's sign flipped (the hold-down's k3 and the leakage's
/// c_int negated), moves some metric far beyond the tolerance.
#[test]
fn a_small_change_of_an_effect_is_caught() {
    let cases = effect_cases();
    let changed = small_changes_are_caught(&cases, &[("hold_down", 0), ("leakage", 0)]);
    assert!(changed >= 40, "{changed} parameters changed");
}

/// The expressions' pin can fail: a 1 % change of any named parameter, or the platen force's
/// quadratic damper (c2) and the flow across the piston (cl) negated, moves some metric far
/// beyond the tolerance.
#[test]
fn a_small_change_of_an_expression_is_caught() {
    let cases = effect_cases_in(&expressions_fixture());
    let flips = [("expression:force", 0), ("expression:flows", 0)];
    let changed = small_changes_are_caught(&cases, &flips);
    assert!(changed >= 30, "{changed} parameters changed");
}

/// A case with its `k`-th parameter times `factor`, against the case's own metrics.
fn moved(c: &EffectCase, k: usize, factor: f64) -> (f64, String) {
    let mut off = EffectCase {
        effect: c.effect.clone(),
        amp_g: c.amp_g,
        params: c.params.clone(),
        case: Case {
            amp_g: c.amp_g,
            gains: Vec::new(),
            metrics: c.case.metrics.clone(),
        },
    };
    off.params[k].1 *= factor;
    effect_deviation(c, &run_effect(&off))
}

/// Every parameter of every effect of `cases` times 1.01 in the first set where it acts, and
/// the `flips` (an effect, a parameter's index) negated in the effect's first set, each moves some
/// metric by over 100 times the tolerance; how many parameters were changed.
fn small_changes_are_caught(cases: &[EffectCase], flips: &[(&str, usize)]) -> usize {
    let mut effects: Vec<&str> = cases.iter().map(|c| c.effect.as_str()).collect();
    effects.dedup();
    let mut changed = 0;
    for effect in &effects {
        let sets: Vec<&EffectCase> = cases
            .iter()
            .filter(|c| c.effect == *effect && !c.params.is_empty())
            .collect();
        let Some(first) = sets.first() else {
            continue;
        };
        for (k, (path, _)) in first.params.iter().enumerate() {
            // The first set, where the parameter acts there (not zero, not inapplicable:
            // `applies`). A compensator's setting that acts in some runs only (a cap where it is
            // reached, a freeze, the inverse's fit where it is copied into the loop): the first
            // set where it acts, and some set must.
            let searched = if acts_in_some_runs(path) {
                sets.len()
            } else {
                1
            };
            let acting = sets[..searched].iter().filter(|c| {
                let v = c.params[k].1;
                v != 0.0 && applies(&c.params, path)
            });
            let mut tried = acting.map(|c| moved(c, k, 1.01));
            let Some(first) = tried.next() else {
                continue;
            };
            let (d, name) = std::iter::once(first.clone())
                .chain(tried)
                .find(|(d, _)| *d > 100.0 * TOLERANCE)
                .unwrap_or(first);
            assert!(
                d > 100.0 * TOLERANCE,
                "{path} x 1.01 moved {name} by only {d:e} in every set where it acts"
            );
            changed += 1;
        }
    }
    for &(effect, k) in flips {
        let c = cases.iter().find(|c| c.effect == effect).unwrap();
        let (d, name) = moved(c, k, -1.0);
        assert!(
            d > 100.0 * TOLERANCE,
            "{} negated moved {name} by only {d:e}",
            c.params[k].0
        );
    }
    changed
}
