//! Measured data brought to the model: campaigns, a file's time base, a test aligned to the model.

pub mod aligned;
pub mod campaign;
pub mod timebase;
