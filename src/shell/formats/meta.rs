//! The key-value metadata vshake writes into its Parquet files (docs/formats.md, "Results
//! tables"): every key and every kind of file is defined once, here.

use std::fmt;

macro_rules! keys {
    ($($(#[$doc:meta])* $Key:ident = $name:literal,)*) => {
        /// A metadata key (written as `vshake.<name>`).
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum Key {
            $($(#[$doc])* $Key,)*
        }

        impl Key {
            /// Every key.
            pub const ALL: &'static [Key] = &[$(Key::$Key),*];

            /// The key as written in the file.
            pub const fn as_str(self) -> &'static str {
                match self {
                    $(Key::$Key => concat!("vshake.", $name),)*
                }
            }
        }
    };
}

keys! {
    /// What the file is ([`Kind`]).
    Kind = "kind",
    /// The study, resolved: every default written out (a results file).
    Study = "study",
    /// The study file a results file was made from (absolute), whose folder relative paths in
    /// the study are read from when the run is resumed.
    StudyFile = "study_file",
    /// The run spec, resolved (a time history or a synthetic measurement).
    Spec = "spec",
    Seed = "seed",
    Version = "version",
    SchemaVersion = "schema_version",
    /// The design's method (`monte_carlo`, `sobol`, …).
    Design = "design",
    Samples = "samples",
    /// The excitations' names, in order ([`list`]).
    Excitations = "excitations",
    /// The parameter columns' paths and column names, in order ([`list`]).
    Parameters = "parameters",
    ParameterColumns = "parameter_columns",
    /// The metric names, in order ([`list`]).
    Metrics = "metrics",
    /// The design's dimensions in order (the varied variables; a design file's columns): for a
    /// Saltelli design, block 2 + i of a base point swaps dimension i ([`list`]).
    DesignParameters = "design_parameters",
    /// Set when a results file is closed: whether it holds every row of its study (or shard),
    /// and how many it holds of how many. A file without them (older versions) is complete.
    Complete = "complete",
    RowsDone = "rows_done",
    RowsTotal = "rows_total",
    /// The CRC-32 of each row group as written (`crc32:` and a comma-separated list), checked by
    /// `study run --resume` and `study merge` (formats::integrity).
    RowGroupCrc32 = "row_group_crc32",
    /// The CRC-32 of the file's own `vshake.*` metadata but the checksums (the study, seed and
    /// shard its rows were made for), checked with the row groups' (formats::integrity).
    MetadataCrc32 = "metadata_crc32",
    /// The engines that computed a results file's rows, in the order they ran (`cpu`, `cuda`;
    /// [`list`]): a run resumed, or shards merged, across backends name both.
    Backend = "backend",
    /// A shard's place: `study merge` checks and removes them.
    ShardIndex = "shard_index",
    ShardCount = "shard_count",
    ShardSamples = "shard_samples",
    /// The sample a history belongs to.
    SampleId = "sample_id",
    /// How the model was driven in a comparison (closed loop, open loop on a measured channel).
    Drive = "drive",
    Campaign = "campaign",
    /// The command that made the file (`tune FILE --model M`).
    Command = "command",
    /// A diagnosis's verdict in one sentence.
    Verdict = "verdict",
    /// The results file a sensitivity analysis read.
    Source = "source",
    Bootstrap = "bootstrap",
    /// How a run ended (`ok`, `failed at …`).
    Status = "status",
    /// The noise a synthetic measurement was given.
    Noise = "noise",
    /// A response spectrum's damping ratio.
    Damping = "damping",
}

/// The keys of a shard's place.
pub const SHARD_KEYS: [Key; 3] = [Key::ShardIndex, Key::ShardCount, Key::ShardSamples];

/// The keys a file gets when it is closed (not carried over by a merge or a resume).
pub const COMPLETION_KEYS: [Key; 5] = [
    Key::Complete,
    Key::RowsDone,
    Key::RowsTotal,
    Key::RowGroupCrc32,
    Key::MetadataCrc32,
];

impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What a file is: the value of [`Key::Kind`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    StudyResults,
    TimeHistory,
    Compare,
    Diagnose,
    Sensitivity,
    SyntheticMeasurement,
    Spectrum,
    DriveIteration,
    FrequencyResponse,
    TuneEvaluations,
    TuneGenerations,
}

impl Kind {
    pub const fn as_str(self) -> &'static str {
        match self {
            Kind::StudyResults => "study_results",
            Kind::TimeHistory => "time_history",
            Kind::Compare => "compare",
            Kind::Diagnose => "diagnose",
            Kind::Sensitivity => "sensitivity",
            Kind::SyntheticMeasurement => "synthetic_measurement",
            Kind::Spectrum => "response_spectrum",
            Kind::DriveIteration => "drive_iteration",
            Kind::FrequencyResponse => "frequency_response",
            Kind::TuneEvaluations => "tune_evaluations",
            Kind::TuneGenerations => "tune_generations",
        }
    }
}

/// One metadata pair.
pub fn pair(key: Key, value: impl ToString) -> (String, String) {
    (key.as_str().to_string(), value.to_string())
}

/// The pairs every file starts with: its kind and the version of vshake that wrote it.
pub fn header(kind: Kind) -> Vec<(String, String)> {
    vec![
        pair(Key::Kind, kind.as_str()),
        pair(Key::Version, env!("CARGO_PKG_VERSION")),
    ]
}

/// The value of `key` in `meta`.
pub fn get(meta: &[(String, String)], key: Key) -> Option<&str> {
    meta.iter()
        .find(|(k, _)| k == key.as_str())
        .map(|(_, v)| v.as_str())
}

/// Whether `meta` is of kind `kind`.
pub fn is(meta: &[(String, String)], kind: Kind) -> bool {
    get(meta, Key::Kind) == Some(kind.as_str())
}

/// The separator of a list-valued key. Names in such lists (excitations, metrics, parameter
/// paths and columns) cannot contain it: excitation names are checked where a study is read.
pub const LIST_SEPARATOR: char = ',';

/// A list-valued key's value.
pub fn list<S: AsRef<str>>(items: impl IntoIterator<Item = S>) -> String {
    items
        .into_iter()
        .map(|s| s.as_ref().to_string())
        .collect::<Vec<_>>()
        .join(&LIST_SEPARATOR.to_string())
}

/// The items of a list-valued key's value (none for an empty value).
pub fn items(value: &str) -> Vec<String> {
    value
        .split(LIST_SEPARATOR)
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect()
}

/// The key under which the Arrow writer keeps the file's Arrow schema (rewritten by every writer).
pub const ARROW_SCHEMA: &str = "ARROW:schema";

/// `meta` without the pairs a new file of the same run must not copy: the completion keys and
/// the Arrow schema, and `also` (a merge drops the shard keys too).
pub fn carried<'a>(
    meta: impl IntoIterator<Item = (&'a String, &'a String)>,
    also: &[Key],
) -> Vec<(String, String)> {
    let dropped =
        |k: &str| k == ARROW_SCHEMA || COMPLETION_KEYS.iter().chain(also).any(|d| d.as_str() == k);
    meta.into_iter()
        .filter(|(k, _)| !dropped(k))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect()
}

/// Adds `item` to the list-valued `key` of `meta` (made where missing; an item it has is not
/// added twice).
pub fn add_item(meta: &mut Vec<(String, String)>, key: Key, item: &str) {
    match meta.iter_mut().find(|(k, _)| k == key.as_str()) {
        Some((_, v)) if items(v).iter().any(|i| i == item) => {}
        Some((_, v)) if v.is_empty() => *v = item.to_string(),
        Some((_, v)) => *v = format!("{v}{LIST_SEPARATOR}{item}"),
        None => meta.push(pair(key, item)),
    }
}

/// The completion pairs of a file holding `done` of `total` rows.
pub fn completion(done: usize, total: usize) -> Vec<(String, String)> {
    vec![
        pair(Key::Complete, done == total),
        pair(Key::RowsDone, done),
        pair(Key::RowsTotal, total),
    ]
}

/// `(rows done, rows total)` of a file its writer marked incomplete; `None` for a complete file.
pub fn incomplete(meta: &[(String, String)]) -> Option<(String, String)> {
    let n = |k| get(meta, k).unwrap_or("?").to_string();
    (get(meta, Key::Complete) == Some("false")).then(|| (n(Key::RowsDone), n(Key::RowsTotal)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn add_item_appends_once() {
        let mut m = vec![pair(Key::Seed, 1)];
        add_item(&mut m, Key::Backend, "cuda");
        add_item(&mut m, Key::Backend, "cuda");
        assert_eq!(get(&m, Key::Backend), Some("cuda"));
        add_item(&mut m, Key::Backend, "cpu");
        assert_eq!(get(&m, Key::Backend), Some("cuda,cpu"));
        assert_eq!(m.len(), 2);
    }

    #[test]
    fn keys_are_distinct_and_prefixed() {
        for (i, k) in Key::ALL.iter().enumerate() {
            assert!(k.as_str().starts_with("vshake.") && k.as_str().len() > 7);
            assert!(
                Key::ALL[..i].iter().all(|j| j.as_str() != k.as_str()),
                "{k} twice"
            );
        }
    }

    #[test]
    fn lists_round_trip_and_completion_reads_back() {
        assert_eq!(items(&list(["a", "b_c"])), vec!["a", "b_c"]);
        assert!(items(&list(Vec::<String>::new())).is_empty());
        assert_eq!(
            incomplete(&completion(3, 8)),
            Some(("3".to_string(), "8".to_string()))
        );
        assert_eq!(incomplete(&completion(8, 8)), None);
        assert_eq!(
            incomplete(&[]),
            None,
            "a file without the keys (older versions) is complete"
        );
    }
}
