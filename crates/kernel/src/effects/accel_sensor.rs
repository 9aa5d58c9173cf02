//! Effect `accel_sensor`: the recorded acceleration channel passes through the accelerometer and its anti-alias filter: a second-order
//! low-pass (corner f_c, damping ζ) and a pure delay τ (`sensor_chain` has the equations and their
//! realisation). It changes what is recorded, not the plant. Its signature: a residual in the
//! acceleration channel alone — a phase lag that grows with frequency and, near f_c, a change of
//! amplitude — while the other channels agree with the model.

use super::sensor_chain::sensor_effect;
use super::{EffectInfo, Stage};
use crate::param_table::{params, Range};

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "measurement chain",
    summary: "the acceleration channel's sensor and anti-alias filter: a low-pass and a delay",
    params: Params::FIELDS,
    stages: &[Stage {
        label: "",
        // Corner, damping and delay: the filter's whole shape (issue 51).
        free: &["f_c", "zeta", "delay"],
        scan: Some(("f_c", &[15.0, 30.0, 60.0, 120.0, 240.0])),
        size: None,
        shape: None,
        start: &[],
    }],
};

params! {
    /// Effect `accel_sensor`: the recorded acceleration channel through a second-order low-pass
    /// and a delay (`sensor_chain`).
    pub struct Params {
        f_c: "Hz", "hz", 80.0, Range::closed(2.0, 400.0), Chosen,
            "Corner of the channel's low-pass [chosen: an anti-alias filter below a 1 kHz acquisition].";
        zeta: "-", "", std::f64::consts::FRAC_1_SQRT_2, Range::closed(0.05, 2.0), Chosen,
            "Damping ratio of the low-pass [chosen: 1/√2, a second-order Butterworth].";
        delay: "s", "s", 1.0e-3, Range::closed(0.0, 0.02), Chosen,
            "Delay of the channel [chosen: 1 ms, a conversion and buffering delay].";
    }
}

sensor_effect!(AccelSensor, 0);
