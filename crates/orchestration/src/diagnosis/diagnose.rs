//! Diagnosis: which physical effect is most likely missing from the model.
//!
//! Every candidate effect of the library is fitted to the campaign (the free parameters of the
//! first of its `EffectInfo::stages`, from the best point of the stage's start scan where it has
//! one, and from the state map's finding of its law where there is one, [`seeds`], the better fit
//! kept; the candidates in parallel; a fit that cannot reach significance stops early,
//! [`fit::fit_unprofiled`]; the leading ones whose fits stop at [`MAX_ITER`] go on,
//! [`polish_leaders`], and the leading ones are checked along each parameter,
//! [`profile_leaders`]) and ranked by the Bayesian
//! information criterion: ΔBIC = χ²_baseline − χ²_candidate − p·ln n (n the features' degrees of
//! freedom, p parameters added). With the features scaled by their noise, χ² of a right model is
//! ≈ n − p, so:
//! - a candidate is *significant* when ΔBIC > [`SIGNIFICANT_BIC`] (Kass & Raftery's "very strong"
//!   evidence; fitting p parameters to noise alone lowers χ² by about p, far below p·ln n) and it
//!   explains at least [`EXPLAINS_SOME`] of the misfit beyond noise. Significant candidates rank
//!   first, each group by ΔBIC;
//! - the share of the misfit it *explains* is (χ²_b − χ²_c)/(χ²_b − n): the part of the
//!   baseline's χ² beyond what noise leaves that the candidate removes. It is the one measure the
//!   fit minimises, so a fit that lowers χ² never reports 0 %. (Until issue 51 the share was
//!   taken from the residual rms over tests and channels, each relative to its signal, which
//!   weighs the channels differently from the fit: a spool lag that cut χ² threefold was reported
//!   as explaining nothing because the rms of one channel rose. The rms is still reported beside
//!   the χ², per test and channel, and the verdict says how far the named effects leave it from
//!   its noise floor.)
//!
//! **Several missing effects: forward selection with refit.** When the best candidate is
//! significant and the χ² it leaves is still above what noise leaves by more than any further
//! parameter's BIC penalty, every remaining candidate is fitted again *on top of it*, its
//! parameters freed together with the chosen ones' (starting from their estimates); the best is
//! added if its ΔBIC over the chosen set is significant and it removes at least [`ADDS_ENOUGH`]
//! of the χ² beyond noise the set leaves, and so on, up to [`MAX_EFFECTS`]. The final set is then
//! checked (`prune`): each effect added is refitted out of it, and one that does not, in the final
//! joint fit, remove [`ADDS_ENOUGH`] of what the others leave without it, with a significant ΔBIC,
//! is dropped (a later effect may have taken over what it had removed). Each named effect's share
//! is reported as it stands in the final joint fit: the share of the baseline's misfit beyond
//! noise that the set loses without it. A leader that merely tied with the next candidates alone
//! ([`TIE`]) gives way to one of them when, in its place in the final joint fit, that one fits
//! better: selection then runs again from it, and the better set is named ([`settle_leader`]).
//! Where the signals show the residual in some tests only, the leading library candidates are
//! also fitted to those tests alone, their effect off in the others ([`group_variants`]); where
//! the `expression` candidate is the state map's term and a library effect is named, the terms
//! read off the signals (a line, an offset), before any fit and in the residual the named set
//! leaves, are tried on top of the named set ([`beside_named`]). Where no test is at the noise,
//! the tests are split again once the signals' best term is fitted ([`split_after_term`]). The
//! verdict
//! names "A + B" and the share each adds when together they explain at least
//! [`EXPLAINS_TOGETHER`] of the misfit beyond noise; a best candidate that
//! explains less than [`EXPLAINS_ENOUGH`] (alone or with those added) is reported as such: the
//! missing effect is probably not in the library, and the starting model's residual mapped onto
//! the plant's states ([`crate::diagnosis::statemap`]) names the state and term it follows. A named set that
//! leaves more than [`NOISE_FACTOR`] times the noise floor is said to, with the state and term of
//! what it leaves.

use crate::diagnosis::compare::ComparedTest;
use crate::diagnosis::fit::{self, FeatureInfo, Free, Problem};
use crate::diagnosis::seeds::{self, Seed};
use crate::diagnosis::signals::{self, Signals};
use crate::diagnosis::statemap::StateMap;
use crate::diagnosis::terms::{self, Evidence, Term};
use crate::measured::aligned::AlignedTest;
use rayon::prelude::*;
use std::ops::Range;
use vshake_kernel::effects::building;
use vshake_kernel::params::{EffectId, ModelParams};

/// The family of the sensors' effects: a verdict naming it says which channel's measurement.
pub const MEASUREMENT_FAMILY: &str = "measurement chain";

/// ΔBIC above which a candidate counts as significant.
pub const SIGNIFICANT_BIC: f64 = 10.0;
/// Share of the misfit beyond noise (χ²) a candidate must explain to be called significant at all
/// [chosen: 1 %. Over thousands of features a flexible effect lowers χ² by more than the BIC
/// penalty by absorbing a sliver of the misfit (a numerical floor, an unmodelled detail); a
/// candidate that removes under a hundredth of what the user sees is not evidence of anything.]
pub const EXPLAINS_SOME: f64 = 0.01;
/// Share of the misfit beyond noise a candidate must explain to be named the missing effect.
pub const EXPLAINS_ENOUGH: f64 = 0.5;
/// Share of the misfit beyond noise several effects must explain together to be named
/// together: more than one effect is a claim that the library holds the whole of what is missing,
/// so they must take the residual (nearly) to the noise; otherwise two wrong effects could each
/// mimic part of an effect the library does not have.
pub const EXPLAINS_TOGETHER: f64 = 0.9;
/// Leading candidates whose fits go on when they stop at [`MAX_ITER`] ([`polish_leaders`]).
pub const POLISHED: usize = 3;
/// Iterations of each candidate's fit.
pub const MAX_ITER: usize = 25;
/// Most effects forward selection names together.
pub const MAX_EFFECTS: usize = 3;
/// Share of the misfit beyond noise (χ²) left by the effects chosen so far that a further effect
/// must remove to be added. [chosen: a quarter. When the library's closest form of an effect is
/// only close (a flow-gain curve standing in for a sharp dead band), what it leaves is large in
/// χ² over thousands of features, and other flexible effects each take a sliver of it with a
/// significant ΔBIC; an effect that removes a sliver is not a second missing effect.]
pub const ADDS_ENOUGH: f64 = 0.25;
/// Share of the baseline's misfit beyond noise (χ²) an added effect must remove on its own in
/// the final joint fit to be named, unless the set is at the noise with it: every test within
/// [`NOISE_FACTOR`] of its noise, or the χ² over them all within NOISE_FACTOR² of the noise's
/// where it is not without the part (a second effect 5x the noise beside one 100x it removes
/// 0.25 % of the baseline; a friction's Stribeck and viscous terms beside a supply, the last
/// 0.6 %). [chosen: 2 %, the "clear share". A table whose actuators' valves differed
/// was named "flow_gain 28 %, + supply 0.06 %": the supply took a third of what the flow gain
/// left, a χ² 300 times the noise's, and was evidence of nothing.]
pub const NAMES_ALONE: f64 = 0.02;
/// Candidates ranked next behind the best that may take its place in the named set
/// ([`settle_leader`]).
pub const ALTERNATES: usize = 2;
/// A candidate ties with the best when the χ² beyond noise it leaves alone is within this factor
/// of the best's. [chosen: 1.25. Two forms of one mechanism (a valve's pure delay and its spool's
/// second-order lag) fit a campaign alone to within a fraction of a percent of each other; which
/// ranks first then turns on the channels' weights, yet only one of them, with the effects added
/// to it, takes the residual to the noise.]
pub const TIE: f64 = 1.25;
/// A chosen set of effects is "right to the noise" when it leaves a residual rms within this
/// factor of the noise floor. [chosen: 1.5, the criterion for a fit that is done.]
pub const NOISE_FACTOR: f64 = 1.5;

/// One fitted candidate.
pub struct Candidate {
    pub effect: EffectId,
    pub family: &'static str,
    pub free: Vec<Free>,
    pub fit: Result<fit::FitResult, fit::FitError>,
    pub delta_bic: f64,
    /// Share of the baseline's χ² beyond noise the fit removes.
    pub explained: f64,
    /// The finding of the state map its fit started from, where that start was the better
    /// ([`crate::diagnosis::seeds`]); None where it started from the effect's own.
    pub origin: Option<String>,
}

impl Step {
    /// What it adds.
    pub fn part(&self) -> Part {
        Part {
            effect: self.effect,
            stage: self.stage,
        }
    }
}

impl Candidate {
    /// What it names: its effect.
    pub fn part(&self) -> Part {
        Part {
            effect: self.effect,
            stage: 0,
        }
    }

    /// ΔBIC above [`SIGNIFICANT_BIC`] and at least [`EXPLAINS_SOME`] of the misfit beyond noise
    /// explained.
    pub fn significant(&self) -> bool {
        self.delta_bic > SIGNIFICANT_BIC && self.explained >= EXPLAINS_SOME
    }
    pub fn chi2(&self) -> f64 {
        self.fit.as_ref().map_or(f64::INFINITY, |f| f.chi2_after())
    }

    /// The tests it is fitted to where that is a group of them ([`group_variants`]): its effect
    /// is off in the others.
    pub fn group(&self) -> Option<Vec<usize>> {
        let mask = self.free.first()?.tests;
        let same = self.free.iter().all(|f| f.tests == mask);
        (same && mask != fit::ALL_TESTS).then(|| {
            (0..fit::GROUP_TESTS)
                .filter(|&t| mask >> t & 1 == 1)
                .collect()
        })
    }

    /// Its name in tables: the effect's, and for a group the tests' numbers from 1
    /// (`specimen[1,3,5,7]`).
    pub fn label(&self) -> String {
        match self.group() {
            Some(g) => {
                let n: Vec<String> = g.iter().map(|t| (t + 1).to_string()).collect();
                format!("{}[{}]", self.effect, n.join(","))
            }
            None => self.effect.to_string(),
        }
    }
}

/// A share as a percentage, to two significant figures below 1 % (a share is never shown as
/// "0 %" unless it is nil).
pub fn percent(share: f64) -> String {
    match 100.0 * share {
        p if p >= 1.0 || p == 0.0 || !p.is_finite() => format!("{p:.0} %"),
        p if p >= 0.01 => format!("{p:.2} %"),
        p => format!("{p:.1e} %"),
    }
}

/// A part of the model a diagnosis names: an effect (stage 0), or a further stage of one (a
/// specimen's second mode, [`vshake_kernel::effects::EffectInfo::stages`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Part {
    pub effect: EffectId,
    pub stage: usize,
}

impl std::fmt::Display for Part {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.stage {
            0 => write!(f, "{}", self.effect),
            k => write!(
                f,
                "{}'s {}",
                self.effect,
                self.effect.info().stages[k].label
            ),
        }
    }
}

/// One effect (or a further stage of a chosen one) added by forward selection on top of those
/// chosen before it.
pub struct Step {
    pub effect: EffectId,
    /// The stage of the effect it adds (0: the effect itself).
    pub stage: usize,
    pub family: &'static str,
    /// The joint fit: the parameters of every chosen effect so far, this one's last.
    pub free: Vec<Free>,
    pub fit: fit::FitResult,
    /// ΔBIC over the effects chosen before it.
    pub delta_bic: f64,
    /// Share of the baseline's misfit beyond noise (χ²) that the chosen effects explain together,
    /// this one included.
    pub explained: f64,
}

/// A part the verdict names, with the indices of its parameters in the named fit's.
type NamedPart = (Part, Range<usize>);

/// The outcome of a diagnosis.
pub struct Diagnosis {
    pub baseline: fit::Eval,
    /// Degrees of freedom of the features: the χ² of a model right to the noise.
    pub n: usize,
    /// Noise floor of the residual rms.
    pub noise_rms: f64,
    /// Noise floor of each channel's residual rms (acceleration, displacement, force).
    pub channel_noise: [f64; 3],
    /// Candidates, best first.
    pub candidates: Vec<Candidate>,
    /// Effects forward selection added on top of the best candidate, in order.
    pub more: Vec<Step>,
    /// Each named part's share of the baseline's misfit beyond noise (χ²) on its own in the
    /// final joint fit (the χ² it leaves refitted without it): the best candidate's, then each
    /// step's; empty when forward selection added nothing.
    pub own: Vec<f64>,
    pub features: Vec<FeatureInfo>,
    /// Each test's sample rate, Hz: a record's evidence is split by frequency band.
    pub rates_hz: Vec<f64>,
    /// The starting model's residual mapped onto the plant's states, when the caller made it
    /// ([`crate::diagnosis::statemap`]): a verdict of "not in the library" then names the state and term
    /// the residual follows.
    pub state_map: Option<crate::diagnosis::statemap::StateMap>,
    /// The residual the named effects leave, mapped likewise (when the caller made it): a
    /// verdict whose effects do not take the residual to the noise names what is left.
    pub state_map_after: Option<crate::diagnosis::statemap::StateMap>,
    /// The plain evidence in the starting model's residual (when the caller read it,
    /// [`crate::diagnosis::signals`]): offsets, spectral lines, tests that differ.
    pub signals: Signals,
    /// Per test, the starting model's residual in units of its noise (√(χ²/dof)).
    pub test_misfit: Vec<f64>,
    /// Per test and channel, the features' degrees of freedom ([`Problem::dof_table`]): what a
    /// fit's residual is measured against, channel by channel ([`Self::worst_channel`]).
    pub dof_table: Vec<[f64; 3]>,
    /// The model's expressions as written (`opening = "x - c*sign(x)"`), which a verdict that
    /// names the `expression` effect gives as its form; empty where it writes none.
    pub written: String,
    /// The expression term the diagnosis gave the models as the `expression` candidate, where
    /// it gave one ([`diagnose_campaign`], [`crate::diagnosis::terms`]).
    pub term: Option<Term>,
    /// The expression terms fitted to choose [`Self::term`], where there were several.
    pub terms_tried: Vec<Tried>,
}

/// What the diagnosis concludes.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// The baseline already fits to the noise, or no candidate lowers the misfit significantly.
    NothingSignificant,
    /// The best candidate (and those forward selection added to it) is significant and explains
    /// most of the residual.
    Missing { effects: Vec<Part>, explained: f64 },
    /// The best candidate (with those added to it) is significant but explains little of the
    /// residual.
    Unexplained { effects: Vec<Part>, explained: f64 },
}

impl Diagnosis {
    pub fn verdict(&self) -> Verdict {
        match self.named_verdict() {
            Verdict::Unexplained { .. } if self.starts_at_noise() => Verdict::NothingSignificant,
            v => v,
        }
    }

    /// Whether the starting model is already at the noise: its residual within [`NOISE_FACTOR`]
    /// of the noise floor, and every test's misfit (√(χ²/dof)) within it too. A candidate that
    /// explains a small share of what little is left is then no sign of a missing effect outside
    /// the library.
    pub fn starts_at_noise(&self) -> bool {
        self.baseline.residual_rms() <= NOISE_FACTOR * self.noise_rms
            && self.test_misfit.iter().all(|m| !(*m > NOISE_FACTOR))
    }

    /// The verdict from the candidates alone.
    fn named_verdict(&self) -> Verdict {
        match self.candidates.first() {
            Some(c) if c.significant() => {
                let effects: Vec<Part> = std::iter::once(c.part())
                    .chain(self.more.iter().map(Step::part))
                    .collect();
                let explained = self.more.last().map_or(c.explained, |s| s.explained);
                if self.more.is_empty() || explained >= EXPLAINS_TOGETHER {
                    if explained >= EXPLAINS_ENOUGH {
                        Verdict::Missing { effects, explained }
                    } else {
                        Verdict::Unexplained { effects, explained }
                    }
                } else if c.explained >= EXPLAINS_ENOUGH {
                    // The effects added to it do not close the gap to the noise: name the first only.
                    Verdict::Missing {
                        effects: vec![c.part()],
                        explained: c.explained,
                    }
                } else {
                    Verdict::Unexplained { effects, explained }
                }
            }
            _ => Verdict::NothingSignificant,
        }
    }

    /// The parameters and the joint fit of the effects the verdict names (none when it names
    /// none).
    pub fn named_fit(&self) -> Option<(&[Free], &fit::FitResult)> {
        let n = match self.verdict() {
            Verdict::Missing { effects, .. } | Verdict::Unexplained { effects, .. } => {
                effects.len()
            }
            Verdict::NothingSignificant => return None,
        };
        match n {
            0 => None,
            1 => self
                .candidates
                .first()
                .and_then(|c| c.fit.as_ref().ok().map(|f| (c.free.as_slice(), f))),
            n => self.more.get(n - 2).map(|s| (s.free.as_slice(), &s.fit)),
        }
    }

    /// ", but leaves a residual 3.9× the noise floor: …" when the named effects do not take the
    /// residual to within [`NOISE_FACTOR`] of the noise (`plural`: "leave", of several); empty
    /// when they do.
    fn short_of_noise(&self, plural: bool) -> String {
        let Some((_, f)) = self.named_fit() else {
            return String::new();
        };
        let ratio = f.after.residual_rms() / self.noise_rms;
        let worst = self.worst_channel(&f.after);
        let channel = match worst {
            Some((t, c, m)) if m > NOISE_FACTOR => format!(
                "{} the {} of test {} at {m:.1}x its noise",
                if ratio > NOISE_FACTOR { " and" } else { "" },
                ["acceleration", "displacement", "force"][c],
                self.signals.names.get(t).map_or("?", |n| n.as_str())
            ),
            _ if ratio > NOISE_FACTOR => String::new(),
            _ => return String::new(),
        };
        let floor = match ratio > NOISE_FACTOR {
            true => format!(" a residual {ratio:.1}x the noise floor"),
            false => String::new(),
        };
        let left = self
            .state_map_after
            .as_ref()
            .and_then(|m| m.sentence())
            .map_or(String::new(), |s| format!("; in what is left, {s}"));
        let (leave, form) = match plural {
            true => ("leave", "their forms are"),
            false => ("leaves", "its form is"),
        };
        format!(", but {leave}{floor}{channel}: {form} probably not quite the plant's{left}")
    }

    /// Whether `e` leaves more than [`NOISE_FACTOR`] times the noise: over every test and
    /// channel, or in one test's channel.
    pub fn above_noise(&self, e: &fit::Eval) -> bool {
        e.residual_rms() > NOISE_FACTOR * self.noise_rms
            || self.worst_channel(e).is_some_and(|w| w.2 > NOISE_FACTOR)
    }

    /// The test and channel whose residual in `e` is furthest from its noise, with √(χ²/dof)
    /// there: a channel measured far more finely than the others (a load cell's force) can be
    /// many times its noise while the residual rms over every channel, each relative to its
    /// signal, is at the floor.
    pub fn worst_channel(&self, e: &fit::Eval) -> Option<(usize, usize, f64)> {
        if e.failure.is_some() {
            return None;
        }
        let table = fit::chi2_per_channel(&self.features, e, &self.dof_table);
        let misfits = table.into_iter().enumerate().flat_map(|(t, m)| {
            (0..3)
                .filter(move |&c| !m[c].is_nan())
                .map(move |c| (t, c, m[c].sqrt()))
        });
        misfits.max_by(|a, b| a.2.total_cmp(&b.2))
    }

    /// The channels whose starting residual exceeds [`NOISE_FACTOR`] times their noise floor.
    pub(crate) fn channels_off(&self) -> Vec<usize> {
        (0..3)
            .filter(|&c| self.baseline.channel_rms(c) > NOISE_FACTOR * self.channel_noise[c])
            .collect()
    }

    /// "; the residual sits in the acceleration channel alone …" when the named effects are the
    /// measurement chain and one channel alone misfits; empty otherwise.
    fn measurement_note(&self, effects: &[Part]) -> String {
        let off = self.channels_off();
        let chain = effects
            .iter()
            .all(|p| p.effect.info().family == MEASUREMENT_FAMILY);
        match off.as_slice() {
            [c] if chain => {
                let ch = ["acceleration", "displacement", "force"][*c];
                format!("; the residual sits in the {ch} channel alone (the others agree with the model to the noise): it is the {ch} channel's measurement, not the plant")
            }
            _ => String::new(),
        }
    }

    /// The family a verdict gives for `effect`: the library's, or the expressions as written.
    fn family(&self, effect: EffectId) -> &str {
        match effect {
            EffectId::Expression if !self.written.is_empty() => &self.written,
            _ => effect.info().family,
        }
    }

    /// The verdict in plain words.
    pub fn summary(&self) -> String {
        let best = self.candidates.first();
        match self.verdict() {
            Verdict::NothingSignificant => match best {
                Some(c) if self.starts_at_noise() && c.significant() => format!(
                    "no significant missing effect: the starting model is at the noise (residual {:.2}x the noise floor, every test within {NOISE_FACTOR}x its noise; best: {}, explaining {:.0} % of the little beyond noise)",
                    self.baseline.residual_rms() / self.noise_rms,
                    c.effect,
                    100.0 * c.explained,
                ),
                Some(c) if c.delta_bic > SIGNIFICANT_BIC => format!(
                    "no candidate explains the residual significantly (best: {}, dBIC = {:.1}, but it explains {:.1} % of the misfit beyond noise, under {:.0} %); {}{}{}",
                    c.effect,
                    c.delta_bic,
                    100.0 * c.explained,
                    100.0 * EXPLAINS_SOME,
                    self.nothing_missing(),
                    self.where_it_fails(),
                    self.signal_note()
                ),
                _ => format!(
                    "no candidate explains the residual significantly (best: {}, dBIC = {:.1} <= {SIGNIFICANT_BIC}); {}{}{}",
                    best.map_or("-", |c| c.effect.name()),
                    best.map_or(f64::NAN, |c| c.delta_bic),
                    self.nothing_missing(),
                    self.where_it_fails(),
                    self.signal_note()
                ),
            },
            Verdict::Missing { effects, explained } if effects.len() == 1 => format!(
                "most likely missing: {} ({}){}{}; it explains {:.0} % of the misfit beyond noise (dBIC = {:.0}){}{}",
                effects[0],
                self.family(effects[0].effect),
                self.leader_group(),
                self.fitted_values(),
                100.0 * explained,
                best.map_or(f64::NAN, |c| c.delta_bic),
                self.short_of_noise(false) + &self.bound_note(),
                self.measurement_note(&effects)
            ) + &self.signal_note_if_short(),
            Verdict::Missing { effects, explained } => {
                let (list, shown) = self.named_list();
                let shares = match shown {
                    1 => "it explains".to_string(),
                    _ => "together they explain".to_string(),
                };
                let each = match shown {
                    1 => format!(" (dBIC = {:.0})", self.named_delta_bic()),
                    _ => format!(" (what the joint fit loses without each: {})", self.shares()),
                };
                format!(
                    "most likely missing: {list}; {shares} {:.0} % of the misfit beyond noise{each}{}{}",
                    100.0 * explained,
                    self.short_of_noise(shown > 1) + &self.bound_note(),
                    self.measurement_note(&effects)
                ) + &self.signal_note_if_short()
            }
            Verdict::Unexplained { effects, explained } if effects.len() == 1 => format!(
                "the best candidate, {}, explains only {:.0} % of the misfit beyond noise: the missing effect is probably not in the library{}{}",
                effects[0],
                100.0 * explained,
                self.where_it_fails(),
                self.signal_note()
            ),
            Verdict::Unexplained { effects, explained } => format!(
                "the best candidates together, {}, explain only {:.0} % of the misfit beyond noise (what the joint fit loses without each: {}): the missing effect is probably not in the library{}{}",
                effects.iter().map(|e| e.to_string()).collect::<Vec<_>>().join(" + "),
                100.0 * explained,
                self.shares(),
                self.where_it_fails(),
                self.signal_note()
            ),
        }
    }

    /// "no significant missing effect", unless some test's residual is over
    /// [`signals::TEST_CARRIES`] times its noise, or the signals show something: then that is
    /// said instead.
    fn nothing_missing(&self) -> String {
        let worst = (self.test_misfit.iter().enumerate())
            .filter(|(_, m)| m.is_finite())
            .max_by(|a, b| a.1.total_cmp(b.1));
        match worst {
            Some((t, &m)) if m > signals::TEST_CARRIES => format!(
                "yet the residual of test {} is {m:.1}x its noise: something is missing that no candidate of the library reproduces",
                self.signals.names.get(t).map_or("?", |n| n.as_str())
            ),
            _ if !self.signals.is_empty() => {
                "no effect of the library explains it".to_string()
            }
            _ => "no significant missing effect".to_string(),
        }
    }

    /// "; the signals show …" (offsets, spectral lines, tests that differ); empty when they show
    /// nothing.
    fn signal_note(&self) -> String {
        if self.signals.is_empty() {
            return String::new();
        }
        format!("; the signals show {}", self.signals.sentences().join("; "))
    }

    /// [`Self::signal_note`] when the named effects leave more than [`NOISE_FACTOR`] times the
    /// noise floor, or name a term read off the signals; where they name a term or an effect
    /// fitted to a group of tests, the tests that differ alone (the evidence it rests on: a
    /// specimen in a 1 Hz test also reads as a force gain, which the fit has explained); empty
    /// otherwise.
    fn signal_note_if_short(&self) -> String {
        match self.named_fit() {
            Some((_, f)) if self.above_noise(&f.after) => self.signal_note(),
            Some(_) if self.names_evidence() => self.signal_note(),
            Some(_) if self.names_a_group() || self.named_group().is_some() => {
                (self.signals.split_sentence())
                    .map_or(String::new(), |s| format!("; the signals show {s}"))
            }
            _ => String::new(),
        }
    }

    /// " in f1_a0p5, f2_a1p5 and f4_a0p8 only" where the best candidate is fitted to a group of
    /// tests ([`group_variants`]); empty otherwise.
    fn leader_group(&self) -> String {
        match self.named_group() {
            Some(g) => format!(" in {} only", self.signals.list(g.into_iter())),
            None => String::new(),
        }
    }

    /// The tests the named best candidate is fitted to, where that is a group of them (its
    /// effect off in the others).
    pub fn named_group(&self) -> Option<Vec<usize>> {
        match self.verdict() {
            Verdict::NothingSignificant => None,
            _ => self.candidates.first()?.group(),
        }
    }

    /// The term the verdict names, if it names the diagnosis's expression term.
    pub fn named_term(&self) -> Option<&Term> {
        self.term.as_ref().filter(|_| self.names_expression())
    }

    /// Whether the verdict names the `expression` candidate.
    fn names_expression(&self) -> bool {
        let named = match self.verdict() {
            Verdict::Missing { effects, .. } | Verdict::Unexplained { effects, .. } => effects,
            Verdict::NothingSignificant => Vec::new(),
        };
        named.iter().any(|p| p.effect == EffectId::Expression)
    }

    /// Whether the verdict names a term given to some tests only.
    pub fn names_a_group(&self) -> bool {
        (self.named_term()).is_some_and(|t| t.tests().len() < self.test_misfit.len())
    }

    /// Whether the verdict names a term read off the signals (an offset, a line).
    pub fn names_evidence(&self) -> bool {
        (self.named_term()).is_some_and(|t| t.evidence != Evidence::Map)
    }

    /// "; spool_dynamics.zeta = 5.00 is at the top of its range [0.05, 5]: …" for the named
    /// parameters whose estimates are at a bound of their range ([`AT_BOUND`]); empty where none
    /// is. A fit stopped at a bound has not found the plant's value: a spool of 35 Hz damped at
    /// 1.3 fitted from a start at 0.7 followed the lag's ridge to ζ = 5, 134 Hz.
    fn bound_note(&self) -> String {
        let Some((free, f)) = self.named_fit() else {
            return String::new();
        };
        let at: Vec<String> = (free.iter().zip(&f.estimate))
            .filter_map(|(p, &v)| {
                let r = p.info.range;
                let near =
                    |b: f64| b.is_finite() && b != 0.0 && (v - b).abs() <= AT_BOUND * b.abs();
                let side = match (near(r.lo), near(r.hi)) {
                    (_, true) => "top",
                    (true, _) => "bottom",
                    _ => return None,
                };
                Some(format!(
                    "{} = {} is at the {side} of its range [{}, {}]",
                    p.info.path(),
                    three_figures(v),
                    r.lo,
                    r.hi
                ))
            })
            .collect();
        match at.is_empty() {
            true => String::new(),
            false => format!(
                "; {}: the fit stopped at a bound, not at the plant's value (the effect's form, or the fit's start, is not the plant's: `study fit --model` from another start tells which)",
                signals::join_and(&at.iter().map(String::as_str).collect::<Vec<_>>())
            ),
        }
    }

    /// "; the missing valve flow follows sign(x) in spool opening (R² = 0.96): …", from the
    /// state map; empty without one, when no state explains the residual, or when the starting
    /// model is already within [`NOISE_FACTOR`] of the noise floor.
    fn where_it_fails(&self) -> String {
        if !(self.baseline.residual_rms() > NOISE_FACTOR * self.noise_rms) {
            return String::new();
        }
        self.state_map
            .as_ref()
            .and_then(|m| m.sentence())
            .map_or(String::new(), |s| format!("; {s}"))
    }
}

/// `v` with at least three significant figures (whole numbers from 1000 up keep all their
/// digits), in plain notation between 0.001 and 10⁶: "29.9", "0.787", "6997", "1.25e-10".
pub fn three_figures(v: f64) -> String {
    match v.abs() {
        a if a == 0.0 || !a.is_finite() => format!("{v}"),
        a if !(1e-3..1e6).contains(&a) => format!("{v:.2e}"),
        a => {
            let decimals = (2 - a.log10().floor() as i32).max(0) as usize;
            format!("{v:.decimals$}")
        }
    }
}

impl Diagnosis {
    /// " with freq_hz = 29.9 Hz, zeta = 0.787 (its fit started from the state map's lag of the
    /// opening (…))": the named candidate's fitted parameters, and the finding its fit started
    /// from where it did; empty when the verdict names none.
    fn fitted_values(&self) -> String {
        let (Some((free, f)), Some(c)) = (self.named_fit(), self.candidates.first()) else {
            return String::new();
        };
        let values = self.values_in(free, &f.estimate, 0..free.len());
        let origin = c
            .origin
            .as_ref()
            .map_or(String::new(), |o| format!(" (its fit started from {o})"));
        format!(" with {}{origin}", values.join(", "))
    }

    /// "freq_hz = 29.9 Hz", … for the parameters `range` of `free` at `estimate`: a term's
    /// phases left out and its line's amplitudes summed up.
    fn values_in(&self, free: &[Free], estimate: &[f64], range: Range<usize>) -> Vec<String> {
        let term = self.named_term();
        let phase = |name: &str| term.is_some_and(|t| t.is_phase_param(name));
        let named: Vec<(&str, f64)> = (free[range.clone()].iter().zip(&estimate[range.clone()]))
            .map(|(p, &v)| (p.info.name, v))
            .collect();
        let amplitudes = term.and_then(|t| {
            let (lo, hi, n) = t.amplitudes(&named).filter(|a| a.2 > 0)?;
            let (lo, hi, unit) = (three_figures(lo), three_figures(hi), t.unit());
            Some(format!("amplitude {lo} to {hi} {unit} in its {n} tests"))
        });
        (named.iter().zip(&free[range]))
            .filter(|((name, _), _)| !phase(name))
            .map(|((name, v), p)| {
                let unit = vshake_kernel::params::unit_after(p.info.unit);
                format!("{name} = {}{unit}", three_figures(*v))
            })
            .chain(amplitudes)
            .collect()
    }

    /// ΔBIC of the named fit against the baseline: χ²_baseline − χ² − p·ln n, p its parameters.
    fn named_delta_bic(&self) -> f64 {
        let Some((free, f)) = self.named_fit() else {
            return f64::NAN;
        };
        let score = Scoring::of(&self.baseline, self.n);
        score.chi2_b - score.bic(f.chi2_after(), free.len())
    }

    /// The named parts with the ranges of their parameters in the named fit, its parameters
    /// `free` and the fit; None where the verdict names none.
    fn named_parts(&self) -> Option<(Vec<NamedPart>, &[Free], &fit::FitResult)> {
        let (Verdict::Missing { effects, .. } | Verdict::Unexplained { effects, .. }) =
            self.verdict()
        else {
            return None;
        };
        let (free, f) = self.named_fit()?;
        let first = self.candidates.first()?;
        let ranges = param_ranges(first.free.len(), &self.more[..effects.len() - 1]);
        Some((effects.into_iter().zip(ranges).collect(), free, f))
    }

    /// Whether the named part `i` of `parts` is a stage of an effect that a later stage of it
    /// has made void: every parameter it frees fitted to nothing ([`fitted_to_nothing`]). The
    /// effect is then named by its later stages (leakage fitted as external leakage alone, its
    /// internal leakage at 0).
    fn void_stage(parts: &[NamedPart], free: &[Free], f: &fit::FitResult, i: usize) -> bool {
        let range = &parts[i].1;
        let nothing = |k: usize| fitted_to_nothing(&free[k], f, k);
        has_later_stage(parts, i) && !range.is_empty() && range.clone().all(nothing)
    }

    /// The indices, in the named fit's parameters, of a void stage's ([`Self::void_stage`]):
    /// the model a diagnosis writes holds them at 0, as its verdict says.
    pub fn void_params(&self) -> Vec<usize> {
        let Some((parts, free, f)) = self.named_parts() else {
            return Vec::new();
        };
        (0..parts.len())
            .filter(|&i| Self::void_stage(&parts, free, f, i))
            .flat_map(|i| parts[i].1.clone())
            .collect()
    }

    /// "leakage (leakage) with c_int = … + leakage's external leakage with c_ext = …": each named
    /// part with its fitted values; a void stage ([`Self::void_stage`]) is not named, its
    /// parameters are said to be fitted to 0 beside its effect's next stage.
    fn named_list(&self) -> (String, usize) {
        let Some((parts, free, f)) = self.named_parts() else {
            return (String::new(), 0);
        };
        let void: Vec<bool> = (0..parts.len())
            .map(|i| Self::void_stage(&parts, free, f, i))
            .collect();
        let mut out = Vec::new();
        for (i, (p, range)) in parts.iter().enumerate() {
            if void[i] {
                continue;
            }
            let family = match (out.is_empty(), p.stage) {
                (true, _) | (_, 0) => format!(" ({})", self.family(p.effect)),
                _ => String::new(),
            };
            let group = if i == 0 {
                self.leader_group()
            } else {
                String::new()
            };
            let mut values = self.values_in(free, &f.estimate, range.clone());
            let zeroed = (0..i).filter(|&j| void[j] && parts[j].0.effect == p.effect);
            for k in zeroed.flat_map(|j| parts[j].1.clone()) {
                let e = three_figures(f.estimate[k]);
                let why = match f.se[k].is_finite() && f.estimate[k].abs() <= VOID * f.se[k] {
                    true => format!("{e} ± {}", three_figures(f.se[k])),
                    false => format!("{e}, from {} fitted alone", three_figures(free[k].start)),
                };
                values.push(format!("{} fitted to 0 ({why})", free[k].info.name));
            }
            out.push(format!("{p}{family}{group} with {}", values.join(", ")));
        }
        let n = out.len();
        (out.join(" + "), n)
    }

    /// What each chosen effect removes on its own in the final joint fit: "A 60 %, + B 35 %"
    /// (shares of the baseline's misfit beyond noise). A stage with later stages named takes
    /// them with it ("specimen (all stages) 100 %"); a void stage is left out.
    fn shares(&self) -> String {
        let Some((parts, free, f)) = self.named_parts() else {
            return String::new();
        };
        let own = self.own.iter().copied().chain(std::iter::repeat(f64::NAN));
        let mut out = Vec::new();
        for (i, ((p, _), s)) in parts.iter().zip(own).enumerate() {
            if Self::void_stage(&parts, free, f, i) {
                continue;
            }
            let plus = if out.is_empty() { "" } else { "+ " };
            let all = match has_later_stage(&parts, i) {
                true => " (all stages)",
                false => "",
            };
            out.push(format!("{plus}{p}{all} {}", percent(s)));
        }
        out.join(", ")
    }
}

impl Diagnosis {
    /// Maps the residual the named effects leave (None when a test's model run fails).
    fn map_after(&mut self, aligned: &[AlignedTest]) {
        if let Some((free, fit)) = self.named_fit() {
            let fitted: Vec<AlignedTest> = (aligned.iter().enumerate())
                .map(|(i, t)| AlignedTest {
                    model: fit::apply_estimates_in(i, &t.model, free, &fit.estimate),
                    ..t.clone()
                })
                .collect();
            self.state_map_after = state_map(&fitted);
        }
    }
}

/// Each test of `aligned` run as it was driven and compared (the first model failure if any).
fn compared(aligned: &[AlignedTest]) -> Result<Vec<ComparedTest>, String> {
    let solver = Default::default();
    aligned
        .par_iter()
        .map(|t| crate::diagnosis::compare::compare_test(t, &solver))
        .collect()
}

/// The residual of `aligned` mapped onto the plant's states (None when a model run fails).
fn state_map(aligned: &[AlignedTest]) -> Option<StateMap> {
    compared(aligned)
        .ok()
        .map(|c| crate::diagnosis::statemap::map(&c))
}

/// The free parameters of `effect` at their values in `model`.
pub fn free_of(effect: EffectId, model: &ModelParams) -> Vec<Free> {
    free_of_stage(effect, 0, model)
}

/// The free parameters of stage `stage` of `effect` at their values in `model` (where that is 0,
/// at the stage's start value, if it has one); a building's storeys above its `storeys` are not
/// freed (they change nothing).
pub(crate) fn free_of_stage(effect: EffectId, stage: usize, model: &ModelParams) -> Vec<Free> {
    if effect == EffectId::Expression {
        return expression_free(model);
    }
    let s = &effect.info().stages[stage];
    let unused = |n: &&&str| {
        effect == EffectId::Building && building::unused(n, building::Params::of(model)).is_some()
    };
    s.free
        .iter()
        .filter(|n| !unused(n))
        .map(|n| {
            let info = ModelParams::lookup(&format!("{effect}.{n}"))
                .expect("default free parameters are registered");
            let v = info.get(model);
            let start = s.start.iter().find(|(name, _)| name == n).map(|x| x.1);
            Free::new(info, start.filter(|_| v == 0.0).unwrap_or(v))
        })
        .collect()
}

/// The expressions' free parameters: the named ones some expression of `model` reads, at their
/// values there (a model file's value is the fit's start).
fn expression_free(model: &ModelParams) -> Vec<Free> {
    slots_free(model, model.expression.slots_read())
}

/// The named parameters of the expressions' `slots`, at their values in `model`.
fn slots_free(model: &ModelParams, slots: Vec<usize>) -> Vec<Free> {
    let e = &model.expression;
    (slots.into_iter())
        .filter_map(|slot| ModelParams::lookup(&format!("expression.{}", e.names[slot])))
        .map(|info| Free::new(info, info.get(model)))
        .collect()
}

/// The expressions' free parameters in `problem`: those some test's expression reads (a term may
/// be given to some tests only, or with one parameter per test), at the first such test's values.
fn expression_free_in(problem: &Problem) -> Vec<Free> {
    let mut slots: Vec<usize> = (problem.tests.iter())
        .flat_map(|t| t.model.expression.slots_read())
        .collect();
    slots.sort_unstable();
    slots.dedup();
    slots_free(reference_model(problem, EffectId::Expression), slots)
}

/// The free parameters of stage `stage` of `effect` in `problem`: the expressions' over every
/// test ([`expression_free_in`]), another effect's in its reference model.
fn free_in(problem: &Problem, effect: EffectId, stage: usize) -> Vec<Free> {
    match effect {
        EffectId::Expression => expression_free_in(problem),
        _ => free_of_stage(effect, stage, reference_model(problem, effect)),
    }
}

/// `free` with the scanned start of stage `stage` of `effect` (see [`fit::scanned`]): sized where
/// the stage has a size, the sizes of the earlier stages giving way (a first mode's mass,
/// fitted alone, stood in for the second's too).
fn scanned(problem: &Problem, free: &[Free], effect: EffectId, stage: usize) -> Vec<Free> {
    let stages = effect.info().stages;
    let s = &stages[stage];
    let path = s.scan.map(|(name, _)| format!("{effect}.{name}"));
    let scan = path.as_deref().zip(s.scan.map(|(_, v)| v));
    let shape = s.shape.map(|(name, v)| (format!("{effect}.{name}"), v));
    let shape = shape.as_ref().map(|(n, v)| (n.as_str(), *v));
    let sizing = fit::Sizing {
        size: s.size.map(|name| format!("{effect}.{name}")),
        give: (stages[..stage].iter())
            .filter_map(|e| Some(format!("{effect}.{}", e.size?)))
            .collect(),
    };
    fit::scanned(problem, free, scan, &sizing, shape)
}

/// How a candidate's fit is scored against the baseline: its χ², the χ² noise leaves (the
/// features' degrees of freedom) and ln of it (the BIC's penalty per parameter).
struct Scoring {
    chi2_b: f64,
    n: f64,
    ln_n: f64,
}

impl Scoring {
    /// Against the evaluation `baseline`, of `n` degrees of freedom.
    fn of(baseline: &fit::Eval, n: usize) -> Scoring {
        Scoring {
            chi2_b: baseline.chi2(),
            n: n as f64,
            ln_n: (n as f64).ln(),
        }
    }

    /// The Bayesian information criterion of a fit leaving `chi2` with `p` parameters, up to a
    /// constant: χ² + p·ln n.
    fn bic(&self, chi2: f64, p: usize) -> f64 {
        chi2 + p as f64 * self.ln_n
    }

    /// Share of the baseline's χ² beyond noise that a fit leaving `chi2` removes, in [0, 1].
    fn share(&self, chi2: f64) -> f64 {
        let excess = self.chi2_b - self.n;
        if excess > 0.0 && chi2.is_finite() {
            ((self.chi2_b - chi2) / excess).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// The candidate `effect` with its parameters `free` and their fit: its ΔBIC and the share of
    /// the misfit beyond noise it explains.
    fn candidate(
        &self,
        effect: EffectId,
        free: Vec<Free>,
        fit: Result<fit::FitResult, fit::FitError>,
        origin: Option<String>,
    ) -> Candidate {
        let p = free.len() as f64;
        let (delta_bic, explained) = match &fit {
            Ok(f) => (
                self.chi2_b - f.chi2_after() - p * self.ln_n,
                self.share(f.chi2_after()),
            ),
            Err(_) => (f64::NEG_INFINITY, 0.0),
        };
        Candidate {
            effect,
            family: effect.info().family,
            free,
            fit,
            delta_bic,
            explained,
            origin,
        }
    }
}

/// Significant candidates first, each group by ΔBIC.
fn rank(out: &mut [Candidate]) {
    out.sort_by(|a, b| {
        b.significant()
            .cmp(&a.significant())
            .then(b.delta_bic.total_cmp(&a.delta_bic))
    });
}

/// Leading library candidates [`group_variants`] fits again to a group of tests. [chosen: 2,
/// as [`ALTERNATES`]: the effect that leads alone over every test is, where it acts in some
/// tests only, among the first few.]
pub const GROUP_LEADERS: usize = 2;

/// The leading [`GROUP_LEADERS`] significant library candidates fitted again in each of the
/// `groups` of tests alone (their effect off in the others: a specimen on the table for some
/// tests of a campaign, a set-up changed between them), each from the better of its own start
/// and its estimates over every test, screened as every candidate is (`reach`:
/// [`fit::fit_unprofiled`]); each is a candidate of its own ([`Candidate::label`]), and `out` is
/// ranked again (a leading one is then polished and profiled as any leader). No group of every
/// test, or of none, and none where the campaign has more tests than a group can hold
/// ([`fit::GROUP_TESTS`]).
fn group_variants(
    problem: &Problem,
    out: &mut Vec<Candidate>,
    groups: &[Vec<usize>],
    (baseline, reach): (&fit::Eval, f64),
    s: &Scoring,
) {
    let n = problem.tests.len();
    let groups: Vec<&[usize]> = (groups.iter())
        .filter(|g| !g.is_empty() && g.len() < n && n <= fit::GROUP_TESTS)
        .map(Vec::as_slice)
        .collect();
    let library = |c: &&Candidate| c.significant() && c.effect != EffectId::Expression;
    let leaders: Vec<&Candidate> = out.iter().filter(library).take(GROUP_LEADERS).collect();
    let pairs: Vec<(&Candidate, &[usize])> = (leaders.iter())
        .flat_map(|&c| groups.iter().map(move |&g| (c, g)))
        .collect();
    let more: Vec<Candidate> = (pairs.par_iter())
        .filter_map(|&(c, group)| {
            let f = c.fit.as_ref().ok()?;
            let in_group =
                |free: Vec<Free>| -> Vec<Free> { free.iter().map(|p| p.in_tests(group)).collect() };
            // The start scan with the effect in the group alone: over every test it lands in
            // another valley (a 5.5 Hz specimen in 3 tests of 7 scanned to 23.6 Hz).
            let own = in_group(free_in(problem, c.effect, 0));
            let own = scanned(problem, &own, c.effect, 0);
            let starts = [own, in_group(at_estimates(&c.free, &f.estimate))];
            (starts.into_par_iter())
                .map(|free| {
                    let r = fit::fit_unprofiled(problem, &free, MAX_ITER, baseline.clone(), reach);
                    s.candidate(c.effect, free, r, None)
                })
                .min_by(|a, b| a.chi2().total_cmp(&b.chi2()))
        })
        .collect();
    out.extend(more);
    rank(out);
}

/// The leading [`POLISHED`] significant candidates whose fits stopped at [`MAX_ITER`] go on from
/// their estimates (up to 4 × [`MAX_ITER`] more), and the candidates are ranked again: two
/// effects of one family may both explain nearly all, and the one whose parameters are
/// correlated (a dead volume and an air fraction) converges slowly; stopping it early would rank
/// the other first.
fn polish_leaders(problem: &Problem, out: &mut [Candidate], baseline: &fit::Eval, s: &Scoring) {
    let slow: Vec<usize> = (0..out.len().min(POLISHED))
        .filter(|&i| out[i].significant() && out[i].fit.as_ref().is_ok_and(|f| !f.converged))
        .collect();
    let again: Vec<(usize, Candidate)> = slow
        .par_iter()
        .filter_map(|&i| {
            let c = &out[i];
            let f = c.fit.as_ref().ok()?;
            let restart = at_estimates(&c.free, &f.estimate);
            let r = fit::fit_from(problem, &restart, 4 * MAX_ITER, baseline.clone()).ok()?;
            let origin = c.origin.clone();
            (r.chi2_after() < f.chi2_after())
                .then(|| (i, s.candidate(c.effect, restart, Ok(r), origin)))
        })
        .collect();
    for (i, c) in again {
        out[i] = c;
    }
    rank(out);
}

/// The leading [`POLISHED`] candidates' fits checked along each parameter
/// ([`fit::FitResult::profile`]: their standard errors where χ² is not smooth, their estimates
/// where a probe finds a lower χ²), and the candidates ranked again. The others keep
/// Gauss–Newton's errors: their estimates are shown nowhere but the report's table, and the
/// check costs a batch or more per round (on a 7-test broadband campaign it was 40 % of the
/// batches when every candidate had it).
fn profile_leaders(problem: &Problem, out: &mut [Candidate], s: &Scoring) {
    let top = out.len().min(POLISHED);
    let profiled: Vec<(usize, Candidate)> = (0..top)
        .into_par_iter()
        .filter_map(|i| {
            let c = &out[i];
            let f = c.fit.as_ref().ok()?.clone().profile(problem, &c.free);
            let origin = c.origin.clone();
            Some((i, s.candidate(c.effect, c.free.clone(), Ok(f), origin)))
        })
        .collect();
    for (i, c) in profiled {
        out[i] = c;
    }
    rank(out);
}

/// `free` (`study fit`'s parameters) started as a diagnosis starts them: for every stage of an
/// effect one of whose parameters is free, in order, the stage's start values where the
/// parameter is 0 (a second mode's mass: at 0 the mode is absent and its frequency has no effect)
/// and then the stage's start scan (a resonance's frequency).
pub fn scan_starts(problem: &Problem, free: &[Free]) -> Vec<Free> {
    let mut out = free.to_vec();
    for effect in EffectId::ALL {
        for (k, stage) in effect.info().stages.iter().enumerate() {
            let path = |n: &str| format!("{effect}.{n}");
            let touched = stage
                .free
                .iter()
                .any(|n| out.iter().any(|f| f.info.path() == path(n)));
            if !touched {
                continue;
            }
            for f in out.iter_mut() {
                let start = stage.start.iter().find(|(n, _)| f.info.path() == path(n));
                if let (Some(&(_, v)), true) = (start, f.start == 0.0) {
                    *f = f.at(v);
                }
            }
            out = scanned(problem, &out, effect, k);
        }
    }
    out
}

/// The campaign diagnosed: the starting model's residual mapped onto the states and read for
/// the signals' evidence, every candidate fitted (those of the map's findings from there,
/// [`crate::diagnosis::seeds`]) and ranked, and the residual the named effects leave mapped.
/// The maps stay None, the signals empty, where a test's model run fails (the diagnosis
/// reports that itself).
///
/// The `expression` effect, where `candidates` has it, is the model's own expressions; where the
/// model writes none, the state map's static term ([`StateMap::term`]) is given to the tests'
/// models in `problem` as their expression (the effect left off) and fitted as that candidate;
/// so are, where the signals show them, a channel's offset, a spectral line, and the map of the
/// tests not at the noise, given to those tests only ([`choose_term`]: the one that fits best);
/// with none, the candidate is dropped.
pub fn diagnose_campaign(
    problem: &mut Problem,
    candidates: &[EffectId],
    aligned: &[AlignedTest],
) -> Diagnosis {
    let c = compared(aligned).ok();
    let map = c.as_ref().map(|c| crate::diagnosis::statemap::map(c));
    let seeds = map.as_ref().map_or_else(Vec::new, seeds::from_map);
    let signals = c.as_ref().map(|c| read_signals(problem, c));
    let writes = !problem.tests[0].model.expression.hooks.is_empty();
    let asked = candidates.contains(&EffectId::Expression);
    let (term, tried) = match (&c, asked && !writes) {
        (Some(c), true) => choose_term(problem, c, map.as_ref(), signals.as_ref()),
        _ => (None, Vec::new()),
    };
    let candidates: Vec<EffectId> = (candidates.iter().copied())
        .filter(|&e| e != EffectId::Expression || writes || term.is_some())
        .collect();
    let mut signals = signals;
    if let Some(s) = signals.as_mut() {
        split_after_term(s, &tried);
    }
    let groups = (signals.as_ref())
        .and_then(|s| s.split.as_ref())
        .map_or_else(Vec::new, |split| split_groups(problem.tests.len(), split));
    let mut d = diagnose(problem, &candidates, &seeds, term.is_some(), &groups);
    let mut tried = tried;
    let term = beside_named(problem, &mut d, (&mut tried, aligned), term);
    let term = combined_beside(problem, &mut d, (&mut tried, aligned), term);
    d.signals = signals.unwrap_or(d.signals);
    d.state_map = map;
    let mut aligned = aligned.to_vec();
    if let Some(t) = &term {
        for (i, a) in aligned.iter_mut().enumerate() {
            // Installed in these tests' models before: it cannot fail here.
            t.install(&mut a.model, i).expect("the term installs");
        }
        d.written = t.described(aligned.len(), &d.signals);
    }
    d.map_after(&aligned);
    d.term = term;
    d.terms_tried = tried;
    d
}

/// The groups of tests a split of the signals (the tests that carry the residual, those at the
/// noise) gives the leading candidates ([`group_variants`]): the tests not at the noise, and the
/// tests that carry the residual where some are between. A specimen at 1.2 Hz moves the 4 and 6
/// Hz tests' residual to 2-4x their noise, no further, and is in them; a friction in every test
/// holds low-amplitude tests at 3.5x, and a specimen of 35 t in three others fitted to them too
/// made them 60x worse.
fn split_groups(
    n: usize,
    (carry, clean): &(signals::Misfits, signals::Misfits),
) -> Vec<Vec<usize>> {
    let wide: Vec<usize> = (0..n).filter(|t| clean.iter().all(|c| c.0 != *t)).collect();
    let strict: Vec<usize> = carry.iter().map(|c| c.0).collect();
    match strict.len() < wide.len() {
        true => vec![wide, strict],
        false => vec![wide],
    }
}

/// The signals' evidence in the compared tests `c` of `problem`'s starting model.
fn read_signals(problem: &Problem, c: &[ComparedTest]) -> Signals {
    let baseline = problem.evaluate(1, &|_, _, m| m.clone()).remove(0);
    let sigma: Vec<[f64; 3]> = problem.tests.iter().map(|t| t.sigma).collect();
    signals::read(c, &sigma, &problem.test_misfit(&baseline))
}

/// The expression term given to the models of `problem`'s tests as the `expression` candidate
/// ([`crate::diagnosis::terms`]): of the state map's term of the campaign's `map` (in every
/// test), the term of the map of the tests not at the noise where the `signals` split the tests
/// (in those only: a split also comes of an effect that grows with the amplitude, which the tests
/// at the noise carry too, below their noise), and the terms of the signals' offsets and lines,
/// the one whose fit has the lowest BIC. None where there is none or no model takes one.
fn choose_term(
    problem: &mut Problem,
    c: &[ComparedTest],
    map: Option<&StateMap>,
    signals: Option<&Signals>,
) -> (Option<Term>, Vec<Tried>) {
    let every: Vec<usize> = (0..c.len()).collect();
    let mut options: Vec<Term> = (map.and_then(StateMap::term).iter())
        .map(|t| Term::from_map(t, &every))
        .collect();
    if let Some((_, clean)) = signals.and_then(|s| s.split.as_ref()) {
        let clean: Vec<usize> = clean.iter().map(|x| x.0).collect();
        let group: Vec<usize> = every
            .iter()
            .copied()
            .filter(|i| !clean.contains(i))
            .collect();
        let some: Vec<ComparedTest> = group.iter().map(|&i| c[i].clone()).collect();
        let part = crate::diagnosis::statemap::map(&some).term();
        options.extend(part.map(|t| Term::from_map(&t, &group)));
    }
    options.extend(signals.map_or_else(Vec::new, |s| terms::from_signals(s, c)));
    if options.len() < 2 {
        return (options.pop().filter(|t| install(problem, t)), Vec::new());
    }
    let ln_n = problem.dof().max(2.0).ln();
    let tried: Vec<Tried> = (options.into_iter())
        .map(|t| {
            let (chi2, k, misfit) = term_fit(problem, &t);
            let bic = chi2 + k as f64 * ln_n;
            Tried {
                term: t,
                chi2,
                k,
                bic,
                misfit,
            }
        })
        .collect();
    let best = (tried.iter()).min_by(|a, b| a.bic.total_cmp(&b.bic));
    let best = best.map(|t| t.term.clone()).filter(|t| install(problem, t));
    (best, tried)
}

/// Terms read off the signals that [`beside_named`] tries on top of the named effects, of those
/// read before any fit and of those read off the residual the named set leaves. [chosen: 2 of
/// each; each is one joint fit of the named set with it.]
pub const BESIDE_TRIES: usize = 2;

/// A term read off the signals (an offset, a spectral line) added to the library effects the
/// diagnosis `d` names, where `term`, the `expression` candidate, is the state map's or is not
/// among them: a hum in some tests beside a friction in all of them. The one expression slot held
/// the term that fits best alone (the map's, standing in for the friction), and forward selection
/// never met the line. The signals' terms ([`beside_options`]) are each fitted on top of the
/// named set (its parameters from their estimates, freed with the term's); of those that add as
/// forward selection requires ([`ADDS_ENOUGH`], ΔBIC > [`SIGNIFICANT_BIC`]), the one of the
/// largest ΔBIC is named with them, the set checked again ([`prune`]); it is given to
/// `problem`'s models and becomes the `expression` candidate, fitted alone. Returns the term the
/// models then have.
fn beside_named(
    problem: &mut Problem,
    d: &mut Diagnosis,
    (tried, aligned): (&mut Vec<Tried>, &[AlignedTest]),
    term: Option<Term>,
) -> Option<Term> {
    let Some(lead) = d.candidates.first().filter(|c| c.significant()) else {
        return term;
    };
    let named = std::iter::once(lead.effect).chain(d.more.iter().map(|s| s.effect));
    if named.clone().any(|e| e == EffectId::Expression) || named.count() >= MAX_EFFECTS {
        return term;
    }
    let score = Scoring::of(&d.baseline, d.n);
    let (free, at) = match d.more.last() {
        Some(s) => (at_estimates(&s.free, &s.fit.estimate), s.fit.after.clone()),
        None => match &lead.fit {
            Ok(f) => (at_estimates(&lead.free, &f.estimate), f.after.clone()),
            Err(_) => return term,
        },
    };
    let options = beside_options(problem, (d, tried, aligned), term.as_ref(), &Some);
    // Of the terms that add, the one of the largest ΔBIC (a line's term in the tests that show
    // it, not one with a parameter pair in every test that adds as much).
    let added = (options.into_iter())
        .filter_map(|t| added_beside(problem, &t, (&free, &at), &score).map(|s| (t, s)))
        .max_by(|a, b| a.1.delta_bic.total_cmp(&b.1.delta_bic));
    let Some((t, step)) = added else {
        restore(problem, term.as_ref());
        return term;
    };
    install(problem, &t);
    let mut steps = std::mem::take(&mut d.more);
    steps.push(step);
    (d.more, d.own) = prune(problem, &d.candidates, steps, &score);
    let free = expression_free_in(problem);
    let fit = fit::fit_from(problem, &free, MAX_ITER, d.baseline.clone());
    let alone = score.candidate(EffectId::Expression, free, fit, None);
    if !tried.iter().any(|x| x.term == t) {
        let (chi2, k) = (alone.chi2(), alone.free.len());
        let bic = chi2 + k as f64 * score.ln_n;
        let misfit = Vec::new();
        tried.push(Tried {
            term: t.clone(),
            chi2,
            k,
            bic,
            misfit,
        });
    }
    d.candidates.retain(|c| c.effect != EffectId::Expression);
    d.candidates.push(alone);
    rank(&mut d.candidates[1..]);
    Some(t)
}

/// The named expression term given with a second term read off the signals ([`Term::with`]: on
/// another hook, with parameters of its own) where that adds as forward selection requires
/// ([`ADDS_ENOUGH`], ΔBIC > [`SIGNIFICANT_BIC`]) to the named set's final joint fit (the term's
/// parameters from their estimates, freed with the second's): a line in every test beside an
/// offset in some, where the one expression slot held the line and the offset stayed unfitted.
/// The terms tried are [`beside_options`]'s; of those that add, the one of the largest ΔBIC is
/// taken. The expression must be the set's leader alone or its last step (whose fit the verdict
/// reads). Returns the term `problem`'s models then have.
fn combined_beside(
    problem: &mut Problem,
    d: &mut Diagnosis,
    (tried, aligned): (&mut Vec<Tried>, &[AlignedTest]),
    term: Option<Term>,
) -> Option<Term> {
    let named = term.clone().filter(|_| d.names_expression());
    let (Some(t), Some((free, fit))) = (named, d.named_fit()) else {
        return term;
    };
    let leads = d.more.is_empty() && d.candidates[0].effect == EffectId::Expression;
    let last = d
        .more
        .last()
        .is_some_and(|s| s.effect == EffectId::Expression);
    let score = Scoring::of(&d.baseline, d.n);
    let room = (score.ln_n + SIGNIFICANT_BIC).max(3.0 * (2.0 * score.n).sqrt());
    if !(leads || last) || fit.chi2_after() - score.n <= room {
        return term;
    }
    let (free, at) = (at_estimates(free, &fit.estimate), fit.after.clone());
    // The residual the named set leaves is read with the term in the tests' models.
    let mut given = aligned.to_vec();
    for (i, a) in given.iter_mut().enumerate() {
        if t.install(&mut a.model, i).is_err() {
            return term;
        }
    }
    let with = |o: Term| t.with(&o);
    let options = beside_options(problem, (d, tried, &given), Some(&t), &with);
    let added = (options.into_iter())
        .filter_map(|c| added_beside(problem, &c, (&free, &at), &score).map(|s| (c, s)))
        .max_by(|a, b| a.1.delta_bic.total_cmp(&b.1.delta_bic));
    let Some((c, step)) = added else {
        install(problem, &t);
        return term;
    };
    install(problem, &c);
    let (chi2, k) = (step.fit.chi2_after(), step.free.len());
    tried.push(Tried {
        term: c.clone(),
        chi2,
        k,
        bic: score.bic(chi2, k),
        misfit: Vec::new(),
    });
    match d.more.last_mut() {
        Some(s) => {
            s.delta_bic += step.delta_bic;
            (s.free, s.fit, s.explained) = (step.free, step.fit, step.explained);
            let steps = std::mem::take(&mut d.more);
            (d.more, d.own) = prune(problem, &d.candidates, steps, &score);
        }
        None => {
            d.candidates[0] = score.candidate(EffectId::Expression, step.free, Ok(step.fit), None);
        }
    }
    Some(c)
}

/// The terms [`beside_named`] tries: those read off the signals of the residual the named set
/// leaves (an offset the specimen's residual hid in its tests is then seen in every test), and
/// the signals' terms of `tried` that fit best alone; [`BESIDE_TRIES`] of each of those `as_option`
/// makes an option of (the term as it is; given with the named term, [`combined_beside`]), none
/// twice, none the `expression` candidate's `term`.
fn beside_options(
    problem: &Problem,
    (d, tried, aligned): (&Diagnosis, &[Tried], &[AlignedTest]),
    term: Option<&Term>,
    as_option: &dyn Fn(Term) -> Option<Term>,
) -> Vec<Term> {
    let mut before: Vec<&Tried> = (tried.iter())
        .filter(|t| t.term.evidence != Evidence::Map)
        .collect();
    before.sort_by(|a, b| a.bic.total_cmp(&b.bic));
    let after = (terms_after(problem, d, aligned).into_iter())
        .filter_map(as_option)
        .take(BESIDE_TRIES);
    let before = (before.into_iter())
        .filter_map(|t| as_option(t.term.clone()))
        .take(BESIDE_TRIES);
    let mut out: Vec<Term> = Vec::new();
    for t in after.chain(before) {
        if Some(&t) != term && !out.contains(&t) {
            out.push(t);
        }
    }
    out
}

/// The terms read off the signals of the residual the effects `d` names leave (none where it
/// names none, or a test's run fails).
fn terms_after(problem: &Problem, d: &Diagnosis, aligned: &[AlignedTest]) -> Vec<Term> {
    let Some((free, fit)) = d.named_fit() else {
        return Vec::new();
    };
    let fitted: Vec<AlignedTest> = (aligned.iter().enumerate())
        .map(|(i, t)| AlignedTest {
            model: fit::apply_estimates_in(i, &t.model, free, &fit.estimate),
            ..t.clone()
        })
        .collect();
    let Ok(c) = compared(&fitted) else {
        return Vec::new();
    };
    let sigma: Vec<[f64; 3]> = problem.tests.iter().map(|t| t.sigma).collect();
    let s = signals::read(&c, &sigma, &problem.test_misfit(&fit.after));
    terms::from_signals(&s, &c)
}

/// The step that names `t` on top of the named set (its parameters `free` at their estimates,
/// leaving the evaluation `at`), `t` given to `problem`'s models; None, `t` still given, where
/// it does not add as forward selection requires.
fn added_beside(
    problem: &mut Problem,
    t: &Term,
    (free, at): (&[Free], &fit::Eval),
    score: &Scoring,
) -> Option<Step> {
    if !install(problem, t) {
        return None;
    }
    let mut f = free.to_vec();
    // A term given with a named one: the named one's parameters are in `free` already.
    let new = |p: &Free| !free.iter().any(|q| q.info.path() == p.info.path());
    f.extend(expression_free_in(problem).into_iter().filter(new));
    let r = fit::fit_from(problem, &f, MAX_ITER, at.clone()).ok()?;
    let drop = at.chi2() - r.chi2_after();
    let dbic = drop - (f.len() - free.len()) as f64 * score.ln_n;
    if !(dbic > SIGNIFICANT_BIC && drop >= ADDS_ENOUGH * (at.chi2() - score.n)) {
        return None;
    }
    Some(Step {
        effect: EffectId::Expression,
        stage: 0,
        family: EffectId::Expression.info().family,
        free: f,
        explained: score.share(r.chi2_after()),
        fit: r,
        delta_bic: dbic,
    })
}

/// `problem`'s models given `term` again (their expressions cleared where there is none).
fn restore(problem: &mut Problem, term: Option<&Term>) {
    match term {
        Some(t) => {
            install(problem, t);
        }
        None => (problem.tests.iter_mut()).for_each(|t| t.model.expression.hooks.clear()),
    }
}

/// One expression term [`choose_term`] fitted: its χ², parameters and BIC.
pub struct Tried {
    pub term: Term,
    pub chi2: f64,
    pub k: usize,
    pub bic: f64,
    /// Each test's misfit (√(χ²/dof)) with the term fitted; empty where its fit failed.
    pub misfit: Vec<f64>,
}

/// The χ² of `problem` given the term `t`, its parameters fitted, their number, and each test's
/// misfit then (χ² infinite and no misfits where a model refuses the term or the fit fails).
fn term_fit(problem: &mut Problem, t: &Term) -> (f64, usize, Vec<f64>) {
    if !install(problem, t) {
        return (f64::INFINITY, t.params.len(), Vec::new());
    }
    let free = expression_free_in(problem);
    let before = problem.evaluate(1, &|_, _, m| m.clone()).remove(0);
    match fit::fit_unprofiled(problem, &free, MAX_ITER, before, f64::INFINITY) {
        Ok(f) => (f.chi2_after(), free.len(), problem.test_misfit(&f.after)),
        Err(_) => (f64::INFINITY, free.len(), Vec::new()),
    }
}

/// Where the signals split no tests, their split once the term read off them that fits best
/// (an offset, a line: of `tried`, the lowest BIC) is fitted: an offset in every test keeps the
/// tests a specimen is absent from above the noise, and hides that it is in some only.
fn split_after_term(s: &mut Signals, tried: &[Tried]) {
    if s.split.is_some() {
        return;
    }
    let best = (tried.iter())
        .filter(|t| t.term.evidence != Evidence::Map && t.bic.is_finite())
        .min_by(|a, b| a.bic.total_cmp(&b.bic));
    if let Some(t) = best {
        s.split = signals::split(&t.misfit);
        s.between = signals::between(&t.misfit);
        s.split_after = s.split.as_ref().map(|_| t.term.written());
    }
}

/// `problem`'s tests given the expression `term` (those it is not given to, its parameters
/// only); false where a model refuses it.
fn install(problem: &mut Problem, term: &Term) -> bool {
    (problem.tests.iter_mut().enumerate()).all(|(i, t)| term.install(&mut t.model, i).is_ok())
}

/// A significant library candidate within [`SIGNIFICANT_BIC`] of a leading state-map term is
/// ranked first: the term is the regression's stand-in for whatever is missing, and names the
/// physics only where it fits clearly better than every effect the library has.
fn prefer_library(out: &mut [Candidate]) {
    let Some(lead) = out.first().filter(|c| c.effect == EffectId::Expression) else {
        return;
    };
    let close = |c: &Candidate| c.significant() && lead.delta_bic - c.delta_bic <= SIGNIFICANT_BIC;
    if let Some(i) = out
        .iter()
        .position(|c| c.effect != EffectId::Expression && close(c))
    {
        out[..=i].rotate_right(1);
    }
}

/// Fits every candidate (from its own start and from each of its seeds', keeping the better
/// fit: [`crate::diagnosis::seeds`]) and ranks them.
///
/// `generic`: the `expression` candidate is the state map's term, which ranks behind a library
/// effect that fits about as well ([`prefer_library`]). `groups`: groups of tests where the
/// signals split them ([`Signals::split`], [`split_groups`]): the leading library candidates are
/// also fitted to each alone ([`group_variants`]).
pub fn diagnose(
    problem: &Problem,
    candidates: &[EffectId],
    seeds: &[Seed],
    generic: bool,
    groups: &[Vec<usize>],
) -> Diagnosis {
    let baseline = problem.evaluate(1, &|_, _, m| m.clone()).remove(0);
    let n = problem.dof().round() as usize;
    let score = Scoring::of(&baseline, n);
    // A candidate that cannot explain [`EXPLAINS_SOME`] cannot be significant: its fit may stop
    // early ([`fit::fit_unprofiled`]).
    let reach = score.chi2_b - EXPLAINS_SOME * (score.chi2_b - score.n).max(0.0);
    let mut out: Vec<Candidate> = candidates
        .par_iter()
        .map(|&effect| {
            let own = scanned(problem, &free_in(problem, effect, 0), effect, 0);
            let seeded = seeds::starts(&own, effect, seeds);
            let starts =
                std::iter::once((own, None)).chain(seeded.into_iter().map(|(f, o)| (f, Some(o))));
            // The first of equal fits: the effect's own start.
            (starts.map(|(free, origin)| {
                let fit = fit::fit_unprofiled(problem, &free, MAX_ITER, baseline.clone(), reach);
                score.candidate(effect, free, fit, origin)
            }))
            .min_by(|a, b| a.chi2().total_cmp(&b.chi2()))
            .expect("the effect's own start")
        })
        .collect();
    rank(&mut out);
    group_variants(problem, &mut out, groups, (&baseline, reach), &score);
    polish_leaders(problem, &mut out, &baseline, &score);
    profile_leaders(problem, &mut out, &score);
    if generic {
        prefer_library(&mut out);
    }
    let more = forward_selection(problem, &out, (&[], &score));
    let chosen = prune(problem, &out, more, &score);
    let chosen = settle_leader(problem, &mut out, chosen, &score);
    let (more, own) = narrow_group(problem, &mut out, chosen, (&baseline, &score));
    Diagnosis {
        test_misfit: problem.test_misfit(&baseline),
        dof_table: problem.dof_table(),
        noise_rms: problem.noise_rms(),
        channel_noise: std::array::from_fn(|c| problem.channel_noise_rms(c)),
        baseline,
        n,
        candidates: out,
        more,
        own,
        features: problem.features(),
        rates_hz: problem.tests.iter().map(|t| t.samples.rate_hz).collect(),
        state_map: None,
        state_map_after: None,
        signals: Signals {
            names: problem.tests.iter().map(|t| t.name.clone()).collect(),
            ..Default::default()
        },
        written: written(reference_model(problem, EffectId::Expression)),
        term: None,
        terms_tried: Vec::new(),
    }
}

/// The model whose parameters a candidate of `effect` starts from: the first test's, or for the
/// expressions the first that writes them (the state map's term may be given to some tests
/// only).
fn reference_model(problem: &Problem, effect: EffectId) -> &ModelParams {
    let mut models = problem.tests.iter().map(|t| &t.model);
    let writes = |m: &&ModelParams| !m.expression.hooks.is_empty();
    match effect {
        EffectId::Expression => models.find(writes),
        _ => None,
    }
    .unwrap_or(&problem.tests[0].model)
}

/// `model`'s expressions as written: `opening = "…", force = "…"`.
fn written(model: &ModelParams) -> String {
    let hooks = model.expression.hooks.iter();
    let each: Vec<String> = hooks
        .map(|h| format!("{} = {:?}", h.hook.key(), h.source))
        .collect();
    each.join(", ")
}

/// Forward selection on top of the best candidate (see the module docs): the effects it adds;
/// `before`, the parts named from another leader, are tried first ([`best_addition`]).
fn forward_selection(
    problem: &Problem,
    ranked: &[Candidate],
    (before, score): (&[Part], &Scoring),
) -> Vec<Step> {
    let n = score.n;
    let Some(best) = ranked.first().filter(|c| c.significant()) else {
        return Vec::new();
    };
    let Ok(best_fit) = &best.fit else {
        return Vec::new();
    };
    let mut chosen: Vec<Part> = vec![best.part()];
    // The chosen parameters at their estimates, and the evaluation they leave.
    let mut free = at_estimates(&best.free, &best_fit.estimate);
    let mut at = best_fit.after.clone();
    let mut steps = Vec::new();
    while chosen.len() < MAX_EFFECTS {
        // Room left: even a perfect further effect of one parameter must beat its penalty, and
        // the χ² left must exceed what noise leaves by more than its own spread (a χ² of n
        // degrees of freedom has standard deviation √(2n); [chosen: three of them]).
        if at.chi2() - n <= (score.ln_n + SIGNIFICANT_BIC).max(3.0 * (2.0 * n).sqrt()) {
            break;
        }
        let first = before.get(steps.len()).copied();
        let at_now = (&chosen[..], &free[..], &at);
        let Some((part, f, r, dbic)) = best_addition(problem, ranked, at_now, (first, score))
        else {
            break;
        };
        let (f, r, dbic) = polished(problem, f, r, dbic);
        free = at_estimates(&f, &r.estimate);
        at = r.after.clone();
        chosen.push(part);
        steps.push(Step {
            effect: part.effect,
            stage: part.stage,
            family: part.effect.info().family,
            free: f,
            explained: score.share(r.chi2_after()),
            fit: r,
            delta_bic: dbic,
        });
    }
    steps
}

/// The named set `chosen` (the best candidate, then its steps, and each part's own share) with
/// its leader replaced by a candidate that tied with it alone ([`ALTERNATES`], [`TIE`]) where the
/// set then fits better by more than [`SIGNIFICANT_BIC`] in BIC: the tied candidate is put first
/// in `out` and forward selection and [`prune`] run again from it; the better of the two sets
/// (in BIC) is kept, and `out`'s order with it.
fn settle_leader(
    problem: &Problem,
    out: &mut [Candidate],
    chosen: (Vec<Step>, Vec<f64>),
    score: &Scoring,
) -> (Vec<Step>, Vec<f64>) {
    let Some(last) = chosen.0.last() else {
        return chosen;
    };
    let current = score.bic(last.fit.chi2_after(), last.free.len());
    let Some((j, swapped)) = best_swap(problem, out, &chosen.0, score) else {
        return chosen;
    };
    if swapped >= current - SIGNIFICANT_BIC {
        return chosen;
    }
    out[..=j].rotate_right(1);
    if let Some(again) = reselected(problem, out, (current, &chosen.0), score) {
        return again;
    }
    out[..=j].rotate_left(1);
    chosen
}

/// The named set found again from `out`'s leader, by forward selection and [`prune`], where its
/// BIC is below `current`'s (the set it would replace, its leader's `steps`); None where it is
/// not. The parts `current` added are tried first, in their order ([`best_addition`]).
fn reselected(
    problem: &Problem,
    out: &[Candidate],
    (current, named): (f64, &[Step]),
    score: &Scoring,
) -> Option<(Vec<Step>, Vec<f64>)> {
    let before: Vec<Part> = named.iter().map(Step::part).collect();
    let more = forward_selection(problem, out, (&before, score));
    let again = prune(problem, out, more, score);
    (set_bic(&out[0], &again.0, score) < current).then_some(again)
}

/// The named set `chosen` again from its leader fitted to fewer tests, where it leads as a group
/// variant ([`group_variants`]): a test is dropped from its group where the set's final joint fit
/// (or the leader's alone), refitted without it in the group, fits as well ([`narrowed`]).
/// Friction in every test held the low-amplitude tests above the noise, so a weak supply in three
/// tests was fitted to five, a flow-gain curve beside it making up the difference, and a specimen
/// in three tests to five, 20x the noise. The narrowed leader is fitted alone (from its
/// estimates) and put first in `out`, and forward selection and [`prune`] run again from it; the
/// better of the two sets (in BIC) is kept, and `out` with it.
fn narrow_group(
    problem: &Problem,
    out: &mut Vec<Candidate>,
    chosen: (Vec<Step>, Vec<f64>),
    (baseline, score): (&fit::Eval, &Scoring),
) -> (Vec<Step>, Vec<f64>) {
    let (Some(group), Ok(f)) = (out[0].group(), &out[0].fit) else {
        return chosen;
    };
    // The named set's final joint fit: the last step's, or the leader's alone.
    let (set, fitted) = match chosen.0.last() {
        Some(s) => (&s.free, &s.fit),
        None => (&out[0].free, f),
    };
    let fewer = narrowed(problem, (set, fitted, out[0].free.len()), &group);
    if fewer.len() == group.len() {
        return chosen;
    }
    let c = &out[0];
    let free: Vec<Free> = (at_estimates(&c.free, &f.estimate).iter())
        .map(|p| p.in_tests(&fewer))
        .collect();
    let fit = fit::fit_from(problem, &free, MAX_ITER, baseline.clone());
    let narrowed = score.candidate(c.effect, free, fit, c.origin.clone());
    if narrowed.fit.is_err() {
        return chosen;
    }
    let current = set_bic(&out[0], &chosen.0, score);
    out.insert(0, narrowed);
    if let Some(again) = reselected(problem, out, (current, &chosen.0), score) {
        return again;
    }
    out.remove(0);
    chosen
}

/// How close (relative) an estimate is to a bound of its range to be reported as at it
/// ([`Diagnosis::bound_note`]). [chosen: 1e-3]
pub const AT_BOUND: f64 = 1e-3;
/// A stage's parameter, in a range from 0, fitted to 0 within this many standard errors is
/// fitted to nothing ([`fitted_to_nothing`]). [chosen: 2, the acceptance's "within 2 SE"; an
/// internal leakage beside external leakage alone was fitted to 1.2e-16 ± 9.6e-15.]
pub const VOID: f64 = 2.0;

/// A stage's parameter, in a range from 0, fitted to below this share of its start, the value
/// its stage was fitted to before, is fitted to nothing whatever its standard error: one that
/// is not finite (a log-scaled parameter near 0, whose derivative in its scaled coordinate
/// vanishes there), or one so small that a bias of the records' drive is significant. [chosen:
/// an internal leakage beside external leakage alone came to 8.6e-17 from 1.9e-11 (4.5e-6) on
/// synthetic records, and to 9.4e-15 ± 6.8e-17 (5e-4 of its start) on five real PEER records;
/// a stage the data carry stays at a share of order 1.]
pub const VOID_SHARE: f64 = 1e-3;

/// Whether a later stage of the effect of the named part `i` is named too.
fn has_later_stage(parts: &[NamedPart], i: usize) -> bool {
    let p = parts[i].0;
    parts
        .iter()
        .any(|(q, _)| q.effect == p.effect && q.stage > p.stage)
}

/// Whether the parameter `p`, the `k`th of the fit `f`, was fitted to nothing: in a range from
/// 0, and within [`VOID`] standard errors of 0 or below [`VOID_SHARE`] of its start.
fn fitted_to_nothing(p: &Free, f: &fit::FitResult, k: usize) -> bool {
    let (e, se) = (f.estimate[k].abs(), f.se[k]);
    let small = p.start > 0.0 && e <= VOID_SHARE * p.start;
    p.info.range.lo == 0.0 && (e <= VOID * se || small)
}

/// Most a test's removal from a group may raise the joint fit's χ² and still be made: a test in
/// which the effect changes nothing beyond the noise says nothing of it. [chosen: 1, a standard
/// deviation of one feature]
pub const NARROW_TOLERANCE: f64 = 1.0;

/// The leader's `group` after backward elimination in the named set's joint fit `fitted` of the
/// parameters `set` (the leader's its first `n_lead`): each round refits the set with each test
/// dropped from the leader's group in turn (from the estimates), and drops the one whose refit
/// has the lowest χ² where that is at most [`NARROW_TOLERANCE`] above the set's; until none is
/// or one test is left.
fn narrowed(
    problem: &Problem,
    (set, fitted, n_lead): (&[Free], &fit::FitResult, usize),
    group: &[usize],
) -> Vec<usize> {
    let mut g = group.to_vec();
    let mut free = at_estimates(set, &fitted.estimate);
    let mut chi2 = fitted.chi2_after();
    // The group keeps one test at least.
    while g.len() > 1 {
        let tries: Vec<(usize, Vec<Free>, f64)> = (g.par_iter())
            .filter_map(|&t| {
                let rest: Vec<usize> = g.iter().copied().filter(|&x| x != t).collect();
                let f: Vec<Free> = (free.iter().enumerate())
                    .map(|(k, p)| if k < n_lead { p.in_tests(&rest) } else { *p })
                    .collect();
                let before = fitted.before.clone();
                // A drop that cannot come within the tolerance stops early.
                let reach = chi2 + NARROW_TOLERANCE;
                let r = fit::fit_unprofiled(problem, &f, MAX_ITER, before, reach).ok()?;
                Some((t, at_estimates(&f, &r.estimate), r.chi2_after()))
            })
            .collect();
        let best = (tries.into_iter()).min_by(|a, b| a.2.total_cmp(&b.2));
        match best {
            Some((t, f, c)) if c <= chi2 + NARROW_TOLERANCE => {
                g.retain(|&x| x != t);
                (free, chi2) = (f, c);
            }
            _ => break,
        }
    }
    g
}

/// The BIC of the named set: the last of `steps`' joint fit, or the leader `lead` alone.
fn set_bic(lead: &Candidate, steps: &[Step], score: &Scoring) -> f64 {
    match steps.last() {
        Some(s) => score.bic(s.fit.chi2_after(), s.free.len()),
        None => score.bic(lead.chi2(), lead.free.len()),
    }
}

/// The tied candidate (its index in `out`) whose joint fit in the leader's place, with the
/// parameters of `steps` from their final estimates, fits best, and that fit's BIC (χ² + p·ln n);
/// None where no candidate ties. A tied candidate is one of the [`ALTERNATES`] library effects
/// ranked next, significant, not already named, whose χ² beyond noise alone is within [`TIE`]
/// times the leader's.
fn best_swap(
    problem: &Problem,
    out: &[Candidate],
    steps: &[Step],
    score: &Scoring,
) -> Option<(usize, f64)> {
    let last = steps.last()?;
    let parts: Vec<Part> = std::iter::once(out[0].part())
        .chain(steps.iter().map(Step::part))
        .collect();
    let rest = kept(&parts, &param_ranges(out[0].free.len(), steps), 0);
    let excess = |c: &Candidate| c.chi2() - score.n;
    let tied = |c: &Candidate| {
        c.significant()
            && c.effect != EffectId::Expression
            && excess(c) <= TIE * excess(&out[0])
            && !parts.iter().any(|p| p.effect == c.effect)
    };
    let tries: Vec<(usize, f64)> = (1..out.len().min(1 + ALTERNATES))
        .filter(|&j| tied(&out[j]))
        .collect::<Vec<_>>()
        .into_par_iter()
        .filter_map(|j| {
            let alone = out[j].fit.as_ref().ok()?;
            let mut f = at_estimates(&out[j].free, &alone.estimate);
            let others = rest.iter().map(|&k| last.free[k].at(last.fit.estimate[k]));
            f.extend(others);
            let before = last.fit.before.clone();
            let r = fit::fit_unprofiled(problem, &f, MAX_ITER, before, f64::INFINITY).ok()?;
            Some((j, score.bic(r.chi2_after(), f.len())))
        })
        .collect();
    tries.into_iter().min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The named set (the best candidate, then `steps`) checked in its final joint fit: each part is
/// refitted out of it, and the weakest added part that does not remove [`ADDS_ENOUGH`] of the
/// misfit beyond noise the others leave without it, with ΔBIC > [`SIGNIFICANT_BIC`], and either
/// [`NAMES_ALONE`] of the baseline's or a set at the noise, is dropped, the set refitted
/// without it, until every one does. Returns the steps kept and each named
/// part's share of the baseline's misfit beyond noise on its own in the final joint fit (empty
/// when only the best candidate is named).
fn prune(
    problem: &Problem,
    ranked: &[Candidate],
    mut steps: Vec<Step>,
    score: &Scoring,
) -> (Vec<Step>, Vec<f64>) {
    while let Some(last) = steps.last() {
        let parts: Vec<Part> = std::iter::once(ranked[0].part())
            .chain(steps.iter().map(Step::part))
            .collect();
        let ranges = param_ranges(ranked[0].free.len(), &steps);
        let chi2 = last.fit.chi2_after();
        let without: Vec<Option<(Vec<Free>, fit::FitResult)>> = (0..parts.len())
            .into_par_iter()
            .map(|i| refit_without(problem, last, &parts, &ranges, i))
            .collect();
        // (share of the baseline's misfit, share of what the others leave, ΔBIC, the χ² without
        // it); a part whose removal leaves no parameter leaves the baseline.
        let own: Vec<(f64, f64, f64, f64)> = without
            .iter()
            .enumerate()
            .map(|(i, w)| {
                let c = match w {
                    Some((_, r)) => r.chi2_after(),
                    None if kept(&parts, &ranges, i).is_empty() => score.chi2_b,
                    None => f64::INFINITY,
                };
                let p = ranges[i].len() as f64;
                let left = (c - chi2) / (c - score.n);
                let base = score.share(chi2) - score.share(c);
                (base, left, c - chi2 - p * score.ln_n, c)
            })
            .collect();
        // At the noise, no part need take a clear share of the baseline: the last few of it may
        // be a shape's. The set is at the noise where it leaves every test within NOISE_FACTOR
        // of its noise, or the χ² over them all within NOISE_FACTOR² of the noise's where it is
        // not without the part.
        let noise = NOISE_FACTOR * NOISE_FACTOR * score.n;
        let at_noise = worst_test(problem, &last.fit) <= NOISE_FACTOR;
        let weakest = (1..parts.len())
            .filter(|&i| {
                let to_noise = chi2 <= noise && own[i].3 > noise;
                let clear = own[i].0 >= NAMES_ALONE || at_noise || to_noise;
                !(own[i].1 >= ADDS_ENOUGH && own[i].2 > SIGNIFICANT_BIC && clear)
            })
            .min_by(|&a, &b| own[a].1.total_cmp(&own[b].1));
        let Some(i) = weakest else {
            return (steps, own.iter().map(|o| o.0).collect());
        };
        let last_part = parts.len() - 1;
        let alone = !(0..parts.len()).any(|j| j != i && parts[j].effect == parts[i].effect);
        let refit = without.into_iter().nth(i).flatten();
        match refit {
            // The last part dropped: the fit before it stands.
            _ if i == last_part => steps.truncate(i - 1),
            Some((f, r)) if alone => {
                // The refit kept is checked along each parameter (its errors are shown).
                let r = r.profile(problem, &f);
                steps.remove(i - 1);
                let k = steps.len();
                let before = match k {
                    1 => ranked[0].chi2(),
                    _ => steps[k - 2].fit.chi2_after(),
                };
                let s = &mut steps[k - 1];
                let p_new = ranges[last_part].len() as f64;
                s.delta_bic = before - r.chi2_after() - p_new * score.ln_n;
                s.explained = score.share(r.chi2_after());
                s.free = f;
                s.fit = r;
            }
            _ => steps.truncate(i - 1),
        }
    }
    (steps, Vec::new())
}

/// The largest misfit of a test (√(χ²/dof) over its channels) that the fit `r` leaves.
fn worst_test(problem: &Problem, r: &fit::FitResult) -> f64 {
    (problem.test_misfit(&r.after).into_iter())
        .map(|m| if m.is_nan() { f64::INFINITY } else { m })
        .fold(0.0, f64::max)
}

/// The indices of each named part's parameters in the final joint fit's: the best candidate's
/// first (`n_best` of them), then each step's.
fn param_ranges(n_best: usize, steps: &[Step]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::with_capacity(steps.len() + 1);
    out.push(0..n_best);
    for s in steps {
        let start = out.last().map_or(0, |r| r.end);
        out.push(start..s.free.len());
    }
    out
}

/// The indices of the joint fit's parameters kept without part `i` and the further stages of its
/// effect that follow it.
fn kept(parts: &[Part], ranges: &[std::ops::Range<usize>], i: usize) -> Vec<usize> {
    let dropped = |j: usize| {
        j == i || (parts[j].effect == parts[i].effect && parts[j].stage > parts[i].stage)
    };
    (0..parts.len())
        .filter(|&j| !dropped(j))
        .flat_map(|j| ranges[j].clone())
        .collect()
}

/// The final joint fit `last` refitted from its estimates without part `i` (and the further
/// stages of its effect that follow it): its parameters and fit, None where the fit fails.
fn refit_without(
    problem: &Problem,
    last: &Step,
    parts: &[Part],
    ranges: &[std::ops::Range<usize>],
    i: usize,
) -> Option<(Vec<Free>, fit::FitResult)> {
    let free: Vec<Free> = kept(parts, ranges, i)
        .iter()
        .map(|&k| last.free[k].at(last.fit.estimate[k]))
        .collect();
    if free.is_empty() {
        return None;
    }
    let r = fit::fit_unprofiled(
        problem,
        &free,
        MAX_ITER,
        last.fit.before.clone(),
        f64::INFINITY,
    );
    Some((free, r.ok()?))
}

/// The parameters `free` at the values `estimate`.
fn at_estimates(free: &[Free], estimate: &[f64]) -> Vec<Free> {
    free.iter().zip(estimate).map(|(f, &v)| f.at(v)).collect()
}

/// What forward selection may add to the `chosen` parts: every other candidate that could be
/// fitted, and the next stage of each chosen effect that has one.
fn additions(ranked: &[Candidate], chosen: &[Part]) -> Vec<Part> {
    let has = |e: EffectId| chosen.iter().any(|p| p.effect == e);
    let mut out: Vec<Part> = ranked
        .iter()
        .filter(|c| !has(c.effect) && c.fit.is_ok())
        .map(Candidate::part)
        .collect();
    // An effect's group variant ([`group_variants`]) is the same addition.
    let mut seen = Vec::new();
    out.retain(|p| match seen.contains(p) {
        true => false,
        false => {
            seen.push(*p);
            true
        }
    });
    for p in chosen {
        let next = p.stage + 1;
        let last = !chosen
            .iter()
            .any(|q| q.effect == p.effect && q.stage > p.stage);
        if last && next < p.effect.info().stages.len() {
            out.push(Part {
                effect: p.effect,
                stage: next,
            });
        }
    }
    out
}

/// The candidate that adds most to the chosen parts (their parameters `free`, leaving the
/// evaluation `at`): what it adds, the joint parameters, their fit and its ΔBIC; None where no
/// addition is significant and removes [`ADDS_ENOUGH`] of the misfit left. Where `first`, a part
/// named before from another leader ([`reselected`]), is among the additions and adds so, it is
/// taken without fitting the others: the set it was named in tied with this one.
fn best_addition(
    problem: &Problem,
    ranked: &[Candidate],
    (chosen, free, at): (&[Part], &[Free], &fit::Eval),
    (first, score): (Option<Part>, &Scoring),
) -> Option<(Part, Vec<Free>, fit::FitResult, f64)> {
    let rest = additions(ranked, chosen);
    let chi2_at = at.chi2();
    let excess_at = chi2_at - score.n;
    // An addition that cannot remove [`ADDS_ENOUGH`] of what is left stops early, and only the
    // one chosen is checked along each parameter.
    let reach = chi2_at - ADDS_ENOUGH * excess_at;
    let p_new = |f: &[Free]| (f.len() - free.len()) as f64;
    let adds = |(part, f, r): (Part, Vec<Free>, Result<fit::FitResult, fit::FitError>)| {
        let r = r.ok()?;
        let drop = chi2_at - r.chi2_after();
        let dbic = drop - p_new(&f) * score.ln_n;
        (dbic > SIGNIFICANT_BIC && drop >= ADDS_ENOUGH * excess_at).then_some((part, f, r, dbic))
    };
    let fitted = |part: Part| {
        let f = with_addition(problem, free, part);
        let r = fit::fit_unprofiled(problem, &f, MAX_ITER, at.clone(), reach);
        (part, f, r)
    };
    let named = first
        .filter(|p| rest.contains(p))
        .and_then(|p| adds(fitted(p)));
    let (part, f, r, _) = match named {
        Some(a) => a,
        None => (rest
            .par_iter()
            .map(|&part| fitted(part))
            .collect::<Vec<_>>())
        .into_iter()
        .filter_map(adds)
        .max_by(|a, b| a.3.total_cmp(&b.3))?,
    };
    let r = r.profile(problem, &f);
    let dbic = chi2_at - r.chi2_after() - p_new(&f) * score.ln_n;
    Some((part, f, r, dbic))
}

/// The parameters `free` with those of `part` added, from its scanned start; a further stage of
/// a chosen effect acts in the tests its first does.
fn with_addition(problem: &Problem, free: &[Free], part: Part) -> Vec<Free> {
    let mut f = free.to_vec();
    let tests = (free.iter())
        .find(|p| p.info.component.effect() == Some(part.effect))
        .map_or(fit::ALL_TESTS, |p| p.tests);
    let added = free_in(problem, part.effect, part.stage).into_iter();
    f.extend(added.map(|p| fit::Free { tests, ..p }));
    if part.stage > 0 {
        revive(&mut f, part.effect);
    }
    scanned(problem, &f, part.effect, part.stage)
}

/// Share of its default below which a positive parameter has collapsed toward 0 [chosen: a
/// thousandth; a fit scaled by log cannot return from there within its iterations].
const COLLAPSED: f64 = 1e-3;

/// `free` with `effect`'s parameters that collapsed toward 0 ([`COLLAPSED`]) started at their
/// defaults again: held at the wrong shape, an effect's fit may drive one to 0 (seal friction
/// of Stribeck velocity 0.04 m/s and σ 15 kN·s/m, fitted with the defaults' shape, put f_s at
/// 1e-4 N), and on the log scale the fit that frees the shape could not bring it back (f_s
/// stayed at 5e-4 N, f_c 3.5 % high, 2.9x the noise). The fit may take it to 0 again.
fn revive(free: &mut [Free], effect: EffectId) {
    for p in free.iter_mut() {
        let default = p.info.default;
        let ours = p.info.component.effect() == Some(effect);
        if ours && p.log && default > 0.0 && p.start < COLLAPSED * default {
            *p = p.at(default);
        }
    }
}

/// A joint fit `r` (of the parameters `f`, with ΔBIC `dbic`) that did not converge, refitted
/// from its estimates with more iterations where that lowers its χ²: the parameters (started
/// where the fit returned was started: its scaled coordinates are relative to them), the fit
/// and the ΔBIC it then has.
fn polished(
    problem: &Problem,
    mut f: Vec<Free>,
    mut r: fit::FitResult,
    mut dbic: f64,
) -> (Vec<Free>, fit::FitResult, f64) {
    if !r.converged {
        // The chosen set's parameters started where they compensated for the missing effect:
        // the joint fit may need more iterations than a candidate's screening fit.
        let restart = at_estimates(&f, &r.estimate);
        if let Ok(polished) = fit::fit_from(problem, &restart, 4 * MAX_ITER, r.after.clone()) {
            if polished.chi2_after() <= r.chi2_after() {
                dbic += r.chi2_after() - polished.chi2_after();
                r = polished;
                f = restart;
            }
        }
    }
    (f, r, dbic)
}

/// The feature groups (test, harmonic) whose χ² a candidate lowers most: (test, harmonic, χ²
/// baseline, χ² candidate), largest reduction first.
pub fn evidence(d: &Diagnosis, c: &Candidate, top: usize) -> Vec<(usize, usize, f64, f64)> {
    let Ok(f) = &c.fit else { return Vec::new() };
    let b = fit::grouped(&d.features, &d.rates_hz, &d.baseline.r);
    let a = fit::grouped(&d.features, &d.rates_hz, &f.after.r);
    let mut v: Vec<(usize, usize, f64, f64)> = b
        .iter()
        .map(|(&(t, k), &x)| (t, k, x, a.get(&(t, k)).copied().unwrap_or(f64::NAN)))
        .collect();
    v.sort_by(|x, y| (y.2 - y.3).total_cmp(&(x.2 - x.3)));
    v.truncate(top);
    v
}
