//! Campaigns (docs/formats.md): a TOML file listing measured tests and how each was driven.
//!
//! ```toml
//! [campaign]
//! name = "bare_table_2026_03"
//! description = "bare-table sine tests"
//!
//! [[test]]
//! name = "sine_3hz_1p73g"
//! data = "sine_3hz_1p73g.csv"          # relative to the campaign file; CSV or Parquet
//! excitation = { kind = "sine", freq_hz = 3.0, amp_g = 1.73, taper_s = 1.0 }
//! model = { platen = { m = 150000.0 } } # optional per-test model overrides
//! weights = { accel = 1.0, disp = 0.0 } # optional channel weights (accel, disp, force)
//! t0_s = 0.5                            # optional: where the excitation starts, in the file's time
//! ```
//!
//! A sine test's reference states are analytic (docs/model.md §4); a record test's come from the named
//! column of its data file. Where the excitation starts in the file is found from `ref_disp_m`
//! (a sine) or is the first row (a record), unless `t0_s` says; a sine lasts until `ref_disp_m`
//! leaves it, or `duration_s` when given ([`crate::measured::aligned`]).

use crate::runs::spec::{self, ExcitationSpec};
use crate::toml_fields::{Fields, InputError, Issues};
use std::path::PathBuf;
use vshake_kernel::channels;
use vshake_kernel::params::{EffectId, ModelParams};

/// A column named in a campaign's `columns` table: its header (or 1-based position) and unit.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mapped {
    pub name: Option<String>,
    pub index: Option<usize>,
    pub unit: Option<String>,
}

/// The keys of `[campaign]`, of each `[[test]]` and of a test's `weights`; docs/formats.md
/// describes each (a test checks it).
pub const CAMPAIGN_KEYS: [&str; 3] = ["name", "description", "columns"];
pub const TEST_KEYS: [&str; 7] = [
    "name",
    "data",
    "excitation",
    "model",
    "weights",
    "t0_s",
    "columns",
];
/// The keys of an entry of a `columns` table.
pub const COLUMN_KEYS: [&str; 3] = ["name", "column", "unit"];
pub const WEIGHT_KEYS: [&str; 3] = ["accel", "disp", "force"];

/// Channel weights of a test (used by fits; 1 by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    pub accel: f64,
    pub disp: f64,
    pub force: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Weights {
            accel: 1.0,
            disp: 1.0,
            force: 1.0,
        }
    }
}

/// One measured test of a campaign.
#[derive(Debug, Clone)]
pub struct TestSpec {
    pub name: String,
    /// Data file, relative to the campaign file.
    pub data: PathBuf,
    pub excitation: ExcitationSpec,
    /// The campaign's model with this test's overrides.
    pub model: ModelParams,
    /// The effects this test's model table switches off (`enabled = false`): a fit that adds
    /// one to the campaign leaves it off here.
    pub off: Vec<EffectId>,
    pub weights: Weights,
    /// Whether the excitation table set `window_cycles` (else the window follows the file's
    /// length) and `duration_s` (else the file's length is the duration).
    pub window_given: bool,
    pub duration_given: bool,
    /// Where the excitation starts, in the file's time (`t0_s`), s; found from the data if None.
    pub t0_s: Option<f64>,
    /// The file's columns of channels vshake does not recognise by name: the campaign's
    /// `columns` table with the test's own entries over it (channel key → header or position,
    /// and unit).
    pub columns: Vec<(String, Mapped)>,
}

/// A parsed campaign.
#[derive(Debug, Clone)]
pub struct Campaign {
    pub name: String,
    pub description: String,
    pub tests: Vec<TestSpec>,
}

impl Campaign {
    /// Parses a campaign; `base_model` is the model the tests start from (defaults, or a model
    /// file given with `--model`).
    pub fn from_toml(
        text: &str,
        file: &str,
        base_model: &ModelParams,
    ) -> Result<Campaign, InputError> {
        let table = crate::toml_fields::parse(text, file)?;
        let mut issues = Issues::default();
        let mut root = Fields::new("", &table);
        let (name, description, columns) = read_header(&mut root, &mut issues);
        let mut tests = Vec::new();
        match root.tables("test", &mut issues) {
            Some(list) if list.is_empty() => issues.push("test", "the campaign lists no test"),
            Some(list) => {
                for t in list {
                    if let Some(test) = read_test(t, (base_model, &columns), &mut issues) {
                        if tests.iter().any(|x: &TestSpec| x.name == test.name) {
                            issues.push("test", format!("test name {:?} is used twice", test.name));
                        }
                        tests.push(test);
                    }
                }
            }
            None => issues.push("test", "missing ([[test]] entries)"),
        }
        root.finish(&["campaign", "test"], &mut issues);
        issues.into_result(file)?;
        Ok(Campaign {
            name,
            description,
            tests,
        })
    }
}

/// `[campaign]`: its name (required), description and `columns` table.
fn read_header(
    root: &mut Fields<'_>,
    issues: &mut Issues,
) -> (String, String, Vec<(String, Mapped)>) {
    let (mut name, mut description, mut columns) = (String::new(), String::new(), Vec::new());
    match root.table("campaign", issues) {
        Some(mut c) => {
            name = c.str("name", issues).unwrap_or("").to_string();
            description = c.str("description", issues).unwrap_or("").to_string();
            columns = read_columns(&mut c, &[], issues);
            if name.is_empty() {
                issues.push("campaign.name", "missing");
            }
            c.finish(&CAMPAIGN_KEYS, issues);
        }
        None => issues.push("campaign", "missing table ([campaign] name = ...)"),
    }
    (name, description, columns)
}

/// A `columns` table (`accel = "A1 Table X"`, or `accel = { name = "A1 Table X", unit = "g" }`,
/// or `{ column = 4, unit = "g" }` by 1-based position for a file without a header) over the
/// entries `base` (the campaign's), each key a channel, each unit one vshake knows.
fn read_columns(
    t: &mut Fields<'_>,
    base: &[(String, Mapped)],
    issues: &mut Issues,
) -> Vec<(String, Mapped)> {
    let mut out = base.to_vec();
    let Some(mut c) = t.table("columns", issues) else {
        return out;
    };
    let keys: Vec<String> = c.keys().cloned().collect();
    let channels: Vec<&str> = channels::CHANNELS.iter().map(|ch| ch.1).collect();
    for key in keys {
        if channels::channel(&key).is_none() {
            continue; // reported by finish below
        }
        let Some(m) = read_mapped(&mut c, &key, issues) else {
            continue;
        };
        let key = channels::channel(&key).map_or(key, |ch| ch.1.to_string());
        out.retain(|(k, _)| *k != key);
        out.push((key, m));
    }
    c.finish(&channels, issues);
    out
}

/// One entry of a `columns` table (see [`read_columns`]).
fn read_mapped(c: &mut Fields<'_>, key: &str, issues: &mut Issues) -> Option<Mapped> {
    let path = c.path_of(key);
    let mut m = Mapped::default();
    match c.value(key)? {
        toml::Value::String(name) => m.name = Some(name.clone()),
        toml::Value::Table(t) => {
            let mut f = Fields::new(path.clone(), t);
            m.name = f.str("name", issues).map(str::to_string);
            m.index = match f.int("column", issues) {
                Some(k) if k >= 1 => Some(k as usize),
                Some(k) => {
                    issues.push(f.path_of("column"), format!("{k}: columns count from 1"));
                    None
                }
                None => None,
            };
            m.unit = f.str("unit", issues).map(str::to_string);
            f.finish(&COLUMN_KEYS, issues);
        }
        other => {
            let found = other.type_str();
            issues.push(path, format!("expected the column's header or a table {{ name = \"...\", unit = \"...\" }}, found {found}"));
            return None;
        }
    }
    if let Some(u) = m.unit.as_deref().filter(|u| channels::unit(u).is_none()) {
        issues.push(
            format!("{path}.unit"),
            format!("unknown unit {u:?}; vshake knows {}", channels::unit_list()),
        );
    }
    if m.name.is_some() == m.index.is_some() {
        issues.push(
            path,
            "give the column's header (`name`) or its 1-based position (`column`), one of them",
        );
        return None;
    }
    Some(m)
}

/// One `[[test]]`: its name, data file, model (the base one with the test's overrides), weights,
/// start and excitation; None where one of name, data or excitation is missing or wrong.
fn read_test(
    mut t: Fields<'_>,
    (base_model, base_columns): (&ModelParams, &[(String, Mapped)]),
    issues: &mut Issues,
) -> Option<TestSpec> {
    let tname = t.str("name", issues).map(str::to_string);
    let data = t.str("data", issues).map(PathBuf::from);
    if tname.is_none() {
        issues.push(t.path_of("name"), "missing");
    }
    if data.is_none() {
        issues.push(
            t.path_of("data"),
            "missing (the CSV or Parquet file of the test)",
        );
    }
    let mut model = base_model.clone();
    let mut off = Vec::new();
    if let Some(m) = t.table("model", issues) {
        off = spec::read_model(m, &mut model, issues);
        spec::validate_model(&model, &t.path_of("model"), issues);
    }
    let weights = read_weights(&mut t, issues);
    let columns = read_columns(&mut t, base_columns, issues);
    let t0_s = t.f64("t0_s", issues);
    let (mut window_given, mut duration_given) = (false, false);
    let excitation = match t.table("excitation", issues) {
        Some(e) => {
            window_given = e.has("window_cycles");
            duration_given = e.has("duration_s");
            spec::read_excitation_in(e, &model, issues, &[], data.as_deref())
        }
        None => {
            issues.push(
                t.path_of("excitation"),
                "missing (an inline table: { kind = \"sine\", freq_hz = ..., amp_g = ... })",
            );
            None
        }
    };
    t.finish(&TEST_KEYS, issues);
    let (Some(name), Some(data), Some(excitation)) = (tname, data, excitation) else {
        return None;
    };
    Some(TestSpec {
        name,
        data,
        excitation,
        model,
        off,
        weights,
        window_given,
        duration_given,
        t0_s,
        columns,
    })
}

/// A test's `weights` table (accel, disp, force; none negative), else the default weights.
fn read_weights(t: &mut Fields<'_>, issues: &mut Issues) -> Weights {
    let mut weights = Weights::default();
    if let Some(mut w) = t.table("weights", issues) {
        for (key, slot) in [
            ("accel", &mut weights.accel),
            ("disp", &mut weights.disp),
            ("force", &mut weights.force),
        ] {
            if let Some(v) = w.f64(key, issues) {
                if v < 0.0 {
                    issues.push(w.path_of(key), format!("{v} must not be negative"));
                }
                *slot = v;
            }
        }
        w.finish(&WEIGHT_KEYS, issues);
    }
    weights
}

/// Reads a model file: `[model.<component>]` tables as in run files (other tables are refused).
pub fn model_from_toml(text: &str, file: &str) -> Result<ModelParams, InputError> {
    let table = crate::toml_fields::parse(text, file)?;
    let mut issues = Issues::default();
    let mut root = Fields::new("", &table);
    let mut model = ModelParams::default();
    match root.table("model", &mut issues) {
        Some(m) => {
            spec::read_model(m, &mut model, &mut issues);
        }
        None => issues.push("model", "missing ([model.<component>] tables)"),
    }
    root.finish(&["model"], &mut issues);
    spec::validate_model(&model, "model", &mut issues);
    issues.into_result(file)?;
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The campaign example of docs/formats.md, read from the page itself (the first `toml`
    /// block under "## Campaigns"), so that the page and this test cannot drift apart.
    fn formats_example() -> String {
        let page = include_str!("../../../../docs/formats.md");
        let section = &page[page
            .find("\n## Campaigns")
            .expect("docs/formats.md: ## Campaigns")..];
        let block = &section[section.find("```toml\n").expect("a toml block") + 8..];
        block[..block.find("```").expect("the block's end")].to_string()
    }

    #[test]
    fn reads_the_formats_md_example() {
        let c = Campaign::from_toml(&formats_example(), "c.toml", &ModelParams::default()).unwrap();
        assert_eq!(c.name, "bare_table_2026_03");
        let names: Vec<&str> = c.tests.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "sine_3hz_1p73g",
                "sine_3hz_3p20g_pretrigger",
                "el_centro_50pct"
            ]
        );
        assert_eq!(c.tests[0].model.platen.m, 144000.0);
        assert_eq!(c.tests[0].t0_s, None);
        let pretrigger = &c.tests[1];
        assert_eq!(pretrigger.model.platen.m, 150000.0);
        assert_eq!(pretrigger.t0_s, Some(0.5));
        assert_eq!(pretrigger.weights.force, 0.0);
        assert_eq!(pretrigger.weights.accel, 1.0);
        assert!(pretrigger.window_given);
        assert_eq!(pretrigger.data, PathBuf::from("sine_3hz_3p20g.csv"));
    }

    #[test]
    fn record_tests_default_to_their_own_data_file() {
        let c = Campaign::from_toml(&formats_example(), "c.toml", &ModelParams::default()).unwrap();
        match &c.tests[2].excitation {
            ExcitationSpec::Record { file, column, .. } => {
                assert_eq!(file, &PathBuf::from("elcentro50.parquet"));
                assert_eq!(column, "ref_disp_m");
            }
            other => panic!("{other:?}"),
        }
    }
}
