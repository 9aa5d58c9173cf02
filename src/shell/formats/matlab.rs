//! MATLAB MAT-files as tables: level 5 files (`save` up to `-v7`; v7 compresses each variable),
//! read with the `matfile` crate. Each real numeric vector is a column named as its variable
//! (`t`, `RefDisp`, `accel_g`), each matrix of samples × channels gives columns `M(:,1)`, ...
//! (so that a campaign's `columns` table maps them by name or by position, as with a CSV header).
//! Scalars, text, structs, cells and MATLAB `table` objects hold no channel: they are skipped,
//! and named in the note where nothing else was found. A v7.3 file (HDF5) is refused by
//! [`super::tables`] with the MATLAB line that saves it readably.

/// The columns of a MAT-file: names, values (every one as f64) and what was read or skipped.
#[derive(Debug, Default)]
pub struct MatColumns {
    pub names: Vec<String>,
    pub values: Vec<Vec<f64>>,
    /// The variables skipped, with why (`fs (a scalar)`).
    pub skipped: Vec<String>,
    /// Whether any variable was compressed (a v7 file).
    pub compressed: bool,
    /// How many variables are neither numeric arrays nor listed in `skipped` (text, structs,
    /// cells, objects such as a MATLAB `table`).
    pub other: usize,
}

/// The first bytes of a level 5 MAT-file's text header.
pub const V5_MAGIC: &[u8] = b"MATLAB 5.0 MAT-file";

/// Reads the numeric variables of the level 5 MAT-file `bytes` as columns, or says why it cannot
/// be read. A parser panic on a corrupt file is caught and reported as such.
pub fn columns(bytes: &[u8]) -> Result<MatColumns, String> {
    let (elements, compressed) = elements(bytes)?;
    let parsed = std::panic::catch_unwind(|| matfile::MatFile::parse(bytes))
        .map_err(|_| "the file is corrupt (the MAT-file parser stopped)".to_string())?
        .map_err(|e| format!("the file is corrupt or truncated ({})", short(&e)))?;
    let mut out = MatColumns {
        compressed,
        ..MatColumns::default()
    };
    for a in parsed.arrays() {
        add_array(&mut out, a);
    }
    out.other = elements.saturating_sub(parsed.arrays().len());
    Ok(out)
}

/// The parser's error, on one line and at most 120 characters (its debug form can hold bytes).
fn short(e: &matfile::Error) -> String {
    let s = format!("{e}");
    let s = s.lines().next().unwrap_or("").to_string();
    if s.chars().count() > 120 {
        s.chars().take(120).collect::<String>() + "…"
    } else {
        s
    }
}

/// The number of variables (top-level data elements) of a level 5 MAT-file and whether any is
/// compressed (a v7 file), each one's extent checked against the file's length: a truncated file
/// is an error saying where it ends.
fn elements(bytes: &[u8]) -> Result<(usize, bool), String> {
    let big = bytes.get(126..128) == Some(b"MI");
    let word = |at: usize| {
        let b: [u8; 4] = bytes.get(at..at + 4)?.try_into().ok()?;
        Some(if big {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        } as usize)
    };
    let (mut at, mut n, mut compressed) = (128usize, 0usize, false);
    while at < bytes.len() {
        let (Some(kind), Some(size)) = (word(at), word(at + 4)) else {
            return Err(format!(
                "the file is truncated (it ends inside variable {} at byte {})",
                n + 1,
                bytes.len()
            ));
        };
        // A variable is a matrix (miMATRIX, 14) or a compressed one (miCOMPRESSED, 15); the
        // parser would print a line to stdout for anything else.
        if kind != 14 && kind != 15 {
            return Err(format!(
                "the file is corrupt: variable {} at byte {at} has data type {kind}, not a matrix",
                n + 1
            ));
        }
        // Uncompressed elements are padded to 8 bytes; compressed ones are not.
        let padded = if kind == 15 {
            size
        } else {
            size.div_ceil(8) * 8
        };
        let end = at.saturating_add(8).saturating_add(padded);
        if at + 8 + size > bytes.len() {
            return Err(format!(
                "the file is truncated: variable {} needs {} bytes from byte {at}, the file has {}",
                n + 1,
                8 + size,
                bytes.len()
            ));
        }
        n += 1;
        compressed |= kind == 15;
        at = end;
    }
    Ok((n, compressed))
}

/// One array as columns (a vector: one; a samples × channels matrix: one per channel), or as a
/// skipped variable with why.
fn add_array(out: &mut MatColumns, a: &matfile::Array) {
    let name = a.name().to_string();
    let Some(values) = real_values(a.data()) else {
        out.skipped.push(format!("{name} (complex)"));
        return;
    };
    let size = a.size();
    let n = values.len();
    let long = size.iter().copied().max().unwrap_or(0);
    if n < 2 {
        out.skipped.push(format!("{name} (a scalar)"));
    } else if long == n {
        out.names.push(name);
        out.values.push(values);
    } else if size.len() == 2 {
        // Column-major: size[0] rows of size[1] columns; samples run along the longer dimension.
        let (rows, cols) = (size[0], size[1]);
        let channel = |j: usize| -> Vec<f64> {
            if rows >= cols {
                values[j * rows..(j + 1) * rows].to_vec()
            } else {
                (0..cols).map(|i| values[i * rows + j]).collect()
            }
        };
        for j in 0..rows.min(cols) {
            out.names.push(format!("{name}(:,{})", j + 1));
            out.values.push(channel(j));
        }
    } else {
        out.skipped
            .push(format!("{name} (a {}-D array)", size.len()));
    }
}

/// The real part of numeric data as f64; None where it has an imaginary part.
fn real_values(d: &matfile::NumericData) -> Option<Vec<f64>> {
    use matfile::NumericData as N;
    fn f<T: Copy + Into<f64>, U>(real: &[T], imag: &Option<U>) -> Option<Vec<f64>> {
        imag.is_none()
            .then(|| real.iter().map(|&x| x.into()).collect())
    }
    match d {
        N::Double { real, imag } => f(real, imag),
        N::Single { real, imag } => f(real, imag),
        N::Int8 { real, imag } => f(real, imag),
        N::UInt8 { real, imag } => f(real, imag),
        N::Int16 { real, imag } => f(real, imag),
        N::UInt16 { real, imag } => f(real, imag),
        N::Int32 { real, imag } => f(real, imag),
        N::UInt32 { real, imag } => f(real, imag),
        N::Int64 { real, imag } => imag
            .is_none()
            .then(|| real.iter().map(|&x| x as f64).collect()),
        N::UInt64 { real, imag } => imag
            .is_none()
            .then(|| real.iter().map(|&x| x as f64).collect()),
    }
}

/// A level 5 MAT-file (uncompressed, as MATLAB's `save -v6`; MATLAB, SciPy and this reader load
/// it) of double column vectors [MathWorks, "MAT-File Format": a 128-byte header, then one
/// miMATRIX element per variable, each sub-element padded to 8 bytes].
pub fn v5_bytes(vars: &[(&str, &[f64])]) -> Vec<u8> {
    fn element(kind: u32, body: &[u8]) -> Vec<u8> {
        let mut e = kind.to_le_bytes().to_vec();
        e.extend((body.len() as u32).to_le_bytes());
        e.extend(body);
        e.resize(e.len().div_ceil(8) * 8, 0);
        e
    }
    let mut out = b"MATLAB 5.0 MAT-file, written by vshake (study synth)".to_vec();
    out.resize(124, b' ');
    out.extend(0x0100u16.to_le_bytes());
    out.extend(b"IM");
    for (name, v) in vars {
        // mxDOUBLE_CLASS (6), no flags; dimensions n × 1; the name; the values (miDOUBLE, 9).
        let flags: Vec<u8> = [6u32, 0].iter().flat_map(|x| x.to_le_bytes()).collect();
        let dims: Vec<u8> = [v.len() as i32, 1]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let data: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        let mut body = element(6, &flags);
        body.extend(element(5, &dims));
        body.extend(element(1, name.as_bytes()));
        body.extend(element(9, &data));
        out.extend(element(14, &body));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_files_read_back_exactly() {
        let t = [0.0, 0.5, 1.0, 1.5];
        let a = [1.0, -2.5e-3, f64::MIN_POSITIVE, 3.0e8];
        let m = columns(&v5_bytes(&[("time_s", &t), ("accel_mps2", &a)])).unwrap();
        assert_eq!(m.names, ["time_s", "accel_mps2"]);
        assert_eq!(m.values, [t.to_vec(), a.to_vec()]);
        assert!(!m.compressed);
    }
}
