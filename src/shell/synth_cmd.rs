//! `study synth`: measurement files (FORMATS.md) made by the model, with hidden parameter changes
//! and seeded sensor noise, for testing comparisons and diagnoses on data whose truth is known.

use super::campaign_io::{load_campaign, load_model};
use super::cli::SynthArgs;
use super::sim_cmd::reference_for;
use super::tables::{self, Column};
use super::{BadInput, RunFailed};
use crate::kernel::params::ModelParams;
use crate::kernel::simulate::LaneStatus;
use crate::orchestration::sim;
use crate::orchestration::spec::{ExcitationSpec, SimSpec};
use anyhow::Context;
use chacha20::ChaCha8Rng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::io::Write;
use std::path::Path;

/// Channels that take sensor noise, and their column names.
const NOISY: [(&str, &str); 5] = [("accel", "accel_mps2"), ("disp", "disp_m"), ("force", "force_n"), ("p1", "p1_pa"), ("p2", "p2_pa")];

/// Switches on the named effects.
pub fn apply_effects(model: &mut ModelParams, effects: &[String]) -> anyhow::Result<()> {
    for e in effects {
        let switch = model.effects.get_mut(e.trim()).ok_or_else(|| {
            BadInput(format!("--effect {e:?}: unknown effect; the library has {}", crate::kernel::params::EFFECTS.join(", ")))
        })?;
        *switch = true;
    }
    Ok(())
}

/// Parses `path=value` model settings into `model`.
pub fn apply_sets(model: &mut ModelParams, sets: &[String]) -> anyhow::Result<()> {
    for s in sets {
        let (path, value) = s.split_once('=').ok_or_else(|| BadInput(format!("--set {s:?}: expected component.name=value")))?;
        let info = ModelParams::lookup(path.trim()).ok_or_else(|| BadInput(format!("--set {s:?}: unknown parameter `{}` (`study params` lists them)", path.trim())))?;
        let v: f64 = value.trim().parse().map_err(|_| BadInput(format!("--set {s:?}: {value:?} is not a number")))?;
        (info.set)(model, v);
    }
    if let Err(list) = model.validate() {
        return Err(BadInput(format!("--set: {}", list.iter().map(|i| i.to_string()).collect::<Vec<_>>().join("; "))).into());
    }
    Ok(())
}

/// Parses `--noise accel=0.05,disp=1e-5` (standard deviations in SI units).
pub fn parse_noise(spec: Option<&str>) -> anyhow::Result<[f64; 5]> {
    let mut out = [0.0; 5];
    let Some(spec) = spec else { return Ok(out) };
    for item in spec.split(',').filter(|s| !s.trim().is_empty()) {
        let (k, v) = item.split_once('=').ok_or_else(|| BadInput(format!("--noise {item:?}: expected channel=std")))?;
        let i = NOISY.iter().position(|(n, _)| *n == k.trim()).ok_or_else(|| {
            BadInput(format!("--noise: unknown channel {:?}; expected {}", k.trim(), NOISY.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")))
        })?;
        let v: f64 = v.trim().parse().map_err(|_| BadInput(format!("--noise {item:?}: not a number")))?;
        if !(v >= 0.0 && v.is_finite()) {
            return Err(BadInput(format!("--noise {item:?}: the standard deviation must be >= 0")).into());
        }
        out[i] = v;
    }
    Ok(out)
}

/// Writes a measured-test table as CSV (shortest round-trip digits) or Parquet, by extension.
pub fn write_measured(path: &Path, cols: &[(&str, Vec<f64>)], meta: &[(String, String)]) -> anyhow::Result<()> {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("parquet") || e.eq_ignore_ascii_case("pq")) {
        return tables::write_table(path, cols.iter().map(|(n, v)| (n.to_string(), Column::F64(v.clone()))).collect(), meta);
    }
    let out = tables::AtomicFile::new(path);
    let mut w = std::io::BufWriter::new(std::fs::File::create(&out.tmp).with_context(|| format!("cannot create {}", out.tmp.display()))?);
    writeln!(w, "{}", cols.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(","))?;
    for r in 0..cols[0].1.len() {
        let line: Vec<String> = cols.iter().map(|(_, v)| format!("{:?}", v[r])).collect();
        writeln!(w, "{}", line.join(","))?;
    }
    w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    out.commit()?;
    Ok(())
}

pub fn run(args: &SynthArgs) -> anyhow::Result<()> {
    let mut model = load_model(args.model.as_deref())?;
    apply_effects(&mut model, &args.effect)?;
    apply_sets(&mut model, &args.set)?;
    let noise = parse_noise(args.noise.as_deref())?;
    let lc = load_campaign(&args.campaign, &model)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "study synth {} -> {}", args.campaign.display(), args.out.display())?;
    for (i, test) in lc.campaign.tests.iter().enumerate() {
        let mut test_model = test.model.clone();
        apply_effects(&mut test_model, &args.effect)?;
        apply_sets(&mut test_model, &args.set)?;
        let reference = reference_for(&test.excitation, &test_model, &lc.base)?;
        let spec = SimSpec { model: test_model, excitation: test.excitation.clone(), solver: Default::default() };
        let outcome = sim::run_sim(&spec, &reference)?;
        if let LaneStatus::Failed { time_s, reason } = outcome.result.status {
            return Err(RunFailed(format!("test {:?}: the model failed at t = {time_s:.4} s: {reason}", test.name)).into());
        }
        let h = &outcome.history;
        let ch = |n: &str| h.channel(n).expect("channel").to_vec();
        let mut cols: Vec<(&str, Vec<f64>)> = vec![
            ("time_s", ch("time_s")),
            ("ref_disp_m", reference.command.clone()),
            ("disp_m", ch("disp_m")),
            ("accel_mps2", ch("accel_mps2")),
            ("valve_cmd_v", ch("valve_cmd_v")),
            ("force_n", ch("force_n")),
            ("p1_pa", ch("p1_pa")),
            ("p2_pa", ch("p2_pa")),
            ("spool_m", ch("spool_m")),
        ];
        for (c, (_, col)) in NOISY.iter().enumerate() {
            if noise[c] > 0.0 {
                let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
                rng.set_stream((i * NOISY.len() + c) as u64);
                let dist = Normal::new(0.0, noise[c]).expect("std >= 0");
                let v = &mut cols.iter_mut().find(|(n, _)| n == col).expect("noisy column").1;
                for x in v.iter_mut() {
                    *x += dist.sample(&mut rng);
                }
            }
        }
        let path = args.out.join(&test.data);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let mut meta = vec![
            ("vshake.kind".to_string(), "synthetic_measurement".to_string()),
            ("vshake.spec".to_string(), spec.resolved_toml()),
            ("vshake.noise".to_string(), args.noise.clone().unwrap_or_default()),
            ("vshake.seed".to_string(), args.seed.to_string()),
            ("vshake.version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
        ];
        if args.blind {
            meta.retain(|(k, _)| k != "vshake.spec");
        }
        write_measured(&path, &cols, &meta)?;
        // A record that lives in its own file is copied along, so the folder is a whole campaign.
        if let ExcitationSpec::Record { file, .. } = &test.excitation {
            if file != &test.data {
                let dst = args.out.join(file);
                if let Some(dir) = dst.parent() {
                    std::fs::create_dir_all(dir)?;
                }
                std::fs::copy(lc.base.join(file), &dst).with_context(|| format!("copying the record {}", file.display()))?;
            }
        }
        writeln!(stdout, "  {:<24} {} ({} rows)", test.name, path.display(), h.len())?;
    }
    let dst = args.out.join(lc.file.file_name().unwrap_or_default());
    if std::fs::canonicalize(&lc.file).ok() != std::fs::canonicalize(&dst).ok() {
        std::fs::copy(&lc.file, &dst).with_context(|| format!("copying {}", lc.file.display()))?;
    }
    writeln!(stdout, "  campaign                 {}", dst.display())?;
    Ok(())
}
