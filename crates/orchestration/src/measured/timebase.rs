//! The time base of a measured file: a uniform grid t_n = t_0 + n/R rebuilt from the row index
//! and a rate R fitted to the time column.
//!
//! Data-acquisition exports print time with 5–9 significant digits (numpy `%.9g`, MATLAB,
//! spreadsheets, a fixed number of decimals), so consecutive steps jitter by rounding. That is
//! not an error. The checks, in order:
//!
//! 1. the printed resolution q_n of each row: the decimal quantum of its shortest round-trip
//!    representation (`12.3457` → 1e-4 s; trailing zeros only make it coarser, i.e. more lenient);
//! 2. the step: the median of the differences, robust to a few gaps;
//! 3. each difference in whole steps m = ⌊d_n/step⌉: m ≥ 2 is a gap (rows missing just before
//!    row n), m ≤ 0 time that does not increase, named at that row — where that can be told: in
//!    a column whose every difference is a whole number of steps (exact values, whatever their
//!    digits), or where the two rows' printed resolution is finer than half a step;
//! 4. the grid: least squares t_n ≈ t_0 + n·Δ over every row; the rate 1/Δ is taken as the
//!    nearest whole number of hertz when that is within four standard errors of the fit (a
//!    DAQ's rates are whole numbers; the rebuilt grid is then exact), and t_0 refitted;
//! 5. every row within rounding of the grid: |t_n − (t_0 + nΔ)| ≤ max(q_n/2, 5 % of Δ) (either
//!    consistent with its printed digits, or within a tolerance relative to the step); anything
//!    further is a drifting clock or an edited row, named.
//!
//! Where the printed resolution is coarser than half a step, step 3 cannot work: a dropped row
//! cannot be told from rounding, which the result says ([`TimeBase::unresolved`]).

use std::fmt;

/// Share of a step by which a row may miss the grid whatever its printed digits [chosen: float32
/// time columns, and clocks stamped to a few microseconds, stay well inside it; a dropped row is
/// a whole step].
pub const STEP_TOLERANCE: f64 = 0.05;

/// A uniform grid rebuilt from a time column.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeBase {
    /// Sample rate R, Hz.
    pub rate_hz: f64,
    /// Time of row 0 on the grid, s.
    pub t0_s: f64,
    pub rows: usize,
    /// Largest |t_n − grid(n)|, s.
    pub max_jitter_s: f64,
    /// Printed resolution of the latest rows (the coarsest, with significant digits), s (0 for
    /// a column of exact values).
    pub resolution_s: f64,
    /// Significant digits of the most finely printed row (17 at full precision).
    pub digits: u32,
    /// Decimal places, where the column is printed with a fixed number of them (the latest rows
    /// are printed as finely as the earliest), else None.
    pub decimals: Option<u32>,
    /// Whether the rate was snapped to a whole number of hertz.
    pub whole_hz: bool,
    /// The printed resolution is too coarse to detect dropped rows from time alone.
    pub unresolved: bool,
}

impl TimeBase {
    /// Time of row `n` on the grid, s.
    pub fn time(&self, n: f64) -> f64 {
        self.t0_s + n / self.rate_hz
    }
    /// The step 1/R, s.
    pub fn step(&self) -> f64 {
        1.0 / self.rate_hz
    }
    /// Whether the time column needed rebuilding (it was not exactly on the grid).
    pub fn rounded(&self) -> bool {
        self.max_jitter_s > 0.0
    }
    /// One line on how the grid was rebuilt, for the notes of a comparison (None when the column
    /// was exact).
    pub fn note(&self) -> Option<String> {
        if !self.rounded() {
            return None;
        }
        let mut s = format!(
            "time_s jitters by up to ±{:.2e} s ({:.1} % of a step) around a uniform grid, consistent with rounding to {}; the grid was rebuilt from the row index at {} Hz",
            self.max_jitter_s,
            100.0 * self.max_jitter_s * self.rate_hz,
            match self.decimals {
                Some(d) => format!("{d} decimal place(s)"),
                None => format!("{} significant digits", self.digits),
            },
            fmt_rate(self.rate_hz)
        );
        if self.unresolved {
            s.push_str(&format!(" (printed to {:.0e} s, coarser than half a step: dropped rows cannot be detected from the time column)", self.resolution_s));
        }
        Some(s)
    }
}

/// A rate for printing: whole hertz exactly, else six significant digits.
pub fn fmt_rate(r: f64) -> String {
    if r == r.round() {
        format!("{r:.0}")
    } else {
        format!("{r:.6}")
    }
}

/// Why a time column is refused. Rows are 1-based data rows.
#[derive(Debug, Clone, PartialEq)]
pub enum TimeProblem {
    TooFew {
        rows: usize,
    },
    GoesBack {
        row: usize,
        t: f64,
        prev: f64,
    },
    Gap {
        row: usize,
        t: f64,
        prev: f64,
        missing: usize,
        step: f64,
        more: usize,
    },
    OffGrid {
        row: usize,
        t: f64,
        grid: f64,
        allowed: f64,
        rate_hz: f64,
    },
}

impl TimeProblem {
    /// The 1-based data row the problem is at.
    pub fn row(&self) -> usize {
        match self {
            TimeProblem::TooFew { rows } => *rows,
            TimeProblem::GoesBack { row, .. }
            | TimeProblem::Gap { row, .. }
            | TimeProblem::OffGrid { row, .. } => *row,
        }
    }
}

impl fmt::Display for TimeProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TimeProblem::TooFew { rows } => write!(f, "{rows} row(s): a test needs at least two samples"),
            TimeProblem::GoesBack { t, prev, .. } => write!(f, "time {t} s does not increase (previous row {prev} s); rounding of the printed digits cannot explain it"),
            TimeProblem::Gap { t, prev, missing, step, more, .. } => {
                write!(f, "time jumps from {prev} s to {t} s: {missing} row(s) missing before this row (the file's step is {step:.6e} s); a gap is not rounding")?;
                if *more > 0 {
                    write!(f, " ({more} more gap(s) further on)")?;
                }
                Ok(())
            }
            TimeProblem::OffGrid { t, grid, allowed, rate_hz, .. } => write!(
                f,
                "time {t} s is {:.3e} s off the uniform grid fitted to the file ({} Hz; its printed digits and 5 % of a step allow ±{allowed:.3e} s): the sampling clock drifts or rows were edited",
                t - grid,
                fmt_rate(*rate_hz)
            ),
        }
    }
}

/// Ulps of its value by which a printed time may have moved on its way in: a column in another
/// unit (ms) is scaled to seconds as it is read, and the product is rounded, as was the printed
/// value [chosen: a scaled decimal is within 2 ulps of the scaled decimal's nearest double].
const CONVERSION_ULPS: f64 = 4.0;

/// Decimal quantum of the shortest representation of `x` (0 for 0) within [`CONVERSION_ULPS`] of
/// it, and its significant digits: the digits it was printed with, in whatever unit.
pub(crate) fn printed_quantum(x: f64) -> (f64, u32) {
    if x == 0.0 || !x.is_finite() {
        return (0.0, 1);
    }
    let a = x.abs();
    let shortest = quantum_of(&format!("{a:e}"));
    if shortest.1 < 15 {
        return shortest;
    }
    let near = |s: &String| {
        s.parse::<f64>()
            .is_ok_and(|y| (y - a).abs() <= CONVERSION_ULPS * f64::EPSILON * a)
    };
    (1..shortest.1 as usize)
        .map(|p| format!("{a:.*e}", p - 1))
        .find(near)
        .map_or(shortest, |s| quantum_of(&s))
}

/// The quantum and significant digits of `s`, a number printed by `{:e}`.
fn quantum_of(s: &str) -> (f64, u32) {
    let (mant, exp) = s.split_once('e').expect("{:e} has an exponent");
    let exp: i32 = exp.parse().expect("exponent");
    let mant = mant.trim_end_matches('0').trim_end_matches('.');
    let decimals = mant.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    (10f64.powi(exp - decimals), decimals as u32 + 1)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Rebuilds the grid of a time column (see the module docs).
pub(crate) fn rebuild(t: &[f64]) -> Result<TimeBase, TimeProblem> {
    let n = t.len();
    if n < 2 {
        return Err(TimeProblem::TooFew { rows: n });
    }
    let quanta = quanta_of(t);
    let q = |i: usize| quanta[i].0;
    let d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let step = nominal_step(t, &d)?;
    let line = Line::fit(t);
    // Rows printing the same time are rounding only where the rate cannot be printed exactly.
    let repeats = d.iter().any(|&x| x <= 0.0);
    let printable = !repeats || printable_step(1.0 / line.rate_hz, &quanta);
    let (jittery, unreliable) = check_steps(t, &d, step, &q, printable)?;
    let (a, rate_hz, b, whole_hz) = (line.a, line.rate_hz, line.b, line.whole_hz);
    let grid = |i: usize| a + i as f64 / rate_hz;
    // The grid itself is uncertain by the fit's standard errors (rounding averages out).
    let nf = n as f64;
    let fit_err = 4.0 * line.s_e * (1.0 / nf + (nf / 2.0).powi(2) / line.sxx).sqrt();
    let mut max_jitter: f64 = 0.0;
    for i in 0..n {
        let e = t[i] - grid(i);
        let allowed = (0.5 * q(i) * (1.0 + 1e-9)).max(STEP_TOLERANCE * b)
            + fit_err
            + 4.0 * f64::EPSILON * t[i].abs();
        if e.abs() > allowed {
            return Err(TimeProblem::OffGrid {
                row: i + 1,
                t: t[i],
                grid: grid(i),
                allowed,
                rate_hz,
            });
        }
        max_jitter = max_jitter.max(e.abs());
    }
    // On the grid to the last bit of each value: the column was exact, nothing was rebuilt.
    let exact = (0..n).all(|i| (t[i] - grid(i)).abs() <= 4.0 * f64::EPSILON * t[i].abs().max(b));
    let digits = quanta.iter().map(|x| x.1).max().unwrap_or(17);
    let decimals = fixed_decimals(&quanta);
    let resolution_s = match (jittery, decimals) {
        (false, _) => 0.0,
        (true, Some(d)) => 10f64.powi(-(d as i32)),
        // The latest rows' typical quantum (one printed with trailing zeros dropped, `20`, says
        // nothing of the digits).
        (true, None) => median(
            &mut quanta[n - n.div_ceil(10)..]
                .iter()
                .map(|x| x.0)
                .collect::<Vec<_>>(),
        ),
    };
    Ok(TimeBase {
        rate_hz,
        t0_s: if exact { t[0] } else { a },
        rows: n,
        max_jitter_s: if exact { 0.0 } else { max_jitter },
        resolution_s,
        digits,
        decimals,
        whole_hz,
        unresolved: jittery && unreliable * 2 > n,
    })
}

/// Each time's printed quantum and digits; a zero tells nothing of the digits it was printed
/// with, so it gets the column's typical quantum.
fn quanta_of(t: &[f64]) -> Vec<(f64, u32)> {
    let mut quanta: Vec<(f64, u32)> = t.iter().map(|&x| printed_quantum(x)).collect();
    let mut nonzero: Vec<f64> = quanta.iter().map(|x| x.0).filter(|q| *q > 0.0).collect();
    if !nonzero.is_empty() {
        let typical = median(&mut nonzero);
        for (x, qx) in t.iter().zip(quanta.iter_mut()) {
            if *x == 0.0 {
                qx.0 = typical;
            }
        }
    }
    quanta
}

/// Decimal places of a column printed with a fixed number of them: its last tenth of rows
/// (the largest times) printed as finely as the whole column, to 1e-1 s or finer, and coarser
/// than full precision. With significant digits the largest times are printed the coarsest.
fn fixed_decimals(quanta: &[(f64, u32)]) -> Option<u32> {
    let finest = |q: &[(f64, u32)]| {
        q.iter()
            .map(|x| x.0)
            .filter(|q| *q > 0.0)
            .fold(f64::INFINITY, f64::min)
    };
    let all = finest(quanta);
    let last = finest(&quanta[quanta.len() - quanta.len().div_ceil(10)..]);
    let places = -all.log10().round();
    (all == last && (1.0..=12.0).contains(&places)).then_some(places as u32)
}

/// Whether the file's step (from the fitted rate) is a whole number of the column's finest
/// printed quantum, so that an exact column is possible at all: at 1024 Hz printed to 1 ms two
/// rows print the same time every 43 rows, while every difference is a whole millisecond, which
/// alone would look like an exact column with rows that do not advance.
fn printable_step(step: f64, quanta: &[(f64, u32)]) -> bool {
    let finest = quanta
        .iter()
        .map(|x| x.0)
        .filter(|q| *q > 0.0)
        .fold(f64::INFINITY, f64::min);
    if !finest.is_finite() {
        return true;
    }
    let k = step / finest;
    (k - k.round()).abs() <= 0.01 * k.round().max(1.0)
}

/// The step between rows: the median difference `d` (it resists gaps), or the mean where
/// printing is so coarse that steps repeat; time that does not advance is refused.
fn nominal_step(t: &[f64], d: &[f64]) -> Result<f64, TimeProblem> {
    let n = t.len();
    let step_med = median(&mut d.to_vec());
    let step_mean = (t[n - 1] - t[0]) / (n - 1) as f64;
    let step = if step_med > 0.0 && (step_med / step_mean - 1.0).abs() < 0.5 {
        step_med
    } else {
        step_mean
    };
    if !(step > 0.0) {
        let i = (1..n).find(|&i| t[i] <= t[i - 1]).unwrap_or(1);
        return Err(TimeProblem::GoesBack {
            row: i + 1,
            t: t[i],
            prev: t[i - 1],
        });
    }
    Ok(step)
}

/// Whole steps between rows. An exact column (every difference a multiple of the step, and the
/// file's rate printable at its digits: [`printable_step`]) tells gaps whatever its digits; a rounded one where its rows' digits resolve a step. Returns
/// whether the column jitters and how many differences its digits cannot resolve; the first
/// problem in row order is refused (after a gap, only further gaps are counted).
fn check_steps(
    t: &[f64],
    d: &[f64],
    step: f64,
    q: &dyn Fn(usize) -> f64,
    printable: bool,
) -> Result<(bool, usize), TimeProblem> {
    let steps: Vec<f64> = d.iter().map(|di| (di / step).round()).collect();
    let jittery = !printable
        || d.iter()
            .zip(&steps)
            .any(|(di, m)| (di - m * step).abs() > 1e-6 * step);
    let reliable = |i: usize| !jittery || 0.5 * (q(i) + q(i - 1)) < 0.5 * step;
    let mut first: Option<TimeProblem> = None;
    let mut gaps = 0;
    let mut unreliable = 0;
    for i in 1..t.len() {
        if !reliable(i) {
            unreliable += 1;
            continue;
        }
        let allowed = 0.5 * (q(i) + q(i - 1)) + STEP_TOLERANCE * step;
        match (&first, step_problem(t, i, (steps[i - 1], step), allowed)) {
            (_, None) => {}
            (None, Some(p @ TimeProblem::Gap { .. })) => {
                first = Some(p);
                gaps = 1;
            }
            (None, Some(p)) => return Err(p),
            (Some(_), Some(TimeProblem::Gap { .. })) => gaps += 1,
            (Some(_), Some(_)) => break,
        }
    }
    if let Some(TimeProblem::Gap {
        row,
        t,
        prev,
        missing,
        step,
        ..
    }) = first
    {
        return Err(TimeProblem::Gap {
            row,
            t,
            prev,
            missing,
            step,
            more: gaps - 1,
        });
    }
    Ok((jittery, unreliable))
}

/// What the difference into row `i` (0-based) is, `m` whole steps of `step` within `allowed`:
/// one step (None), a gap, time that does not increase, or a stray row.
fn step_problem(t: &[f64], i: usize, (m, step): (f64, f64), allowed: f64) -> Option<TimeProblem> {
    let (row, ti, prev) = (i + 1, t[i], t[i - 1]);
    if (ti - prev - m * step).abs() > allowed {
        // Neither one step nor a whole number of them: an edited or stray row.
        Some(TimeProblem::OffGrid {
            row,
            t: ti,
            grid: prev + m.max(1.0) * step,
            allowed,
            rate_hz: 1.0 / step,
        })
    } else if m <= 0.0 {
        Some(TimeProblem::GoesBack { row, t: ti, prev })
    } else if m >= 2.0 {
        Some(TimeProblem::Gap {
            row,
            t: ti,
            prev,
            missing: m as usize - 1,
            step,
            more: 0,
        })
    } else {
        None
    }
}

/// The least-squares line t_i = a + b·i through the times, snapped to a whole rate in Hz when
/// that is within its standard error.
struct Line {
    a: f64,
    b: f64,
    rate_hz: f64,
    whole_hz: bool,
    /// The residual standard error and Σ(i − ī)², for the grid's own uncertainty.
    s_e: f64,
    sxx: f64,
}

impl Line {
    fn fit(t: &[f64]) -> Line {
        let nf = t.len() as f64;
        let im = (nf - 1.0) / 2.0;
        let tm = t.iter().sum::<f64>() / nf;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for (i, &ti) in t.iter().enumerate() {
            let x = i as f64 - im;
            sxy += x * (ti - tm);
            sxx += x * x;
        }
        let mut b = sxy / sxx;
        let mut a = tm - b * im;
        let s_e = (t
            .iter()
            .enumerate()
            .map(|(i, &ti)| (ti - a - b * i as f64).powi(2))
            .sum::<f64>()
            / (nf - 2.0).max(1.0))
        .sqrt();
        let se_b = s_e / sxx.sqrt();
        let whole = (1.0 / b).round();
        let mut whole_hz = false;
        if whole >= 1.0 && (1.0 / whole - b).abs() <= (4.0 * se_b).max(1e-12 * b) {
            b = 1.0 / whole;
            a = t
                .iter()
                .enumerate()
                .map(|(i, &ti)| ti - i as f64 * b)
                .sum::<f64>()
                / nf;
            whole_hz = true;
        }
        // An intercept within a millionth of a step of the first printed time is that time (0
        // stays 0, not -1e-13).
        if (a - t[0]).abs() < 1e-6 * b {
            a = t[0];
        }
        Line {
            a,
            b,
            rate_hz: if whole_hz { whole } else { 1.0 / b },
            whole_hz,
            s_e,
            sxx,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn printed(t: &[f64], digits: usize) -> Vec<f64> {
        t.iter()
            .map(|x| format!("{:.*e}", digits - 1, x).parse().unwrap())
            .collect()
    }

    fn grid(rate: f64, n: usize, t0: f64) -> Vec<f64> {
        (0..n).map(|i| t0 + i as f64 / rate).collect()
    }

    #[test]
    fn quantum_of_printed_digits() {
        assert_eq!(printed_quantum(12.3457), (1e-4, 6));
        assert_eq!(printed_quantum(0.0009765625).1, 7);
        assert!((printed_quantum(1.5e-3).0 - 1e-4).abs() < 1e-20);
        // A column in ms scaled to seconds: the digits printed, not those of the product.
        for ms in ["24674.6", "1234.57", "0.48828125", "59999.9"] {
            let printed = printed_quantum(ms.parse::<f64>().unwrap());
            let scaled = printed_quantum(ms.parse::<f64>().unwrap() * 1e-3);
            assert_eq!(scaled.1, printed.1, "{ms} ms");
            assert!((scaled.0 / printed.0 - 1e-3).abs() < 1e-15, "{ms} ms");
        }
        // Times computed exactly keep their full digits.
        assert!(printed_quantum(1.0 / 3.0).1 >= 15);
    }

    #[test]
    fn time_printed_in_ms_and_scaled_to_seconds_is_read_by_its_printed_digits() {
        // A trial's 2048 Hz exports: ms at `%.6g` (refused past 10 s as off a 2040.8 Hz grid)
        // and ms to one decimal (refused at row 14 as off a 2000 Hz grid).
        let exact = grid(2048.0, 20 * 2048, 0.0);
        let ms: Vec<f64> = exact.iter().map(|t| t * 1e3).collect();
        for (what, text) in [
            ("%.6g", printed(&ms, 6)),
            (
                "%.1f",
                ms.iter()
                    .map(|t| format!("{t:.1}").parse().unwrap())
                    .collect(),
            ),
        ] {
            let s: Vec<f64> = text.iter().map(|t| t * 1e-3).collect();
            let tb = rebuild(&s).unwrap_or_else(|e| panic!("ms at {what}: {e}"));
            assert_eq!(tb.rate_hz, 2048.0, "ms at {what}");
            let note = tb.note().unwrap();
            let said = if what == "%.6g" {
                "6 significant digits"
            } else {
                "4 decimal place(s)"
            };
            assert!(note.contains(said), "ms at {what}: {note}");
        }
    }

    #[test]
    fn rounded_time_at_common_rates_rebuilds_the_exact_grid() {
        for rate in [200.0, 256.0, 500.0, 512.0, 1000.0, 1024.0, 2000.0, 2048.0] {
            for digits in [6, 7, 9] {
                let n = (12.0 * rate) as usize;
                let exact = grid(rate, n, 0.0);
                let tb = rebuild(&printed(&exact, digits))
                    .unwrap_or_else(|e| panic!("{rate} Hz, {digits} digits: {e}"));
                assert_eq!(tb.rate_hz, rate, "{rate} Hz, {digits} digits");
                assert!(tb.whole_hz);
                assert!(tb.t0_s.abs() < 1e-7, "{}", tb.t0_s);
                assert!(!tb.unresolved);
            }
        }
        // A rate that is not a whole number of hertz keeps its fitted value.
        let r = 1000.0 / 3.0;
        let tb = rebuild(&printed(&grid(r, 4000, 0.25), 9)).unwrap();
        assert!(
            !tb.whole_hz && (tb.rate_hz / r - 1.0).abs() < 1e-8,
            "{}",
            tb.rate_hz
        );
        // Exact binary times need no rebuilding.
        let tb = rebuild(&grid(1024.0, 3000, 0.0)).unwrap();
        assert!(!tb.rounded() && tb.note().is_none());
        // A note says the jitter is rounding.
        let tb = rebuild(&printed(&grid(256.0, 3000, 0.0), 6)).unwrap();
        assert!(
            tb.note()
                .unwrap()
                .contains("rounding to 6 significant digits"),
            "{:?}",
            tb.note()
        );
    }

    #[test]
    fn a_gap_is_named_at_its_own_row() {
        let mut t = printed(&grid(512.0, 4000, 0.0), 7);
        t.drain(1000..1010);
        match rebuild(&t) {
            Err(TimeProblem::Gap {
                row, missing, more, ..
            }) => {
                assert_eq!((row, missing, more), (1001, 10, 0));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn time_going_back_and_a_drifting_clock_are_refused() {
        let mut t = grid(1024.0, 3000, 0.0);
        t[2] = 0.0;
        assert!(matches!(
            rebuild(&t),
            Err(TimeProblem::GoesBack { row: 3, .. })
        ));
        // A clock 0.2 % fast for the second half: within a step everywhere, off the grid.
        let t: Vec<f64> = (0..4000)
            .map(|i| {
                if i < 2000 {
                    i as f64 / 1000.0
                } else {
                    2.0 + (i - 2000) as f64 * 1.002 / 1000.0
                }
            })
            .collect();
        let e = rebuild(&t).unwrap_err();
        assert!(matches!(e, TimeProblem::OffGrid { .. }), "{e:?}");
        assert!(e.to_string().contains("drifts"), "{e}");
    }

    #[test]
    fn too_coarse_printing_is_accepted_but_says_so() {
        // 2048 Hz printed with 4 decimals: a step is 4.9e-4 s, the resolution 1e-4 s: resolvable.
        let t: Vec<f64> = grid(2048.0, 20000, 0.0)
            .iter()
            .map(|x| (x * 1e4).round() / 1e4)
            .collect();
        let tb = rebuild(&t).unwrap();
        assert_eq!(tb.rate_hz, 2048.0);
        assert!(!tb.unresolved);
        // Printed to 1 ms: consistent with rounding, but a dropped row could hide.
        let t: Vec<f64> = grid(2048.0, 20000, 0.0)
            .iter()
            .map(|x| (x * 1e3).round() / 1e3)
            .collect();
        let tb = rebuild(&t).unwrap();
        assert_eq!(tb.rate_hz, 2048.0);
        assert!(tb.unresolved && tb.note().unwrap().contains("cannot be detected"));
    }

    #[test]
    fn fixed_decimals_coarser_than_a_rate_are_rounding_not_repeated_rows() {
        // 1024 Hz printed to 1 ms: every difference is a whole millisecond, and every 43rd is 0.
        let decimals = |rate: f64, scale: f64| -> Vec<f64> {
            grid(rate, 20480, 0.0)
                .iter()
                .map(|x| (x * scale).round() / scale)
                .collect()
        };
        for (rate, scale) in [(1024.0, 1e3), (512.0, 1e3), (1024.0, 1e4), (4096.0, 1e4)] {
            let tb = rebuild(&decimals(rate, scale))
                .unwrap_or_else(|e| panic!("{rate} Hz to {}: {e}", 1.0 / scale));
            assert_eq!(tb.rate_hz, rate);
            let places = scale.log10() as u32;
            assert_eq!(tb.decimals, Some(places));
            let note = tb.note().unwrap();
            assert!(
                note.contains(&format!("{places} decimal place(s)")),
                "{note}"
            );
        }
        // At 1000 Hz the same printing is exact, and a repeated time is still refused.
        let mut t = decimals(1000.0, 1e3);
        assert!(!rebuild(&t).unwrap().rounded());
        t[5000] = t[4999];
        t.remove(5001);
        assert!(
            matches!(rebuild(&t), Err(TimeProblem::GoesBack { row: 5001, .. })),
            "{:?}",
            rebuild(&t)
        );
    }
}
