//! Column names and units as a lab's data-acquisition system writes them: `Time (s)`,
//! `Ref Disp [mm]`, `accel_g`, `TIME_S`, MATLAB `writetable`'s `RefDisp`. A header is split into
//! a name and a unit (in brackets or parentheses at its end, or a last `_`/space-separated word
//! that is a unit); the name is recognised as one of vshake's channels by its words (case,
//! spaces, `_` and camel case ignored; `Disp`/`Displacement`/`Position`, `Accel`/`Acceleration`,
//! `Ref`/`Reference`/`Command`/`Target`), and the unit gives the factor to SI. A name written
//! exactly as vshake's column (`accel_mps2`) is taken as it is. Pure: the readers in
//! `formats::measured_files` apply what [`resolve`] finds; the channels and units are the
//! kernel's vocabulary (`kernel::channels`).

use crate::kernel::channels::*;
use crate::orchestration::measured::campaign::Mapped;
/// A header split into its name and the unit text written with it (`Accel (g)` → `Accel`, `g`;
/// `disp_mm` → `disp`, `mm`); no unit text where none is written.
pub fn split(header: &str) -> (String, Option<String>) {
    let h = header.trim();
    for (open, close) in [('(', ')'), ('[', ']'), ('{', '}')] {
        if let Some(body) = h.strip_suffix(close) {
            if let Some(i) = body.rfind(open) {
                if body[i + 1..].trim_start().starts_with(':') {
                    // A MATLAB column index (`data(:,2)`, a MAT-file matrix's column), no unit.
                    return split(&body[..i]);
                }
                return (
                    body[..i].trim().to_string(),
                    Some(body[i + 1..].trim().to_string()),
                );
            }
        }
    }
    // vshake's own form, `<channel>_<unit>`: the last word is a unit, known or not.
    let stem = |s: &str| {
        CHANNELS.iter().any(|c| {
            c.0.rsplit_once('_')
                .is_some_and(|(st, _)| st.eq_ignore_ascii_case(s))
        })
    };
    match h.rfind(['_', ' ']) {
        Some(i) if i > 0 && (unit(&h[i + 1..]).is_some() || stem(&h[..i])) => (
            h[..i].trim_end_matches(['_', ' ']).to_string(),
            Some(h[i + 1..].to_string()),
        ),
        _ => (h.to_string(), None),
    }
}

/// The lower-case words of a name: split at anything not a letter or digit and at camel case
/// (`RefDisp` → `ref`, `disp`).
pub fn words(name: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut cur = String::new();
    let mut prev_lower = false;
    for ch in name.chars() {
        if !ch.is_alphanumeric() {
            out.extend((!cur.is_empty()).then(|| std::mem::take(&mut cur)));
            prev_lower = false;
            continue;
        }
        if ch.is_uppercase() && prev_lower && !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
        prev_lower = ch.is_lowercase() || ch.is_ascii_digit();
        cur.extend(ch.to_lowercase());
    }
    out.extend((!cur.is_empty()).then_some(cur));
    out
}

const REF: &[&str] = &[
    "ref",
    "reference",
    "command",
    "cmd",
    "target",
    "demand",
    "setpoint",
    "drive",
];
const DISP: &[&str] = &["disp", "displacement", "pos", "position", "stroke"];
const ACCEL: &[&str] = &["accel", "acceleration", "acc"];

/// The channel (its column name) a header's name means by its words, if any.
pub fn recognise(name: &str) -> Option<&'static str> {
    let w = words(name);
    let has = |set: &[&str]| w.iter().any(|x| set.contains(&x.as_str()));
    let is = |s: &[&str]| w.len() == s.len() && w.iter().zip(s).all(|(a, b)| a == b);
    let joined = w.concat();
    Some(match () {
        _ if has(&["time", "t"]) && w.len() <= 2 => "time_s",
        _ if has(&["valve", "servovalve"]) && !has(&["spool"]) => "valve_cmd_v",
        _ if has(&["spool"]) => "spool_m",
        _ if has(DISP) && has(REF) => "ref_disp_m",
        _ if has(REF) => return None,
        _ if has(DISP) => "disp_m",
        _ if has(ACCEL) => "accel_mps2",
        _ if has(&["force", "load"]) => "force_n",
        _ if joined == "p1" || is(&["pressure", "1"]) || has(&["cap"]) => "p1_pa",
        _ if joined == "p2" || is(&["pressure", "2"]) || has(&["rod"]) => "p2_pa",
        _ => return None,
    })
}

/// One column of a file as vshake reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct Resolved {
    /// vshake's name for it (a channel's column name, or the name asked for).
    pub name: String,
    /// Its position in the file's header.
    pub index: usize,
    /// Factor to SI.
    pub to_si: f64,
    /// What was read, when it was not vshake's own name (`` `Accel (g)` as accel_mps2, g → m/s² ``).
    pub note: Option<String>,
}

/// Why a column could not be read.
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnProblem {
    /// Nothing in the header means it.
    Missing(String),
    /// `header`'s unit is not one vshake knows.
    UnknownUnit { header: String, unit: String },
    /// `header`'s unit measures another quantity than the column holds.
    WrongQuantity {
        header: String,
        unit: String,
        column: String,
    },
    /// Several headers mean it.
    Ambiguous {
        column: String,
        headers: Vec<String>,
    },
    /// Several columns of the file have this one name (positions from 1).
    SameName {
        column: String,
        header: String,
        positions: Vec<usize>,
    },
    /// One column of the file read as two channels.
    Twice {
        header: String,
        columns: [String; 2],
    },
    /// A `columns` entry names a header or position the file lacks.
    NotInFile { column: String, what: String },
}

impl std::fmt::Display for ColumnProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ColumnProblem::Missing(c) => write!(f, "required column `{c}` is missing"),
            ColumnProblem::UnknownUnit { header, unit } => write!(
                f,
                "column `{header}`: unknown unit `{unit}` (vshake reads {}; docs/formats.md)",
                unit_list()
            ),
            ColumnProblem::WrongQuantity { header, unit, column } => {
                let q = channel(column).map_or("", |c| c.2.si());
                write!(f, "column `{header}` read as `{column}`, but its unit `{unit}` is not one of {q} (another channel? docs/formats.md lists the names vshake recognises)")
            }
            ColumnProblem::Ambiguous { column, headers } => write!(
                f,
                "columns {} all look like `{column}`: name the one to read in the campaign's `columns` table, e.g. columns = {{ {} = \"{}\" }}, or rename it to `{column}` (docs/formats.md)",
                headers.iter().map(|h| format!("`{h}`")).collect::<Vec<_>>().join(", "),
                channel(column).map_or(column.as_str(), |c| c.1),
                headers.first().map_or("", |h| h.as_str())
            ),
            ColumnProblem::SameName { column, header, positions } => write!(
                f,
                "columns {} are {} named `{header}`: give the position of the one to read as `{column}` in the campaign's `columns` table, e.g. columns = {{ {} = {} }} (positions count every column of the file, in order, from 1; docs/formats.md)",
                join_positions(positions),
                if positions.len() == 2 { "both" } else { "all" },
                channel(column).map_or(column.as_str(), |c| c.1),
                positions.first().unwrap_or(&1)
            ),
            ColumnProblem::Twice { header, columns } => write!(
                f,
                "column `{header}` would be read as both `{}` and `{}`: give each channel its own column in the campaign's `columns` table (positions count every column of the file, in order; docs/formats.md)",
                columns[0], columns[1]
            ),
            ColumnProblem::NotInFile { column, what } => {
                write!(f, "the campaign's `columns` table maps `{column}` to {what}, which the file does not have")
            }
        }
    }
}

/// "3 and 9", "2, 5 and 7".
fn join_positions(p: &[usize]) -> String {
    let s: Vec<String> = p.iter().map(usize::to_string).collect();
    match s.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
        _ => s.join(""),
    }
}

/// The one position in `headers` of the name `name` (trimmed), None where there is none, or the
/// problem naming every position where several columns have it.
fn named_once(
    column: &str,
    headers: &[String],
    name: &str,
) -> Result<Option<usize>, ColumnProblem> {
    let at: Vec<usize> = (0..headers.len())
        .filter(|&i| headers[i].trim() == name.trim())
        .collect();
    match at.as_slice() {
        [] => Ok(None),
        [i] => Ok(Some(*i)),
        _ => Err(ColumnProblem::SameName {
            column: column.to_string(),
            header: name.trim().to_string(),
            positions: at.iter().map(|i| i + 1).collect(),
        }),
    }
}

/// The factor to SI of the unit `text` written with `header` for `column`, or why it has none.
fn factor(header: &str, text: &str, column: &str) -> Result<Unit, ColumnProblem> {
    let u = unit(text).ok_or_else(|| ColumnProblem::UnknownUnit {
        header: header.to_string(),
        unit: text.to_string(),
    })?;
    match channel(column) {
        Some((_, _, q)) if q != u.quantity => Err(ColumnProblem::WrongQuantity {
            header: header.to_string(),
            unit: text.to_string(),
            column: column.to_string(),
        }),
        _ => Ok(u),
    }
}

/// Where `column` is in `headers` (with `units`, a units row under the header, where there is
/// one), and its factor to SI: a `columns` mapping first, then the exact name, then the one
/// header whose name means it.
fn locate(
    column: &str,
    headers: &[String],
    units: Option<&[String]>,
    map: Option<&Mapped>,
) -> Result<Option<Resolved>, ColumnProblem> {
    let at = |i: usize, unit_text: Option<String>| read_at(column, headers, units, i, unit_text);
    if let Some(m) = map {
        let i = match (&m.name, m.index) {
            (Some(n), _) => named_once(column, headers, n)?,
            (None, Some(k)) => (k >= 1 && k <= headers.len()).then(|| k - 1),
            (None, None) => None,
        };
        let what = (m.name.clone()).map_or(format!("column {}", m.index.unwrap_or(0)), |n| {
            format!("`{n}`")
        });
        let i = i.ok_or(ColumnProblem::NotInFile {
            column: column.to_string(),
            what,
        })?;
        return at(i, m.unit.clone()).map(Some);
    }
    if channel(column).is_none() {
        let exact = headers.iter().position(|h| h == column);
        // Not a channel (a record's own column, a results table's metric): by its exact name, as
        // it is.
        return Ok(exact.map(|index| Resolved {
            name: column.to_string(),
            index,
            to_si: 1.0,
            note: None,
        }));
    }
    // Two columns of vshake's own name: neither is taken silently.
    if let Some(i) = named_once(column, headers, column)? {
        return at(i, None).map(Some);
    }
    let lower: Vec<usize> = (0..headers.len())
        .filter(|&i| headers[i].trim().eq_ignore_ascii_case(column))
        .collect();
    let found: Vec<usize> = if lower.len() == 1 {
        lower
    } else {
        (0..headers.len())
            .filter(|&i| recognise(&split(&headers[i]).0) == Some(column_of(column)))
            .collect()
    };
    match found.as_slice() {
        [] => Ok(None),
        [i] => at(*i, None).map(Some),
        _ => Err(ColumnProblem::Ambiguous {
            column: column.to_string(),
            headers: found.iter().map(|&i| headers[i].clone()).collect(),
        }),
    }
}

/// `column` read from header `i`, its unit `unit_text` where given, else the one written in the
/// header, else the units row's, else none (SI, with a note where the name is not vshake's).
fn read_at(
    column: &str,
    headers: &[String],
    units: Option<&[String]>,
    i: usize,
    unit_text: Option<String>,
) -> Result<Resolved, ColumnProblem> {
    let h = &headers[i];
    let (_, written) = split(h);
    let below = units
        .and_then(|u| u.get(i))
        .map(|u| strip_brackets(u).to_string())
        .filter(|u| !u.is_empty());
    let text = unit_text.or(written).or(below);
    let (to_si, what) = match &text {
        Some(t) => {
            let u = factor(h, t, column)?;
            let si = channel(column).map_or("SI", |c| c.2.si());
            (u.to_si, format!("{t} → {si}"))
        }
        None => (1.0, "no unit written: read as SI".to_string()),
    };
    let note = (h != column).then(|| format!("`{h}` read as {column} ({what})"));
    Ok(Resolved {
        name: column.to_string(),
        index: i,
        to_si,
        note,
    })
}

/// A channel's column name, whether given as it or as its key.
fn column_of(name_or_key: &str) -> &'static str {
    channel(name_or_key).map_or("", |c| c.0)
}

/// The `wanted` columns (each required) and the `optional` ones present, located in `headers`
/// (and a units row, `units`) with their factors to SI; `map` is a campaign's `columns` table
/// (by channel key or column name). Every problem is returned, not only the first.
pub fn resolve(
    headers: &[String],
    units: Option<&[String]>,
    wanted: &[&str],
    optional: &[&str],
    map: &[(String, Mapped)],
) -> Result<Vec<Resolved>, Vec<ColumnProblem>> {
    let mapped = |c: &str| {
        map.iter()
            .find(|(k, _)| k == c || channel(k).is_some_and(|ch| ch.0 == c))
            .map(|(_, m)| m)
    };
    let (mut out, mut problems) = (Vec::new(), Vec::new());
    for (c, required) in wanted
        .iter()
        .map(|c| (c, true))
        .chain(optional.iter().map(|c| (c, false)))
    {
        match locate(c, headers, units, mapped(c)) {
            Ok(Some(r)) => out.push(r),
            Ok(None) if required => problems.push(ColumnProblem::Missing(c.to_string())),
            Ok(None) => {}
            Err(p) => problems.push(p),
        }
    }
    problems.extend(read_twice(headers, &out));
    if problems.is_empty() {
        Ok(out)
    } else {
        Err(problems)
    }
}

/// One file column read as two channels (a `columns` table's position or name that another
/// channel takes too): a problem naming both.
fn read_twice(headers: &[String], out: &[Resolved]) -> Vec<ColumnProblem> {
    let mut problems = Vec::new();
    for (k, a) in out.iter().enumerate() {
        if let Some(b) = out[..k].iter().find(|b| b.index == a.index) {
            problems.push(ColumnProblem::Twice {
                header: headers[a.index].clone(),
                columns: [b.name.clone(), a.name.clone()],
            });
        }
    }
    problems
}

/// Whether every cell of `row` is a unit (or empty), with at least one unit: a units row.
pub(crate) fn is_units_row(row: &[String]) -> bool {
    row.iter().any(|c| unit(strip_brackets(c)).is_some())
        && row
            .iter()
            .all(|c| c.trim().is_empty() || unit(strip_brackets(c)).is_some())
}

/// A unit cell without its brackets (`[mm]` → `mm`).
pub fn strip_brackets(c: &str) -> &str {
    c.trim()
        .trim_start_matches(['(', '[', '{'])
        .trim_end_matches([')', ']', '}'])
        .trim()
}

/// How a text table is laid out: its separator, where its header, units row and data start.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// `,`, `;`, tab, or b' ' for runs of spaces and tabs.
    pub sep: u8,
    /// 0-based line of the header (None: no header, the first line is data).
    pub header: Option<usize>,
    /// 0-based line of a units row under the header.
    pub units: Option<usize>,
    /// 0-based line of the first data row.
    pub data: usize,
}

/// The fields of `line` split at `sep` (b' ': runs of white space; a bracketed unit after a
/// space joins the word before it).
pub fn fields(line: &str, sep: u8) -> Vec<String> {
    if sep != b' ' {
        return line
            .split(sep as char)
            .map(|f| f.trim().trim_matches('"').to_string())
            .collect();
    }
    let mut out: Vec<String> = Vec::new();
    for w in line.split_whitespace() {
        match out.last_mut() {
            Some(prev) if w.starts_with(['(', '[']) => {
                prev.push(' ');
                prev.push_str(w);
            }
            _ => out.push(w.to_string()),
        }
    }
    out
}

/// Whether `cell` is a number (a decimal comma where the separator is not the comma).
fn numeric(cell: &str, sep: u8) -> bool {
    let c = cell.trim();
    c.parse::<f64>().is_ok()
        || (sep != b','
            && c.matches(',').count() == 1
            && c.replace(',', ".").parse::<f64>().is_ok())
}

/// The first line of `lines` from which two lines in a row are all numbers, with as many fields
/// (at least two), at separator `sep`: (line, fields).
fn first_data(lines: &[&str], sep: u8) -> Option<(usize, usize)> {
    let data = |l: &str| {
        let f = fields(l, sep);
        (f.len() >= 2 && f.iter().all(|c| numeric(c, sep))).then_some(f.len())
    };
    let rows: Vec<(usize, usize)> = (lines.iter().enumerate())
        .filter(|(_, l)| !l.trim().is_empty())
        .take(200)
        .filter_map(|(i, l)| data(l).map(|n| (i, n)))
        .collect();
    rows.windows(2)
        .find(|w| w[0].1 == w[1].1)
        .map(|w| w[0])
        .or(rows.first().copied().filter(|_| rows.len() == 1))
}

/// The layout of a text table: the separator giving the most fields on the first data rows
/// (`,` on a tie), the header the last line before them whose fields are all words, a units row
/// under it, preamble lines above it. A file with no two numeric rows is read as header + data.
pub fn layout(text: &str) -> Layout {
    let lines: Vec<&str> = text.lines().collect();
    let best = [b',', b';', b'\t', b' ']
        .into_iter()
        .filter_map(|sep| first_data(&lines, sep).map(|(d, n)| (sep, d, n)))
        .max_by_key(|&(sep, _, n)| (n, [b' ', b'\t', b';', b','].iter().position(|&c| c == sep)));
    let Some((sep, d, n)) = best else {
        let sep = [b',', b';', b'\t']
            .into_iter()
            .max_by_key(|&c| {
                (
                    lines
                        .first()
                        .map_or(0, |l| l.bytes().filter(|&b| b == c).count()),
                    c == b',',
                )
            })
            .unwrap_or(b',');
        return Layout {
            sep,
            header: Some(0),
            units: None,
            data: 1,
        };
    };
    let words = |i: usize| {
        let f = fields(lines[i], sep);
        f.len() == n && f.iter().all(|c| !numeric(c, sep))
    };
    let above: Vec<usize> = (0..d).filter(|&i| words(i)).collect();
    let is_units = |i: usize| is_units_row(&fields(lines[i], sep));
    match above.as_slice() {
        [] => Layout {
            sep,
            header: None,
            units: None,
            data: d,
        },
        [.., h, u] if is_units(*u) && !is_units(*h) => Layout {
            sep,
            header: Some(*h),
            units: Some(*u),
            data: u + 1,
        },
        [.., h] => Layout {
            sep,
            header: Some(*h),
            units: None,
            data: h + 1,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn headers_split_into_name_and_unit() {
        assert_eq!(split("Accel (g)"), ("Accel".into(), Some("g".into())));
        assert_eq!(
            split("Ref Disp [mm]"),
            ("Ref Disp".into(), Some("mm".into()))
        );
        assert_eq!(split("disp_mm"), ("disp".into(), Some("mm".into())));
        assert_eq!(split("accel_mps2"), ("accel".into(), Some("mps2".into())));
        assert_eq!(split("TIME_S"), ("TIME".into(), Some("S".into())));
        assert_eq!(split("RefDisp"), ("RefDisp".into(), None));
        assert_eq!(split("p1"), ("p1".into(), None));
        // A MAT-file matrix's column: an index, not a unit.
        assert_eq!(split("data(:,2)"), ("data".into(), None));
        assert_eq!(split("accel_g(:,1)"), ("accel".into(), Some("g".into())));
    }

    #[test]
    fn names_are_recognised_in_common_spellings() {
        for (h, c) in [
            ("Time", "time_s"),
            ("RefDisp", "ref_disp_m"),
            ("Reference Displacement", "ref_disp_m"),
            ("Command Position", "ref_disp_m"),
            ("Disp", "disp_m"),
            ("Table Displacement", "disp_m"),
            ("Accel", "accel_mps2"),
            ("Platen Acceleration", "accel_mps2"),
            ("Actuator Force", "force_n"),
            ("Valve Cmd", "valve_cmd_v"),
            ("p1", "p1_pa"),
            ("Pressure 2", "p2_pa"),
            ("spool", "spool_m"),
        ] {
            assert_eq!(recognise(h), Some(c), "{h}");
        }
        assert_eq!(
            recognise("Ref Accel"),
            None,
            "a reference acceleration is not the measured one"
        );
        assert_eq!(recognise("A1 Table X"), None);
    }

    #[test]
    fn units_convert_to_si() {
        let f = |h: &str, c: &str| resolve(&s(&[h]), None, &[c], &[], &[]).unwrap()[0].to_si;
        assert_eq!(f("Accel (g)", "accel_mps2"), crate::kernel::params::G);
        assert_eq!(f("Disp (mm)", "disp_m"), 1e-3);
        assert_eq!(f("Time (ms)", "time_s"), 1e-3);
        assert_eq!(f("Accel (m/s^2)", "accel_mps2"), 1.0);
        assert_eq!(f("Force (kN)", "force_n"), 1e3);
        assert_eq!(f("P1 (bar)", "p1_pa"), 1e5);
        assert_eq!(f("P2 (MPa)", "p2_pa"), 1e6);
        assert!((f("P1 (psi)", "p1_pa") - 6894.757293168361).abs() < 1e-9);
        assert_eq!(f("TIME_S", "time_s"), 1.0);
        assert_eq!(f("accel_mps2", "accel_mps2"), 1.0);
    }

    #[test]
    fn problems_name_the_column_and_the_cause() {
        let e = resolve(
            &s(&["Time (s)", "Accel (furlongs)"]),
            None,
            &["time_s", "accel_mps2"],
            &[],
            &[],
        );
        assert!(
            matches!(&e.unwrap_err()[0], ColumnProblem::UnknownUnit { unit, .. } if unit == "furlongs")
        );
        let e = resolve(
            &s(&["Time (s)", "Accel (mm)"]),
            None,
            &["accel_mps2"],
            &[],
            &[],
        );
        assert!(matches!(
            &e.unwrap_err()[0],
            ColumnProblem::WrongQuantity { .. }
        ));
        let e = resolve(
            &s(&["Disp 1 (mm)", "Disp 2 (mm)"]),
            None,
            &["disp_m"],
            &[],
            &[],
        );
        assert!(
            matches!(&e.unwrap_err()[0], ColumnProblem::Ambiguous { headers, .. } if headers.len() == 2)
        );
        // Two columns of one name, the channel's own: an error naming both positions.
        let e = resolve(
            &s(&["time_s", "disp_m", "accel_mps2", "disp_m"]),
            None,
            &["time_s", "disp_m"],
            &[],
            &[],
        );
        let p = &e.unwrap_err()[0];
        assert!(
            matches!(p, ColumnProblem::SameName { positions, .. } if positions == &[2, 4]),
            "{p:?}"
        );
        assert!(p
            .to_string()
            .starts_with("columns 2 and 4 are both named `disp_m`"));
        let e = resolve(&s(&["Time (s)"]), None, &["time_s", "disp_m"], &[], &[]);
        assert_eq!(
            e.unwrap_err(),
            vec![ColumnProblem::Missing("disp_m".into())]
        );
    }

    #[test]
    fn a_columns_table_and_a_units_row_are_used() {
        let map = vec![(
            "accel".to_string(),
            Mapped {
                name: Some("A1 Table X".into()),
                index: None,
                unit: Some("g".into()),
            },
        )];
        let r = resolve(
            &s(&["t", "A1 Table X"]),
            None,
            &["time_s", "accel_mps2"],
            &[],
            &map,
        )
        .unwrap();
        assert_eq!((r[1].index, r[1].to_si), (1, crate::kernel::params::G));
        let units = s(&["s", "[mm]"]);
        assert!(is_units_row(&units));
        let r = resolve(
            &s(&["Time", "Disp"]),
            Some(&units),
            &["time_s", "disp_m"],
            &[],
            &[],
        )
        .unwrap();
        assert_eq!(r[1].to_si, 1e-3);
        assert!(!is_units_row(&s(&["0.0", "1.5"])));
        // A position another channel takes already (`t` is time by its name): both named.
        let twice = vec![(
            "disp".to_string(),
            Mapped {
                name: None,
                index: Some(1),
                unit: Some("mm".into()),
            },
        )];
        let p = resolve(&s(&["t", "x"]), None, &["time_s", "disp_m"], &[], &twice).unwrap_err();
        assert_eq!(p.len(), 1);
        assert!(p[0]
            .to_string()
            .starts_with("column `t` would be read as both `time_s` and `disp_m`"));
    }

    #[test]
    fn layouts_are_found() {
        let l = layout("Time (s),Disp (mm)\n0.0,1.0\n0.1,2.0\n");
        assert_eq!(
            l,
            Layout {
                sep: b',',
                header: Some(0),
                units: None,
                data: 1
            }
        );
        let l = layout("Test: sine\nDate: today\nrate 1024\n\nTime;Disp\ns;mm\n0,0;1,5\n0,1;2,5\n");
        assert_eq!(
            l,
            Layout {
                sep: b';',
                header: Some(4),
                units: Some(5),
                data: 6
            }
        );
        let l = layout("  0.0000000e+00  1.0e-3\n  9.765625e-04  2.0e-3\n");
        assert_eq!(
            l,
            Layout {
                sep: b' ',
                header: None,
                units: None,
                data: 0
            }
        );
        let l = layout("time_s ref_disp_m\n0.0 1.0\n0.1 2.0\n");
        assert_eq!(
            l,
            Layout {
                sep: b' ',
                header: Some(0),
                units: None,
                data: 1
            }
        );
        // A bad first data row stays a data row (reported by the reader, with its line).
        let l = layout("time_s,disp_m\n0.0,abc\n0.1,2.0\n0.2,3.0\n");
        assert_eq!(
            l,
            Layout {
                sep: b',',
                header: Some(0),
                units: None,
                data: 1
            }
        );
        assert_eq!(
            fields("Time (s)  Disp [mm]", b' '),
            s(&["Time (s)", "Disp [mm]"])
        );
    }
}
