//! A drive iteration's journal: every run of the table, written as it ends, so that an iteration
//! stopped by a signal (or killed) continues with `study iterate --resume` to the same result,
//! bit for bit. The iteration is deterministic given its runs' responses, so the runs replayed
//! from the journal take it back to where it stopped. Text, one record per line, every number as
//! the hex of its bits (as in [`super::tune_journal`]):
//!
//! ```text
//! vshake-iterate-journal 1
//! spec <the run file's text, UTF-8 in hex>
//! model <the --model file's text in hex, or ->
//! settings <the settings' line, in hex>
//! run <n> <the drive's hash> ok <response bits ...> <checksum>
//! run <n> <the drive's hash> failed <the reason in hex> <checksum>
//! ```
//!
//! Each `run` line ends with the FNV-1a hash of the line before it, so that an edited or damaged
//! journal is refused rather than resumed into another result; a last line cut short by a kill
//! (no newline) is dropped. A replayed run whose drive's hash is not the journal's is refused
//! too (the iteration would not be the one journaled).

use super::tune_journal::{bits_line, field, floats, fnv1a, hex_text, unhex_text};

const MAGIC: &str = "vshake-iterate-journal 1";

/// One run as stored: the hash of its drive's bits and its response (or why it failed).
#[derive(Debug, Clone, PartialEq)]
pub struct StoredRun {
    pub drive_hash: u64,
    pub response: Result<Vec<f64>, String>,
}

/// A journal read back: the inputs it was made from and its whole runs.
#[derive(Debug, Clone)]
pub struct IterateJournal {
    pub spec_text: String,
    pub model_text: Option<String>,
    pub settings: String,
    pub runs: Vec<StoredRun>,
}

/// The journal's first lines.
pub fn header(spec_text: &str, model_text: Option<&str>, settings: &str) -> String {
    let model = model_text.map_or("-".to_string(), hex_text);
    format!(
        "{MAGIC}\nspec {}\nmodel {model}\nsettings {}\n",
        hex_text(spec_text),
        hex_text(settings)
    )
}

/// The hash of a drive's bits (FNV-1a over their hex).
pub fn drive_hash(drive: &[f64]) -> u64 {
    fnv1a(&bits_line(drive))
}

/// Run `n`'s line (from 1), closed by its checksum.
pub fn run_line(n: usize, run: &StoredRun) -> String {
    let body = match &run.response {
        Ok(r) => format!("run {n} {:016x} ok {}", run.drive_hash, bits_line(r)),
        Err(why) => format!("run {n} {:016x} failed {}", run.drive_hash, hex_text(why)),
    };
    let sum = fnv1a(&body);
    format!("{body} {sum:016x}\n")
}

/// Reads a journal; `Err` names the line that is not one (a last line without its newline, cut
/// short by a kill, is dropped, not an error).
pub fn read(text: &str) -> Result<IterateJournal, String> {
    let mut lines = complete(text).lines().enumerate();
    let mut next = |what: &str| {
        lines
            .next()
            .map(|(_, l)| l)
            .ok_or_else(|| format!("ends before its {what} line"))
    };
    if next("first")? != MAGIC {
        return Err(format!(
            "line 1: not an iteration journal (expected {MAGIC:?})"
        ));
    }
    let spec_text = field(next("spec")?, "spec", 2).and_then(|h| unhex_text(h, 2))?;
    let model_text = match field(next("model")?, "model", 3)? {
        "-" => None,
        h => Some(unhex_text(h, 3)?),
    };
    let settings = field(next("settings")?, "settings", 4).and_then(|h| unhex_text(h, 4))?;
    let runs = lines
        .map(|(i, line)| run(line, i + 1, i - 3))
        .collect::<Result<_, _>>()?;
    Ok(IterateJournal {
        spec_text,
        model_text,
        settings,
        runs,
    })
}

/// `text` up to its last whole line: what a kill in the middle of a write leaves is dropped.
pub fn complete(text: &str) -> &str {
    &text[..text.rfind('\n').map_or(0, |i| i + 1)]
}

/// Line `n`, the journal's run `expected` (from 1).
fn run(line: &str, n: usize, expected: usize) -> Result<StoredRun, String> {
    let (body, sum) = line
        .rsplit_once(' ')
        .ok_or(format!("line {n}: expected `run ...`"))?;
    if sum != format!("{:016x}", fnv1a(body)) {
        return Err(format!(
            "line {n}: the run does not match its checksum (the journal was edited or damaged)"
        ));
    }
    let mut w = field(body, "run", n)?.splitn(4, ' ');
    let index = w.next().and_then(|s| s.parse::<usize>().ok());
    if index != Some(expected) {
        return Err(format!("line {n}: expected run {expected}"));
    }
    let hash = w.next().and_then(|s| u64::from_str_radix(s, 16).ok());
    let drive_hash = hash.ok_or(format!("line {n}: the drive's hash is not hex"))?;
    let response = match (w.next(), w.next().unwrap_or("")) {
        (Some("ok"), rest) => Ok(floats(rest.split(' '), n)?),
        (Some("failed"), rest) => Err(unhex_text(rest, n)?),
        _ => return Err(format!("line {n}: expected `ok` or `failed`")),
    };
    Ok(StoredRun {
        drive_hash,
        response,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn journal() -> String {
        let mut text = header("[excitation]\n", None, "gain 0.8");
        let runs = [
            StoredRun {
                drive_hash: drive_hash(&[1.0, -0.5]),
                response: Ok(vec![0.25, f64::from_bits(0x7ff8_0000_0000_0001), -0.0]),
            },
            StoredRun {
                drive_hash: drive_hash(&[2.0]),
                response: Err("pressure P2 of actuator 1 left its range".into()),
            },
        ];
        for (i, r) in runs.iter().enumerate() {
            text += &run_line(i + 1, r);
        }
        text
    }

    #[test]
    fn a_journal_reads_back_bit_for_bit_and_drops_a_line_cut_short() {
        let text = journal();
        let j = read(&text).unwrap();
        assert_eq!(
            (j.spec_text.as_str(), j.model_text),
            ("[excitation]\n", None)
        );
        assert_eq!(j.settings, "gain 0.8");
        assert_eq!(j.runs.len(), 2);
        let bits: Vec<u64> = j.runs[0]
            .response
            .clone()
            .unwrap()
            .iter()
            .map(|x| x.to_bits())
            .collect();
        assert_eq!(
            bits,
            [
                0.25f64.to_bits(),
                0x7ff8_0000_0000_0001,
                (-0.0f64).to_bits()
            ]
        );
        assert_eq!(j.runs[0].drive_hash, drive_hash(&[1.0, -0.5]));
        assert_ne!(j.runs[0].drive_hash, drive_hash(&[1.0, -0.25]));
        assert_eq!(
            j.runs[1].response,
            Err("pressure P2 of actuator 1 left its range".into())
        );
        // A kill in the middle of the third line's write: it is dropped.
        let cut = text.clone() + "run 3 00ff ok 3ff0";
        assert_eq!(read(&cut).unwrap().runs.len(), 2);
    }

    #[test]
    fn an_edited_journal_is_refused_naming_the_line() {
        let text = journal().replacen(" ok 3fd", " ok 3fe", 1);
        let e = read(&text).unwrap_err();
        assert!(
            e.starts_with("line 5: the run does not match its checksum"),
            "{e}"
        );
        let e = read("vshake-tune-journal 1\n").unwrap_err();
        assert!(e.contains("not an iteration journal"), "{e}");
    }
}
