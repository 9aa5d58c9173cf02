//! The real test prepared on the virtual table: drive iteration, CMA-ES and controller tuning.

pub mod cmaes;
pub mod drive_iteration;
pub mod iterate_journal;
pub mod tune;
pub mod tune_journal;
pub mod tune_spec;
