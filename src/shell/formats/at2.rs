//! The PEER NGA `.AT2` acceleration format (docs/formats.md "Records"): a few header lines, one
//! of which gives the number of points and the time step, then the accelerations (in g) in
//! free-format lines of any count.
//!
//! The variants met in real files, all read here:
//! - NGA-West2: `NPTS=  3930, DT=   .0100 SEC` (also `DT= 0.005, NPTS= 8000`, `;` or no comma);
//! - NGA-West1 / PEER 1999: `  3930    0.01000    NPTS, DT` (the numbers first, then the names
//!   in their order) — any header line naming both NPTS and DT;
//! - units stated in the header (`UNITS OF G`; `CM/S/S` or `CM/SEC2` are converted to g with a
//!   note; none stated: g, with a note);
//! - values as `.2783597E-02`, `2.783597e-3`, Fortran `D` exponents, and fixed-width fields
//!   that touch (`-.12E-02-.56E-03`).
//!
//! The values must be exactly NPTS (a last line of zero padding beyond NPTS is dropped, with a
//! note); every problem names the file and its line.

use crate::orchestration::measured::aligned::NumTable;
use crate::orchestration::runs::quake_spec::{AT2_COLUMN, AT2_TIME};
use crate::shell::formats::input::TableError;
use std::path::Path;

const KIND: &str = "PEER .AT2";

/// Reads an `.AT2` file into the columns `time_s` (k·DT) and `accel_g`.
pub fn read(path: &Path) -> Result<NumTable, TableError> {
    let bytes = crate::shell::formats::input::read_input(path).map_err(|err| TableError::Io {
        file: path.to_path_buf(),
        err,
    })?;
    let text = String::from_utf8_lossy(&bytes);
    parse(&text)
        .map(|(t, a, notes)| NumTable {
            file: path.to_path_buf(),
            names: vec![AT2_TIME.into(), AT2_COLUMN.into()],
            columns: vec![t, a],
            first_line: None,
            notes,
        })
        .map_err(|message| TableError::Format {
            file: path.to_path_buf(),
            kind: KIND,
            message,
        })
}

/// Time (s), acceleration (g) and the notes of reading them.
pub type Parsed = (Vec<f64>, Vec<f64>, Vec<String>);

/// (time, acceleration in g, notes) of an AT2 text.
pub fn parse(text: &str) -> Result<Parsed, String> {
    let lines: Vec<&str> = text.lines().collect();
    let Some(h) = lines.iter().take(12).position(|l| {
        let u = l.to_ascii_uppercase();
        u.contains("NPTS") && u.contains("DT")
    }) else {
        return Err("no NPTS/DT line in its first 12 lines (e.g. `NPTS=  3930, DT= .0100 SEC`); is it a PEER .AT2 file?".into());
    };
    let (npts, dt) =
        npts_dt(lines[h]).map_err(|m| format!("line {}: {m}: {:?}", h + 1, lines[h].trim()))?;
    let mut notes = Vec::new();
    let factor = unit_factor(&lines[..h], &mut notes);
    let mut values = Vec::with_capacity(npts);
    for (i, line) in lines.iter().enumerate().skip(h + 1) {
        for tok in line.split(|c: char| c.is_whitespace() || c == ',') {
            for v in split_touching(tok) {
                let x =
                    number(v).ok_or_else(|| format!("line {}: {v:?} is not a number", i + 1))?;
                if !x.is_finite() {
                    return Err(format!("line {}: {v:?} is not a finite number", i + 1));
                }
                values.push(x * factor);
            }
        }
    }
    if values.len() < npts {
        return Err(format!(
            "{} values after the header, but NPTS = {npts} (line {}); is the file cut short?",
            values.len(),
            h + 1
        ));
    }
    if values.len() > npts {
        if values[npts..].iter().all(|v| *v == 0.0) {
            notes.push(format!(
                "{} zeros after the NPTS = {npts} values (padding of the last line) were dropped",
                values.len() - npts
            ));
            values.truncate(npts);
        } else {
            return Err(format!("{} values after the header, but NPTS = {npts} (line {}); the header and the data disagree", values.len(), h + 1));
        }
    }
    let time = (0..npts).map(|k| k as f64 * dt).collect();
    Ok((time, values, notes))
}

/// NPTS and DT from their header line, in either layout (see the module docs).
fn npts_dt(line: &str) -> Result<(usize, f64), String> {
    let u = line.to_ascii_uppercase();
    let (ip, id) = (
        u.find("NPTS").expect("checked"),
        u.find("DT").expect("checked"),
    );
    // Named values: the first number after each name.
    let after = |at: usize| -> Option<f64> {
        let rest = u[at..]
            .trim_start_matches(|c: char| c.is_ascii_alphabetic())
            .trim_start_matches(|c: char| c == '=' || c == ':' || c.is_whitespace());
        let end = rest
            .find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'E')))
            .unwrap_or(rest.len());
        number(&rest[..end])
    };
    let (n, dt) = match (after(ip + 4), after(id + 2)) {
        (Some(n), Some(dt)) => (n, dt),
        _ => {
            // The numbers first, the names after them in the same order.
            let nums: Vec<f64> = u
                .split(|c: char| c.is_whitespace() || c == ',')
                .filter_map(number)
                .collect();
            if nums.len() < 2 {
                return Err("cannot read NPTS and DT".into());
            }
            if ip < id {
                (nums[0], nums[1])
            } else {
                (nums[1], nums[0])
            }
        }
    };
    if !(n >= 2.0 && n.fract() == 0.0 && n < 1e9) {
        return Err(format!("NPTS = {n} is not a whole number of at least 2"));
    }
    if !(dt > 0.0 && dt < 10.0) {
        return Err(format!("DT = {dt} s must be in (0, 10) s"));
    }
    Ok((n as usize, dt))
}

/// The factor to g from the header's unit line.
fn unit_factor(header: &[&str], notes: &mut Vec<String>) -> f64 {
    let h = header.join(" ").to_ascii_uppercase();
    if h.contains("UNITS OF G") || h.contains("IN G") || h.contains("(G)") {
        1.0
    } else if h.contains("CM/S") || h.contains("CM/SEC") || h.contains("GAL") {
        notes.push("the header gives cm/s²: converted to g (÷ 980.665)".into());
        1.0 / 980.665
    } else {
        notes.push("the header states no unit: read as g (the PEER NGA convention)".into());
        1.0
    }
}

/// A number in Fortran or Rust notation (`.5E-02`, `1.0D-03`); `None` otherwise.
fn number(s: &str) -> Option<f64> {
    if s.is_empty() {
        return None;
    }
    s.replace(['D', 'd'], "E").parse().ok()
}

/// A token split where fixed-width fields touch: at a sign that follows a digit or a point.
fn split_touching(tok: &str) -> Vec<&str> {
    if tok.is_empty() {
        return Vec::new();
    }
    let b = tok.as_bytes();
    let mut parts = Vec::new();
    let mut start = 0;
    for i in 1..b.len() {
        if (b[i] == b'-' || b[i] == b'+') && (b[i - 1].is_ascii_digit() || b[i - 1] == b'.') {
            parts.push(&tok[start..i]);
            start = i;
        }
    }
    parts.push(&tok[start..]);
    parts
}

#[cfg(test)]
mod tests {
    use super::*;

    const WEST2: &str = "PEER NGA STRONG MOTION DATABASE RECORD
Imperial Valley-06, 10/15/1979, El Centro Array #6, 230
ACCELERATION TIME SERIES IN UNITS OF G
NPTS=    7, DT=   .0100 SEC
  .1000000E-02  .2000000E-02 -.3000000E-02  .4000000E-02  .5000000E-02
 -.6000000E-02  .7000000E-02
";

    #[test]
    fn header_variants_give_the_same_record() {
        let want = vec![0.001, 0.002, -0.003, 0.004, 0.005, -0.006, 0.007];
        let west1 = "PACIFIC ENGINEERING AND ANALYSIS STRONG-MOTION DATA\n IMPERIAL VALLEY 10/15/79 2316, EL CENTRO ARRAY #6, 230\n ACCELERATION TIME HISTORY IN UNITS OF G\n    7    0.01000    NPTS, DT\n .1000000E-02 .2000000E-02-.3000000E-02 .4000000E-02\n .5000000E-02-.6000000E-02 .7000000E-02\n";
        let swapped = "header\nIN UNITS OF G\nDT= 0.01 SEC, NPTS= 7\n1.0e-3 2.0e-3 -3.0e-3 4.0e-3 5.0e-3 -6.0e-3 7.0e-3 0.0 0.0\n";
        let fortran = "x\ny\nunits of g\nNPTS=7 DT=.01\n 0.1D-02 0.2D-02 -0.3D-02\n 0.4D-02\n 0.5D-02\n -0.6D-02 0.7D-02\n";
        for (name, text) in [
            ("west2", WEST2),
            ("west1", west1),
            ("dt first, zero padding", swapped),
            ("fortran D, one to three a line", fortran),
        ] {
            let (t, a, _) = parse(text).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(a.len(), 7, "{name}");
            for (x, y) in a.iter().zip(&want) {
                assert!((x - y).abs() < 1e-15, "{name}: {a:?}");
            }
            assert_eq!(t[6], 0.06, "{name}");
        }
        let gal = "title\nACCELERATION IN CM/S/S\nNPTS= 2, DT= 0.02\n980.665 -490.3325\n";
        let (_, a, notes) = parse(gal).unwrap();
        assert!(
            (a[0] - 1.0).abs() < 1e-15 && (a[1] + 0.5).abs() < 1e-15 && notes[0].contains("cm/s²")
        );
    }

    #[test]
    fn bad_files_name_their_line() {
        let short = WEST2.replace(" -.6000000E-02  .7000000E-02\n", "");
        assert!(parse(&short)
            .unwrap_err()
            .contains("5 values after the header, but NPTS = 7"));
        let bad = WEST2.replace("-.3000000E-02", "-.30x0000E-02");
        assert!(
            parse(&bad).unwrap_err().starts_with("line 5:"),
            "{}",
            parse(&bad).unwrap_err()
        );
        assert!(parse("just\nsome\ntext\n")
            .unwrap_err()
            .contains("no NPTS/DT line"));
        let zero_dt = WEST2.replace("DT=   .0100", "DT=   0.0");
        assert!(parse(&zero_dt).unwrap_err().contains("DT = 0 s"));
    }
}
