//! The rows of one parameter table: each parameter's unit, default, valid range, source and
//! description, and the [`params!`] macro that generates a table's struct from them.
//!
//! A table knows nothing of the model it sits in: the baseline's tables
//! ([`crate::baseline_params`]), the ground motion's ([`crate::ground`]) and each library
//! effect's are generated here, and [`crate::params`] assembles them into the model's
//! parameter set and its registry (`component.name`). So the effect library, below the model,
//! never names the model's type.

use std::fmt;

/// Where a default comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Published value of the LHPOST virtual model.
    Paper,
    /// Not published; chosen by this project (the reason is in the parameter's description).
    Chosen,
    /// From the publication cited in the parameter's description (not the LHPOST paper).
    Literature,
}

impl fmt::Display for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Source::Paper => "paper",
            Source::Chosen => "chosen",
            Source::Literature => "literature",
        })
    }
}

/// Valid range of a parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub lo: f64,
    pub hi: f64,
    pub lo_inclusive: bool,
    pub hi_inclusive: bool,
}

impl Range {
    pub const fn gt(lo: f64) -> Self {
        Range {
            lo,
            hi: f64::INFINITY,
            lo_inclusive: false,
            hi_inclusive: false,
        }
    }
    pub const fn ge(lo: f64) -> Self {
        Range {
            lo,
            hi: f64::INFINITY,
            lo_inclusive: true,
            hi_inclusive: false,
        }
    }
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Range {
            lo,
            hi,
            lo_inclusive: true,
            hi_inclusive: true,
        }
    }
    pub const fn open_closed(lo: f64, hi: f64) -> Self {
        Range {
            lo,
            hi,
            lo_inclusive: false,
            hi_inclusive: true,
        }
    }
    pub const fn any() -> Self {
        Range {
            lo: f64::NEG_INFINITY,
            hi: f64::INFINITY,
            lo_inclusive: false,
            hi_inclusive: false,
        }
    }
    /// True when `v` is finite and inside the range.
    pub fn contains(&self, v: f64) -> bool {
        if !v.is_finite() {
            return false;
        }
        let lo_ok = if self.lo_inclusive {
            v >= self.lo
        } else {
            v > self.lo
        };
        let hi_ok = if self.hi_inclusive {
            v <= self.hi
        } else {
            v < self.hi
        };
        lo_ok && hi_ok
    }
}

impl fmt::Display for Range {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let l = if self.lo_inclusive { '[' } else { '(' };
        let h = if self.hi_inclusive { ']' } else { ')' };
        let fmt_v = |v: f64| {
            if v == f64::INFINITY {
                "inf".to_string()
            } else if v == f64::NEG_INFINITY {
                "-inf".to_string()
            } else {
                format!("{v}")
            }
        };
        write!(f, "{l}{}, {}{h}", fmt_v(self.lo), fmt_v(self.hi))
    }
}

/// One row of a parameter table.
#[derive(Debug, Clone, Copy)]
pub struct FieldInfo {
    /// Field name inside its table.
    pub name: &'static str,
    /// Unit as printed for humans.
    pub unit: &'static str,
    /// Unit suffix for table column names (empty for dimensionless).
    pub unit_suffix: &'static str,
    pub default: f64,
    pub range: Range,
    pub source: Source,
    /// What the parameter means, and for [chosen] values why this value.
    pub doc: &'static str,
}

/// A table's values by row index (the order of its `FIELDS`).
pub trait Fields {
    /// The value of row `i`.
    fn field(&self, i: usize) -> f64;
    /// Sets row `i` to `v`.
    fn set_field(&mut self, i: usize, v: f64);
}

/// One problem found by validating a parameter set.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamIssue {
    /// `component.name` (or several, comma-separated, for a relation between parameters).
    pub path: String,
    pub message: String,
}

impl fmt::Display for ParamIssue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path, self.message)
    }
}

/// Generates one parameter table: its struct, its `Default`, its rows (`FIELDS`) and [`Fields`].
///
/// `pub struct Name { rows }`. Row syntax: `name: unit, suffix, default, range, source,
/// "description";`
macro_rules! params {
    (
        $(#[$meta:meta])*
        pub struct $Struct:ident {
            $( $name:ident : $unit:literal, $suffix:literal, $default:expr, $range:expr, $src:ident, $doc:literal; )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq)]
        pub struct $Struct {
            $(
                #[doc = $doc]
                #[doc = ""]
                #[doc = concat!("Unit: ", $unit, ". Default: `", stringify!($default), "`. Range: `",
                    stringify!($range), "`. Source: ", stringify!($src), ".")]
                pub $name: f64,
            )*
        }

        impl Default for $Struct {
            fn default() -> Self {
                $Struct { $( $name: $default, )* }
            }
        }

        impl $Struct {
            /// The table's rows, in field order.
            pub const FIELDS: &'static [$crate::param_table::FieldInfo] = &[
                $(
                    $crate::param_table::FieldInfo {
                        name: stringify!($name),
                        unit: $unit,
                        unit_suffix: $suffix,
                        default: $default,
                        range: $range,
                        source: $crate::param_table::Source::$src,
                        doc: $doc,
                    },
                )*
            ];
        }

        impl $crate::param_table::Fields for $Struct {
            fn field(&self, i: usize) -> f64 {
                [$(self.$name),*][i]
            }
            fn set_field(&mut self, i: usize, v: f64) {
                *[$(&mut self.$name),*][i] = v;
            }
        }
    };
}
pub(crate) use params;
