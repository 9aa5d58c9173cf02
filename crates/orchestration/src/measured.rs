//! Measured data brought to the model: campaigns, the channels' vocabulary (names, units), a file's time base, a test aligned to the model.

pub mod aligned;
pub mod campaign;
pub mod channels;
pub mod timebase;
