//! Every file format vshake reads or writes: inputs and their problems, measured files (CSV,
//! MATLAB, Parquet), PEER .AT2 records, results tables written and read back, their metadata and
//! checksums, campaigns' files.

pub mod at2;
pub mod campaign_io;
pub mod headers;
pub mod input;
pub(crate) mod integrity;
pub mod matlab;
pub mod measured_files;
pub mod meta;
pub mod parquet_read;
pub mod parquet_write;
pub mod results_reader;
