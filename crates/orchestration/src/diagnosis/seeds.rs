//! The state map's findings as candidates: a term with memory the starting model's residual
//! follows ([`crate::diagnosis::residual_memory`]) is a law the library has, read at the
//! parameters the map found, and the diagnosis fits it from there.
//!
//! - A lag of the opening (the missing opening follows x_f − x, x_f the opening through a
//!   second-order lag of natural frequency f_n and damping ratio ζ, with a positive gain) is the
//!   law of `spool_dynamics`: it is started at freq_hz = f_n, zeta = ζ.
//! - An oscillator on the platen (the missing platen force is the force m·z̈ of a body of mass m
//!   on a spring and damper of f_n and ζ, m > 0) is the law of the specimen's first mode: it is
//!   started at m1 = m (where the files have the force; else the library's mass), f1 = f_n,
//!   zeta1 = ζ.
//!
//! A finding is used only where the map's fit of it explains at least [`statemap::MIN_R2`] of
//! its residual and its frequency lies inside the range the map searched (at the range's top the
//! data say only "fast"). Each value is clamped into the parameter's valid range.
//!
//! How a seed is used (`diagnose`): the candidate is fitted from its own start (its start
//! scan's best point) and from each seed's, and the fit that ends with the lower χ² is kept; the
//! candidate then says it started from the finding. The library's scan covers a resonance's
//! frequency only, at the library's damping; the map's point covers the damping and the mass
//! too. [chosen: a second fit, not a choice of start by the χ² at the start: a start that fits
//! better need not end better (Levenberg–Marquardt from either may stop in another valley), and
//! the candidate that wins a diagnosis is the one whose fit ends lowest.]

use crate::diagnosis::fit::Free;
use crate::diagnosis::residual_memory::{self, Kind, MemoryFit};
use crate::diagnosis::statemap::{self, StateMap};
use vshake_kernel::params::EffectId;

/// A start for a candidate effect, read from a finding of the state map.
#[derive(Debug, Clone, PartialEq)]
pub struct Seed {
    pub effect: EffectId,
    /// Parameters of the effect (their names in its table) and their starts.
    pub values: Vec<(&'static str, f64)>,
    /// The finding in words: "the state map's lag of the opening (f_n 29.40 Hz, ζ 81.0 %, …)".
    pub finding: String,
}

/// The seeds of the findings of `map` (see the module docs).
pub fn from_map(map: &StateMap) -> Vec<Seed> {
    map.memory
        .iter()
        .filter(|(_, m)| m.r2 >= statemap::MIN_R2 && m.f_n < residual_memory::F_HI)
        .filter_map(|(_, m)| seed_of(m))
        .collect()
}

/// The seed of one finding with memory, None where its gain says no such law (a lead, a negative
/// mass).
fn seed_of(m: &MemoryFit) -> Option<Seed> {
    // "a lag of the opening" without its article.
    let what = m.kind.name().split_once(' ').map_or("", |(_, w)| w);
    let finding = format!("the state map's {what} ({})", m.describe());
    let values = match m.kind {
        Kind::Lag if m.gain > 0.0 => vec![("freq_hz", m.f_n), ("zeta", m.zeta)],
        Kind::Carried if m.gain > 0.0 => vec![("m1", m.gain), ("f1", m.f_n), ("zeta1", m.zeta)],
        // No force channel: the mass means nothing, the library's stays.
        Kind::Carried if m.gain.is_nan() => vec![("f1", m.f_n), ("zeta1", m.zeta)],
        Kind::Lag | Kind::Carried => return None,
    };
    let effect = match m.kind {
        Kind::Lag => EffectId::SpoolDynamics,
        Kind::Carried => EffectId::Specimen,
    };
    Some(Seed {
        effect,
        values,
        finding,
    })
}

/// `free` (the candidate `effect`'s parameters at its own start) with the values of `seed`,
/// clamped into their ranges; parameters the seed does not name keep their start.
fn with_seed(free: &[Free], effect: EffectId, seed: &Seed) -> Vec<Free> {
    free.iter()
        .map(|f| {
            let named = seed
                .values
                .iter()
                .find(|(n, _)| f.info.path() == format!("{effect}.{n}"));
            match named {
                Some(&(_, v)) => f.at(clamp_into(f, v)),
                None => *f,
            }
        })
        .collect()
}

/// `v` inside the valid range of `f`'s parameter (a finite bound that is open moved in by a
/// millionth; an infinite one stays).
fn clamp_into(f: &Free, v: f64) -> f64 {
    let r = f.info.range;
    let inward = |b: f64, dir: f64| {
        if !b.is_finite() || r.contains(b) {
            b
        } else {
            b + dir * 1e-6 * b.abs().max(1e-12)
        }
    };
    let (lo, hi) = (inward(r.lo, 1.0), inward(r.hi, -1.0));
    v.clamp(lo, hi.max(lo))
}

/// The starts a seed gives candidate `effect` (whose own start is `free`): each seed's for it,
/// with the finding it came from.
pub fn starts(free: &[Free], effect: EffectId, seeds: &[Seed]) -> Vec<(Vec<Free>, String)> {
    seeds
        .iter()
        .filter(|s| s.effect == effect)
        .map(|s| (with_seed(free, effect, s), s.finding.clone()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn memory(kind: Kind, f_n: f64, zeta: f64, gain: f64) -> MemoryFit {
        MemoryFit {
            kind,
            f_n,
            zeta,
            gain,
            r2: 0.97,
        }
    }

    #[test]
    fn a_lag_seeds_the_spool_and_an_oscillator_the_specimen() {
        let lag = seed_of(&memory(Kind::Lag, 29.4, 0.81, 0.9)).unwrap();
        assert_eq!(lag.effect, EffectId::SpoolDynamics);
        assert_eq!(lag.values, vec![("freq_hz", 29.4), ("zeta", 0.81)]);
        assert!(
            lag.finding
                .starts_with("the state map's lag of the opening (f_n 29.40 Hz, ζ 81.0 %"),
            "{}",
            lag.finding
        );
        let body = seed_of(&memory(Kind::Carried, 6.2, 0.02, 31e3)).unwrap();
        assert_eq!(body.effect, EffectId::Specimen);
        assert_eq!(
            body.values,
            vec![("m1", 31e3), ("f1", 6.2), ("zeta1", 0.02)]
        );
        let no_force = seed_of(&memory(Kind::Carried, 6.2, 0.02, f64::NAN)).unwrap();
        assert_eq!(no_force.values, vec![("f1", 6.2), ("zeta1", 0.02)]);
    }

    #[test]
    fn a_lead_or_a_negative_mass_seeds_nothing() {
        assert_eq!(seed_of(&memory(Kind::Lag, 70.0, 0.1, -0.87)), None);
        assert_eq!(seed_of(&memory(Kind::Carried, 20.0, 0.06, -300.0)), None);
    }

    #[test]
    fn a_seed_is_clamped_into_the_parameters_range() {
        use vshake_kernel::params::ModelParams;
        let m = ModelParams::default();
        let free: Vec<Free> = ["freq_hz", "zeta"]
            .map(|n| {
                let info = ModelParams::lookup(&format!("spool_dynamics.{n}")).unwrap();
                Free::new(info, info.get(&m))
            })
            .to_vec();
        let seed = Seed {
            effect: EffectId::SpoolDynamics,
            values: vec![("zeta", 9.0)],
            finding: String::new(),
        };
        let s = with_seed(&free, EffectId::SpoolDynamics, &seed);
        let zeta = s.iter().find(|f| f.info.name == "zeta").unwrap();
        assert_eq!(zeta.start, 5.0);
        let freq = s.iter().find(|f| f.info.name == "freq_hz").unwrap();
        assert_eq!(freq.start, m.effect_params.spool_dynamics.freq_hz);
        // A range open to infinity (a mass, ≥ 0): the value stays; below it, the bound.
        let mass = Free::new(ModelParams::lookup("specimen.m1").unwrap(), 20e3);
        assert_eq!(clamp_into(&mass, 2.3e3), 2.3e3);
        assert_eq!(clamp_into(&mass, -5.0), 0.0);
        // An open finite bound (a pump's flow, > 0): moved in.
        let q = Free::new(ModelParams::lookup("supply.q_pump").unwrap(), 0.2);
        assert!(clamp_into(&q, 0.0) > 0.0);
    }
}
