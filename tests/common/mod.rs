//! Helpers shared by the integration tests.

use std::path::Path;
use vshake::shell::tables::{read_bools, read_columns_allow_nan, read_strings};

/// The state and term a report's residual follows, from its `stateterms.parquet`: the row the
/// map's sentence names (`named`), else (nothing named) the per-state regression of largest R²
/// over the platen's force balance and the chambers' flow balance, and its strongest term.
/// Returns (residual, state, term, R²).
pub fn followed_state(report: &Path) -> (String, String, String, f64) {
    let p = report.join("stateterms.parquet");
    let (res, states, terms) = (read_strings(&p, "residual").unwrap(), read_strings(&p, "states").unwrap(), read_strings(&p, "term").unwrap());
    let named = read_bools(&p, "named").unwrap();
    let r2 = read_columns_allow_nan(&p, &["r2"]).unwrap().column("r2").unwrap().to_vec();
    let rows = || (0..res.len()).filter(|&i| states[i] != "all" && (res[i] == "platen_force" || res[i] == "valve_flow" || res[i] == "valve_opening"));
    let top = rows().map(|i| r2[i]).fold(f64::NEG_INFINITY, f64::max);
    let best = (0..res.len()).find(|&i| named[i]).or_else(|| rows().find(|&i| r2[i] == top)).unwrap();
    (res[best].clone(), states[best].clone(), terms[best].clone(), r2[best])
}
