//! References of the earthquake-type excitations (docs/model.md §4b): acceleration records made
//! into displacements, stochastic ground motions, sweeps and band-limited random motions; the
//! table's limits checked before a run; each realisation's noise from (seed, stream).
//!
//! **Noise.** A realisation's white noise is the ChaCha8 stream `stream` of the seed
//! `seed ^ NOISE_SALT` (standard normal draws by `rand_distr`): a study's design uses the
//! streams of `seed` itself, so the two never share numbers. `stream` is the excitation's fixed
//! realisation, or the sample id for `realisation = "per_sample"`; a realisation is therefore a
//! function of (seed, sample id) only, whatever the thread count, chunk or shard.
//!
//! **How each reference gets its derivatives.** Records and stochastic motions: the processed
//! displacement (kernel::ground::to_displacement) through the 4th-order state-variable filter of
//! every record (kernel::excitation::Record). Sweeps and random motions: exact, from their
//! closed forms (kernel::ground::Jet).

use crate::runs::spec::{ExcitationSpec, RecordUnit};
use chacha20::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use vshake_kernel::excitation::{Record, Reference, Signal};
use vshake_kernel::ground::{self, Multisine, Processing};
use vshake_kernel::params::{Component, ModelParams, G};

/// Mixed into a study's seed for the excitation noise (so it never shares the design's streams).
pub const NOISE_SALT: u64 = 0x6e6f_6973_655f_7631; // "noise_v1"

/// The noise generator of stream `stream` of `seed` (see the module docs).
fn noise_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ NOISE_SALT);
    rng.set_stream(stream);
    rng
}

/// `n` standard normal draws of stream `stream` of `seed` (see the module docs).
pub fn noise(seed: u64, stream: u64, n: usize) -> Vec<f64> {
    let mut rng = noise_rng(seed, stream);
    (0..n)
        .map(|_| rng.sample::<f64, _>(StandardNormal))
        .collect()
}

/// The reference of a generated excitation (stochastic, sweep, random) for `model` (whose
/// `ground.*` a stochastic motion reads), with noise of (`seed`, `sample`) where it has any. An
/// error says why the motion cannot run (the table's limits).
pub fn generated(
    excitation: &ExcitationSpec,
    model: &ModelParams,
    seed: u64,
    sample: u64,
) -> Result<Reference, String> {
    let f_s = model.controller.f_s;
    let r = match excitation {
        ExcitationSpec::Stochastic {
            duration_s,
            realisation,
            seed: own,
            ground: given,
            processing,
            f_ref_hz,
        } => {
            // The model's ground.* (a study's sampled values), the excitation's own keys over them.
            let mut m = model.clone();
            for (name, v) in given {
                let info = ModelParams::rows(Component::Ground)
                    .find(|p| p.name == *name)
                    .expect("a ground parameter name");
                info.set(&mut m, *v);
            }
            let g = m.ground;
            let n = (duration_s * f_s).round() as usize;
            let white = noise(own.unwrap_or(seed), realisation.stream(sample), n);
            let accel = ground::filtered_noise(&g, &white, 1.0 / f_s);
            // A generated motion is fed to the table's reference generator: a command.
            let filter = (*f_ref_hz, Signal::Command);
            from_acceleration(&accel, 0.0, 1.0 / f_s, processing, filter, f_s)
        }
        ExcitationSpec::Sweep { sweep, .. } => {
            closed_form(f_s, sweep.duration_s, |t| sweep.states(t))
        }
        ExcitationSpec::Random {
            f_lo_hz,
            f_hi_hz,
            rms_g,
            duration_s,
            taper_s,
            realisation,
            seed: own,
        } => {
            let df = 1.0 / duration_s;
            let count =
                ((f_hi_hz / df).floor() - (f_lo_hz / df).ceil().max(1.0) + 1.0).max(1.0) as usize;
            let mut rng = noise_rng(own.unwrap_or(seed), realisation.stream(sample));
            let phases: Vec<f64> = (0..count)
                .map(|_| 2.0 * std::f64::consts::PI * rng.random::<f64>())
                .collect();
            let m = Multisine::new(*f_lo_hz, *f_hi_hz, *duration_s, *taper_s, rms_g * G, |k| {
                phases[k % phases.len()]
            });
            closed_form(f_s, *duration_s, |t| m.states(t))
        }
        ExcitationSpec::Sine { .. } | ExcitationSpec::Record { .. } => {
            unreachable!("sines and records are built by sim::reference_for")
        }
    };
    crate::runs::limits::check_limits(&r, model)?;
    Ok(r)
}

/// A reference from closed-form states at every tick of `duration` s.
fn closed_form(f_s: f64, duration: f64, states: impl Fn(f64) -> [f64; 4]) -> Reference {
    let n = (duration * f_s).round() as usize + 1;
    let x: Vec<[f64; 4]> = (0..n).map(|k| states(k as f64 / f_s)).collect();
    Reference::from_states(f_s, &x)
}

/// A displacement reference from a ground acceleration (m/s², every `dt` s from `t0`): processed
/// into a displacement, then made into reference states as a record of what `filter` says
/// (its corner, Hz, and whether it is a command or the tracked reference).
pub(crate) fn from_acceleration(
    accel: &[f64],
    t0: f64,
    dt: f64,
    p: &Processing,
    filter: (f64, Signal),
    f_s: f64,
) -> Reference {
    let d = ground::to_displacement(accel, dt, p);
    let rec = Record {
        time_s: (0..d.disp_m.len()).map(|k| t0 + k as f64 * dt).collect(),
        disp_m: d.disp_m,
        f_ref_hz: filter.0,
        signal: filter.1,
    };
    rec.reference(f_s)
}

/// A record column in SI after its unit and scaling: `scale` times, or to the peak `pga_g`.
pub fn scaled(values: &[f64], unit: RecordUnit, scale: f64, pga_g: Option<f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.iter().map(|x| x * unit.to_si()).collect();
    match pga_g {
        Some(g) => {
            ground::scale_to_pga(&mut v, g * G);
        }
        None => v.iter_mut().for_each(|x| *x *= scale),
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runs::spec::Realisation;

    fn stochastic(realisation: Realisation) -> ExcitationSpec {
        ExcitationSpec::Stochastic {
            duration_s: 10.0,
            realisation,
            seed: None,
            ground: vec![("pga_g", 0.3)],
            processing: Processing::default(),
            f_ref_hz: 50.0,
        }
    }

    #[test]
    fn a_realisation_depends_on_seed_and_stream_only() {
        let m = ModelParams::default();
        let a = generated(&stochastic(Realisation::PerSample), &m, 7, 3).unwrap();
        let b = generated(&stochastic(Realisation::PerSample), &m, 7, 3).unwrap();
        let c = generated(&stochastic(Realisation::PerSample), &m, 7, 4).unwrap();
        let fixed = generated(&stochastic(Realisation::Fixed(3)), &m, 7, 99).unwrap();
        assert_eq!(a, b);
        assert_ne!(a.x, c.x);
        assert_eq!(a, fixed);
        // The generated acceleration peaks at the asked PGA before processing; the reference
        // (high-passed, filtered) stays near it.
        let (_, _, peak_a) = a.peaks();
        assert!((peak_a / (0.3 * G) - 1.0).abs() < 0.2, "{}", peak_a / G);
    }

    #[test]
    fn every_key_of_the_excitation_applies_over_the_model() {
        // The excitation's keys, all of them, win over the model's ground.*; the others stay.
        let keys = vec![("pga_g", 0.4), ("f_g_hz", 1.2), ("zeta_g", 0.35)];
        let exc = |ground| ExcitationSpec::Stochastic {
            duration_s: 8.0,
            realisation: Realisation::Fixed(1),
            seed: None,
            ground,
            processing: Processing::default(),
            f_ref_hz: 50.0,
        };
        let mut m = ModelParams::default();
        m.ground.t_strong_s = 3.0;
        let mut by_model = m.clone();
        (
            by_model.ground.pga_g,
            by_model.ground.f_g_hz,
            by_model.ground.zeta_g,
        ) = (0.4, 1.2, 0.35);
        assert_eq!(
            generated(&exc(keys), &m, 5, 0).unwrap(),
            generated(&exc(vec![]), &by_model, 5, 0).unwrap()
        );
        assert_ne!(
            generated(&exc(vec![("pga_g", 0.4)]), &m, 5, 0).unwrap(),
            generated(&exc(vec![]), &by_model, 5, 0).unwrap()
        );
    }

    #[test]
    fn limits_are_named() {
        let m = ModelParams::default();
        // 20 g on the 144 t platen needs 28 MN, beyond the 6.8 MN of controller.f_max.
        let big = ExcitationSpec::Stochastic {
            duration_s: 10.0,
            realisation: Realisation::Fixed(0),
            seed: None,
            ground: vec![("pga_g", 20.0)],
            processing: Processing::default(),
            f_ref_hz: 50.0,
        };
        let Err(e) = generated(&big, &m, 1, 0) else {
            panic!("a 20 g motion passed the limits")
        };
        assert!(
            e.contains("exceeds the table's limits") && e.contains("controller.f_max"),
            "{e}"
        );
    }
}
