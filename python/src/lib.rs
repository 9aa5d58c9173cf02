//! `vshake._native`: the pyo3 layer under the `vshake` Python package (python/vshake). Each
//! function is a `vshake::shell::api` call with the GIL released; errors become `VshakeError`
//! (`InputError` for bad input: the file, key or row is in the message, as the command line says).

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use std::path::{Path, PathBuf};
use vshake::shell::api::{self, Study};

create_exception!(
    vshake,
    VshakeError,
    PyException,
    "A vshake error: a run that failed, or the system (exit code 1 of `study`)."
);
create_exception!(
    vshake,
    InputError,
    VshakeError,
    "Bad input: the message names the file, key, column or row (exit code 2 of `study`)."
);

fn py_err(e: anyhow::Error) -> PyErr {
    let message = format!("{e:#}");
    if vshake::shell::exit_code(&e) == 2 {
        InputError::new_err(message)
    } else {
        VshakeError::new_err(message)
    }
}

/// The study a call names: a file, or TOML text whose relative paths start at `base`.
fn study<'a>(
    path: &'a Option<PathBuf>,
    toml: &'a Option<String>,
    base: &'a Path,
) -> PyResult<Study<'a>> {
    match (path, toml) {
        (Some(p), None) => Ok(Study::File(p)),
        (None, Some(t)) => Ok(Study::Text { toml: t, base }),
        _ => Err(InputError::new_err(
            "give a study file or the study's TOML text, one of them",
        )),
    }
}

/// `study run`: the results table written to `out`; returns the printed summary.
#[pyfunction]
#[pyo3(signature = (out, path=None, toml=None, base=PathBuf::from("."), model=None, threads=0))]
fn run_study(
    py: Python<'_>,
    out: PathBuf,
    path: Option<PathBuf>,
    toml: Option<String>,
    base: PathBuf,
    model: Option<PathBuf>,
    threads: usize,
) -> PyResult<String> {
    let s = study(&path, &toml, &base)?;
    py.detach(|| api::run_study(s, model.as_deref(), &out, threads))
        .map_err(py_err)
}

/// Parameter sets (name, values) against a study's excitations: a results table written to `out`.
#[pyfunction]
#[pyo3(signature = (out, columns, path=None, toml=None, base=PathBuf::from("."), metrics=None, model=None, threads=0))]
#[allow(clippy::too_many_arguments)]
fn evaluate(
    py: Python<'_>,
    out: PathBuf,
    columns: Vec<(String, Vec<f64>)>,
    path: Option<PathBuf>,
    toml: Option<String>,
    base: PathBuf,
    metrics: Option<Vec<String>>,
    model: Option<PathBuf>,
    threads: usize,
) -> PyResult<String> {
    let s = study(&path, &toml, &base)?;
    py.detach(|| {
        api::evaluate(
            s,
            &columns,
            metrics.as_deref(),
            model.as_deref(),
            &out,
            threads,
        )
    })
    .map_err(py_err)
}

/// `study sim` of a run's TOML text: the time history written to `out`; returns the status and
/// the metrics.
#[pyfunction]
#[pyo3(signature = (toml, out, base=PathBuf::from("."), model=None))]
fn simulate(
    py: Python<'_>,
    toml: String,
    out: PathBuf,
    base: PathBuf,
    model: Option<PathBuf>,
) -> PyResult<(String, Vec<(String, f64)>)> {
    let r = py
        .detach(|| api::simulate(&toml, &base, model.as_deref(), &out))
        .map_err(py_err)?;
    let metrics = r
        .metrics
        .into_iter()
        .map(|(n, v)| (n.to_string(), v))
        .collect();
    Ok((r.status, metrics))
}

/// `study compare CAMPAIGN --report DIR`: returns the printed report.
#[pyfunction]
#[pyo3(signature = (campaign, report, model=None, threads=0))]
fn compare(
    py: Python<'_>,
    campaign: PathBuf,
    report: PathBuf,
    model: Option<PathBuf>,
    threads: usize,
) -> PyResult<String> {
    py.detach(|| api::compare(&campaign, model.as_deref(), &report, threads))
        .map_err(py_err)
}

/// `study diagnose CAMPAIGN --report DIR [--out MODEL]`: returns the printed report.
#[pyfunction]
#[pyo3(signature = (campaign, report, model=None, candidates=Vec::new(), out=None, threads=0))]
fn diagnose(
    py: Python<'_>,
    campaign: PathBuf,
    report: PathBuf,
    model: Option<PathBuf>,
    candidates: Vec<String>,
    out: Option<PathBuf>,
    threads: usize,
) -> PyResult<String> {
    py.detach(|| {
        api::diagnose(
            &campaign,
            model.as_deref(),
            &candidates,
            &report,
            out.as_deref(),
            threads,
        )
    })
    .map_err(py_err)
}

/// `study fit CAMPAIGN --effect E --free P --out MODEL`: returns the printed report.
#[pyfunction]
#[pyo3(signature = (campaign, out, effects=Vec::new(), free=Vec::new(), model=None, max_iter=200, threads=0))]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    campaign: PathBuf,
    out: PathBuf,
    effects: Vec<String>,
    free: Vec<String>,
    model: Option<PathBuf>,
    max_iter: usize,
    threads: usize,
) -> PyResult<String> {
    py.detach(|| {
        api::fit(
            &campaign,
            &effects,
            &free,
            model.as_deref(),
            &out,
            max_iter,
            threads,
        )
    })
    .map_err(py_err)
}

/// `study plot RESULTS --out DIR`: the plots and index.html; returns the index's path.
#[pyfunction]
#[pyo3(signature = (results, out, metrics=None, bootstrap=200))]
fn plot_study(
    py: Python<'_>,
    results: PathBuf,
    out: PathBuf,
    metrics: Option<Vec<String>>,
    bootstrap: usize,
) -> PyResult<PathBuf> {
    py.detach(|| {
        vshake::shell::commands::plot_cmd::plot(&results, &out, metrics.as_deref(), bootstrap)
    })
    .map_err(py_err)
}

/// A parameter as `study params` lists it.
type ParamRow = (
    String,
    String,
    String,
    String,
    String,
    f64,
    f64,
    f64,
    String,
    String,
    String,
);

/// Every parameter: path, component, name, column, unit, default, low, high, range, source,
/// meaning.
#[pyfunction]
fn params() -> Vec<ParamRow> {
    api::parameters()
        .into_iter()
        .map(|p| {
            (
                p.path(),
                p.component.name().to_string(),
                p.name.to_string(),
                p.column_name(),
                p.unit.to_string(),
                p.default,
                p.range.lo,
                p.range.hi,
                p.range.to_string(),
                p.source.to_string(),
                p.doc.to_string(),
            )
        })
        .collect()
}

/// The effect library: name, family, the parameters a diagnosis frees, what it adds.
#[pyfunction]
fn effects() -> Vec<(String, String, Vec<String>, String)> {
    vshake::kernel::effects::LIBRARY
        .iter()
        .map(|e| {
            let free = e.free().iter().map(|s| s.to_string()).collect();
            (
                e.name.to_string(),
                e.family.to_string(),
                free,
                e.summary.to_string(),
            )
        })
        .collect()
}

/// TOML text of a JSON object (the Python layer's dicts): tables, arrays, strings, numbers,
/// booleans; a null is refused with its key.
#[pyfunction]
fn toml_of_json(json: &str) -> PyResult<String> {
    let value: serde_json::Value =
        serde_json::from_str(json).map_err(|e| InputError::new_err(format!("not JSON: {e}")))?;
    let table: toml::Table = serde_json::from_value(value).map_err(|e| {
        InputError::new_err(format!(
            "cannot be TOML: {e} (a None or a nested list of tables?)"
        ))
    })?;
    toml::to_string(&table).map_err(|e| InputError::new_err(format!("cannot be TOML: {e}")))
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("VshakeError", m.py().get_type::<VshakeError>())?;
    m.add("InputError", m.py().get_type::<InputError>())?;
    m.add_function(wrap_pyfunction!(run_study, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(plot_study, m)?)?;
    m.add_function(wrap_pyfunction!(params, m)?)?;
    m.add_function(wrap_pyfunction!(effects, m)?)?;
    m.add_function(wrap_pyfunction!(toml_of_json, m)?)?;
    Ok(())
}
