//! The library's front for programs that embed vshake (the Python package in `python/`): each
//! command as a function of values. Tables are written where the caller says, the report a
//! command prints is returned as text, and errors are the commands' own (file, key, row).

use crate::kernel::params::{ModelParams, ParamInfo};
use crate::orchestration::runs::single;
use crate::orchestration::runs::spec::SimSpec;
use crate::orchestration::study::batch::Plan;
use crate::orchestration::study::problem::StudySpec;
use crate::shell::cli::{CompareArgs, DiagnoseArgs, FitArgs, RunArgs};
use crate::shell::commands::run_cmd;
use crate::shell::gpu::Backend;
use crate::shell::job::study_job::{self, Job};
use crate::shell::BadInput;
use std::path::Path;

/// A study: a file, or TOML text whose relative paths (records, design files) start at `base`.
pub enum Study<'a> {
    File(&'a Path),
    Text { toml: &'a str, base: &'a Path },
}

impl Study<'_> {
    fn text(&self) -> anyhow::Result<String> {
        match self {
            Study::File(f) => crate::shell::formats::input::read_input_text(f)
                .map_err(|e| BadInput(format!("{}: cannot read: {e}", f.display())).into()),
            Study::Text { toml, .. } => Ok(toml.to_string()),
        }
    }

    fn base(&self) -> &Path {
        match self {
            Study::File(f) => f.parent().unwrap_or(Path::new(".")),
            Study::Text { base, .. } => base,
        }
    }

    /// How errors and the results' metadata name it.
    fn label(&self) -> String {
        match self {
            Study::File(f) => std::fs::canonicalize(f)
                .unwrap_or_else(|_| f.to_path_buf())
                .display()
                .to_string(),
            Study::Text { .. } => "(study text)".into(),
        }
    }
}

/// `study run`'s arguments for a run writing `out` with `threads` (0: every core), quietly.
fn run_args(model: Option<&Path>, out: &Path, threads: usize) -> RunArgs {
    RunArgs {
        file: None,
        resume: None,
        model: model.map(Path::to_path_buf),
        dry_run: false,
        yes: true,
        checkpoint_secs: 30.0,
        out: Some(out.to_path_buf()),
        threads,
        chunk: None,
        samples: None,
        quiet: true,
        log_progress: false,
        shard: None,
        backend: Backend::Auto,
    }
}

/// `study run`: the study's results table written to `out`; returns the printed summary.
pub fn run_study(
    study: Study,
    model: Option<&Path>,
    out: &Path,
    threads: usize,
) -> anyhow::Result<String> {
    let args = run_args(model, out, threads);
    let base_model = crate::shell::formats::campaign_io::load_model(model)?;
    let label = study.label();
    let spec = StudySpec::from_toml_on(&study.text()?, &label, base_model)?;
    let job = Job::of_spec(&args, spec, study.base(), &label)?;
    let mut text = Vec::new();
    run_cmd::execute(&args, job, &mut text, false)?;
    Ok(String::from_utf8_lossy(&text).into_owned())
}

/// Runs given parameter sets (`columns`: a name as `study params` or a results table names it,
/// and one value per set) against the study's excitations (its [[excitations]], [model.*],
/// [solver], [spectrum], [responses] metrics and fixed variables; its design is replaced by the
/// sets), writing a results table to `out` as `study run` does.
pub fn evaluate(
    study: Study,
    columns: &[(String, Vec<f64>)],
    metrics: Option<&[String]>,
    model: Option<&Path>,
    out: &Path,
    threads: usize,
) -> anyhow::Result<String> {
    let sets = columns.first().map_or(0, |c| c.1.len());
    if let Some((name, c)) = columns.iter().find(|c| c.1.len() != sets) {
        return Err(BadInput(format!(
            "parameter `{name}` has {} values; the first one has {sets}",
            c.len()
        ))
        .into());
    }
    if sets == 0 {
        return Err(
            BadInput("no parameter sets to evaluate (give at least one row)".into()).into(),
        );
    }
    let label = study.label();
    let text = design_replaced(&study.text()?, &label, sets, metrics)?;
    let spec = StudySpec::from_toml_on(
        &text,
        &label,
        crate::shell::formats::campaign_io::load_model(model)?,
    )?;
    let names: Vec<String> = columns.iter().map(|c| c.0.clone()).collect();
    let infos = study_job::parameters_of_columns(&names, "parameters")?;
    let wanted: Vec<String> = infos.iter().map(|i| i.path()).collect();
    let references = study_job::references(&spec, study.base(), &wanted)?;
    let rows: Vec<Vec<f64>> = (0..sets)
        .map(|r| columns.iter().map(|c| c.1[r]).collect())
        .collect();
    let plan = Plan::from_table(&spec, infos, rows, references);
    let args = run_args(model, out, threads);
    let job = Job::of_plan(&args, spec, plan, &label)?;
    let mut text = Vec::new();
    run_cmd::execute(&args, job, &mut text, false)?;
    Ok(String::from_utf8_lossy(&text).into_owned())
}

/// The study's TOML with its design replaced by `sets` rows given in memory.
fn design_replaced(
    text: &str,
    label: &str,
    sets: usize,
    metrics: Option<&[String]>,
) -> anyhow::Result<String> {
    let mut t: toml::Table = crate::orchestration::toml_fields::parse(text, label)?;
    fixed_into_model(&mut t);
    let mut method = toml::Table::new();
    method.insert("sampling".into(), "file".into());
    method.insert("file".into(), "(parameters in memory)".into());
    t.insert("method".into(), method.into());
    let study = t
        .entry("study")
        .or_insert_with(|| toml::Table::new().into());
    if let Some(s) = study.as_table_mut() {
        s.entry("name").or_insert_with(|| "evaluate".into());
        s.insert("samples".into(), (sets as i64).into());
    }
    if let Some(o) = t.get_mut("output").and_then(toml::Value::as_table_mut) {
        o.remove("histories");
        o.remove("file");
    }
    if let Some(m) = metrics {
        let r = t
            .entry("responses")
            .or_insert_with(|| toml::Table::new().into());
        if let Some(r) = r.as_table_mut() {
            let names: Vec<toml::Value> = m.iter().map(|s| s.as_str().into()).collect();
            r.insert("metrics".into(), names.into());
        }
    }
    Ok(toml::to_string(&t)?)
}

/// Removes a study's [[variables]]; its fixed ones become values of its model (`[model.*]`), as
/// every sample of `study run` has them.
fn fixed_into_model(t: &mut toml::Table) {
    let Some(toml::Value::Array(vars)) = t.remove("variables") else {
        return;
    };
    for v in vars.iter().filter_map(toml::Value::as_table) {
        let text = |k: &str| v.get(k).and_then(toml::Value::as_str);
        let (Some(name), Some("fixed"), Some(value)) =
            (text("name"), text("distribution"), v.get("value"))
        else {
            continue;
        };
        let Some((component, param)) = name.split_once('.') else {
            continue;
        };
        let model = t
            .entry("model")
            .or_insert_with(|| toml::Table::new().into());
        let part = model.as_table_mut().map(|m| {
            m.entry(component)
                .or_insert_with(|| toml::Table::new().into())
        });
        if let Some(p) = part.and_then(toml::Value::as_table_mut) {
            p.insert(param.into(), value.clone());
        }
    }
}

/// A run's outcome: its status in words and its metrics (name, value; NaN where not defined).
pub struct Simulated {
    pub status: String,
    pub metrics: Vec<(&'static str, f64)>,
}

/// `study sim` of a run file's text (relative record paths start at `base`) on `model`: the
/// time history of every channel written to `out`.
pub fn simulate(
    toml: &str,
    base: &Path,
    model: Option<&Path>,
    out: &Path,
) -> anyhow::Result<Simulated> {
    let spec = SimSpec::from_toml_on(
        toml,
        "(run text)",
        crate::shell::formats::campaign_io::load_model(model)?,
    )?;
    let reference = crate::shell::run_spec::build_reference(&spec, base)?;
    let outcome = single::run_sim(&spec, &reference)?;
    let status = crate::shell::commands::sim_cmd::status_text(&outcome.result.status);
    crate::shell::commands::sim_cmd::write_history(out, &spec, &outcome, &status)?;
    Ok(Simulated {
        status,
        metrics: outcome
            .result
            .metrics
            .columns_for(spec.model.effects.building),
    })
}

/// `study compare CAMPAIGN --report DIR`: returns the printed report.
pub fn compare(
    campaign: &Path,
    model: Option<&Path>,
    report: &Path,
    threads: usize,
) -> anyhow::Result<String> {
    let args = CompareArgs {
        campaign: campaign.to_path_buf(),
        model: model.map(Path::to_path_buf),
        report: Some(report.to_path_buf()),
        open_loop: None,
        strict: false,
        threads,
        log_progress: false,
    };
    captured(|o| crate::shell::commands::compare_cmd::run_to(&args, o))
}

/// `study diagnose CAMPAIGN --report DIR [--out MODEL]`: returns the printed report.
pub fn diagnose(
    campaign: &Path,
    model: Option<&Path>,
    candidates: &[String],
    report: &Path,
    out: Option<&Path>,
    threads: usize,
) -> anyhow::Result<String> {
    let args = DiagnoseArgs {
        campaign: campaign.to_path_buf(),
        model: model.map(Path::to_path_buf),
        candidates: candidates.to_vec(),
        report: Some(report.to_path_buf()),
        out: out.map(Path::to_path_buf),
        strict: false,
        threads,
        backend: Backend::Auto,
        log_progress: false,
    };
    captured(|o| crate::shell::commands::diagnose_cmd::run_to(&args, o))
}

/// `study fit CAMPAIGN --effect E --free P --out MODEL`: returns the printed report.
pub fn fit(
    campaign: &Path,
    effects: &[String],
    free: &[String],
    model: Option<&Path>,
    out: &Path,
    max_iter: usize,
    threads: usize,
) -> anyhow::Result<String> {
    let args = FitArgs {
        campaign: campaign.to_path_buf(),
        effect: effects.to_vec(),
        free: free.to_vec(),
        model: model.map(Path::to_path_buf),
        out: out.to_path_buf(),
        max_iter,
        strict: false,
        threads,
        backend: Backend::Auto,
        log_progress: false,
    };
    captured(|o| crate::shell::commands::fit_cmd::run_to(&args, o))
}

fn captured(
    f: impl FnOnce(&mut dyn std::io::Write) -> anyhow::Result<()>,
) -> anyhow::Result<String> {
    let mut text = Vec::new();
    f(&mut text)?;
    Ok(String::from_utf8_lossy(&text).into_owned())
}

/// Every parameter of the model and the effect library, as `study params` lists them.
pub fn parameters() -> Vec<&'static ParamInfo> {
    ModelParams::registry().collect()
}
