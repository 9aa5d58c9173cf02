//! The table's limits against a motion: the stroke, the velocity and the force to accelerate
//! the platen and the specimen on it, checked before a run (`study sim`, studies, the drive
//! iteration's every drive).

use vshake_kernel::excitation::Reference;
use vshake_kernel::params::{ModelParams, G};

/// The table's limits against a reference's peaks: the stroke (actuator.l), the velocity
/// (controller.v_max) and the force to accelerate the platen and the specimen on it
/// ((platen.m + specimen.m1 + m2 + m3) · a ≤ controller.f_max; the specimen as a rigid mass, a
/// lower bound on the force near its modes, where its base shear is amplified).
pub fn check_limits(r: &Reference, model: &ModelParams) -> Result<(), String> {
    let over = limits_exceeded(r, model);
    if over.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "the motion exceeds the table's limits: {}; scale it down",
            over.join("; ")
        ))
    }
}

/// Each of [`check_limits`]'s limits that `r` exceeds, said in a phrase.
pub fn limits_exceeded(r: &Reference, model: &ModelParams) -> Vec<String> {
    let (x, v, a) = r.peaks();
    let (l, v_max) = (model.actuator.l, model.controller.v_max);
    let mut over = Vec::new();
    if x >= l {
        over.push(format!(
            "peak displacement {x:.4} m reaches the stroke (half stroke actuator.l = {l} m)"
        ));
    }
    if v > v_max {
        over.push(format!(
            "peak velocity {v:.3} m/s exceeds controller.v_max = {v_max} m/s"
        ));
    }
    if let Some(why) = force_exceeded(model, a) {
        over.push(why);
    }
    over
}

/// Why a peak acceleration `a` (m/s²) needs more force than the table has, if it does: the
/// platen and the specimen on it (as a rigid mass) against controller.f_max.
pub fn force_exceeded(model: &ModelParams, a: f64) -> Option<String> {
    let (m, f_max) = (model.platen.m, model.controller.f_max);
    let specimen = specimen_mass(model);
    let carried = if specimen > 0.0 {
        format!("the {m} kg platen and the {specimen} kg specimen (as a rigid mass)")
    } else {
        format!("the {m} kg platen")
    };
    let force = (m + specimen) * a;
    (force > f_max).then(|| {
        format!(
            "peak acceleration {:.3} g needs {:.3} MN on {carried}, beyond controller.f_max = {} MN",
            a / G,
            force / 1e6,
            f_max / 1e6
        )
    })
}

/// The specimens' mass on the platen (the modal specimen's modal masses, the building's floors),
/// kg; 0 when neither is on.
fn specimen_mass(model: &ModelParams) -> f64 {
    use vshake_kernel::effects::{building, specimen};
    let modal = if model.effects.specimen {
        let q = specimen::Params::of(model);
        q.m1 + q.m2 + q.m3
    } else {
        0.0
    };
    let floors = if model.effects.building {
        building::storeys(building::Params::of(model))
            .iter()
            .map(|s| s.0)
            .sum()
    } else {
        0.0
    };
    modal + floors
}
