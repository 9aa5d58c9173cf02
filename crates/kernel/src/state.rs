//! The plant's state vector, per lane: how many states and what each index holds. The
//! integrator (`simulate`), the effects' view of the plant (`effects::PlantView`) and the
//! observers read states by these indices.

/// Number of plant states per lane.
pub const NP: usize = 7;

/// Indices of the plant states.
pub mod idx {
    /// Cap-side pressure of actuator i, Pa.
    pub const P1: [usize; 2] = [0, 2];
    /// Rod-side pressure of actuator i, Pa.
    pub const P2: [usize; 2] = [1, 3];
    /// Platen displacement, m.
    pub const Y: usize = 4;
    /// Platen velocity, m/s.
    pub const VEL: usize = 5;
    /// Friction law variable z, −.
    pub const Z: usize = 6;
}
