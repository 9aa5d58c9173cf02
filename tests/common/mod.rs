//! Helpers shared by the integration tests.

use std::path::Path;
use vshake::shell::tables::{read_columns_allow_nan, read_strings};

/// The state and term a report's residual follows most, from its `stateterms.parquet`: over the
/// platen's force balance and the chambers' flow balance (as a flow and as an opening), the
/// per-state regression of largest R² and its strongest term (the regression's first row).
/// Returns (residual, state, term, R²).
pub fn followed_state(report: &Path) -> (String, String, String, f64) {
    let p = report.join("stateterms.parquet");
    let (res, states, terms) = (read_strings(&p, "residual").unwrap(), read_strings(&p, "states").unwrap(), read_strings(&p, "term").unwrap());
    let r2 = read_columns_allow_nan(&p, &["r2"]).unwrap().column("r2").unwrap().to_vec();
    let rows = || (0..res.len()).filter(|&i| states[i] != "all" && (res[i] == "platen_force" || res[i] == "valve_flow" || res[i] == "valve_opening"));
    let top = rows().map(|i| r2[i]).fold(f64::NEG_INFINITY, f64::max);
    let best = rows().find(|&i| r2[i] == top).unwrap();
    (res[best].clone(), states[best].clone(), terms[best].clone(), r2[best])
}
