//! What a building on the platen experiences in a run (the `building` effect's channels of a
//! time history): per storey the peak drift, drift ratio and ductility demand, the peak floor
//! acceleration and the storey's work, and the peak base shear. What a test planner checks first.

use super::single::History;
use vshake_kernel::effects::building;
use vshake_kernel::params::{ModelParams, G};

/// The peaks of one storey.
#[derive(Debug, Clone, PartialEq)]
pub struct StoreyPeaks {
    /// Peak |drift|, m.
    pub drift_m: f64,
    /// Peak |drift| over the storey height.
    pub drift_ratio: f64,
    /// Peak |drift| over the yield drift F_y/k (a ductility demand; below 1 the storey stayed
    /// elastic). NaN for a linear building.
    pub ductility: f64,
    /// Peak |absolute acceleration| of the floor above, g.
    pub floor_accel_g: f64,
    /// The storey's work ∫R dd at the end of the run, J: what it dissipated by yielding, plus the
    /// elastic energy of its drift at the end.
    pub energy_j: f64,
}

/// What the building experienced.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildingResponse {
    pub storeys: Vec<StoreyPeaks>,
    /// Peak |base shear|, N.
    pub base_shear_n: f64,
    /// The building's weight, N.
    pub weight_n: f64,
}

/// The building's response in `history` (a run of `model`); `None` where the building is off or
/// the history lacks its channels (a run that failed at its first tick).
pub fn building_response(model: &ModelParams, history: &History) -> Option<BuildingResponse> {
    if !model.effects.building {
        return None;
    }
    let p = building::Params::of(model);
    let peak = |name: &str| -> Option<f64> {
        Some(
            history
                .channel(name)?
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs())),
        )
    };
    let storeys = building::storeys(p);
    let mut out = Vec::with_capacity(storeys.len());
    for (i, &(_, k, fy)) in storeys.iter().enumerate() {
        let n = i + 1;
        let drift_m = peak(&format!("drift_{n}_m"))?;
        out.push(StoreyPeaks {
            drift_m,
            drift_ratio: drift_m / p.height,
            ductility: if p.law == 0.0 {
                f64::NAN
            } else {
                drift_m * k / fy
            },
            floor_accel_g: peak(&format!("floor_accel_{n}_mps2"))? / G,
            energy_j: *history.channel(&format!("energy_{n}_j"))?.last()?,
        });
    }
    Some(BuildingResponse {
        storeys: out,
        base_shear_n: peak("base_shear_n")?,
        weight_n: storeys.iter().map(|s| s.0).sum::<f64>() * G,
    })
}

impl BuildingResponse {
    /// The largest drift ratio of any storey.
    pub fn peak_drift_ratio(&self) -> f64 {
        self.storeys.iter().fold(0.0, |m, s| m.max(s.drift_ratio))
    }
}

/// Storey by storey, as `study sim` and `study iterate` print it.
impl std::fmt::Display for BuildingResponse {
    fn fmt(&self, o: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            o,
            "  the building: peak base shear {:.1} kN ({:.3} of its weight)",
            self.base_shear_n / 1e3,
            self.base_shear_n / self.weight_n
        )?;
        writeln!(
            o,
            "  {:>6} {:>10} {:>11} {:>10} {:>14} {:>12}",
            "storey", "drift mm", "drift ratio", "ductility", "floor accel g", "work kJ"
        )?;
        for (i, s) in self.storeys.iter().enumerate() {
            let ductility = if s.ductility.is_nan() {
                "-".to_string()
            } else {
                format!("{:.2}", s.ductility)
            };
            writeln!(
                o,
                "  {:>6} {:>10.2} {:>10.3}% {:>10} {:>14.3} {:>12.2}",
                i + 1,
                s.drift_m * 1e3,
                s.drift_ratio * 100.0,
                ductility,
                s.floor_accel_g,
                s.energy_j / 1e3
            )?;
        }
        Ok(())
    }
}
