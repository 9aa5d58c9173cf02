//! Measured tests brought to the model: the file's own time base, where the excitation starts
//! and ends in the file, the analysis window in the file's own samples, the model's drive at the
//! controller's rate, and the checks that catch a wrong file before it becomes wrong science.
//!
//! **Time base.** [`crate::measured::timebase`]: a uniform grid t_n = t_0 + n/R rebuilt from the row index
//! and a fitted rate R (any rate; rounded time is not an error, a gap is).
//!
//! **Alignment.** The model's t = 0 is the start of the excitation. For a sine test it is found
//! from `ref_disp_m` (unless the campaign gives `t0_s`): the phase of the reference's fundamental
//! after the taper gives the start modulo a period; of the few candidates a period apart before
//! the first motion (the first sample above 1 % of the peak), the one whose sine (taper
//! included) fits the column best by least squares is refined by golden-section search to 1e-9
//! of a row, and taken on the row when within 0.01 row of one. The excitation ends where
//! `ref_disp_m` leaves the campaign's sine (more than max(1e-3·X, 6× its rms mismatch) for a
//! quarter cycle; not in the file's last quarter cycle, too short to tell from an edge effect of
//! the export), or at `duration_s` after the start when given. Rows before the start
//! (pre-trigger) and after the end are not compared. A record test starts at the first row (or
//! at `t0_s`) and drives the model with its `ref_disp_m` column.
//!
//! **Window.** A sine's analysis window is the last N whole cycles of the excitation,
//! round(N·R/f) of the file's samples (N from `window_cycles`, else every whole cycle after
//! taper_s + 1 s); a record's is all of it. Residuals, harmonics and the fit features are
//! computed on the file's own samples, where the model's channels are interpolated inside the
//! controller's ticks ([`vshake_kernel::resample`]). Harmonics at or above the file's Nyquist
//! frequency R/2 are left out, with a note.
//!
//! **Checks** (each a warning naming the test and the likely cause; an error under `--strict`):
//! `ref_disp_m` against the campaign's excitation (frequency within 2 %, amplitude within 5 %,
//! shape within 5 % rms); the kinematic consistency |A₁|/(ω²|X₁|) of the acceleration and
//! displacement channels (1 for one rigid body; 1/9.81 when the acceleration is in g, 1/1000
//! when the displacement is in mm); the sign of each channel's fundamental against the
//! reference (near ±180°: a flipped sign). Values beyond any physical range ([`LIMITS`]) are
//! errors, like NaN.

use crate::measured::campaign::{TestSpec, Weights};
use crate::measured::timebase::{self, TimeBase};
use crate::runs::spec::ExcitationSpec;
use std::f64::consts::PI;
use std::fmt;
use std::path::PathBuf;
use vshake_kernel::excitation::{Drive, Record, Reference, Sine};
use vshake_kernel::metrics::N_HARM;
use vshake_kernel::params::{ModelParams, G};

/// Required columns of a measured test.
pub const REQUIRED: [&str; 4] = ["time_s", "ref_disp_m", "disp_m", "accel_mps2"];
/// Optional columns of a measured test (read and checked when present).
pub const OPTIONAL: [&str; 5] = ["valve_cmd_v", "force_n", "p1_pa", "p2_pa", "spool_m"];

/// Largest magnitude each column may hold, with its unit [chosen: an order of magnitude or more
/// beyond any shake table (the LHPOST: ±0.75 m, 4.7 g bare, 6.8 MN, 20.7 MPa, ±10 V), so only
/// a corrupt cell or a wrong unit reaches it].
pub const LIMITS: [(&str, f64, &str); 9] = [
    ("time_s", 1.0e7, "s"),
    ("ref_disp_m", 10.0, "m"),
    ("disp_m", 10.0, "m"),
    ("accel_mps2", 100.0 * G, "m/s² (100 g)"),
    ("valve_cmd_v", 100.0, "V"),
    ("force_n", 1.0e9, "N"),
    ("p1_pa", 1.0e9, "Pa (1 GPa)"),
    ("p2_pa", 1.0e9, "Pa (1 GPa)"),
    ("spool_m", 1.0, "m"),
];

/// Named f64 columns read from one file (the shell reads; this layer checks).
#[derive(Debug, Clone)]
pub struct NumTable {
    pub file: PathBuf,
    pub names: Vec<String>,
    pub columns: Vec<Vec<f64>>,
    /// The 1-based line of data row 1 in a text file (messages then give the line too).
    pub first_line: Option<usize>,
    /// What the reader noticed (another separator, decimal commas).
    pub notes: Vec<String>,
}

impl NumTable {
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }
    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }
    /// A problem at a column and a 1-based data row.
    pub fn problem(
        &self,
        column: Option<&str>,
        row: Option<usize>,
        message: impl Into<String>,
    ) -> DataProblem {
        let mut place = String::new();
        if let Some(c) = column {
            place.push_str(&format!("column `{c}`"));
        }
        if let Some(r) = row {
            place.push_str(&format!(
                "{}row {r}",
                if place.is_empty() { "" } else { ", " }
            ));
            if let Some(l) = self.first_line {
                place.push_str(&format!(" (line {})", r + l - 1));
            }
        }
        DataProblem {
            file: self.file.display().to_string(),
            place,
            message: message.into(),
        }
    }

    /// The rebuilt time base of column `name`.
    pub fn time_base(&self, name: &str) -> Result<TimeBase, DataProblem> {
        let t = self.column(name).expect("time column was read");
        timebase::rebuild(t).map_err(|e| self.problem(Some(name), Some(e.row()), e.to_string()))
    }

    /// Magnitudes beyond [`LIMITS`]: the first offending row of each column, and how many.
    pub fn check_limits(&self) -> Vec<DataProblem> {
        let mut out = Vec::new();
        for (name, limit, unit) in LIMITS {
            let Some(col) = self.column(name) else {
                continue;
            };
            let beyond = col.iter().filter(|v| v.abs() > limit).count();
            if let Some((i, v)) = col.iter().enumerate().find(|(_, v)| v.abs() > limit) {
                let why = if beyond == 1 {
                    "a corrupt cell?".to_string()
                } else {
                    let hint = match name {
                        "disp_m" | "ref_disp_m" | "spool_m" => " (mm? vshake reads metres)",
                        "accel_mps2" => " (mm/s²? vshake reads m/s²)",
                        "p1_pa" | "p2_pa" => " (vshake reads Pa)",
                        _ => "",
                    };
                    format!("{beyond} rows are beyond it: the column is in another unit{hint}")
                };
                out.push(self.problem(
                    Some(name),
                    Some(i + 1),
                    format!(
                        "{v:e} is beyond any physical range (|value| ≤ {limit:e} {unit}): {why}"
                    ),
                ));
            }
        }
        out
    }
}

/// A problem with a data file: the file, the place (column, row, line) and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct DataProblem {
    pub file: String,
    pub place: String,
    pub message: String,
}

impl fmt::Display for DataProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.place.is_empty() {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{}: {}: {}", self.file, self.place, self.message)
        }
    }
}

/// What drives the model in a comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpenLoop {
    /// The measured valve command `valve_cmd_v` replaces the controller.
    Valve,
    /// The measured spool position `spool_m` replaces the controller and the valve's dynamics.
    Spool,
}

impl OpenLoop {
    pub fn column(self) -> &'static str {
        match self {
            OpenLoop::Valve => "valve_cmd_v",
            OpenLoop::Spool => "spool_m",
        }
    }
}

/// How the excitation's start was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// From `ref_disp_m` (sine).
    Detected,
    /// The campaign's `t0_s`.
    Given,
    /// The file's first row (record).
    FirstRow,
}

/// Where a test's excitation sits in its file.
#[derive(Debug, Clone, PartialEq)]
pub struct Alignment {
    pub time: TimeBase,
    /// Row (fractional) of the excitation's start: the model's t = 0.
    pub start_row: f64,
    pub start: Start,
    /// The first row after the excitation (rows from here on are not compared).
    pub end_row: usize,
    /// Rows of the analysis window, [w0, w1).
    pub window: (usize, usize),
    /// Whole cycles in the window (sine tests).
    pub cycles: Option<u32>,
}

impl Alignment {
    /// File time of the excitation's start, s.
    pub fn start_s(&self) -> f64 {
        self.time.time(self.start_row)
    }
    /// File time of the excitation's end (the instant after its last sample), s.
    pub fn end_s(&self) -> f64 {
        self.time.time(self.end_row as f64)
    }
    /// Recording before the excitation, s.
    pub(crate) fn pre_trigger_s(&self) -> f64 {
        (self.start_row / self.time.rate_hz).max(0.0)
    }
    /// Recording after the excitation, s.
    pub(crate) fn after_s(&self) -> f64 {
        (self.time.rows - self.end_row) as f64 / self.time.rate_hz
    }
}

/// The compared samples of a test: its analysis window in the file.
#[derive(Debug, Clone, PartialEq)]
pub struct Samples {
    /// The file's sample rate, Hz.
    pub rate_hz: f64,
    /// Model time of each sample (from the excitation's start), s.
    pub tau: Vec<f64>,
    /// File time of each sample (on the rebuilt grid), s.
    pub time: Vec<f64>,
    /// Reference displacement, velocity and acceleration at each sample.
    pub ref_x: Vec<f64>,
    pub ref_v: Vec<f64>,
    pub ref_a: Vec<f64>,
    /// The sine's frequency (None for a record), Hz.
    pub fundamental_hz: Option<f64>,
    /// Harmonics 1 … n_harm lie below the file's Nyquist frequency (≤ 9).
    pub n_harm: usize,
}

impl Samples {
    pub fn len(&self) -> usize {
        self.tau.len()
    }
    pub fn is_empty(&self) -> bool {
        self.tau.is_empty()
    }
}

/// Measured channels over the compared samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    pub accel: Vec<f64>,
    pub disp: Vec<f64>,
    pub force: Option<Vec<f64>>,
    pub p1: Option<Vec<f64>>,
    pub p2: Option<Vec<f64>>,
    pub valve_cmd: Option<Vec<f64>>,
    pub spool: Option<Vec<f64>>,
}

/// A measured test, ready to be compared with or fitted by the model.
#[derive(Debug, Clone)]
pub struct AlignedTest {
    pub name: String,
    pub file: PathBuf,
    pub excitation: ExcitationSpec,
    /// The campaign's model with the test's overrides.
    pub model: ModelParams,
    /// The effects the test's model table switches off ([`TestSpec::off`]).
    pub off: Vec<vshake_kernel::effects::EffectId>,
    pub weights: Weights,
    pub alignment: Alignment,
    /// The model's drive at the controller's ticks, lasting a tick beyond the last sample.
    pub drive: Reference,
    pub samples: Samples,
    pub measured: Measured,
    /// What was done to read the file (rounded time rebuilt, a pre-trigger, omitted harmonics).
    pub notes: Vec<String>,
    /// What looks wrong with the file (an error under `--strict`).
    pub warnings: Vec<String>,
}

/// Where the excitation sits in a file: its start (a fractional row), how the start was found,
/// its end, the whole cycles of a sine's window, and a record's reference.
struct Located {
    start_row: f64,
    start: Start,
    end_row: usize,
    cycles: Option<u32>,
    record: Option<Reference>,
}

/// Aligns a measured test to the model; `record` is the table holding a record excitation's
/// column when it is another file than the test's data. Every problem of the file is returned.
pub fn align(
    test: &TestSpec,
    data: &NumTable,
    record: Option<&NumTable>,
    open_loop: Option<OpenLoop>,
) -> Result<AlignedTest, Vec<DataProblem>> {
    let time = check_file(data, open_loop)?;
    let mut data = data.clone();
    let data = &mut data;
    let mut notes = data.notes.clone();
    notes.extend(time.note());
    notes.extend(remove_offsets(test, data, &time));
    let mut warnings = Vec::new();
    let (rate, rows) = (time.rate_hz, time.rows);
    let located = locate(test, data, record, &time, &mut warnings)?;
    let (start_row, start, end_row, cycles) = (
        located.start_row,
        located.start,
        located.end_row,
        located.cycles,
    );
    let window = analysis_window(test, data, &located, rate)?;
    let tau: Vec<f64> = (window.0..window.1)
        .map(|n| (n as f64 - start_row) / rate)
        .collect();
    let drive = model_drive(
        test,
        data,
        located.record,
        &tau,
        (start_row, rate),
        open_loop,
    );
    let (ref_x, ref_v, ref_a) = reference_states(&test.excitation, &drive, &tau);
    let (fundamental_hz, n_harm) = harmonics_in(test, data, rate, &mut notes)?;
    let measured = measured_channels(data, window);
    let alignment = Alignment {
        time,
        start_row,
        start,
        end_row,
        window,
        cycles,
    };
    notes.extend(alignment.notes(rows));
    let samples = Samples {
        rate_hz: rate,
        time: (window.0..window.1)
            .map(|n| alignment.time.time(n as f64))
            .collect(),
        tau,
        ref_x,
        ref_v,
        ref_a,
        fundamental_hz,
        n_harm,
    };
    warnings.extend(
        channel_checks(&samples, &measured)
            .into_iter()
            .map(|w| format!("test {:?}: {w}", test.name)),
    );
    Ok(AlignedTest {
        name: test.name.clone(),
        file: data.file.clone(),
        excitation: test.excitation.clone(),
        model: model_for(test, open_loop),
        off: test.off.clone(),
        weights: test.weights,
        alignment,
        drive,
        samples,
        measured,
        notes,
        warnings,
    })
}

/// Rows before the tracked reference moves that a feedback's static offset is measured over
/// at least, else over its whole quiet lead. [chosen: 16, a standard error of a quarter of the
/// noise's σ.]
pub const OFFSET_STILL_ROWS: usize = 16;

/// Rows at rest that a static offset is measured over at least [chosen: a quiet lead shorter
/// than this cannot tell an offset from the first samples of the motion].
pub const OFFSET_MIN_LEAD_S: f64 = 0.05;

/// Removes a static offset of `ref_disp_m` and `disp_m` (a table homed off zero, a transducer
/// not zeroed): the mean over the file's quiet lead, the rows before the column first leaves its
/// starting level by more than its noise, where that lead lasts [`OFFSET_MIN_LEAD_S`] or more and
/// the offset exceeds both its noise and 0.1 % of the column's motion about it. The model starts
/// at rest at zero (docs/model.md §4), so an offset would otherwise read as motion: the start of
/// the excitation found at the first row, the phase of a sine off. Returns a note per column.
fn remove_static_offsets(data: &mut NumTable, rate_hz: f64) -> Vec<String> {
    let mut notes = Vec::new();
    for name in ["ref_disp_m", "disp_m"] {
        let Some(i) = data.names.iter().position(|n| n == name) else {
            continue;
        };
        let reference = (name == "disp_m")
            .then(|| data.column("ref_disp_m"))
            .flatten();
        let Some((offset, lead)) = static_offset(&data.columns[i], reference, rate_hz) else {
            continue;
        };
        data.columns[i].iter_mut().for_each(|x| *x -= offset);
        notes.push(format!(
            "{name} rests at {:+.4} mm for the first {:.3} s (a static offset: the table homed off zero, or the transducer not zeroed); removed, so that the column starts from zero as the model does",
            offset * 1e3,
            lead as f64 / rate_hz
        ));
    }
    notes
}

/// Removes static offsets of `ref_disp_m` and `disp_m`: measured over the file's quiet lead
/// where the reference has one ([`remove_static_offsets`]); else, for a sine test, the
/// reference's offset from the campaign's sine, removed from both columns
/// ([`remove_sine_offset`]; a lead of `disp_m` alone, shorter than the reference's, holds the
/// first motion too); else a lead of `disp_m` alone, or without one its mean difference from
/// the reference ([`remove_feedback_offset`]). Returns the notes.
fn remove_offsets(test: &TestSpec, data: &mut NumTable, time: &TimeBase) -> Vec<String> {
    let ref_lead = (data.column("ref_disp_m")).and_then(|r| static_offset(r, None, time.rate_hz));
    if let (None, ExcitationSpec::Sine { sine, .. }) = (ref_lead, &test.excitation) {
        if let Some(note) = remove_sine_offset(test, sine, data, time) {
            return vec![note];
        }
    }
    let mut notes = remove_static_offsets(data, time.rate_hz);
    let no_lead = |x: &[f64]| quiet_lead(x, time.rate_hz).is_none();
    if data.column("disp_m").is_some_and(no_lead) {
        notes.extend(remove_feedback_offset(data));
    }
    notes
}

/// Removes a static offset of a sine test's `ref_disp_m` (and the same from `disp_m`: the table
/// homed off zero moves both) where the file has no quiet lead to measure it over (the recording
/// starts with the excitation): the mean of the column less the campaign's sine over the
/// excitation as aligned, refined by aligning again without it (the mean over whole cycles hardly
/// depends on the start, so a few passes converge). Removed where it exceeds 0.1 % of the sine's
/// amplitude and ten standard errors of that mean. Returns the note.
fn remove_sine_offset(
    test: &TestSpec,
    sine: &Sine,
    data: &mut NumTable,
    time: &TimeBase,
) -> Option<String> {
    let i = data.names.iter().position(|n| n == "ref_disp_m")?;
    let rate_hz = time.rate_hz;
    // The excitation's end as the column shows it, not its duration_s: a start misplaced by the
    // offset could put that past the file's end.
    let given = test.t0_s.map(|t| (t - time.t0_s) * rate_hz);
    let mut r = data.columns[i].clone();
    let mut total = 0.0;
    for _ in 0..4 {
        let fit = align_sine(sine, &r, rate_hz, given, None);
        if fit.error.is_some() {
            return None;
        }
        let (lo, hi) = (fit.start_row.ceil().max(0.0) as usize, fit.end_row);
        if hi <= lo + 1 {
            return None;
        }
        let e: Vec<f64> = (lo..hi)
            .map(|k| r[k] - sine.displacement((k as f64 - fit.start_row) / rate_hz))
            .collect();
        let mean = e.iter().sum::<f64>() / e.len() as f64;
        let spread = (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / e.len() as f64).sqrt();
        if mean.abs() <= (1e-3 * sine.amp_m).max(10.0 * spread / (e.len() as f64).sqrt()) {
            break;
        }
        total += mean;
        r.iter_mut().for_each(|v| *v -= mean);
    }
    if total == 0.0 {
        return None;
    }
    for name in ["ref_disp_m", "disp_m"] {
        if let Some(k) = data.names.iter().position(|n| n == name) {
            data.columns[k].iter_mut().for_each(|v| *v -= total);
        }
    }
    Some(format!(
        "ref_disp_m is offset by {:+.4} mm from the campaign's sine over the excitation (a static offset: the table homed off zero; the file has no quiet lead to measure it over); removed from ref_disp_m and disp_m",
        total * 1e3
    ))
}

/// The static offset of column `x` and the rows of its quiet lead (see
/// [`remove_static_offsets`]), or None where there is none to remove. With the tracked
/// `reference` (the feedback's, its own offset removed), the offset is x's mean over the lead's
/// rows before the reference leaves its level by x's noise σ (at least [`OFFSET_STILL_ROWS`] of
/// them; else the whole lead): the lead ends only where x leaves its level by several σ, so it
/// holds the excitation's first motion (a taper's start), which its mean would count as offset,
/// up to a few σ; before the reference moves, the table cannot have.
fn static_offset(x: &[f64], reference: Option<&[f64]>, rate_hz: f64) -> Option<(f64, usize)> {
    let (lead, sigma) = quiet_lead(x, rate_hz)?;
    let still = reference.map_or(lead, |r| {
        let level = r.first().copied().unwrap_or(0.0);
        (r[..lead.min(r.len())].iter())
            .position(|v| (v - level).abs() > sigma)
            .unwrap_or(lead)
    });
    let rows = if still >= OFFSET_STILL_ROWS {
        still
    } else {
        lead
    };
    let offset = x[..rows].iter().sum::<f64>() / rows as f64;
    let motion = x.iter().map(|v| (v - offset).abs()).fold(0.0, f64::max);
    (offset.abs() > (10.0 * sigma).max(1e-3 * motion)).then_some((offset, lead))
}

/// The rows of column `x`'s quiet lead (before it first leaves its starting level by more than
/// its noise), with that noise σ; None where the lead is shorter than [`OFFSET_MIN_LEAD_S`] or
/// the column never moves.
fn quiet_lead(x: &[f64], rate_hz: f64) -> Option<(usize, f64)> {
    let n = x.len();
    let head = &x[..n.min(16)];
    let mut sorted = head.to_vec();
    sorted.sort_by(f64::total_cmp);
    let level = sorted[sorted.len() / 2];
    let sigma = noise_of(&x[..n.min(64)]);
    let amplitude = x.iter().map(|v| (v - level).abs()).fold(0.0, f64::max);
    let band = (8.0 * sigma).max(1e-6 * amplitude);
    let lead = x.iter().position(|v| (v - level).abs() > band).unwrap_or(n);
    ((lead as f64) >= OFFSET_MIN_LEAD_S * rate_hz && lead < n).then_some((lead, sigma))
}

/// The noise σ of `x` from its second differences (robust: their median absolute value; the
/// second difference of white noise has √6 its standard deviation, that of a smooth motion
/// sampled finely almost none, so a column moving from its first row does not pass its motion
/// off as noise).
fn noise_of(x: &[f64]) -> f64 {
    let mut d: Vec<f64> = x
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).map_or(0.0, |m| 1.4826 * m / 6f64.sqrt())
}

/// Removes a steady offset of `disp_m` from `ref_disp_m` where `disp_m` has no quiet lead to
/// measure it over (the file starts with the motion): the median of disp_m − ref_disp_m over the
/// first rows, while the reference is at rest at zero (within [chosen: 0.1 %] of its peak, and
/// moving at under 0.1 % of its peak rate), where there are [`OFFSET_MIN_ROWS`] such rows and the offset
/// exceeds 0.1 % of the reference's motion and ten of their noise's standard errors. There the
/// loop has nothing to track, so what is left is the transducer's zero; over the motion the
/// tracking error would be mixed in. Returns the note.
fn remove_feedback_offset(data: &mut NumTable) -> Option<String> {
    let (r, y) = (data.column("ref_disp_m")?, data.column("disp_m")?);
    let motion = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let rate = |i: usize| r[(i + 1).min(r.len() - 1)] - r[i.saturating_sub(1)];
    let peak_rate = (0..r.len()).fold(0.0f64, |m, i| m.max(rate(i).abs()));
    let mut e: Vec<f64> = (0..r.len())
        .take_while(|&i| r[i].abs() <= 1e-3 * motion && rate(i).abs() <= 1e-3 * peak_rate)
        .map(|i| y[i] - r[i])
        .collect();
    if e.len() < OFFSET_MIN_ROWS {
        return None;
    }
    e.sort_by(f64::total_cmp);
    let offset = e[e.len() / 2];
    let mut dev: Vec<f64> = e.iter().map(|v| (v - offset).abs()).collect();
    dev.sort_by(f64::total_cmp);
    let sd = 1.4826 * dev[dev.len() / 2];
    if !(offset.abs() > (1e-3 * motion).max(10.0 * sd / (e.len() as f64).sqrt())) {
        return None;
    }
    let i = data.names.iter().position(|c| c == "disp_m")?;
    data.columns[i].iter_mut().for_each(|v| *v -= offset);
    Some(format!(
        "disp_m is {:+.4} mm from ref_disp_m where the reference rests at zero (its first {} rows; the file has no quiet lead to measure an offset over): a transducer not zeroed; removed",
        offset * 1e3,
        e.len()
    ))
}

/// Rows at rest a feedback offset is measured over at least [chosen].
const OFFSET_MIN_ROWS: usize = 8;

/// Where the test's excitation sits in the file, by its kind.
fn locate(
    test: &TestSpec,
    data: &NumTable,
    record: Option<&NumTable>,
    time: &TimeBase,
    warnings: &mut Vec<String>,
) -> Result<Located, Vec<DataProblem>> {
    Ok(match &test.excitation {
        ExcitationSpec::Sine { sine, .. } => locate_sine(test, sine, data, time, warnings)?,
        ExcitationSpec::Record {
            column,
            time_column,
            ..
        } => locate_record(test, (column, time_column), data, record, time)?,
        generated => locate_generated(test, generated, data, time)?,
    })
}

/// The model's drive at the controller's ticks, lasting a tick beyond the last sample (`tau`):
/// the sine's or the located reference, its drive replaced by the measured one in open loop.
fn model_drive(
    test: &TestSpec,
    data: &NumTable,
    record: Option<Reference>,
    tau: &[f64],
    (start_row, rate): (f64, f64),
    open_loop: Option<OpenLoop>,
) -> Reference {
    let f_s = test.model.controller.f_s;
    let n_ticks = (tau[tau.len() - 1] * f_s).floor() as usize + 2;
    let mut drive = match (&test.excitation, record) {
        (ExcitationSpec::Sine { sine, .. }, _) => Sine {
            duration_s: n_ticks as f64 / f_s,
            window_cycles: None,
            ..*sine
        }
        .reference(f_s),
        (_, Some(r)) => r,
        (_, None) => unreachable!("a record or a generated motion has its reference"),
    };
    drive.hold_to(n_ticks);
    if let Some(mode) = open_loop {
        drive.drive = measured_drive(
            mode,
            data.column(mode.column()).expect("checked"),
            start_row,
            rate,
            f_s,
            drive.len(),
        );
    }
    drive
}

/// The measured channels over the analysis window (rows `window.0..window.1`).
fn measured_channels(data: &NumTable, window: (usize, usize)) -> Measured {
    let slice = |n: &str| data.column(n).map(|c| c[window.0..window.1].to_vec());
    Measured {
        accel: slice("accel_mps2").expect("required"),
        disp: slice("disp_m").expect("required"),
        force: slice("force_n"),
        p1: slice("p1_pa"),
        p2: slice("p2_pa"),
        valve_cmd: slice("valve_cmd_v"),
        spool: slice("spool_m"),
    }
}

/// The file's magnitudes, its time base and the column an open loop needs.
fn check_file(data: &NumTable, open_loop: Option<OpenLoop>) -> Result<TimeBase, Vec<DataProblem>> {
    let mut problems = data.check_limits();
    let time = data.time_base("time_s").map_err(|p| problems.push(p)).ok();
    if let Some(mode) = open_loop {
        if data.column(mode.column()).is_none() {
            let word = match mode {
                OpenLoop::Valve => "valve",
                OpenLoop::Spool => "spool",
            };
            problems.push(data.problem(
                Some(mode.column()),
                None,
                format!("missing; `--open-loop {word}` drives the model with it"),
            ));
        }
    }
    match time {
        Some(t) if problems.is_empty() => Ok(t),
        _ => Err(problems),
    }
}

/// The test's model as driven: a measured spool already holds the valve's delay and dynamics,
/// so the effects that move the spool are off.
fn model_for(test: &TestSpec, open_loop: Option<OpenLoop>) -> ModelParams {
    let mut model = test.model.clone();
    if open_loop == Some(OpenLoop::Spool) {
        for e in vshake_kernel::effects::EffectId::ALL
            .into_iter()
            .filter(|e| e.moves_spool())
        {
            *model.effects.get_mut(e) = false;
        }
    }
    model
}

/// A sine's start and end in the file (given by `t0_s` or found from `ref_disp_m`) and its
/// window's whole cycles.
fn locate_sine(
    test: &TestSpec,
    sine: &Sine,
    data: &NumTable,
    time: &TimeBase,
    warnings: &mut Vec<String>,
) -> Result<Located, Vec<DataProblem>> {
    let rate = time.rate_hz;
    let given = test.t0_s.map(|t| (t - time.t0_s) * rate);
    let fit = align_sine(
        sine,
        data.column("ref_disp_m").expect("required column"),
        rate,
        given,
        test.duration_given.then_some(sine.duration_s),
    );
    warnings.extend(
        fit.warnings
            .iter()
            .map(|w| format!("test {:?}: {w}", test.name)),
    );
    if let Some(e) = fit.error {
        return Err(vec![data.problem(
            None,
            None,
            format!("test {:?}: {e}", test.name),
        )]);
    }
    let motion_s = (fit.end_row as f64 - fit.start_row) / rate;
    // The default window counts the cycles in the motion as found, give or take the sample at
    // each end (the end is found to a sample).
    let n = if test.window_given {
        sine.window_cycles.unwrap_or(0)
    } else {
        Sine {
            duration_s: motion_s + 1.0 / rate,
            ..*sine
        }
        .default_cycles()
    };
    if n == 0 {
        return Err(vec![data.problem(None, None, format!(
            "test {:?}: the excitation lasts {motion_s:.3} s in the file (from t = {:.4} s): too short for a whole cycle after taper_s + 1 s",
            test.name,
            time.time(fit.start_row)
        ))]);
    }
    let start = if given.is_some() {
        Start::Given
    } else {
        Start::Detected
    };
    Ok(Located {
        start_row: fit.start_row,
        start,
        end_row: fit.end_row,
        cycles: Some(n),
        record: None,
    })
}

/// A record's reference (from `t0_s`, else its first sample, on the data's clock) and the rows
/// it spans in the file; a displacement beyond the stroke is refused at its row.
fn locate_record(
    test: &TestSpec,
    (column, time_column): (&str, &str),
    data: &NumTable,
    record: Option<&NumTable>,
    time: &TimeBase,
) -> Result<Located, Vec<DataProblem>> {
    let ExcitationSpec::Record {
        scale, unit, pga_g, ..
    } = &test.excitation
    else {
        unreachable!("a record")
    };
    let source = record.unwrap_or(data);
    let Some(values) = source.column(column) else {
        return Err(vec![source.problem(
            Some(column),
            None,
            format!("missing: the record of test {:?}", test.name),
        )]);
    };
    let rec_time = if record.is_some() {
        source.time_base(time_column).map_err(|p| vec![p])?
    } else {
        time.clone()
    };
    let t0 = test.t0_s.unwrap_or(rec_time.t0_s);
    let first = ((t0 - rec_time.t0_s) * rec_time.rate_hz).ceil().max(0.0) as usize;
    let rec_t: Vec<f64> = (first..values.len())
        .map(|i| rec_time.time(i as f64) - t0)
        .collect();
    let rec_x = crate::runs::quake::scaled(&values[first..], *unit, *scale, *pga_g);
    if rec_t.len() < 2 {
        return Err(vec![source.problem(
            Some(column),
            None,
            format!(
                "test {:?}: fewer than two record samples after t0_s",
                test.name
            ),
        )]);
    }
    let r = record_reference(
        test,
        (source, column),
        first,
        (rec_t, rec_x),
        rec_time.rate_hz,
    )?;
    let f_s = test.model.controller.f_s;
    let span = (r.len() - 1) as f64 / f_s;
    let rate = time.rate_hz;
    let start_row = ((t0 - time.t0_s) * rate).max(0.0);
    let end_row = (((span + t0 - time.t0_s) * rate + 1e-6).floor() as usize + 1).min(time.rows);
    let start = if test.t0_s.is_some() {
        Start::Given
    } else {
        Start::FirstRow
    };
    Ok(Located {
        start_row,
        start,
        end_row,
        cycles: None,
        record: Some(r),
    })
}

/// A record's reference at the controller's rate: integrated from an acceleration, or its
/// displacement samples (each within the stroke, else refused at its row); within the limits.
fn record_reference(
    test: &TestSpec,
    (source, column): (&NumTable, &str),
    first: usize,
    (rec_t, rec_x): (Vec<f64>, Vec<f64>),
    rate_hz: f64,
) -> Result<Reference, Vec<DataProblem>> {
    let ExcitationSpec::Record {
        f_ref_hz,
        scale,
        unit,
        processing,
        signal,
        ..
    } = &test.excitation
    else {
        unreachable!("a record")
    };
    let f_s = test.model.controller.f_s;
    let r = if unit.is_acceleration() {
        let filter = (*f_ref_hz, *signal);
        crate::runs::quake::from_acceleration(&rec_x, 0.0, 1.0 / rate_hz, processing, filter, f_s)
    } else {
        let l = test.model.actuator.l;
        if let Some((i, v)) = rec_x.iter().enumerate().find(|(_, v)| v.abs() >= l) {
            return Err(vec![source.problem(Some(column), Some(first + i + 1), format!("displacement {v} m (after unit {} and scale {scale}) exceeds the stroke (half stroke actuator.l = {l} m)", unit.name()))]);
        }
        Record {
            time_s: rec_t,
            disp_m: rec_x,
            f_ref_hz: *f_ref_hz,
            signal: *signal,
        }
        .reference(f_s)
    };
    crate::runs::limits::check_limits(&r, &test.model).map_err(|m| {
        vec![source.problem(Some(column), None, format!("test {:?}: {m}", test.name))]
    })?;
    Ok(r)
}

/// A generated motion (stochastic, sweep, random) in a measured test: its reference from the
/// campaign (its own `seed`, else 0), starting at `t0_s` or the file's first row.
fn locate_generated(
    test: &TestSpec,
    excitation: &ExcitationSpec,
    data: &NumTable,
    time: &TimeBase,
) -> Result<Located, Vec<DataProblem>> {
    let r = crate::runs::quake::generated(excitation, &test.model, 0, 0)
        .map_err(|m| vec![data.problem(None, None, format!("test {:?}: {m}", test.name))])?;
    let t0 = test.t0_s.unwrap_or(time.t0_s);
    let span = (r.len() - 1) as f64 / test.model.controller.f_s;
    let start_row = ((t0 - time.t0_s) * time.rate_hz).max(0.0);
    let end_row =
        (((span + t0 - time.t0_s) * time.rate_hz + 1e-6).floor() as usize + 1).min(time.rows);
    let start = if test.t0_s.is_some() {
        Start::Given
    } else {
        Start::FirstRow
    };
    Ok(Located {
        start_row,
        start,
        end_row,
        cycles: None,
        record: Some(r),
    })
}

/// The analysis window, in the file's rows: a sine's last whole cycles, a record's span.
fn analysis_window(
    test: &TestSpec,
    data: &NumTable,
    at: &Located,
    rate: f64,
) -> Result<(usize, usize), Vec<DataProblem>> {
    let w_first = at.start_row.ceil().max(0.0) as usize;
    let window = match (&test.excitation, at.cycles) {
        (ExcitationSpec::Sine { sine, .. }, Some(n)) => {
            let len = (n as f64 * rate / sine.freq_hz).round() as usize;
            if len > at.end_row.saturating_sub(w_first) {
                return Err(vec![data.problem(None, None, format!(
                    "test {:?}: {n} whole cycles ({:.3} s) do not fit in the excitation's {:.3} s in the file",
                    test.name,
                    n as f64 / sine.freq_hz,
                    (at.end_row as f64 - at.start_row) / rate
                ))]);
            }
            (at.end_row - len, at.end_row)
        }
        _ => (w_first, at.end_row),
    };
    if window.1 <= window.0 + 1 {
        return Err(vec![data.problem(
            None,
            None,
            format!(
                "test {:?}: no samples to compare after the excitation's start",
                test.name
            ),
        )]);
    }
    Ok(window)
}

/// Open loop: the measured column `c` at the model's `n` ticks (linear between the file's
/// samples).
fn measured_drive(
    mode: OpenLoop,
    c: &[f64],
    start_row: f64,
    rate: f64,
    f_s: f64,
    n: usize,
) -> Drive {
    let rows = c.len();
    let at = |k: usize| {
        let q = start_row + k as f64 * rate / f_s;
        let i = q.floor().clamp(0.0, (rows - 1) as f64) as usize;
        let w = (q - i as f64).clamp(0.0, 1.0);
        if w == 0.0 || i + 1 >= rows {
            c[i.min(rows - 1)]
        } else {
            c[i] + w * (c[i + 1] - c[i])
        }
    };
    let v: Vec<f64> = (0..n).map(at).collect();
    match mode {
        OpenLoop::Valve => Drive::ValveCommand(v),
        OpenLoop::Spool => Drive::Spool(v),
    }
}

/// Reference states at the samples' model times: analytic for a sine, from the ticks for a record.
fn reference_states(
    excitation: &ExcitationSpec,
    drive: &Reference,
    tau: &[f64],
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    match excitation {
        ExcitationSpec::Sine { sine, .. } => {
            let st: Vec<[f64; 4]> = tau.iter().map(|&t| sine.states(t)).collect();
            (
                st.iter().map(|s| s[0]).collect(),
                st.iter().map(|s| s[1]).collect(),
                st.iter().map(|s| s[2]).collect(),
            )
        }
        _ => (
            tau.iter().map(|&t| drive.at_time(&drive.x, t)).collect(),
            tau.iter().map(|&t| drive.at_time(&drive.v, t)).collect(),
            tau.iter().map(|&t| drive.at_time(&drive.a, t)).collect(),
        ),
    }
}

/// A sine's fundamental and the harmonics below the file's Nyquist frequency (a note names
/// those left out; a fundamental at or above it is refused).
fn harmonics_in(
    test: &TestSpec,
    data: &NumTable,
    rate: f64,
    notes: &mut Vec<String>,
) -> Result<(Option<f64>, usize), Vec<DataProblem>> {
    let ExcitationSpec::Sine { sine, .. } = &test.excitation else {
        return Ok((None, 0));
    };
    let f = sine.freq_hz;
    let n_harm = (1..=N_HARM)
        .take_while(|&k| (k as f64) * f < 0.5 * rate)
        .count();
    if n_harm == 0 {
        return Err(vec![data.problem(Some("time_s"), None, format!("test {:?}: its {f} Hz excitation is at or above the file's Nyquist frequency ({} Hz)", test.name, 0.5 * rate))]);
    }
    if n_harm < N_HARM {
        notes.push(format!(
            "h{}{} ({} Hz and up) at or above the Nyquist frequency of a {} Hz file ({} Hz): left out",
            n_harm + 1,
            if n_harm + 1 < N_HARM { format!("…h{N_HARM}") } else { String::new() },
            (n_harm + 1) as f64 * f,
            timebase::fmt_rate(rate),
            0.5 * rate
        ));
    }
    Ok((Some(f), n_harm))
}

impl Alignment {
    /// What the comparison leaves out of a file of `rows` rows: the recording before the
    /// excitation (a pre-trigger) and after it.
    fn notes(&self, rows: usize) -> Vec<String> {
        let mut notes = Vec::new();
        if self.start_row >= 1.0 && self.start != Start::FirstRow {
            notes.push(format!(
                "the excitation starts at t = {:.4} s (row {}; {}): {:.3} s of recording before it are not compared",
                self.start_s(),
                fmt_row(self.start_row),
                if self.start == Start::Given { "t0_s" } else { "found from ref_disp_m" },
                self.pre_trigger_s()
            ));
        }
        if self.end_row < rows {
            // A row or two (a record a sample longer than its excitation) in rows, not "0.000 s".
            let after = match rows - self.end_row {
                1 => "row recorded after it is".to_string(),
                k if self.after_s() < 0.01 => format!("{k} rows recorded after it are"),
                _ => format!("{:.3} s recorded after it are", self.after_s()),
            };
            notes.push(format!(
                "the excitation ends at t = {:.4} s: the {after} not compared",
                self.end_s()
            ));
        }
        notes
    }
}

/// The outcome of aligning a sine to `ref_disp_m`.
struct SineFit {
    start_row: f64,
    end_row: usize,
    warnings: Vec<String>,
    error: Option<String>,
}

/// Σ (r_n − x_r((n − s)/R))² over rows [lo, hi).
fn misfit(sine: &Sine, r: &[f64], rate: f64, s: f64, lo: usize, hi: usize) -> f64 {
    (lo..hi)
        .map(|n| (r[n] - sine.displacement((n as f64 - s) / rate)).powi(2))
        .sum()
}

/// Golden-section minimum of `f` on [a, b] to `tol`.
fn golden(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64, tol: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    while (b - a).abs() > tol {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

/// Frequency from the zero crossings of `r` over rows [lo, hi) (None with fewer than three).
fn crossing_freq(r: &[f64], rate: f64, lo: usize, hi: usize) -> Option<f64> {
    let mut first = None;
    let mut last = 0.0;
    let mut count = 0usize;
    for n in lo.max(1)..hi {
        let (a, b) = (r[n - 1], r[n]);
        if (a < 0.0) != (b < 0.0) && a != b {
            let t = (n as f64 - 1.0 + a / (a - b)) / rate;
            first.get_or_insert(t);
            last = t;
            count += 1;
        }
    }
    let first = first?;
    (count >= 3 && last > first).then(|| (count - 1) as f64 / (2.0 * (last - first)))
}

/// Finds the start and end of `sine` in `r` (see the module docs).
fn align_sine(
    sine: &Sine,
    r: &[f64],
    rate: f64,
    given_row: Option<f64>,
    duration: Option<f64>,
) -> SineFit {
    let n = r.len();
    let p = rate / sine.freq_hz;
    let mut out = SineFit {
        start_row: 0.0,
        end_row: n,
        warnings: Vec::new(),
        error: None,
    };
    let peak = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let onset = r.iter().position(|v| v.abs() > 0.01 * peak);
    let start = match (given_row, onset) {
        (Some(s), _) => s,
        (None, None) => {
            out.warnings.push("ref_disp_m is zero throughout: the file holds no excitation (is it the right file?); the excitation is taken to start at the first row".into());
            0.0
        }
        (None, Some(on)) => detect_start(sine, r, rate, on as f64),
    };
    out.start_row = start;
    let first = start.ceil().max(0.0) as usize;
    if first >= n {
        out.error = Some(format!(
            "the excitation would start at row {:.1}, after the file's last row ({n})",
            start + 1.0
        ));
        return out;
    }
    let detected_end = end_of_sine(
        sine,
        r,
        rate,
        start,
        ((start + sine.taper_s * rate + 2.0 * p).ceil() as usize).clamp(first + 1, n),
    );
    out.end_row = match duration {
        Some(d) => {
            let end = (start + d * rate - 1e-6).ceil().max(0.0) as usize;
            if end > n {
                out.error = Some(format!(
                    "the file ends {:.4} s into the excitation, before its duration_s = {d} s (it starts at row {:.1}); the file is too short",
                    (n as f64 - start) / rate,
                    start + 1.0
                ));
                return out;
            }
            if detected_end + 1 < end && onset.is_some() {
                out.warnings.push(format!("ref_disp_m leaves the campaign's sine {:.3} s into the excitation, before its duration_s = {d} s", (detected_end as f64 - start) / rate));
            }
            end
        }
        None => detected_end,
    };
    if onset.is_some() {
        out.warnings
            .extend(mismatch(sine, r, rate, start, out.end_row));
    }
    out
}

/// The excitation's start (a fractional row) from the reference column, given its onset `on`
/// (the first row above 1 % of its peak).
fn detect_start(sine: &Sine, r: &[f64], rate: f64, on: f64) -> f64 {
    let (n, f, p) = (r.len(), sine.freq_hz, rate / sine.freq_hz);
    // The start modulo a period, from the phase of the steady sine after the taper.
    let s0 = (on + sine.taper_s * rate).ceil() as usize;
    let cyc = ((n.saturating_sub(s0)) as f64 / p).floor().min(4.0);
    let s_phase = if cyc >= 1.0 {
        let (mut a, mut b) = (0.0, 0.0);
        for k in s0..(s0 + (cyc * p).round() as usize).min(n) {
            let th = 2.0 * PI * f * k as f64 / rate;
            a += r[k] * th.sin();
            b += r[k] * th.cos();
        }
        ((-b).atan2(a) / (2.0 * PI)).rem_euclid(1.0) * p
    } else {
        on
    };
    let region = ((on + sine.taper_s * rate + 2.0 * p).ceil() as usize).min(n);
    let lo = on - 0.2 * sine.taper_s * rate - 1.5 * p;
    let m0 = ((lo - s_phase) / p).floor() as i64;
    let m1 = ((on + 0.5 * p - s_phase) / p).ceil() as i64;
    let best = (m0..=m1)
        .map(|m| s_phase + m as f64 * p)
        .filter(|s| *s >= lo && *s <= on + 0.5 * p)
        .min_by(|a, b| {
            misfit(sine, r, rate, *a, 0, region).total_cmp(&misfit(sine, r, rate, *b, 0, region))
        })
        .unwrap_or(on);
    let s1 = golden(
        |s| misfit(sine, r, rate, s, 0, region),
        best - 0.25 * p,
        best + 0.25 * p,
        1e-9,
    );
    // Where the column leaves the sine, then the start again over the whole excitation.
    let end = end_of_sine(sine, r, rate, s1, region);
    let s2 = golden(
        |s| misfit(sine, r, rate, s, 0, end),
        s1 - 1.0,
        s1 + 1.0,
        1e-9,
    );
    // [chosen] A start within 0.01 row of a row is that row (0.01 row is 5 µs at 2 kHz, 0.02°
    // of a 10 Hz fundamental): a reference column interpolated between controller ticks moves
    // the fitted start by that much.
    if (s2 - s2.round()).abs() < 0.01 {
        s2.round()
    } else {
        s2
    }
}

/// A warning when the reference column between `start` and `end` is not the campaign's sine
/// (another frequency, amplitude or shape), with the likely cause.
fn mismatch(sine: &Sine, r: &[f64], rate: f64, start: f64, end: usize) -> Option<String> {
    let (x, f) = (sine.amp_m, sine.freq_hz);
    let (lo, hi) = (start.ceil().max(0.0) as usize, end);
    let rms_ref = (misfit(sine, r, rate, start, lo, hi) / (hi - lo).max(1) as f64).sqrt();
    let shape = rms_ref / (x / 2f64.sqrt());
    let steady = ((start + sine.taper_s * rate).ceil().max(0.0) as usize).min(hi);
    let f_hat = crossing_freq(r, rate, steady, hi).or_else(|| crossing_freq(r, rate, lo, hi));
    let a_hat = r[steady..hi].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let f_off = f_hat.is_some_and(|fh| (fh / f - 1.0).abs() > 0.02);
    let a_off = steady < hi && (a_hat / x - 1.0).abs() > 0.05;
    if !(f_off || a_off || shape > 0.05) {
        return None;
    }
    let mut w = format!(
        "ref_disp_m does not match the campaign's excitation (sine {f} Hz, {x:.4} m): it oscillates at {} with amplitude {a_hat:.4} m, an rms mismatch of {:.0} % after alignment",
        f_hat.map_or("no clear frequency".to_string(), |v| format!("{v:.3} Hz")),
        100.0 * shape
    );
    if a_off && (a_hat / x / 1000.0 - 1.0).abs() < 0.05 {
        w.push_str(": ref_disp_m in mm?");
    } else if f_off {
        w.push_str(": the file of another test?");
    } else {
        w.push_str(": the file of another test, or another unit?");
    }
    Some(w)
}

/// The first row, after `from`, where `r` leaves the sine started at row `s` for at least a
/// quarter cycle (the file's end when it never does).
fn end_of_sine(sine: &Sine, r: &[f64], rate: f64, s: f64, from: usize) -> usize {
    let n = r.len();
    // A start fitted past the file's end (a column that is a few rows long) leaves nothing.
    let first = (s.ceil().max(0.0) as usize).min(n);
    let from = from.clamp(first, n);
    let e = |k: usize| r[k] - sine.displacement((k as f64 - s) / rate);
    // The column's own mismatch where it surely follows the sine (noise, rounding).
    let own = if from > first {
        ((first..from).map(|k| e(k).powi(2)).sum::<f64>() / (from - first) as f64).sqrt()
    } else {
        0.0
    };
    let tol = (1e-3 * sine.amp_m).max(6.0 * own);
    let quarter = ((rate / sine.freq_hz / 4.0).round() as usize).max(3);
    let mut k = from;
    while k < n {
        if e(k).abs() > tol {
            // A departure in the file's last quarter cycle is not one: too short to tell from
            // an edge effect of the export (a held or interpolated last sample).
            if k + quarter > n {
                return n;
            }
            let hi = k + quarter;
            let rms = ((k..hi).map(|j| e(j).powi(2)).sum::<f64>() / (hi - k) as f64).sqrt();
            if rms > tol {
                // Rows just before, already at the level the column keeps after the sine (it
                // stopped at a zero crossing, say), belong to what follows.
                let level = r[k];
                while k > from && (r[k - 1] - level).abs() <= tol && e(k - 1).abs() <= tol {
                    k -= 1;
                }
                return k;
            }
        }
        k += 1;
    }
    n
}

/// Harmonic k of `x` at model times `tau`: H = (2/n) Σ x·exp(−j 2π k f τ).
fn fundamental(x: &[f64], tau: &[f64], f: f64) -> (f64, f64) {
    let (mut re, mut im) = (0.0, 0.0);
    for (v, t) in x.iter().zip(tau) {
        let c = f * t;
        let (s, co) = (2.0 * PI * (c - c.floor())).sin_cos();
        re += v * co;
        im -= v * s;
    }
    let k = 2.0 / x.len().max(1) as f64;
    (re * k, im * k)
}

/// A 0-based (fractional) row as the 1-based row a user reads: a fraction only when it is one.
pub fn fmt_row(r: f64) -> String {
    if r == r.round() {
        format!("{}", r as i64 + 1)
    } else {
        format!("{:.2}", r + 1.0)
    }
}

pub use vshake_kernel::metrics::wrap_deg;

/// Common unit mix-ups and the factor each puts into a ratio that should be 1.
fn unit_cause(ratio: f64, causes: &[(f64, &str)]) -> Option<String> {
    causes
        .iter()
        .find(|(k, _)| (ratio / k).ln().abs() < 1.25f64.ln())
        .map(|(_, c)| c.to_string())
}

/// Data-only checks on the compared samples: kinematic consistency (units) and the sign of each
/// channel against the reference.
fn channel_checks(s: &Samples, m: &Measured) -> Vec<String> {
    let mut out = Vec::new();
    match s.fundamental_hz {
        Some(f) => {
            let w2 = (2.0 * PI * f).powi(2);
            let (a1, x1) = (
                fundamental(&m.accel, &s.tau, f),
                fundamental(&m.disp, &s.tau, f),
            );
            let (ar1, xr1) = (
                fundamental(&s.ref_a, &s.tau, f),
                fundamental(&s.ref_x, &s.tau, f),
            );
            let mag = |c: (f64, f64)| c.0.hypot(c.1);
            let kappa = mag(a1) / (w2 * mag(x1));
            if kappa.is_finite() && (kappa.ln()).abs() > 1.25f64.ln() {
                let causes = [
                    (1.0 / G, "the acceleration is in g (×9.80665 to m/s²)"),
                    (1e-3, "the displacement is in mm"),
                    (1e-2, "the displacement is in cm"),
                    (1e3, "the acceleration is in mm/s²"),
                    (
                        1e-3 / G,
                        "the acceleration is in g and the displacement in mm",
                    ),
                    (0.0254, "the displacement is in inches"),
                ];
                let cause = unit_cause(kappa, &causes).unwrap_or_else(|| {
                    "a wrong channel, or sensors that do not see one rigid body".into()
                });
                out.push(format!(
                    "the acceleration and displacement channels disagree: |a1|/(w^2 |x1|) = {kappa:.4} (1 for one rigid body; 1/9.81 = 0.102 if the acceleration is in g, 0.001 if the displacement is in mm): likely {cause}"
                ));
            }
            for (name, h, r) in [("accel_mps2", a1, ar1), ("disp_m", x1, xr1)] {
                let ph = wrap_deg((h.1.atan2(h.0) - r.1.atan2(r.0)).to_degrees());
                if ph.abs() > 135.0 && mag(h) > 0.0 {
                    out.push(format!("`{name}` is in antiphase with the reference (its fundamental at {ph:+.1}°): a flipped sign?"));
                }
            }
        }
        None => {
            // A record: regression slope of each channel on its reference.
            for (name, v, r) in [
                ("accel_mps2", &m.accel, &s.ref_a),
                ("disp_m", &m.disp, &s.ref_x),
            ] {
                let rr: f64 = r.iter().map(|x| x * x).sum();
                if rr <= 0.0 {
                    continue;
                }
                let beta = v.iter().zip(r.iter()).map(|(a, b)| a * b).sum::<f64>() / rr;
                if beta < -0.5 {
                    out.push(format!(
                        "`{name}` follows the reference with slope {beta:.3}: a flipped sign?"
                    ));
                } else if !(0.2..=5.0).contains(&beta) {
                    let causes: &[(f64, &str)] = if name == "disp_m" {
                        &[
                            (1e3, "the displacement is in mm"),
                            (1e2, "the displacement is in cm"),
                        ]
                    } else {
                        &[
                            (1.0 / G, "the acceleration is in g"),
                            (1e3, "the acceleration is in mm/s²"),
                        ]
                    };
                    let cause = unit_cause(beta, causes)
                        .unwrap_or_else(|| "a wrong channel or another unit".into());
                    out.push(format!("`{name}` follows the reference with slope {beta:.4} (about 1 for a table that tracks): likely {cause}"));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sine() -> Sine {
        Sine {
            freq_hz: 3.0,
            amp_m: 0.02,
            taper_s: 1.0,
            duration_s: 3.0,
            window_cycles: None,
        }
    }

    fn column(s: &Sine, rate: f64, pre_s: f64, post_s: f64) -> Vec<f64> {
        let n = ((pre_s + s.duration_s + post_s) * rate).round() as usize;
        (0..n)
            .map(|k| {
                let t = k as f64 / rate - pre_s;
                if t < s.duration_s {
                    s.displacement(t)
                } else {
                    0.0
                }
            })
            .collect()
    }

    #[test]
    fn the_start_and_end_of_a_sine_are_found_to_a_fraction_of_a_row() {
        let s = sine();
        for (rate, pre, post) in [
            (1024.0, 0.0, 0.0),
            (256.0, 0.5, 0.0),
            (500.0, 0.3217, 1.0),
            (2048.0, 0.75, 0.4),
        ] {
            let r = column(&s, rate, pre, post);
            let fit = align_sine(&s, &r, rate, None, None);
            assert!(
                fit.error.is_none() && fit.warnings.is_empty(),
                "{rate} Hz: {:?} {:?}",
                fit.error,
                fit.warnings
            );
            assert!(
                (fit.start_row - pre * rate).abs() < 1e-6,
                "{rate} Hz: start {} vs {}",
                fit.start_row,
                pre * rate
            );
            let end = ((pre + s.duration_s) * rate).ceil() as usize;
            assert!(
                (fit.end_row as i64 - end as i64).abs() <= 1,
                "{rate} Hz: end {} vs {end}",
                fit.end_row
            );
        }
        // On a row exactly: the start is snapped to it.
        let fit = align_sine(&s, &column(&s, 256.0, 0.5, 0.0), 256.0, None, None);
        assert_eq!(fit.start_row, 128.0);
        assert_eq!(fit.end_row, 256 * 35 / 10);
    }

    #[test]
    fn a_column_of_a_few_rows_is_an_error_or_a_warning_not_a_panic() {
        // Found by tests/parsers.rs (mutated bytes): an onset in the last rows made the fitted
        // start land past the column's end, and end_of_sine clamped to an empty range.
        use rand::{RngExt, SeedableRng};
        let s = sine();
        let mut g = chacha20::ChaCha8Rng::seed_from_u64(1);
        // Short columns of zeros and random values at several rates (the 9th draw of this
        // stream panicked before the fix).
        for _ in 0..20_000 {
            let n = g.random_range(1..40usize);
            let rate = [1.0, 2.0, 10.0, 100.0, 1024.0][g.random_range(0..5usize)];
            let r: Vec<f64> = (0..n)
                .map(|_| {
                    if g.random_bool(0.5) {
                        0.0
                    } else {
                        g.random_range(-0.03..0.03)
                    }
                })
                .collect();
            let fit = align_sine(&s, &r, rate, None, None);
            assert!(fit.start_row.is_finite(), "{r:?} at {rate} Hz");
            assert!(
                fit.end_row <= r.len(),
                "{r:?} at {rate} Hz: end {}",
                fit.end_row
            );
        }
    }

    #[test]
    fn another_frequency_or_unit_is_named() {
        let s = sine();
        let mut other = s;
        other.freq_hz = 4.0;
        let fit = align_sine(&s, &column(&other, 1024.0, 0.0, 0.0), 1024.0, None, None);
        assert!(
            fit.warnings
                .iter()
                .any(|w| w.contains("4.000 Hz") && w.contains("another test")),
            "{:?}",
            fit.warnings
        );
        let mm: Vec<f64> = column(&s, 1024.0, 0.2, 0.0)
            .iter()
            .map(|v| v * 1000.0)
            .collect();
        let fit = align_sine(&s, &mm, 1024.0, None, None);
        assert!(
            fit.warnings.iter().any(|w| w.contains("in mm?")),
            "{:?}",
            fit.warnings
        );
        let zero = vec![0.0; 3072];
        let fit = align_sine(&s, &zero, 1024.0, None, None);
        assert!(
            fit.warnings.iter().any(|w| w.contains("zero throughout")),
            "{:?}",
            fit.warnings
        );
    }

    #[test]
    fn a_short_file_is_an_error_and_duration_is_honoured() {
        let s = sine();
        let r = column(&s, 1024.0, 0.5, 0.0);
        let fit = align_sine(&s, &r, 1024.0, None, Some(4.0));
        assert!(
            fit.error
                .as_deref()
                .is_some_and(|e| e.contains("too short")),
            "{:?}",
            fit.error
        );
        let fit = align_sine(&s, &r, 1024.0, Some(512.0), Some(2.0));
        assert_eq!((fit.start_row, fit.end_row), (512.0, 512 + 2048));
    }

    #[test]
    fn unit_mixups_are_recognised() {
        assert!(unit_cause(0.1019, &[(1.0 / G, "g")]).is_some());
        assert!(unit_cause(0.5, &[(1.0 / G, "g")]).is_none());
        assert_eq!(wrap_deg(-190.0), 170.0);
        assert_eq!(wrap_deg(540.0), 180.0);
    }
}
