//! The physics kernel: pure computation, no I/O, no serde, no threads.
//!
//! Modules are named after the physical parts of the LHPOST model (docs/model.md):
//! [`controller`] (TVC, §2), [`servovalve`], [`actuator`], [`platen`], [`friction`] (§3),
//! [`excitation`] (§4), [`metrics`] (§5), with [`params`] holding every default and
//! [`simulate`] the lane integrator that ties them together. Optional physical effects plug in
//! through [`effects::Effect`].

// Lane loops index several same-length arrays by the lane number on purpose: that is the
// structure-of-arrays shape LLVM vectorises.
#![allow(clippy::needless_range_loop)]

pub mod actuator;
mod bare;
pub mod baseline_params;
pub mod builds;
pub mod channels;
pub mod controller;
pub mod effects;
pub mod excitation;
pub mod expm;
pub mod expr;
pub mod friction;
pub mod gpu_lanes;
pub mod ground;
pub mod lane_params;
pub mod lanes;
pub mod linalg;
pub mod metrics;
pub mod param_table;
pub mod params;
pub mod platen;
pub mod resample;
pub mod servovalve;
pub mod simulate;
pub mod spectrum;
pub mod state;

/// Actuators driving the platen [paper: two horizontal actuators]. Kept separate in the state so
/// effects may break their symmetry.
pub const N_ACT: usize = 2;

/// Lanes of the bare plant's batch kernel (samples without effects integrated together, design
/// exploration's path): sixteen f64 lanes are four AVX2 or two AVX-512 registers, enough
/// independent work to hide the right-hand side's chain of dependent Newton steps
/// (docs/performance.md).
pub const LANES: usize = 16;

/// Lanes of the batch kernels with effects (the effect set, and one effect at a time for fits
/// and diagnoses). Eight: their per-lane code is written lane by lane and left to LLVM, for which
/// sixteen lanes only add register spills and build time.
pub const EFFECT_LANES: usize = 8;
