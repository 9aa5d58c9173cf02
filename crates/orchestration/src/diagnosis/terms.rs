//! Expression terms a diagnosis gives the tests' models as its `expression` candidate, where
//! the model file writes none ([`crate::diagnosis::diagnose::diagnose_campaign`]):
//!
//! - the state map's static term ([`MapTerm`]), in every test or in the group of tests that
//!   carry the residual;
//! - a channel's steady **offset** ([`signals::Offset`]): `force_channel = "f + off_f"` in the
//!   tests that show it, one value for them all (a sensor's zero, a preload: a constant of the
//!   set-up) or one per test (a zero that moved between tests); where the displacement's
//!   feedback sits further from the tracked reference than the model's loop leaves it, also a
//!   valve's null bias `opening = "x + b_x"` ([`bias_terms`]);
//! - a **spectral line** ([`signals::Line`]): a sinusoid at the line's frequency in the channel
//!   that shows it most, `accel_channel = "a + s_3*sin(2*pi*37.2731*t) + c_3*cos(2*pi*37.2731*t)"`,
//!   or, where it is in several channels, a force of that frequency on the platen (a pump's
//!   ripple, a hum in the drive). Its sine and cosine are per test (a hum's phase at a test's
//!   start is the mains', not the excitation's); its frequency is the least-squares one of each
//!   test's residual ([`signals::refined_frequency`]), written as a number. It is given to every
//!   test and, where only some show the line, to those alone (a hum on one day's set-up).
//!
//! Each is fitted like any effect; the one with the lowest BIC (χ² + k ln n) is the candidate.

use crate::diagnosis::compare::ComparedTest;
use crate::diagnosis::signals::{self, Signals};
use crate::diagnosis::statemap::MapTerm;
use vshake_kernel::effects::expression::{Hook, SLOTS};
use vshake_kernel::param_table::Range;
use vshake_kernel::params::ModelParams;

/// A named parameter of a term: its name, unit and start value.
#[derive(Debug, Clone, PartialEq)]
pub struct TermParam {
    pub name: String,
    pub unit: String,
    pub value: f64,
}

/// What a term stands for.
#[derive(Debug, Clone, PartialEq)]
pub enum Evidence {
    /// The state map's static term.
    Map,
    /// A steady offset of a channel (0 acceleration, 1 displacement, 2 force).
    Offset { channel: usize },
    /// A channel that reads a factor times the model's (0 acceleration, 1 displacement, 2 force).
    Gain { channel: usize },
    /// A spectral line of about `freq_hz`, seen in `channel` (the term may act on the platen).
    Line { channel: usize, freq_hz: f64 },
}

/// An expression term given to some tests' models: `hook = form` in each of them.
#[derive(Debug, Clone, PartialEq)]
pub struct Term {
    pub hook: Hook,
    /// The tests it is given to, each with its form.
    pub forms: Vec<(usize, String)>,
    /// Its parameters (declared in every test, in this order).
    pub params: Vec<TermParam>,
    /// Its form in words where the tests' forms differ ("… per test").
    pub generic: String,
    pub evidence: Evidence,
    /// Terms given with it, each on a hook of its own and with parameters of their own names
    /// ([`Term::with`]): a line in every test beside an offset in some.
    pub also: Vec<Term>,
}

impl Term {
    /// The state map's term, given to the tests `group`.
    pub fn from_map(t: &MapTerm, group: &[usize]) -> Term {
        Term {
            hook: t.hook,
            forms: group.iter().map(|&i| (i, t.form.clone())).collect(),
            params: vec![TermParam {
                name: t.param.clone(),
                unit: t.unit.clone(),
                value: t.value,
            }],
            generic: t.form.clone(),
            evidence: Evidence::Map,
            also: Vec::new(),
        }
    }

    /// It and the terms given with it.
    pub fn parts(&self) -> impl Iterator<Item = &Term> {
        std::iter::once(self).chain(self.also.iter())
    }

    /// It with `other` given too, where `other`'s hooks and parameter names are none of its own
    /// and the expressions' slots hold them all; None where they are not.
    pub fn with(&self, other: &Term) -> Option<Term> {
        let hooks = |t: &Term| t.parts().map(|p| p.hook).collect::<Vec<_>>();
        let names = |t: &Term| -> Vec<String> {
            (t.parts())
                .flat_map(|p| p.params.iter().map(|q| q.name.clone()))
                .collect()
        };
        let (mine, theirs) = (names(self), names(other));
        let clash = hooks(other).iter().any(|h| hooks(self).contains(h))
            || theirs.iter().any(|n| mine.contains(n));
        let slots = mine.len() + theirs.len();
        if clash || slots > SLOTS {
            return None;
        }
        let mut out = self.clone();
        out.also.extend(other.parts().map(|p| Term {
            also: Vec::new(),
            ..p.clone()
        }));
        Some(out)
    }

    /// The tests some part of it is given to, in order.
    pub fn tests(&self) -> Vec<usize> {
        let mut t: Vec<usize> = self
            .parts()
            .flat_map(|p| p.forms.iter().map(|f| f.0))
            .collect();
        t.sort_unstable();
        t.dedup();
        t
    }

    /// `hook = "form"` where every test has the same form, else the generic form; with the
    /// terms given with it, "; "-separated.
    pub fn written(&self) -> String {
        let each: Vec<String> = self.parts().map(Term::written_alone).collect();
        each.join("; ")
    }

    /// [`Term::written`] with the tests each part is given to where that is not every one of the
    /// `n` ("… in f2_a1p5 only"), the tests named as `s` names them.
    pub fn described(&self, n: usize, s: &Signals) -> String {
        let each: Vec<String> = (self.parts())
            .map(|p| match p.forms.len() < n {
                true => format!(
                    "{} in {} only",
                    p.written_alone(),
                    s.list(p.forms.iter().map(|f| f.0))
                ),
                false => p.written_alone(),
            })
            .collect();
        each.join("; ")
    }

    /// [`Term::written`] of this part alone.
    pub fn written_alone(&self) -> String {
        let same = self.forms.windows(2).all(|w| w[0].1 == w[1].1);
        match self.forms.first() {
            Some((_, f)) if same => format!("{} = {f:?}", self.hook.key()),
            _ => self.generic.clone(),
        }
    }

    /// `model` (of test `test`) given the term's parameters at their starts, and its form where
    /// the term is given to that test (its other hooks cleared); the same of the terms given
    /// with it.
    pub fn install(&self, model: &mut ModelParams, test: usize) -> Result<(), String> {
        model.expression.hooks.clear();
        for p in self.parts().flat_map(|t| t.params.iter()) {
            model.name_expression_param(&p.name, &p.unit, Range::any(), p.value)?;
        }
        for t in self.parts() {
            if let Some((_, form)) = t.forms.iter().find(|f| f.0 == test) {
                (model.expression.set(t.hook, form)).map_err(|e| e.to_string())?;
            }
        }
        Ok(())
    }

    /// A model given the term as test `test` has it (the first of its tests where `test` has
    /// none): what `--out` writes.
    pub fn install_one(&self, model: &mut ModelParams, test: usize) -> Result<(), String> {
        let tests = self.tests();
        let t = match tests.contains(&test) {
            true => test,
            false => tests.first().copied().unwrap_or(test),
        };
        self.install(model, t)
    }

    /// A line's fitted sinusoids: the least and the largest amplitude over its tests and their
    /// number, from the fitted values of `params` (names and values, the line's `s_k`, `c_k`
    /// among them); None for another term.
    pub fn amplitudes(&self, params: &[(&str, f64)]) -> Option<(f64, f64, usize)> {
        let line = |t: &&Term| matches!(t.evidence, Evidence::Line { .. });
        let line = self.parts().find(line)?;
        let value = |n: String| params.iter().find(|p| p.0 == n).map(|p| p.1);
        let amp = |t: usize| Some(value(format!("s_{t}"))?.hypot(value(format!("c_{t}"))?));
        let amps: Vec<f64> = (line.forms.iter().map(|f| f.0))
            .filter_map(|t| amp(t + 1))
            .collect();
        let lo = amps.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = amps.iter().copied().fold(0.0, f64::max);
        Some((lo, hi, amps.len()))
    }

    /// The unit of its parameters (of its line's, where a part is a line).
    pub fn unit(&self) -> &str {
        let line = self
            .parts()
            .find(|t| matches!(t.evidence, Evidence::Line { .. }));
        (line.unwrap_or(self).params.first()).map_or("", |p| p.unit.as_str())
    }

    /// Whether `name` is one of a line's per-test sines and cosines.
    pub fn is_phase_param(&self, name: &str) -> bool {
        self.parts().any(|t| {
            matches!(t.evidence, Evidence::Line { .. }) && t.params.iter().any(|p| p.name == name)
        })
    }

    /// Whether the tests' forms differ (a line's per-test phase, an offset per test), or a part
    /// is given to other tests than another.
    pub fn per_test(&self) -> bool {
        let n = self.tests().len();
        self.parts()
            .any(|t| !t.forms.windows(2).all(|w| w[0].1 == w[1].1) || t.forms.len() < n)
    }
}

/// The terms the signals' evidence suggests, for the compared tests `c`: one or two per channel
/// with an offset, one or two per spectral line.
pub fn from_signals(s: &Signals, c: &[ComparedTest]) -> Vec<Term> {
    let mut out = Vec::new();
    for ch in 0..3 {
        let o: Vec<&signals::Offset> = s.offsets.iter().filter(|o| o.channel == ch).collect();
        out.extend(offset_terms(ch, &o, c.len()));
        if ch == 1 {
            out.extend(bias_terms(&o, c));
        }
        let g: Vec<&signals::Gain> = s.gains.iter().filter(|g| g.channel == ch).collect();
        out.extend(gain_terms(ch, &g, &o, c.len()));
    }
    for l in &s.lines {
        out.extend(line_terms(l, c));
    }
    out.retain(|t| t.params.len() <= SLOTS);
    out
}

/// Most tests given an offset each. [chosen: 8, for the expressions' [`SLOTS`] (see
/// [`LINE_TESTS`]).]
pub const OFFSET_TESTS: usize = 8;

/// A channel's hook and the quantity its expression reads.
fn channel_hook(ch: usize) -> (Hook, &'static str, &'static str) {
    match ch {
        0 => (Hook::Accel, "a", "m/s²"),
        1 => (Hook::Disp, "d", "m"),
        _ => (Hook::SensedForce, "f", "N"),
    }
}

/// The offset terms of channel `ch` from its offsets `o`: one value in the tests that show it,
/// one per test where there are several, and one value in every test of the `n` where some do
/// not show it.
fn offset_terms(ch: usize, o: &[&signals::Offset], n: usize) -> Vec<Term> {
    if o.is_empty() {
        return Vec::new();
    }
    let mut out = offset_terms_in(ch, o);
    if o.len() < n {
        // An offset seen in some tests may be in every one, hidden where another residual
        // dominates (a specimen on the table for some tests): the shared term in all of them.
        let mut every = out[0].clone();
        let form = every.forms[0].1.clone();
        every.forms = (0..n).map(|t| (t, form.clone())).collect();
        out.push(every);
    }
    out
}

/// [`offset_terms`] in the tests that show the offset.
fn offset_terms_in(ch: usize, o: &[&signals::Offset]) -> Vec<Term> {
    let (hook, x, unit) = channel_hook(ch);
    let name = format!("off_{x}");
    let mean = o.iter().map(|o| o.value).sum::<f64>() / o.len() as f64;
    let shared = Term {
        hook,
        forms: o
            .iter()
            .map(|o| (o.test, format!("{x} + {name}")))
            .collect(),
        params: vec![param(&name, unit, mean)],
        generic: format!("{} = \"{x} + {name}\"", hook.key()),
        evidence: Evidence::Offset { channel: ch },
        also: Vec::new(),
    };
    if o.len() < 2 || o.len() > OFFSET_TESTS {
        return vec![shared];
    }
    let values: Vec<(usize, f64)> = o.iter().map(|o| (o.test, o.value)).collect();
    let each = each_test(&shared, (&name, unit), &values, &|p| format!("{x} + {p}"));
    vec![shared, each]
}

/// The gain terms of channel `ch` from its gains `g` (and its offsets `o`), in `n` tests: one
/// factor in the tests that show it, one per test where there are several, one in every test
/// where some do not show it (a sensor's calibration holds for the campaign; another residual
/// may hide it), and that one with the channel's offset where it has one (a load cell's factor
/// and a zero that moved).
fn gain_terms(ch: usize, g: &[&signals::Gain], o: &[&signals::Offset], n: usize) -> Vec<Term> {
    if g.is_empty() {
        return Vec::new();
    }
    let (hook, x, _) = channel_hook(ch);
    let name = format!("k_{x}");
    let factor = 1.0 + g.iter().map(|g| g.gain).sum::<f64>() / g.len() as f64;
    let shared = Term {
        hook,
        forms: g
            .iter()
            .map(|g| (g.test, format!("{name} * {x}")))
            .collect(),
        params: vec![param(&name, "-", factor)],
        generic: format!("{} = \"{name} * {x}\"", hook.key()),
        evidence: Evidence::Gain { channel: ch },
        also: Vec::new(),
    };
    let mut out = vec![shared.clone()];
    if (2..=OFFSET_TESTS).contains(&g.len()) {
        let values: Vec<(usize, f64)> = g.iter().map(|g| (g.test, 1.0 + g.gain)).collect();
        out.push(each_test(&shared, (&name, "-"), &values, &|p| {
            format!("{p} * {x}")
        }));
    }
    let every = Term {
        forms: (0..n).map(|t| (t, format!("{name} * {x}"))).collect(),
        ..shared.clone()
    };
    if g.len() < n {
        out.push(every.clone());
    }
    if !o.is_empty() {
        out.push(gain_with_offset(ch, o, every));
    }
    out
}

/// `every` (a channel's factor in every test) with the channel's offset `off_x` added in the
/// tests whose offsets `o` show one, started at their mean.
fn gain_with_offset(ch: usize, o: &[&signals::Offset], every: Term) -> Term {
    let (hook, x, unit) = channel_hook(ch);
    let (name, off) = (format!("k_{x}"), format!("off_{x}"));
    let mean = o.iter().map(|o| o.value).sum::<f64>() / o.len() as f64;
    let with_offset = |t: usize| o.iter().any(|o| o.test == t);
    let in_tests = match o.len() {
        1 => format!("test {}", o[0].test + 1),
        k => format!("{k} tests"),
    };
    Term {
        forms: (every.forms.iter())
            .map(|&(t, _)| match with_offset(t) {
                true => (t, format!("{name} * {x} + {off}")),
                false => (t, format!("{name} * {x}")),
            })
            .collect(),
        params: vec![every.params[0].clone(), param(&off, unit, mean)],
        generic: format!(
            "{} = \"{name} * {x} + {off}\" in {in_tests}, \"{name} * {x}\" in the others",
            hook.key(),
        ),
        ..every
    }
}

/// The valve's null bias a displacement offset with a loop error suggests (`o`, the
/// displacement's offsets): `opening = "x + b_x"` in the tests that show it, one value for them
/// all, and one per test where there are several (a null that drifted between tests). Where the
/// feedback sits Δ further from the tracked reference than the model's loop leaves it, the
/// controller's displacement term holds the spool at k_sp·10·G_d·Δ/D_max (docs/model.md §2,
/// step 3), which a bias b_x = −that cancels in the steady state: the start.
fn bias_terms(o: &[&signals::Offset], c: &[ComparedTest]) -> Vec<Term> {
    let with_loop: Vec<(usize, f64)> = (o.iter())
        .filter_map(|o| Some((o.test, o.loop_error?)))
        .map(|(t, [measured, model])| {
            let ctl = &c[t].test.model.controller;
            let spool_per_m = c[t].test.model.servovalve.k_sp * 10.0 * ctl.g_d / ctl.d_max;
            (t, spool_per_m * (measured - model))
        })
        .collect();
    if with_loop.is_empty() {
        return Vec::new();
    }
    let mean = with_loop.iter().map(|b| b.1).sum::<f64>() / with_loop.len() as f64;
    let evidence = Evidence::Offset { channel: 1 };
    let shared = Term {
        hook: Hook::Opening,
        forms: (with_loop.iter())
            .map(|&(t, _)| (t, "x + b_x".to_string()))
            .collect(),
        params: vec![param("b_x", "m", mean)],
        generic: "opening = \"x + b_x\"".to_string(),
        evidence,
        also: Vec::new(),
    };
    if with_loop.len() < 2 || with_loop.len() > OFFSET_TESTS {
        return vec![shared];
    }
    let each = each_test(&shared, ("b_x", "m"), &with_loop, &|p| format!("x + {p}"));
    vec![shared, each]
}

/// `shared` with a parameter of its own in each test: `name_k` (unit `unit`) started at the test's
/// value in `values` (test index, start), in the form `form` makes of it ("x + b_x_3").
fn each_test(
    shared: &Term,
    (name, unit): (&str, &str),
    values: &[(usize, f64)],
    form: &dyn Fn(&str) -> String,
) -> Term {
    let own = |t: usize| format!("{name}_{}", t + 1);
    Term {
        forms: values.iter().map(|&(t, _)| (t, form(&own(t)))).collect(),
        params: (values.iter())
            .map(|&(t, v)| param(&own(t), unit, v))
            .collect(),
        generic: format!(
            "{} = \"{}\" in each test i",
            shared.hook.key(),
            form(&format!("{name}_i"))
        ),
        ..shared.clone()
    }
}

fn param(name: &str, unit: &str, value: f64) -> TermParam {
    TermParam {
        name: name.to_string(),
        unit: unit.to_string(),
        value,
    }
}

/// Most tests a line term is given to (two slots each): those where the line is largest.
/// [chosen: 10, so that a line term and the other terms of one diagnosis fit in the
/// expressions' [`SLOTS`].]
pub const LINE_TESTS: usize = 10;

/// The terms of a spectral line: a sinusoid in the channel that shows it most (in the tests that
/// show it there), and, where other channels show it too, a force of that frequency on the
/// platen. Each test has its own sine and cosine (`s_k`, `c_k`, k the test's number) and its own
/// least-squares frequency.
fn line_terms(l: &signals::Line, c: &[ComparedTest]) -> Vec<Term> {
    let Some(top) = (l.hits.iter()).max_by(|a, b| a.share.total_cmp(&b.share)) else {
        return Vec::new();
    };
    let ch = top.channel;
    // Every test (a line too weak to stand out in some, or beside a harmonic there, is still
    // there), those that show it in that channel first, as many as the slots hold.
    let share = |t: usize| {
        let h = l.hits.iter().filter(|h| h.test == t && h.channel == ch);
        h.map(|h| h.share).fold(0.0, f64::max)
    };
    let mut tests: Vec<usize> = (0..c.len()).collect();
    tests.sort_by(|&a, &b| share(b).total_cmp(&share(a)));
    tests.truncate(LINE_TESTS);
    tests.sort_unstable();
    // A test without a hit: the line where it is in the tests that show it (at the same ratio to
    // the test's f₀ for a line locked to the excitation).
    let guess = |t: usize| match (l.locked, c[t].test.samples.fundamental_hz) {
        (Some(r), Some(f0)) => r * f0,
        _ => l.freq_hz,
    };
    // Per test: its index, frequency, the residual's sine and cosine there, and those of the
    // acceleration's residual times the platen's mass (the force term's start: a force above
    // the loop's bandwidth moves the platen as F/M).
    let each: Vec<(usize, f64, [f64; 4])> = (tests.into_iter())
        .filter_map(|t| {
            let e = signals::residual(&c[t], ch)?;
            let s = &c[t].test.samples;
            let near = (l.hits.iter().find(|h| h.test == t)).map_or(guess(t), |h| h.freq_hz);
            let f = signals::refined_frequency(&e, &s.tau, near, s.rate_hz);
            let (sn, cs) = signals::projection(&e, &s.tau, f);
            let a = signals::residual(&c[t], 0)?;
            let m = c[t].test.model.platen.m;
            let (sa, ca) = signals::projection(&a, &s.tau, f);
            Some((t, f, [sn, cs, m * sa, m * ca]))
        })
        .collect();
    let (hook, x, unit) = channel_hook(ch);
    let evidence = Evidence::Line {
        channel: ch,
        freq_hz: l.freq_hz,
    };
    // Every test, and, where only some show the line, those alone (a hum in some tests only:
    // the others' sinusoids would fit their noise); the fits' BIC chooses.
    let shown: Vec<(usize, f64, [f64; 4])> = (each.iter().copied())
        .filter(|e| share(e.0) > 0.0)
        .collect();
    let mut groups = vec![(each.as_slice(), false)];
    if !shown.is_empty() && shown.len() < each.len() {
        groups.push((shown.as_slice(), true));
    }
    let mut out = Vec::new();
    for (group, subset) in groups {
        let about = line_about(l, group, c.len(), subset);
        let lead = format!("{x} + ");
        out.push(sinusoid_term(
            group,
            (hook, &lead, unit),
            0,
            &about,
            &evidence,
        ));
        if l.hits.iter().any(|h| h.channel != ch) {
            out.push(sinusoid_term(
                group,
                (Hook::Force, "", "N"),
                2,
                &about,
                &evidence,
            ));
        }
    }
    out
}

/// A line's term in the tests of `group` (test, f_i, the residual's sine and cosine there, and the
/// platen force's): `hook = "lead + s_k*sin(2*pi*f_k*t) + c_k*cos(2*pi*f_k*t)"` in test k, its
/// sine and cosine starting from `start` (0: the channel's, 2: the force's) in `unit`.
fn sinusoid_term(
    group: &[(usize, f64, [f64; 4])],
    (hook, lead, unit): (Hook, &str, &str),
    start: usize,
    about: &str,
    evidence: &Evidence,
) -> Term {
    Term {
        hook,
        forms: (group.iter())
            .map(|&(t, f, _)| (t, format!("{lead}{}", sinusoid(t + 1, f))))
            .collect(),
        params: (group.iter())
            .flat_map(|&(t, _, v)| {
                let k = t + 1;
                [
                    param(&format!("s_{k}"), unit, v[start]),
                    param(&format!("c_{k}"), unit, v[start + 1]),
                ]
            })
            .collect(),
        generic: format!(
            "{} = \"{lead}s_i*sin(2*pi*f_i*t) + c_i*cos(2*pi*f_i*t)\" {about}",
            hook.key()
        ),
        evidence: evidence.clone(),
        also: Vec::new(),
    }
}

/// Where a line term's f_i are, from `each` (test, f_i, …), and in how many of the `n` tests
/// (`subset`: those that show the line).
fn line_about(
    l: &signals::Line,
    each: &[(usize, f64, [f64; 4])],
    n: usize,
    subset: bool,
) -> String {
    let (lo, hi) = signals::bounds(each.iter().map(|e| e.1));
    let f = match (l.locked, hi - lo > 1e-4 * hi) {
        (Some(r), _) => format!("f_i = {r:.4} times test i's frequency ({lo:.4} to {hi:.4} Hz)"),
        (None, true) => format!("f_i from {lo:.4} to {hi:.4} Hz"),
        (None, false) => format!("f_i about {lo:.4} Hz"),
    };
    match (subset, each.len() < n) {
        (true, _) => format!(
            "in each test i of the {} (of {n}) that show the line, {f}",
            each.len()
        ),
        (false, true) => format!(
            "in each test i of the {} (of {n}) where the line is largest, {f}",
            each.len()
        ),
        (false, false) => format!("in each test i, {f}"),
    }
}

/// `s_k*sin(2*pi*f*t) + c_k*cos(2*pi*f*t)`, f written to 8 significant figures.
fn sinusoid(k: usize, f: f64) -> String {
    format!("s_{k}*sin(2*pi*{f:.7e}*t) + c_{k}*cos(2*pi*{f:.7e}*t)")
}
