//! A run file (`study sim`, `study iterate`) read with its model, and the reference of its
//! excitation built (a record read from its file).

use crate::kernel::excitation::Reference;
use crate::kernel::params::ModelParams;
use crate::orchestration::runs::single;
use crate::orchestration::runs::spec::ExcitationSpec;
use crate::orchestration::runs::spec::SimSpec;
use crate::shell::formats::input;
use crate::shell::formats::measured_files;
use crate::shell::BadInput;
use std::path::Path;

/// Reads and validates a run file on the model file `model` (`--model`; None: the defaults).
pub(crate) fn load_spec(file: &Path, model: Option<&Path>) -> anyhow::Result<SimSpec> {
    let base = crate::shell::formats::campaign_io::load_model(model)?;
    let text = input::read_input_text(file)
        .map_err(|e| BadInput(format!("{}: cannot read: {e}", file.display())))?;
    Ok(SimSpec::from_toml_on(
        &text,
        &file.display().to_string(),
        base,
    )?)
}

/// Builds the reference of a spec, reading a record file relative to `base`, with the spec's
/// response spectrum.
pub(crate) fn build_reference(spec: &SimSpec, base: &Path) -> anyhow::Result<Reference> {
    let r = load_reference(&spec.excitation, &spec.model, base, 0)?;
    // An earthquake-type reference carries a spectrum (the default one); a sine none.
    Ok(match r.spectrum {
        Some(_) => r.with_spectrum(spec.spectrum.clone()),
        None => r,
    })
}

/// The reference of one excitation for `model`, reading a record's file relative to `base` (a
/// PEER `.AT2` file by [`crate::shell::formats::at2`]); a generated motion's noise from `seed`.
pub(crate) fn load_reference(
    excitation: &ExcitationSpec,
    model: &ModelParams,
    base: &Path,
    seed: u64,
) -> anyhow::Result<Reference> {
    let record = match excitation {
        ExcitationSpec::Record {
            file,
            column,
            time_column,
            ..
        } => Some(
            measured_files::read_record(&base.join(file), column, time_column)
                .map_err(measured_files::input_if_user)?,
        ),
        _ => None,
    };
    single::reference_for(excitation, model, record.as_ref(), seed)
        .map_err(|p| crate::shell::BadInput(p.to_string()).into())
}
