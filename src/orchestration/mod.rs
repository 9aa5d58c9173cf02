//! Orchestration layer.
