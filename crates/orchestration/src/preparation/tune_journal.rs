//! A tuning's journal: every generation's evaluations, written as each generation ends, so that a
//! tuning stopped by a signal (or killed) continues with `study tune --resume` to the same
//! result, bit for bit. Text, one record per line, every number as the hex of its bits (the runs
//! read back are the runs made, NaN payloads included):
//!
//! ```text
//! vshake-tune-journal 1
//! spec <the tuning file's text, UTF-8 in hex>
//! model <the --model file's text in hex, or ->
//! E <generation> <candidate> <gains' bits ...>
//! R <sample id> <excitation> <values' bits ...> | <status> | <metrics' bits ...>
//! end <generation> <checksum>
//! ```
//!
//! A status is `ok`, `failed <time> nonfinite`, `failed <time> stroke <disp>`, `failed <time>
//! pressure <actuator> <chamber> <pa>` or `invalid <category> <reason in hex>`. Only generations
//! closed by their `end` line count: a line cut short by a kill is dropped with its generation. The
//! `end` line carries the FNV-1a hash of the generation's lines, so that an edited or damaged
//! journal is refused rather than resumed into another result.

use crate::study::batch::{Row, RowStatus, INVALID_MOTION, INVALID_PARAMETERS, INVALID_SETUP};
use vshake_kernel::metrics::Metrics;
use vshake_kernel::simulate::Failure;

const MAGIC: &str = "vshake-tune-journal 1";

/// One evaluation as stored: what [`super::tune::Tuner`] judges again on resume.
#[derive(Debug, Clone)]
pub struct Stored {
    pub generation: usize,
    pub candidate: usize,
    pub gains: Vec<f64>,
    pub rows: Vec<Row>,
}

/// A journal read back: the inputs it was made from and its complete generations.
#[derive(Debug, Clone)]
pub struct Journal {
    pub spec_text: String,
    pub model_text: Option<String>,
    pub generations: Vec<Vec<Stored>>,
}

/// The journal's first lines.
pub fn header(spec_text: &str, model_text: Option<&str>) -> String {
    let model = model_text.map_or("-".to_string(), hex_text);
    format!("{MAGIC}\nspec {}\nmodel {model}\n", hex_text(spec_text))
}

/// The lines of one generation's evaluations, closed by its `end` line.
pub fn generation<'a>(
    generation: usize,
    evals: impl Iterator<Item = (usize, &'a [f64], &'a [Row])>,
) -> String {
    let mut out = String::new();
    for (candidate, gains, rows) in evals {
        out += &format!("E {generation} {candidate} {}\n", bits_line(gains));
        for r in rows {
            out += &format!(
                "R {} {} {} | {} | {}\n",
                r.sample_id,
                r.excitation,
                bits_line(&r.values),
                status_text(&r.status),
                r.metrics
                    .bits()
                    .iter()
                    .map(|b| format!("{b:x}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
        }
    }
    let sum = fnv1a(&out);
    out + &format!("end {generation} {sum:016x}\n")
}

/// The 64-bit FNV-1a hash of `text` (not cryptographic: it catches an edit or damage).
pub(crate) fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Reads a journal; `Err` names the line that is not one (a trailing generation without its
/// `end` line is dropped, not an error).
pub fn read(text: &str) -> Result<Journal, String> {
    let mut lines = complete(text).lines().enumerate();
    let mut next = |what: &str| {
        lines
            .next()
            .ok_or_else(|| format!("ends before its {what} line"))
    };
    let (_, magic) = next("first")?;
    if magic != MAGIC {
        return Err(format!("line 1: not a tuning journal (expected {MAGIC:?})"));
    }
    let (_, spec) = next("spec")?;
    let spec_text = field(spec, "spec", 2).and_then(|h| unhex_text(h, 2))?;
    let (_, model) = next("model")?;
    let model_text = match field(model, "model", 3)? {
        "-" => None,
        h => Some(unhex_text(h, 3)?),
    };
    let (mut generations, mut open) = (Vec::new(), Vec::<Stored>::new());
    let mut since_end = String::new();
    for (i, line) in lines {
        let n = i + 1;
        let (kind, rest) = line.split_once(' ').unwrap_or((line, ""));
        if kind != "end" {
            since_end += line;
            since_end.push('\n');
        }
        match kind {
            "E" => open.push(evaluation(rest, n)?),
            "R" => open
                .last_mut()
                .ok_or(format!("line {n}: a run before its evaluation"))?
                .rows
                .push(row(rest, n)?),
            "end" => {
                let sum = rest.split(' ').nth(1);
                if sum != Some(&format!("{:016x}", fnv1a(&since_end))[..]) {
                    return Err(format!("line {n}: the generation does not match its checksum (the journal was edited or damaged)"));
                }
                since_end.clear();
                generations.push(std::mem::take(&mut open));
            }
            _ => return Err(format!("line {n}: unknown record {kind:?}")),
        }
    }
    Ok(Journal {
        spec_text,
        model_text,
        generations,
    })
}

/// `text` up to its last whole `end` line (past the header when there is none): what a kill in
/// the middle of a write leaves after it is dropped before it is read.
pub fn complete(text: &str) -> &str {
    let (mut at, mut keep) = (0, None);
    for (i, line) in text.split_inclusive('\n').enumerate() {
        at += line.len();
        if (i == 2 && keep.is_none()) || (line.starts_with("end ") && line.ends_with('\n')) {
            keep = Some(at);
        }
    }
    &text[..keep.unwrap_or(text.len())]
}

pub(crate) fn field<'a>(line: &'a str, key: &str, n: usize) -> Result<&'a str, String> {
    line.strip_prefix(key)
        .and_then(|r| r.strip_prefix(' '))
        .ok_or(format!("line {n}: expected `{key} ...`"))
}

fn evaluation(rest: &str, n: usize) -> Result<Stored, String> {
    let mut w = rest.split(' ');
    let mut int = |what: &str| -> Result<usize, String> {
        w.next()
            .and_then(|x| x.parse().ok())
            .ok_or(format!("line {n}: no {what}"))
    };
    let (generation, candidate) = (int("generation")?, int("candidate")?);
    let gains = floats(w, n)?;
    Ok(Stored {
        generation,
        candidate,
        gains,
        rows: Vec::new(),
    })
}

fn row(rest: &str, n: usize) -> Result<Row, String> {
    let parts: Vec<&str> = rest.split(" | ").collect();
    let [head, status, metrics] = parts[..] else {
        return Err(format!(
            "line {n}: a run needs three parts separated by ` | `"
        ));
    };
    let mut w = head.split(' ');
    let sample_id = w.next().and_then(|x| x.parse().ok());
    let excitation = w.next().and_then(|x| x.parse().ok());
    let (Some(sample_id), Some(excitation)) = (sample_id, excitation) else {
        return Err(format!("line {n}: no sample id and excitation"));
    };
    let bits: Vec<u64> = words_bits(metrics.split(' '), n)?;
    Ok(Row {
        sample_id,
        excitation,
        saltelli: None,
        values: floats(w, n)?,
        status: read_status(status, n)?,
        metrics: Metrics::from_bits(&bits).ok_or(format!(
            "line {n}: {} metrics, expected {}",
            bits.len(),
            Metrics::NAN.columns().len()
        ))?,
    })
}

fn status_text(s: &RowStatus) -> String {
    let b = |x: f64| format!("{:x}", x.to_bits());
    match s {
        RowStatus::Ok => "ok".into(),
        RowStatus::Failed { time_s, failure } => {
            let why = match failure {
                Failure::NonFinite => "nonfinite".to_string(),
                Failure::StrokeLimit { disp_m } => format!("stroke {}", b(*disp_m)),
                Failure::Pressure {
                    actuator,
                    chamber,
                    pa,
                } => format!("pressure {actuator} {chamber} {}", b(*pa)),
            };
            format!("failed {} {why}", b(*time_s))
        }
        RowStatus::Invalid { category, reason } => {
            format!("invalid {category} {}", hex_text(reason))
        }
    }
}

fn read_status(text: &str, n: usize) -> Result<RowStatus, String> {
    let w: Vec<&str> = text.split(' ').collect();
    let bad = || format!("line {n}: unreadable status {text:?}");
    let f = |s: &str| {
        u64::from_str_radix(s, 16)
            .map(f64::from_bits)
            .map_err(|_| bad())
    };
    let u = |s: &str| s.parse::<usize>().map_err(|_| bad());
    Ok(match w[..] {
        ["ok"] => RowStatus::Ok,
        ["failed", t, "nonfinite"] => failed(f(t)?, Failure::NonFinite),
        ["failed", t, "stroke", d] => failed(f(t)?, Failure::StrokeLimit { disp_m: f(d)? }),
        ["failed", t, "pressure", a, c, p] => failed(
            f(t)?,
            Failure::Pressure {
                actuator: u(a)?,
                chamber: u(c)?,
                pa: f(p)?,
            },
        ),
        ["invalid", category, reason] => RowStatus::Invalid {
            category: [INVALID_PARAMETERS, INVALID_MOTION, INVALID_SETUP]
                .into_iter()
                .find(|c| *c == category)
                .ok_or_else(bad)?,
            reason: unhex_text(reason, n)?,
        },
        _ => return Err(bad()),
    })
}

fn failed(time_s: f64, failure: Failure) -> RowStatus {
    RowStatus::Failed { time_s, failure }
}

pub(crate) fn bits_line(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{:x}", x.to_bits()))
        .collect::<Vec<_>>()
        .join(" ")
}

fn words_bits<'a>(w: impl Iterator<Item = &'a str>, n: usize) -> Result<Vec<u64>, String> {
    w.filter(|s| !s.is_empty())
        .map(|s| u64::from_str_radix(s, 16).map_err(|_| format!("line {n}: {s:?} is not hex")))
        .collect()
}

pub(crate) fn floats<'a>(w: impl Iterator<Item = &'a str>, n: usize) -> Result<Vec<f64>, String> {
    Ok(words_bits(w, n)?.into_iter().map(f64::from_bits).collect())
}

pub(crate) fn hex_text(t: &str) -> String {
    t.bytes().map(|b| format!("{b:02x}")).collect()
}

pub(crate) fn unhex_text(h: &str, n: usize) -> Result<String, String> {
    let bad = || format!("line {n}: text not in hex");
    if !h.len().is_multiple_of(2) {
        return Err(bad());
    }
    let bytes: Result<Vec<u8>, _> = (0..h.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&h[i..i + 2], 16))
        .collect();
    String::from_utf8(bytes.map_err(|_| bad())?).map_err(|_| bad())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(status: RowStatus, m: f64) -> Row {
        let mut metrics = Metrics::NAN;
        metrics.rms_err_accel_ratio = m;
        Row {
            sample_id: 7,
            excitation: 1,
            saltelli: None,
            values: vec![0.1, -2.5e-7],
            status,
            metrics,
        }
    }

    #[test]
    fn a_journal_reads_back_bit_for_bit_and_drops_an_unfinished_generation() {
        let rows = vec![
            run(RowStatus::Ok, 0.123),
            run(
                failed(
                    1.5,
                    Failure::Pressure {
                        actuator: 1,
                        chamber: 2,
                        pa: -1.2e6,
                    },
                ),
                f64::NAN,
            ),
            run(failed(0.25, Failure::StrokeLimit { disp_m: 0.5 }), f64::NAN),
            run(failed(3.0, Failure::NonFinite), f64::NAN),
            run(
                RowStatus::Invalid {
                    category: INVALID_PARAMETERS,
                    reason: "l_v = 9 | out of [0, 2]\nsecond line".into(),
                },
                f64::NAN,
            ),
        ];
        let gains = [0.38, 0.52];
        let mut text = header("[tune]\nname = \"é\"\n", None);
        text += &generation(0, [(0, &gains[..], &rows[..])].into_iter());
        text += &generation(1, [(0, &gains[..], &rows[..1])].into_iter());
        let cut = text.len() - 8; // generation 1's `end` line cut short by a kill
        let j = read(&text[..cut]).unwrap();
        assert_eq!(j.spec_text, "[tune]\nname = \"é\"\n");
        assert_eq!(j.model_text, None);
        assert_eq!(j.generations.len(), 1);
        let s = &j.generations[0][0];
        assert_eq!(
            (s.generation, s.candidate, s.gains.clone()),
            (0, 0, gains.to_vec())
        );
        for (a, b) in s.rows.iter().zip(&rows) {
            assert_eq!(a.metrics.bits(), b.metrics.bits());
            assert_eq!(a.status, b.status);
            assert_eq!(a.values, b.values);
            assert_eq!((a.sample_id, a.excitation), (b.sample_id, b.excitation));
        }
        assert_eq!(s.rows.len(), rows.len());
        let full = read(&text).unwrap();
        assert_eq!(full.generations.len(), 2);
        assert!(read("something else\n")
            .unwrap_err()
            .contains("not a tuning journal"));
        // One value edited: refused by the generation's checksum, not resumed.
        let edited = text.replacen("3fb999999999999a", "3fb999999999999b", 1);
        assert_ne!(edited, text);
        let why = read(&edited).unwrap_err();
        assert!(why.contains("checksum"), "{why}");
        let bad = text.replace("R 7 1", "R x 1");
        assert!(
            read(&bad).unwrap_err().contains("no sample id"),
            "{:?}",
            read(&bad)
        );
    }
}
