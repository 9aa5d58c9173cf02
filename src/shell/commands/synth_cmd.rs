//! `study synth`: measurement files (docs/formats.md) made by the model, with hidden parameter changes
//! and seeded sensor noise, for testing comparisons and diagnoses on data whose truth is known.

use crate::kernel::excitation::Reference;
use crate::kernel::params::ModelParams;
use crate::kernel::resample::ch;
use crate::kernel::simulate::{LaneStatus, Solver};
use crate::orchestration::measured::campaign::TestSpec;
use crate::orchestration::runs::single;
use crate::orchestration::runs::spec::{ExcitationSpec, SimSpec};
use crate::shell::cli::SynthArgs;
use crate::shell::formats::campaign_io::{self, load_campaign, load_model, LoadedCampaign};
use crate::shell::formats::meta::{self, Key, Kind};
use crate::shell::formats::parquet_write;
use crate::shell::formats::parquet_write::Column;
use crate::shell::run_spec::load_reference;
use crate::shell::BadInput;
use crate::shell::RunFailed;
use anyhow::Context;
use chacha20::ChaCha8Rng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Channels that take sensor noise, and their column names.
const NOISY: [(&str, &str); 5] = [
    ("accel", "accel_mps2"),
    ("disp", "disp_m"),
    ("force", "force_n"),
    ("p1", "p1_pa"),
    ("p2", "p2_pa"),
];

/// Switches on the named effects.
pub(crate) fn apply_effects(model: &mut ModelParams, effects: &[String]) -> anyhow::Result<()> {
    use crate::shell::fit_problem::{check_effect, check_written};
    for e in effects {
        let id = check_effect(e, "--effect")?;
        check_written(id, model, false)?;
        *model.effects.get_mut(id) = true;
    }
    Ok(())
}

/// Parses `path=value` model settings into `model`.
pub(crate) fn apply_sets(model: &mut ModelParams, sets: &[String]) -> anyhow::Result<()> {
    for s in sets {
        let (path, value) = s
            .split_once('=')
            .ok_or_else(|| BadInput(format!("--set {s:?}: expected component.name=value")))?;
        let info = ModelParams::lookup(path.trim()).ok_or_else(|| {
            BadInput(format!(
                "--set {s:?}: unknown parameter `{}` (`study params` lists them)",
                path.trim()
            ))
        })?;
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|_| BadInput(format!("--set {s:?}: {value:?} is not a number")))?;
        info.set(model, v);
    }
    if let Err(list) = model.validate() {
        return Err(BadInput(format!(
            "--set: {}",
            list.iter()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join("; ")
        ))
        .into());
    }
    Ok(())
}

/// A channel's noise: a standard deviation in SI units, or a fraction of the channel's rms in
/// each test (`accel=1%`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Noise {
    Absolute(f64),
    OfRms(f64),
}

impl Noise {
    /// The standard deviation for a channel whose values are `v`.
    fn sd(self, v: &[f64]) -> f64 {
        match self {
            Noise::Absolute(s) => s,
            Noise::OfRms(k) => {
                k * (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
            }
        }
    }
}

/// Parses `--noise accel=0.05,disp=1e-5` (standard deviations in SI units) or `accel=1%` (of
/// each test's rms of the channel).
pub(crate) fn parse_noise(spec: Option<&str>) -> anyhow::Result<[Noise; 5]> {
    let mut out = [Noise::Absolute(0.0); 5];
    let Some(spec) = spec else { return Ok(out) };
    for item in spec.split(',').filter(|s| !s.trim().is_empty()) {
        let (k, v) = item
            .split_once('=')
            .ok_or_else(|| BadInput(format!("--noise {item:?}: expected channel=std")))?;
        let i = NOISY
            .iter()
            .position(|(n, _)| *n == k.trim())
            .ok_or_else(|| {
                BadInput(format!(
                    "--noise: unknown channel {:?}; expected {}",
                    k.trim(),
                    NOISY.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                ))
            })?;
        let (text, percent) = match v.trim().strip_suffix('%') {
            Some(t) => (t.trim(), true),
            None => (v.trim(), false),
        };
        let v: f64 = text
            .parse()
            .map_err(|_| BadInput(format!("--noise {item:?}: not a number")))?;
        if !(v >= 0.0 && v.is_finite()) {
            return Err(BadInput(format!(
                "--noise {item:?}: the standard deviation must be >= 0"
            ))
            .into());
        }
        out[i] = if percent {
            Noise::OfRms(v / 100.0)
        } else {
            Noise::Absolute(v)
        };
    }
    Ok(out)
}

/// Writes a measured-test table as CSV (shortest round-trip digits), Parquet or a MATLAB MAT-file
/// (v5, `.mat`), by extension.
pub fn write_measured(
    path: &Path,
    cols: &[(&str, Vec<f64>)],
    meta: &[(String, String)],
) -> anyhow::Result<()> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("parquet") || e.eq_ignore_ascii_case("pq"))
    {
        return parquet_write::write_table(
            path,
            cols.iter()
                .map(|(n, v)| (n.to_string(), Column::F64(v.clone())))
                .collect(),
            meta,
        );
    }
    let out = parquet_write::AtomicFile::new(path);
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mat"))
    {
        let vars: Vec<(&str, &[f64])> = cols.iter().map(|(n, v)| (*n, v.as_slice())).collect();
        std::fs::write(&out.tmp, crate::shell::formats::matlab::v5_bytes(&vars))
            .with_context(|| format!("cannot write {}", out.tmp.display()))?;
        out.commit()?;
        return Ok(());
    }
    let file = std::fs::File::create(&out.tmp)
        .with_context(|| format!("cannot create {}", out.tmp.display()))?;
    let mut w = csv::Writer::from_writer(file);
    w.write_record(cols.iter().map(|(n, _)| *n))?;
    for r in 0..cols[0].1.len() {
        // `{:?}` of an f64 is its shortest round-trip decimal form.
        w.write_record(cols.iter().map(|(_, v)| format!("{:?}", v[r])))?;
    }
    w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    out.commit()?;
    Ok(())
}

/// Substeps of a run sampled off the controller's ticks [chosen: the written "truth" is a finer
/// run than the default 8 the comparison uses, so a test of another rate also checks the
/// comparison's own integration].
const FINE_SUBSTEPS: usize = 64;

/// Named columns of a measured file.
type Columns = Vec<(&'static str, Vec<f64>)>;

/// The measured-file columns of one test at `rate` (Hz) after `pre_rows` rows at rest: the model
/// sampled at the file's times (at the ticks themselves when the rate is the controller's). The
/// reference column is `recorded` where given (a tracked record's own samples, at the file's
/// times), else x_r at the file's times.
fn sample_test(
    spec: &SimSpec,
    (reference, recorded): (&mut Reference, Option<&[f64]>),
    rate: f64,
    pre_rows: usize,
) -> anyhow::Result<Result<Columns, String>> {
    let f_s = spec.model.controller.f_s;
    let duration = reference.len() as f64 / f_s;
    let n = (duration * rate).round() as usize;
    let tau: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
    reference.hold_to((tau[n - 1] * f_s).floor() as usize + 2);
    let solver = if rate == f_s {
        spec.solver
    } else {
        Solver {
            substeps: FINE_SUBSTEPS,
        }
    };
    let (result, rs) = single::run_sampled(&spec.model, reference, &solver, &tau)?;
    if let LaneStatus::Failed { time_s, reason } = result.status {
        return Ok(Err(format!(
            "the model failed at t = {time_s:.4} s: {reason}"
        )));
    }
    // Rows at rest before the excitation: the model's state at its start.
    let with_rest = |c: usize| -> Vec<f64> {
        let v = rs.channel(c, 0);
        std::iter::repeat_n(v[0], pre_rows).chain(v).collect()
    };
    // What a data-acquisition system records: the reference the controller tracked, x_r; for a
    // tracked record, the record itself (x_r re-interpolated from the ticks would differ from it
    // by the cubic's error, which the derivatives' corner passes into a_r).
    let ref_disp: Vec<f64> = std::iter::repeat_n(reference.x[0], pre_rows)
        .chain(
            tau.iter()
                .enumerate()
                .map(|(i, &t)| match recorded.and_then(|r| r.get(i)) {
                    Some(&x) => x,
                    None => reference.at_time(&reference.x, t),
                }),
        )
        .collect();
    Ok(Ok(vec![
        (
            "time_s",
            (0..pre_rows + n).map(|i| i as f64 / rate).collect(),
        ),
        ("ref_disp_m", ref_disp),
        ("disp_m", with_rest(ch::DISP)),
        ("accel_mps2", with_rest(ch::ACCEL)),
        ("valve_cmd_v", with_rest(ch::VALVE_CMD)),
        ("force_n", with_rest(ch::FORCE)),
        ("p1_pa", with_rest(ch::P1)),
        ("p2_pa", with_rest(ch::P2)),
        ("spool_m", with_rest(ch::SPOOL)),
    ]))
}

pub fn run(args: &SynthArgs) -> anyhow::Result<()> {
    let mut model = load_model(args.model.as_deref())?;
    apply_effects(&mut model, &args.effect)?;
    apply_sets(&mut model, &args.set)?;
    let noise = parse_noise(args.noise.as_deref())?;
    let rate = args.rate.unwrap_or(model.controller.f_s);
    check_timing(rate, args.pre_trigger)?;
    let pre_rows = (args.pre_trigger * rate).round() as usize;
    let lc = load_campaign(&args.campaign, &model)?;
    if !args.force {
        refuse_overwrite(args, &lc)?;
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut stdout = std::io::stdout().lock();
    writeln!(
        stdout,
        "study synth {} -> {}",
        args.campaign.display(),
        args.out.display()
    )?;
    // Every test is run before any file is written: a test whose model fails leaves nothing
    // behind that looks like a campaign.
    let runs: Vec<SynthRun> = (lc.campaign.tests.iter().enumerate())
        .map(|(i, test)| synth_test(args, &lc, (i, test), &noise, (rate, pre_rows)))
        .collect::<anyhow::Result<_>>()?;
    let mut written: Vec<PathBuf> = Vec::new();
    let dst = args.out.join(lc.file.file_name().unwrap_or_default());
    let wrote = (|| -> anyhow::Result<usize> {
        for (test, run) in lc.campaign.tests.iter().zip(&runs) {
            write_test(args, &lc, test, run, &mut written)?;
            let (path, rows) = (args.out.join(&test.data), run.cols[0].1.len());
            writeln!(
                stdout,
                "  {:<24} {} ({rows} rows)",
                test.name,
                path.display()
            )?;
        }
        written.push(dst.clone());
        write_campaign(&lc, &dst, args.as_records)
    })();
    let records = wrote.inspect_err(|_| {
        // A write failed (a full disk): what this run wrote is removed.
        for f in &written {
            let _ = std::fs::remove_file(f);
        }
    })?;
    writeln!(stdout, "  campaign                 {}", dst.display())?;
    writeln!(
        stdout,
        "  ref_disp_m holds the reference the controller tracked (x_r), as a data-acquisition \
         system records it{}",
        if records > 0 {
            format!(
                "; the campaign reads it as the record of its {records} record test(s), \
                 signal = \"reference\""
            )
        } else {
            String::new()
        }
    )?;
    Ok(())
}

/// Every file synth would write in `--out` (the tests' data files, the records they read from
/// files of their own, the campaign): any that exists is refused, naming them, before anything
/// is written.
fn refuse_overwrite(args: &SynthArgs, lc: &LoadedCampaign) -> anyhow::Result<()> {
    let mut targets: Vec<PathBuf> = Vec::new();
    for t in &lc.campaign.tests {
        targets.push(args.out.join(&t.data));
        if let ExcitationSpec::Record { file, .. } = &t.excitation {
            targets.push(args.out.join(file));
        }
    }
    // The campaign itself, where synth writes it into its own folder, is left as it is unless a
    // test is made a record test.
    let dst = args.out.join(lc.file.file_name().unwrap_or_default());
    let itself = std::fs::canonicalize(&lc.file).ok() == std::fs::canonicalize(&dst).ok();
    let rewritten = (lc.campaign.tests.iter())
        .any(|t| read_as_record(&t.excitation, args.as_records).is_some());
    if !itself || rewritten {
        targets.push(dst);
    }
    targets.sort();
    targets.dedup();
    let existing: Vec<String> = (targets.iter())
        .filter(|p| std::fs::symlink_metadata(p).is_ok())
        .map(|p| p.display().to_string())
        .collect();
    if existing.is_empty() {
        return Ok(());
    }
    let shown = existing
        .iter()
        .take(5)
        .cloned()
        .collect::<Vec<_>>()
        .join(", ");
    let more = existing.len().saturating_sub(5);
    Err(BadInput(format!(
        "--out {}: {} file(s) synth would write exist already ({shown}{}); nothing was written: \
         choose another folder, or pass --force to replace them",
        args.out.display(),
        existing.len(),
        if more > 0 {
            format!(" and {more} more")
        } else {
            String::new()
        }
    ))
    .into())
}

/// The reference filter's corner of a test that the synthesised campaign reads as a record
/// test: a record test, and, `as_records`, every other test that is not a sine.
fn read_as_record(e: &ExcitationSpec, as_records: bool) -> Option<f64> {
    match e {
        ExcitationSpec::Record { f_ref_hz, .. } => Some(*f_ref_hz),
        ExcitationSpec::Stochastic { f_ref_hz, .. } if as_records => Some(*f_ref_hz),
        ExcitationSpec::Sweep { .. } | ExcitationSpec::Random { .. } if as_records => {
            Some(crate::orchestration::runs::quake_spec::F_REF_DEFAULT)
        }
        _ => None,
    }
}

/// Writes the campaign of the synthesised files to `dst`: a copy of the campaign, with each
/// record test's excitation made the record of its own file's `ref_disp_m` (the tracked
/// reference, `signal = "reference"`, docs/model.md §4), since that column now holds what the
/// controller tracked — and, `as_records`, every other test that is not a sine; returns how many
/// tests that changed.
fn write_campaign(lc: &LoadedCampaign, dst: &Path, as_records: bool) -> anyhow::Result<usize> {
    let records: Vec<(usize, f64)> = (lc.campaign.tests.iter().enumerate())
        .filter_map(|(i, t)| Some((i, read_as_record(&t.excitation, as_records)?)))
        .collect();
    if records.is_empty() {
        if std::fs::canonicalize(&lc.file).ok() != std::fs::canonicalize(dst).ok() {
            std::fs::copy(&lc.file, dst)
                .with_context(|| format!("copying {}", lc.file.display()))?;
        }
        return Ok(0);
    }
    let head = format!(
        "# Written by study synth from {}: the record tests' data files hold in `ref_disp_m` the\n\
         # reference the controller tracked (x_r), read as each test's record with\n\
         # signal = \"reference\" (docs/model.md §4).\n",
        lc.file.display()
    );
    campaign_io::rewrite_tests(&lc.file, dst, &head, &mut |i, t| {
        if let Some(&(_, f_ref_hz)) = records.iter().find(|r| r.0 == i) {
            let mut e = toml::Table::new();
            e.insert("kind".into(), "record".into());
            e.insert("signal".into(), "reference".into());
            e.insert("f_ref_hz".into(), f_ref_hz.into());
            t.insert("excitation".into(), e.into());
        }
        Ok(())
    })?;
    Ok(records.len())
}

/// `--rate` is a sample rate in (0, 1e6] Hz and `--pre-trigger` in [0, 3600] s.
fn check_timing(rate: f64, pre_trigger: f64) -> anyhow::Result<()> {
    if !(rate.is_finite() && rate > 0.0 && rate <= 1e6) {
        return Err(BadInput(format!(
            "--rate {rate}: must be a sample rate in (0, 1e6] Hz"
        ))
        .into());
    }
    if !(pre_trigger.is_finite() && (0.0..=3600.0).contains(&pre_trigger)) {
        return Err(BadInput(format!(
            "--pre-trigger {pre_trigger}: must be in [0, 3600] s"
        ))
        .into());
    }
    Ok(())
}

/// One test synthesised: its channels, noisy, and the metadata its file gets.
struct SynthRun {
    cols: Columns,
    meta: Vec<(String, String)>,
}

/// Runs test `i` of the campaign with the hidden changes and adds its noise (nothing written).
fn synth_test(
    args: &SynthArgs,
    lc: &LoadedCampaign,
    (i, test): (usize, &TestSpec),
    noise: &[Noise; 5],
    (rate, pre_rows): (f64, usize),
) -> anyhow::Result<SynthRun> {
    let mut test_model = test.model.clone();
    apply_effects(&mut test_model, &args.effect)?;
    apply_sets(&mut test_model, &args.set)?;
    let mut reference = load_reference(&test.excitation, &test_model, &lc.base, 0)?;
    let mut pre_rows = pre_rows;
    let mut recorded = None;
    if let Some(f_ref_hz) = read_as_record(&test.excitation, args.as_records) {
        // The campaign reads this test's x_r as the tracked reference: the truth tracks that
        // reference too, its derivatives the zero-phase filter's (docs/model.md §4).
        let record = single::tracked_record(&reference, rate, pre_rows, f_ref_hz);
        reference = record.reference(test_model.controller.f_s);
        recorded = Some(record.disp_m);
        pre_rows = 0;
    }
    let spec = SimSpec {
        model: test_model,
        excitation: test.excitation.clone(),
        solver: Default::default(),
        spectrum: crate::orchestration::runs::quake_spec::default_spectrum(),
    };
    let mut cols = sample_test(&spec, (&mut reference, recorded.as_deref()), rate, pre_rows)?
        .map_err(|e| RunFailed(format!("test {:?}: {e}", test.name)))?;
    add_noise(&mut cols, noise, args.seed, i);
    let mut meta = meta::header(Kind::SyntheticMeasurement);
    if !args.blind {
        meta.push(meta::pair(Key::Spec, spec.resolved_toml()));
    }
    meta.extend([
        meta::pair(Key::Noise, args.noise.clone().unwrap_or_default()),
        meta::pair(Key::Seed, args.seed),
    ]);
    Ok(SynthRun { cols, meta })
}

/// Writes a synthesised test's data file (and the record file it reads, copied along), each
/// path pushed to `written` before it is written.
fn write_test(
    args: &SynthArgs,
    lc: &LoadedCampaign,
    test: &TestSpec,
    run: &SynthRun,
    written: &mut Vec<PathBuf>,
) -> anyhow::Result<()> {
    let path = args.out.join(&test.data);
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    written.push(path.clone());
    write_measured(&path, &run.cols, &run.meta)?;
    // A record that lives in its own file is copied along, so the folder is a whole campaign.
    if let ExcitationSpec::Record { file, .. } = &test.excitation {
        if file != &test.data {
            let dst = args.out.join(file);
            if let Some(dir) = dst.parent() {
                std::fs::create_dir_all(dir)?;
            }
            written.push(dst.clone());
            std::fs::copy(lc.base.join(file), &dst)
                .with_context(|| format!("copying the record {}", file.display()))?;
        }
    }
    Ok(())
}

/// Seeded Gaussian sensor noise added to the `i`-th test's noisy channels: one stream per test
/// and channel.
fn add_noise(cols: &mut [(&str, Vec<f64>)], noise: &[Noise; 5], seed: u64, i: usize) {
    for (c, (_, col)) in NOISY.iter().enumerate() {
        let v = &mut cols
            .iter_mut()
            .find(|(n, _)| n == col)
            .expect("noisy column")
            .1;
        let sd = noise[c].sd(v);
        if sd > 0.0 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream((i * NOISY.len() + c) as u64);
            let dist = Normal::new(0.0, sd).expect("std >= 0");
            for x in v.iter_mut() {
                *x += dist.sample(&mut rng);
            }
        }
    }
}
