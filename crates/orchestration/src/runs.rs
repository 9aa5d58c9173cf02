//! What one run is and running it: run specifications and their excitations, the earthquake-type
//! references, the table's limits, one configuration through the kernel, what a building on the platen experiences.

pub mod adaptation;
pub mod authority;
pub mod building_response;
pub mod excitation_spec;
pub mod limits;
pub mod passes;
pub mod quake;
pub mod quake_spec;
pub mod single;
pub mod spec;
