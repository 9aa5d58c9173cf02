//! A run file (`study sim`, `study iterate`) read with its model, and the reference of its
//! excitation built (a record read from its file).

use super::tables;
use super::BadInput;
use crate::kernel::excitation::Reference;
use crate::orchestration::runs::spec::SimSpec;
use std::path::Path;

/// Reads and validates a run file on the model file `model` (`--model`; None: the defaults).
pub(crate) fn load_spec(file: &Path, model: Option<&Path>) -> anyhow::Result<SimSpec> {
    let base = super::campaign_io::load_model(model)?;
    let text = tables::read_input_text(file)
        .map_err(|e| BadInput(format!("{}: cannot read: {e}", file.display())))?;
    Ok(SimSpec::from_toml_on(
        &text,
        &file.display().to_string(),
        base,
    )?)
}

/// Builds the reference of a spec, reading a record file relative to `base`.
pub(crate) fn build_reference(spec: &SimSpec, base: &Path) -> anyhow::Result<Reference> {
    tables::load_reference(&spec.excitation, &spec.model, base, 0)
}
