//! Campaign and measured-test files (FORMATS.md): loading, the error behaviour of measured data,
//! and the reference each test is driven with.

use super::sim_cmd::{input_if_user, reference_for};
use super::tables::{self, NumTable};
use super::BadInput;
use crate::kernel::excitation::Reference;
use crate::kernel::params::ModelParams;
use crate::orchestration::campaign::{self, Campaign, TestSpec};
use crate::orchestration::spec::ExcitationSpec;
use std::path::{Path, PathBuf};

/// Required columns of a measured test.
pub const REQUIRED: [&str; 4] = ["time_s", "ref_disp_m", "disp_m", "accel_mps2"];
/// Optional columns of a measured test (read and checked when present).
pub const OPTIONAL: [&str; 5] = ["valve_cmd_v", "force_n", "p1_pa", "p2_pa", "spool_m"];

/// A campaign with the folder its paths are relative to.
pub struct LoadedCampaign {
    pub file: PathBuf,
    pub base: PathBuf,
    pub campaign: Campaign,
}

/// Reads a model file given with `--model` (`[model.<component>]` tables).
pub fn load_model(path: Option<&Path>) -> anyhow::Result<ModelParams> {
    match path {
        None => Ok(ModelParams::default()),
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| BadInput(format!("{}: cannot read: {e}", p.display())))?;
            Ok(campaign::model_from_toml(&text, &p.display().to_string())?)
        }
    }
}

pub fn load_campaign(file: &Path, model: &ModelParams) -> anyhow::Result<LoadedCampaign> {
    let text = std::fs::read_to_string(file).map_err(|e| BadInput(format!("{}: cannot read: {e}", file.display())))?;
    let campaign = Campaign::from_toml(&text, &file.display().to_string(), model)?;
    Ok(LoadedCampaign { file: file.to_path_buf(), base: file.parent().unwrap_or(Path::new(".")).to_path_buf(), campaign })
}

/// Reads a measured test: the required columns, the optional ones present, every cell a finite
/// number, time uniform and increasing, sampled at the controller rate `f_s`.
pub fn read_measured(path: &Path, f_s: f64) -> anyhow::Result<NumTable> {
    let t = tables::read_columns(path, &REQUIRED, &OPTIONAL).map_err(input_if_user)?;
    let dt = t.check_time("time_s").map_err(input_if_user)?;
    if ((1.0 / dt) - f_s).abs() > 1e-6 * f_s {
        return Err(BadInput(format!(
            "{}: column `time_s`: sampled at {:.6} Hz, but the controller runs at f_s = {f_s} Hz (set [model.controller] f_s, or resample the file)",
            path.display(),
            1.0 / dt
        ))
        .into());
    }
    Ok(t)
}

/// The reference a test is driven with, for a file of `rows` rows at `f_s`: a sine lasts as long as
/// the file (its window follows unless given); a record comes from its column.
pub fn test_reference(test: &TestSpec, rows: usize, base: &Path, data: &Path) -> anyhow::Result<Reference> {
    let f_s = test.model.controller.f_s;
    let r = match &test.excitation {
        ExcitationSpec::Sine { sine, .. } => {
            let mut s = *sine;
            let file_duration = rows as f64 / f_s;
            if test.duration_given && (s.duration_s - file_duration).abs() > 0.5 / f_s {
                return Err(BadInput(format!(
                    "test {:?}: excitation.duration_s = {} s but {} holds {file_duration} s ({rows} rows at {f_s} Hz)",
                    test.name,
                    s.duration_s,
                    data.display()
                ))
                .into());
            }
            s.duration_s = file_duration;
            if !test.window_given {
                s.window_cycles = Some(s.default_cycles());
            }
            if s.window_cycles == Some(0) {
                return Err(BadInput(format!("test {:?}: {} is too short for a whole cycle after taper_s + 1 s", test.name, data.display())).into());
            }
            s.reference(f_s)
        }
        ExcitationSpec::Record { .. } => reference_for(&test.excitation, &test.model, base)?,
    };
    if r.len() != rows {
        return Err(BadInput(format!("test {:?}: the reference has {} ticks but {} has {rows} rows", test.name, r.len(), data.display())).into());
    }
    Ok(r)
}
