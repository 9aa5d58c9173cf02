//! A study as a job: the study file read and planned, its outputs and what may stand there,
//! progress, interruption, resuming and sizing.

pub mod interrupt;
pub mod iterate_journal_file;
pub(crate) mod outputs;
pub mod progress;
pub mod resume;
pub mod sizing;
pub mod study_job;
pub mod tune_journal_file;
