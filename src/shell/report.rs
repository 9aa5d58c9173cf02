//! Reports: the shared HTML/SVG kit, the state map's and the tuning's pages.

pub mod kit;
pub mod statemap_report;
pub mod tune_report;
