//! Campaign and measured-test files: loading, and the error behaviour of measured data (every
//! problem of every file of a campaign reported at once, exit code 2).

use crate::kernel::params::ModelParams;
use crate::orchestration::measured::aligned::{self, AlignedTest, OpenLoop, OPTIONAL, REQUIRED};
use crate::orchestration::measured::campaign::{self, Campaign, TestSpec};
use crate::orchestration::runs::spec::ExcitationSpec;
use crate::shell::formats::measured_files;
use crate::shell::formats::measured_files::NumTable;
use crate::shell::BadInput;
use std::path::{Path, PathBuf};

/// A campaign with the folder its paths are relative to.
pub struct LoadedCampaign {
    pub file: PathBuf,
    pub base: PathBuf,
    pub campaign: Campaign,
}

/// Reads a model file given with `--model` (`[model.<component>]` tables).
pub(crate) fn load_model(path: Option<&Path>) -> anyhow::Result<ModelParams> {
    match path {
        None => Ok(ModelParams::default()),
        Some(p) => {
            let text = crate::shell::formats::input::read_input_text(p)
                .map_err(|e| BadInput(format!("{}: cannot read: {e}", p.display())))?;
            Ok(campaign::model_from_toml(&text, &p.display().to_string())?)
        }
    }
}

pub fn load_campaign(file: &Path, model: &ModelParams) -> anyhow::Result<LoadedCampaign> {
    let text = crate::shell::formats::input::read_input_text(file)
        .map_err(|e| BadInput(format!("{}: cannot read: {e}", file.display())))?;
    let campaign = Campaign::from_toml(&text, &file.display().to_string(), model)?;
    Ok(LoadedCampaign {
        file: file.to_path_buf(),
        base: file.parent().unwrap_or(Path::new(".")).to_path_buf(),
        campaign,
    })
}

/// Reads a measured test: the required columns and the optional ones present, every cell a
/// finite number within physical range ([`NumTable::check_limits`]). Every bad cell and every
/// value out of range comes back at once.
/// `map` is the test's `columns` table.
pub fn read_measured(
    path: &Path,
    map: &[(String, crate::orchestration::measured::campaign::Mapped)],
) -> Result<NumTable, Vec<String>> {
    match measured_files::read_columns_lenient(path, &REQUIRED, &OPTIONAL, map) {
        Ok((table, bad)) if bad.is_empty() => Ok(table),
        Ok((table, bad)) => Err(bad
            .iter()
            .map(|e| e.to_string())
            .chain(table.check_limits().iter().map(|p| p.to_string()))
            .collect()),
        Err(e) => Err(e.each()),
    }
}

/// Reads one test's files and aligns it; its problems as lines.
fn load_test(
    lc: &LoadedCampaign,
    test: &TestSpec,
    open_loop: Option<OpenLoop>,
) -> anyhow::Result<Result<AlignedTest, Vec<String>>> {
    let path = lc.base.join(&test.data);
    if !path.is_file() {
        let what = match crate::shell::formats::input::not_regular(&path) {
            Some(kind) => format!("is {kind}, not a data file"),
            None => match std::fs::metadata(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => format!("cannot read: {e}"),
                _ => "not found".into(),
            },
        };
        return Ok(Err(vec![format!(
            "{}: {what} (the data of test `{}` in {})",
            path.display(),
            test.name,
            lc.file.display()
        )]));
    }
    let data = match read_measured(&path, &test.columns) {
        Ok(t) => t,
        Err(problems) => return Ok(Err(problems)),
    };
    // A record in another file than the test's data.
    let record = match &test.excitation {
        ExcitationSpec::Record {
            file,
            column,
            time_column,
            ..
        } if file != &test.data => {
            match measured_files::read_record(&lc.base.join(file), column, time_column) {
                Ok(t) => Some(t),
                Err(e) if e.is_input() => return Ok(Err(e.each())),
                Err(e) => return Err(e.into()),
            }
        }
        _ => None,
    };
    Ok(aligned::align(test, &data, record.as_ref(), open_loop)
        .map_err(|ps| ps.iter().map(|p| p.to_string()).collect()))
}

/// Reads and aligns every test of a campaign. Every problem of every file is reported at once
/// (exit code 2), a missing file once.
pub fn load_tests(
    lc: &LoadedCampaign,
    open_loop: Option<OpenLoop>,
) -> anyhow::Result<Vec<AlignedTest>> {
    let mut tests = Vec::new();
    let mut problems: Vec<String> = Vec::new();
    for test in &lc.campaign.tests {
        match load_test(lc, test, open_loop)? {
            Ok(t) => tests.push(t),
            Err(ps) => problems.extend(ps),
        }
    }
    if !problems.is_empty() {
        return Err(BadInput(problem_list(&lc.file, "measured data", &problems)).into());
    }
    Ok(tests)
}

/// One problem as is; several as a counted list under the campaign's name.
fn problem_list(campaign: &Path, what: &str, problems: &[String]) -> String {
    if problems.len() == 1 {
        return problems[0].clone();
    }
    format!(
        "{} problems in the {what} of {}:\n  - {}",
        problems.len(),
        campaign.display(),
        problems.join("\n  - ")
    )
}

/// The notes and warnings of aligned tests, printed as two blocks; under `strict`, warnings are
/// an error (exit code 2) instead.
pub(crate) fn report_checks(
    out: &mut dyn std::io::Write,
    campaign: &Path,
    tests: &[AlignedTest],
    extra_warnings: &[String],
    strict: bool,
) -> anyhow::Result<()> {
    let notes: Vec<String> = tests
        .iter()
        .flat_map(|t| t.notes.iter().map(move |n| format!("{}: {n}", t.name)))
        .collect();
    let warnings: Vec<String> = tests
        .iter()
        .flat_map(|t| t.warnings.iter().cloned())
        .chain(extra_warnings.iter().cloned())
        .collect();
    if strict && !warnings.is_empty() {
        return Err(BadInput(format!(
            "{} (--strict)",
            problem_list(campaign, "measured data", &warnings)
        ))
        .into());
    }
    if !notes.is_empty() {
        writeln!(out, "\n  notes on the data files:")?;
        for n in &notes {
            writeln!(out, "    {n}")?;
        }
    }
    if !warnings.is_empty() {
        writeln!(
            out,
            "\n  WARNINGS (results above may be wrong science; --strict makes these errors):"
        )?;
        for w in &warnings {
            writeln!(out, "    {w}")?;
        }
    }
    Ok(())
}

/// Writes to `dst` (atomically: nothing half-written is left under its name) the campaign file
/// `src` with `edit` applied to each of its `[[test]]` tables (the test's index, its table), under
/// the comment lines `head` (each starting with `#`, ending with a newline).
pub(crate) fn rewrite_tests(
    src: &Path,
    dst: &Path,
    head: &str,
    edit: &mut dyn FnMut(usize, &mut toml::Table) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    use anyhow::Context;
    let text =
        std::fs::read_to_string(src).with_context(|| format!("reading {}", src.display()))?;
    let mut table: toml::Table = text.parse().context("the campaign was read before")?;
    let tests = (table.get_mut("test"))
        .and_then(toml::Value::as_array_mut)
        .context("the campaign's tests")?;
    for (i, test) in tests.iter_mut().enumerate() {
        if let Some(test) = test.as_table_mut() {
            edit(i, test)?;
        }
    }
    let file = crate::shell::formats::parquet_write::AtomicFile::new(dst);
    std::fs::write(&file.tmp, format!("{head}{table}"))
        .with_context(|| format!("writing {}", file.tmp.display()))?;
    Ok(file.commit()?)
}
