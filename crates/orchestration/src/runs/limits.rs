//! The table's limits against a motion: the stroke, the velocity and the force to accelerate
//! the platen and the specimen on it, checked before a run (`study sim`, studies, the drive
//! iteration's every drive).

use vshake_kernel::excitation::Reference;
use vshake_kernel::params::{ModelParams, G};

/// The table's limits against a reference's peaks: the stroke (actuator.l), the velocity
/// (controller.v_max) and the force to accelerate the platen and the specimen on it
/// ((platen.m + specimen.m1 + m2 + m3 + the building's floors) · a ≤ controller.f_max; the
/// specimens as a rigid mass, a lower bound on the force near their modes, where their base
/// shear is amplified; a yielding building's share capped by its first storey's yield force,
/// [`force_exceeded`]).
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
            "peak velocity {v:.4} m/s exceeds controller.v_max = {v_max} m/s"
        ));
    }
    if let Some(why) = force_exceeded(model, a) {
        over.push(why);
    }
    over
}

/// Why a peak acceleration `a` (m/s²) needs more force than the table has, if it does: the
/// platen and the specimens on it against controller.f_max. A modal specimen counts as a rigid
/// mass; so does a building, except that a yielding one (bilinear or Bouc–Wen storeys) counts
/// at most its first storey's yield force, the base shear at which it yields. Its hardening and
/// damping add to that (a 1500 t building yielding at 250 kN, at 1.2 g: 585 kN of base shear in
/// the run, against 18.8 MN as a rigid mass), so a run that needs more force than the table has
/// can still pass this check; the run's own guards then stop it.
pub fn force_exceeded(model: &ModelParams, a: f64) -> Option<String> {
    let (m, f_max) = (model.platen.m, model.controller.f_max);
    let mut carried = format!("the {m} kg platen");
    let mut force = m * a;
    let modal = modal_mass(model);
    if modal > 0.0 {
        carried += &format!(" and the {modal} kg specimen (as a rigid mass)");
        force += modal * a;
    }
    if let Some((floors, cap)) = building_mass(model) {
        let rigid = floors * a;
        force += cap.map_or(rigid, |fy| rigid.min(fy));
        carried += &match cap {
            Some(fy) => format!(
                " and the {floors} kg building (as a rigid mass up to its first storey's yield force, {fy} N)"
            ),
            None => format!(" and the {floors} kg building (as a rigid mass)"),
        };
    }
    (force > f_max).then(|| {
        format!(
            "peak acceleration {:.3} g needs {:.3} MN on {carried}, beyond controller.f_max = {} MN",
            a / G,
            force / 1e6,
            f_max / 1e6
        )
    })
}

/// The modal specimen's mass on the platen (its modal masses), kg; 0 when it is off.
fn modal_mass(model: &ModelParams) -> f64 {
    if !model.effects.specimen {
        return 0.0;
    }
    let q = vshake_kernel::effects::specimen::Params::of(model);
    q.m1 + q.m2 + q.m3
}

/// The building's floors' mass, kg, and the first storey's yield force where its storeys
/// yield (law bilinear or Bouc–Wen), N; None when it is off.
fn building_mass(model: &ModelParams) -> Option<(f64, Option<f64>)> {
    use vshake_kernel::effects::building;
    if !model.effects.building {
        return None;
    }
    let p = building::Params::of(model);
    let storeys = building::storeys(p);
    let floors = storeys.iter().map(|s| s.0).sum();
    Some((floors, (p.law > 0.0).then_some(storeys[0].2)))
}
