//! The channels of a measured test and the units a lab writes them in: what each channel is
//! (its column name, its key in a campaign's `columns` table, the quantity it measures), and each
//! unit's factor to SI. The vocabulary the file readers (the shell's `formats::headers`) and the
//! campaign reader (the orchestration's `measured::campaign`) share; pure data and lookups.

use std::path::Path;

/// Standard gravity, m/s² (used for amplitudes in g and for the bearing force F_V = M·g).
pub const G: f64 = 9.80665;

/// Whether `path` names a PEER NGA acceleration file (extension `.AT2`, any case): read as a
/// record in g, whatever its columns (the shell's reader and the run files' checks agree on it).
pub fn is_at2(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("at2"))
}

/// What a unit measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    Time,
    Length,
    Acceleration,
    Force,
    Pressure,
    Voltage,
}

impl Quantity {
    /// The SI unit vshake's columns hold.
    pub fn si(self) -> &'static str {
        match self {
            Quantity::Time => "s",
            Quantity::Length => "m",
            Quantity::Acceleration => "m/s²",
            Quantity::Force => "N",
            Quantity::Pressure => "Pa",
            Quantity::Voltage => "V",
        }
    }
}

/// One pound-force in N [NIST SP 811, B.8: 4.448 222].
const LBF: f64 = 4.448_221_615_260_5;

/// Units read from headers: their spellings (lower case, compared case-insensitively), what they
/// measure and the factor to SI [exact definitions: NIST SP 811 appendix B].
const UNITS: &[(&[&str], Quantity, f64)] = &[
    (
        &["s", "sec", "secs", "second", "seconds"],
        Quantity::Time,
        1.0,
    ),
    (
        &["ms", "msec", "millisecond", "milliseconds"],
        Quantity::Time,
        1e-3,
    ),
    (
        &["m", "meter", "meters", "metre", "metres"],
        Quantity::Length,
        1.0,
    ),
    (
        &["mm", "millimeter", "millimeters", "millimetre"],
        Quantity::Length,
        1e-3,
    ),
    (&["cm"], Quantity::Length, 1e-2),
    (&["um", "µm", "micron", "microns"], Quantity::Length, 1e-6),
    (&["in", "inch", "inches"], Quantity::Length, 0.0254),
    (
        &[
            "m/s^2", "m/s2", "m/s²", "m/s/s", "mps2", "m s^-2", "ms-2", "m.s-2",
        ],
        Quantity::Acceleration,
        1.0,
    ),
    (&["g", "gs", "g's"], Quantity::Acceleration, G),
    (
        &["cm/s^2", "cm/s2", "cm/s²", "gal"],
        Quantity::Acceleration,
        1e-2,
    ),
    (&["mm/s^2", "mm/s2", "mm/s²"], Quantity::Acceleration, 1e-3),
    (
        &["in/s^2", "in/s2", "in/s²"],
        Quantity::Acceleration,
        0.0254,
    ),
    (&["n", "newton", "newtons"], Quantity::Force, 1.0),
    (&["kn"], Quantity::Force, 1e3),
    (&["lbf", "lb"], Quantity::Force, LBF),
    (&["kip", "kips"], Quantity::Force, 1e3 * LBF),
    (&["pa"], Quantity::Pressure, 1.0),
    (&["kpa"], Quantity::Pressure, 1e3),
    (&["mpa"], Quantity::Pressure, 1e6),
    (&["bar"], Quantity::Pressure, 1e5),
    (&["psi"], Quantity::Pressure, LBF / (0.0254 * 0.0254)),
    (&["v", "volt", "volts"], Quantity::Voltage, 1.0),
    (&["mv"], Quantity::Voltage, 1e-3),
];

/// A unit read from a header: what it measures and its factor to SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unit {
    pub quantity: Quantity,
    pub to_si: f64,
}

/// The unit `text` names (case, spaces and a `mps2`-style spelling allowed), if it is one.
pub fn unit(text: &str) -> Option<Unit> {
    let t: String = text
        .trim()
        .to_lowercase()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    let t = t.replace("**", "^");
    UNITS
        .iter()
        .find(|(names, _, _)| {
            names.contains(&t.as_str()) || names.contains(&t.replace(' ', "").as_str())
        })
        .map(|&(_, quantity, to_si)| Unit { quantity, to_si })
}

/// Every unit spelling, for messages.
pub fn unit_list() -> String {
    UNITS
        .iter()
        .map(|(n, _, _)| n[0])
        .collect::<Vec<_>>()
        .join(", ")
}

/// vshake's channels: the column name, the key of a campaign's `columns` table, what it measures.
pub const CHANNELS: &[(&str, &str, Quantity)] = &[
    ("time_s", "time", Quantity::Time),
    ("ref_disp_m", "ref_disp", Quantity::Length),
    ("disp_m", "disp", Quantity::Length),
    ("accel_mps2", "accel", Quantity::Acceleration),
    ("valve_cmd_v", "valve_cmd", Quantity::Voltage),
    ("force_n", "force", Quantity::Force),
    ("p1_pa", "p1", Quantity::Pressure),
    ("p2_pa", "p2", Quantity::Pressure),
    ("spool_m", "spool", Quantity::Length),
];

/// The channel row of a column name or a `columns` key.
pub fn channel(name_or_key: &str) -> Option<(&'static str, &'static str, Quantity)> {
    CHANNELS
        .iter()
        .copied()
        .find(|(c, k, _)| *c == name_or_key || *k == name_or_key)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_and_channels_are_found() {
        let g = unit("g").unwrap();
        assert_eq!((g.to_si, g.quantity), (G, Quantity::Acceleration));
        assert_eq!(unit("kN").unwrap().to_si, 1e3);
        assert!(unit("furlong").is_none());
        let (column, key, q) = channel("accel").unwrap();
        assert_eq!(
            (channel(column).unwrap().1, key, q),
            (key, "accel", Quantity::Acceleration)
        );
        assert!(unit_list().contains("psi"));
    }

    /// Each quantity's SI unit, the one a message says a column holds, is read back as that
    /// quantity at a factor of exactly 1; and every channel's column name ends in it (`_m`,
    /// `_mps2`, `_n`, …, the suffix spelled as a unit too).
    #[test]
    fn each_quantitys_si_unit_is_read_at_a_factor_of_one() {
        use Quantity::*;
        for q in [Time, Length, Acceleration, Force, Pressure, Voltage] {
            let u = unit(q.si()).unwrap_or_else(|| panic!("{q:?}: {:?} is no unit", q.si()));
            assert_eq!((u.quantity, u.to_si), (q, 1.0), "{q:?}");
        }
        for (column, _, q) in CHANNELS {
            let suffix = column.rsplit('_').next().unwrap();
            let u = unit(suffix).unwrap_or_else(|| panic!("{column}: {suffix} is no unit"));
            assert_eq!((u.quantity, u.to_si), (*q, 1.0), "{column}");
        }
    }
}
