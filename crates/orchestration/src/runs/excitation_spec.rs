//! The excitation of a run as a spec writes it (a sine, a record, an earthquake-type motion),
//! before any file is read: what it is, how it is described, whether it varies per sample.

use std::path::PathBuf;
use vshake_kernel::excitation::{Signal, Sine};
use vshake_kernel::ground::{Processing, Sweep};
use vshake_kernel::params::{Component, ModelParams};

/// The excitation of a run, as written in a spec (a record's file is not read yet).
#[derive(Debug, Clone, PartialEq)]
pub enum ExcitationSpec {
    Sine {
        sine: Sine,
        /// The amplitude as the user gave it, in g, if it was given in g.
        amp_g: Option<f64>,
    },
    Record {
        file: PathBuf,
        column: String,
        time_column: String,
        f_ref_hz: f64,
        scale: f64,
        /// What the column holds (a `.AT2` file: acceleration in g).
        unit: RecordUnit,
        /// Scale an acceleration record to this peak, g (instead of `scale`).
        pga_g: Option<f64>,
        /// How an acceleration becomes a displacement.
        processing: Processing,
        /// What the record is: the reference the controller tracked, or a command into its
        /// reference generator (docs/model.md §4).
        signal: Signal,
    },
    /// A Kanai–Tajimi / Clough–Penzien ground motion (kernel::ground), its parameters the
    /// model's `ground.*` with `ground` overriding them.
    Stochastic {
        duration_s: f64,
        realisation: Realisation,
        seed: Option<u64>,
        ground: Vec<(&'static str, f64)>,
        processing: Processing,
        f_ref_hz: f64,
    },
    /// A sine sweep (kernel::ground::Sweep); `amp_g` as given, if it was.
    Sweep { sweep: Sweep, amp_g: Option<f64> },
    /// Band-limited random: a random-phase multisine (kernel::ground::Multisine).
    Random {
        f_lo_hz: f64,
        f_hi_hz: f64,
        rms_g: f64,
        duration_s: f64,
        taper_s: f64,
        realisation: Realisation,
        seed: Option<u64>,
    },
}

/// What a record column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordUnit {
    /// Displacement, m (the default).
    M,
    /// Displacement, mm.
    Mm,
    /// Ground acceleration, g (9.80665 m/s²).
    G,
    /// Ground acceleration, m/s².
    Mps2,
}

impl RecordUnit {
    pub const NAMES: [&'static str; 4] = ["m", "mm", "g", "m/s2"];

    pub fn parse(s: &str) -> Option<RecordUnit> {
        Some(match s {
            "m" => RecordUnit::M,
            "mm" => RecordUnit::Mm,
            "g" => RecordUnit::G,
            "m/s2" | "m/s^2" | "m/s²" => RecordUnit::Mps2,
            _ => return None,
        })
    }
    pub fn name(self) -> &'static str {
        match self {
            RecordUnit::M => "m",
            RecordUnit::Mm => "mm",
            RecordUnit::G => "g",
            RecordUnit::Mps2 => "m/s2",
        }
    }
    /// The factor to SI (m or m/s²).
    pub fn to_si(self) -> f64 {
        match self {
            RecordUnit::M | RecordUnit::Mps2 => 1.0,
            RecordUnit::Mm => 1e-3,
            RecordUnit::G => vshake_kernel::params::G,
        }
    }
    pub(crate) fn is_acceleration(self) -> bool {
        matches!(self, RecordUnit::G | RecordUnit::Mps2)
    }
}

/// Which noise realisation a random excitation uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Realisation {
    /// The same realisation for every sample: stream k of the excitation's seed.
    Fixed(u64),
    /// One per sample of a study: stream = the sample id (a run outside a study uses stream 0).
    PerSample,
}

impl Realisation {
    /// The noise stream of sample `sample`.
    pub fn stream(self, sample: u64) -> u64 {
        match self {
            Realisation::Fixed(k) => k,
            Realisation::PerSample => sample,
        }
    }
}

impl ExcitationSpec {
    /// One-line description for printouts.
    /// The excitation in a few words, with its frequency and amplitude in g (NaN for a record).
    pub fn label(&self) -> (String, f64, f64) {
        match self {
            ExcitationSpec::Sine { sine, amp_g } => {
                let g = amp_g.unwrap_or(
                    sine.amp_m * (2.0 * std::f64::consts::PI * sine.freq_hz).powi(2)
                        / vshake_kernel::params::G,
                );
                (
                    format!("sine {} Hz {:.2} g", sine.freq_hz, g),
                    sine.freq_hz,
                    g,
                )
            }
            ExcitationSpec::Record { column, .. } => {
                (format!("record {column}"), f64::NAN, f64::NAN)
            }
            ExcitationSpec::Stochastic { .. } => {
                ("stochastic ground motion".into(), f64::NAN, f64::NAN)
            }
            ExcitationSpec::Sweep { sweep, .. } => (
                format!("sweep {}-{} Hz", sweep.f0_hz, sweep.f1_hz),
                f64::NAN,
                f64::NAN,
            ),
            ExcitationSpec::Random {
                f_lo_hz, f_hi_hz, ..
            } => (format!("random {f_lo_hz}-{f_hi_hz} Hz"), f64::NAN, f64::NAN),
        }
    }

    /// Whether it is a sine (the harmonic metrics) rather than an earthquake-type motion (the
    /// spectral ones).
    pub fn is_sine(&self) -> bool {
        matches!(self, ExcitationSpec::Sine { .. })
    }

    /// Whether its reference depends on the sample: a realisation per sample, or a stochastic
    /// motion whose `ground.*` parameters the study varies (`varied` says which paths vary).
    pub fn per_sample(&self, varied: impl Fn(&str) -> bool) -> bool {
        match self {
            ExcitationSpec::Stochastic {
                realisation,
                ground,
                ..
            } => {
                *realisation == Realisation::PerSample
                    || ModelParams::rows(Component::Ground)
                        .any(|p| varied(&p.path()) && !ground.iter().any(|(n, _)| *n == p.name))
            }
            ExcitationSpec::Random { realisation, .. } => *realisation == Realisation::PerSample,
            _ => false,
        }
    }

    pub fn describe(&self) -> String {
        match self {
            ExcitationSpec::Sine { sine, amp_g } => {
                let amp = match amp_g {
                    Some(g) => format!("{g} g ({:.4} m)", sine.amp_m),
                    None => format!("{} m", sine.amp_m),
                };
                format!(
                    "sine {} Hz, {amp}, taper {} s, {} s run, window {} cycles",
                    sine.freq_hz,
                    sine.taper_s,
                    sine.duration_s,
                    sine.window_cycles.unwrap_or_else(|| sine.default_cycles())
                )
            }
            ExcitationSpec::Record {
                file,
                column,
                f_ref_hz,
                unit,
                signal,
                scale,
                ..
            } if !unit.is_acceleration() => {
                format!(
                    "record {}:{column}{}, {}",
                    file.display(),
                    scaled_by(*scale),
                    filter_words(*signal, *f_ref_hz)
                )
            }
            ExcitationSpec::Record {
                file,
                column,
                f_ref_hz,
                unit,
                pga_g,
                processing,
                signal,
                scale,
                ..
            } => format!(
                "acceleration record {}:{column} ({}){}, high-pass {} Hz, {}",
                file.display(),
                unit.name(),
                pga_g.map_or(scaled_by(*scale), |g| format!(" scaled to {g} g")),
                processing.highpass_hz,
                filter_words(*signal, *f_ref_hz)
            ),
            ExcitationSpec::Stochastic {
                duration_s,
                realisation,
                ..
            } => format!("stochastic ground motion, {duration_s} s, realisation {realisation:?}"),
            ExcitationSpec::Sweep { sweep, amp_g } => format!(
                "{:?} sweep {}-{} Hz over {} s, {}",
                sweep.law,
                sweep.f0_hz,
                sweep.f1_hz,
                sweep.duration_s,
                match (sweep.amp_m, amp_g) {
                    (Some(x), _) => format!("{x} m"),
                    (None, Some(g)) => format!("{g} g"),
                    (None, None) => format!("{} m/s²", sweep.accel_mps2),
                }
            ),
            ExcitationSpec::Random {
                f_lo_hz,
                f_hi_hz,
                rms_g,
                duration_s,
                ..
            } => {
                format!("band-limited random {f_lo_hz}-{f_hi_hz} Hz, {rms_g} g rms, {duration_s} s")
            }
        }
    }
}

/// How a record's reference states are made, in words.
fn filter_words(signal: Signal, f_ref_hz: f64) -> String {
    match signal {
        Signal::Command => format!("a command through the state-variable filter {f_ref_hz} Hz"),
        Signal::Reference => format!("the tracked reference, zero-phase derivatives {f_ref_hz} Hz"),
    }
}

/// A record's `scale` in its description: nothing at 1, else " × scale".
fn scaled_by(scale: f64) -> String {
    if scale == 1.0 {
        String::new()
    } else {
        format!(" × {scale}")
    }
}
