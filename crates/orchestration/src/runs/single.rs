//! One configuration through the kernel (`study sim`): lane 0 of the same lane kernel the batch
//! engine uses, with an [`Observer`] that keeps the time history of every channel of docs/model.md §5.

use crate::measured::aligned::{DataProblem, NumTable};
use crate::runs::quake;
use crate::runs::spec::{ExcitationSpec, SimSpec};
use vshake_kernel::builds;
use vshake_kernel::effects::EffectId;
use vshake_kernel::excitation::{Record, Reference};
use vshake_kernel::params::ModelParams;
use vshake_kernel::resample::Resampler;
use vshake_kernel::simulate::{
    LaneParams, LaneResult, NoObserver, Observer, SetupError, Solver, TickView,
};
use vshake_kernel::spectrum::SpectrumSpec;
use vshake_kernel::state::idx;
use vshake_kernel::{EFFECT_LANES, LANES};

/// A channel of a time history: its column name (the docs/formats.md measured-test name where
/// one exists, so a history can be read back as a measured test), what it holds, and how a tick
/// gives it. A history's rows are made from this list, so the two cannot drift apart.
pub struct Channel {
    pub name: &'static str,
    pub meaning: &'static str,
    pub at: fn(&TickView<'_, 1>) -> f64,
}

/// The channels of a time history, in column order.
pub const CHANNELS: [Channel; 13] = [
    Channel {
        name: "time_s",
        meaning: "time t_k",
        at: |v| v.t,
    },
    Channel {
        name: "ref_disp_m",
        meaning: "reference displacement x_r",
        at: |v| v.r.x,
    },
    Channel {
        name: "ref_accel_mps2",
        meaning: "reference acceleration a_r",
        at: |v| v.r.a,
    },
    Channel {
        name: "disp_m",
        meaning: "platen displacement feedback x",
        at: |v| v.x[0],
    },
    Channel {
        name: "accel_mps2",
        meaning: "platen acceleration dv/dt at t_k",
        at: |v| v.a[0],
    },
    Channel {
        name: "valve_cmd_v",
        meaning: "valve command u after the clamp",
        at: |v| v.u[0],
    },
    Channel {
        name: "force_n",
        meaning: "total actuator force F",
        at: |v| v.f[0],
    },
    Channel {
        name: "p1_pa",
        meaning: "cap-side pressure P1, actuator 1",
        at: |v| v.state[idx::P1[0]][0],
    },
    Channel {
        name: "p2_pa",
        meaning: "rod-side pressure P2, actuator 1",
        at: |v| v.state[idx::P2[0]][0],
    },
    Channel {
        name: "p1_act2_pa",
        meaning: "cap-side pressure P1, actuator 2",
        at: |v| v.state[idx::P1[1]][0],
    },
    Channel {
        name: "p2_act2_pa",
        meaning: "rod-side pressure P2, actuator 2",
        at: |v| v.state[idx::P2[1]][0],
    },
    Channel {
        name: "spool_m",
        meaning: "spool position of actuator 1 (the command x_c unless a valve effect is on)",
        at: |v| v.spool[0],
    },
    Channel {
        name: "ref_vel_mps",
        meaning: "reference velocity v_r",
        at: |v| v.r.v,
    },
];

/// Time history of lane 0, one vector per channel of [`CHANNELS`], then the effects' own
/// channels ([`Effect::responses`](vshake_kernel::effects::Effect::responses): a building's
/// drifts, floor accelerations, base shear) in the order the effects give them.
#[derive(Debug, Clone, Default)]
pub struct History {
    pub columns: Vec<Vec<f64>>,
    /// The effects' channels, by name.
    pub responses: Vec<(&'static str, Vec<f64>)>,
}

impl History {
    /// The response spectrum of the achieved acceleration (`accel_mps2`) over the reference's
    /// window, as the kernel's online spectrum takes it.
    pub fn accel_psa(&self, reference: &Reference, spectrum: &SpectrumSpec) -> Vec<f64> {
        let accel = self
            .channel("accel_mps2")
            .expect("a history has accel_mps2");
        let (w0, w1) = reference.window;
        // A failed run's history can end before the window, or inside it.
        let end = w1.min(accel.len());
        vshake_kernel::spectrum::psa(&accel[w0.min(end)..end], 1.0 / reference.f_s, spectrum)
    }

    pub fn with_capacity(n: usize) -> Self {
        History {
            columns: (0..CHANNELS.len()).map(|_| Vec::with_capacity(n)).collect(),
            responses: Vec::new(),
        }
    }
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The channel called `name`.
    pub fn channel(&self, name: &str) -> Option<&[f64]> {
        self.named_columns()
            .into_iter()
            .find(|(n, _)| *n == name)
            .map(|(_, c)| c)
    }
    /// The columns with their names, for a table.
    pub fn named_columns(&self) -> Vec<(&'static str, &[f64])> {
        CHANNELS
            .iter()
            .map(|c| c.name)
            .zip(self.columns.iter().map(Vec::as_slice))
            .chain(self.responses.iter().map(|(n, c)| (*n, c.as_slice())))
            .collect()
    }
}

impl Observer<1> for History {
    fn tick(&mut self, v: &TickView<'_, 1>) {
        for (c, ch) in self.columns.iter_mut().zip(&CHANNELS) {
            c.push((ch.at)(v));
        }
        let (ticks, responses) = (self.len(), &mut self.responses);
        let mut j = 0;
        (v.responses)(0, &mut |name, x| {
            if j == responses.len() {
                responses.push((name, Vec::with_capacity(ticks)));
            }
            debug_assert_eq!(
                responses[j].0, name,
                "an effect's channels keep their order"
            );
            responses[j].1.push(x);
            j += 1;
        });
    }
}

/// The outcome of one run.
#[derive(Debug, Clone)]
pub struct SimOutcome {
    pub result: LaneResult,
    pub history: History,
}

/// Runs `model` against `reference`, every tick to `obs`: through the effect set when the model
/// switches an effect on, else through the bare baseline kernel ([`builds::run_lane`]).
pub fn run_one(
    model: &ModelParams,
    reference: &Reference,
    solver: &Solver,
    obs: &mut dyn Observer<1>,
) -> Result<LaneResult, SetupError> {
    builds::run_lane(model, reference, solver, obs)
}

/// The lanes of up to [`LANES`] models (`refs[i]` for `models[i]`; one reference is every
/// lane's), without an observer: lanes without effects in one batch of the bare plant's
/// [`LANES`], lanes with one effect that leaves the hydraulics alone (a specimen, a building) in
/// one such batch where the CPU has AVX2 ([`builds::run_wide_single_effect`]), other lanes with
/// effects in batches of [`EFFECT_LANES`] (lanes are independent, bit for bit, so the split does
/// not change a lane). A setup error of any batch is the group's.
pub fn run_group(
    models: &[&ModelParams],
    refs: &[&Reference],
    solver: &Solver,
) -> Result<Vec<LaneResult>, SetupError> {
    assert!(!models.is_empty() && models.len() <= LANES);
    assert!(refs.len() == 1 || refs.len() == models.len());
    if !models.iter().any(|m| m.effects.any()) {
        let lp = LaneParams::<LANES>::new(models)?;
        let refs: [&Reference; LANES] = std::array::from_fn(|l| refs[l.min(refs.len() - 1)]);
        let r = builds::run_bare_lanes(&lp, &refs, solver)?;
        return Ok(r[..models.len()].to_vec());
    }
    if let Some(r) = run_wide(models, refs, solver) {
        return Ok(r?[..models.len()].to_vec());
    }
    let mut out = Vec::with_capacity(models.len());
    for (k, m) in models.chunks(EFFECT_LANES).enumerate() {
        let lo = k * EFFECT_LANES;
        let r = if refs.len() == 1 {
            refs
        } else {
            &refs[lo..lo + m.len()]
        };
        let r: [&Reference; EFFECT_LANES] = std::array::from_fn(|l| r[l.min(r.len() - 1)]);
        let got = run_effect_chunk(m, &r, solver)?;
        out.extend_from_slice(&got[..m.len()]);
    }
    Ok(out)
}

/// More than [`EFFECT_LANES`] models that switch on one library effect, one that leaves the
/// hydraulics alone, as one batch of [`LANES`] ([`builds::run_wide_single_effect`]); `None` where
/// that kernel does not apply.
fn run_wide(
    models: &[&ModelParams],
    refs: &[&Reference],
    solver: &Solver,
) -> Option<Result<[LaneResult; LANES], SetupError>> {
    if models.len() <= EFFECT_LANES {
        return None;
    }
    let [id] = effects_on(models)[..] else {
        return None;
    };
    let refs: [&Reference; LANES] = std::array::from_fn(|l| refs[l.min(refs.len() - 1)]);
    builds::run_wide_single_effect(id, models, &refs, solver)
}

/// The library effects that any of `models` switches on.
fn effects_on(models: &[&ModelParams]) -> Vec<EffectId> {
    EffectId::ALL
        .into_iter()
        .filter(|&e| models.iter().any(|m| m.effects.get(e)))
        .collect()
}

/// Up to [`EFFECT_LANES`] models with effects as the lanes of one batch (`refs[l]` for lane l):
/// with the kernel made for the one library effect they switch on when they share one reference
/// and switch on exactly one (a tuning or a study with a specimen: several times faster, the same
/// numbers bit for bit), else through the effect set.
fn run_effect_chunk(
    models: &[&ModelParams],
    refs: &[&Reference; EFFECT_LANES],
    solver: &Solver,
) -> Result<[LaneResult; EFFECT_LANES], SetupError> {
    if refs.iter().all(|r| std::ptr::eq(*r, refs[0])) {
        return run_lanes_single(models, refs[0], solver, &mut NoObserver);
    }
    builds::run_effect_lanes(models, refs, solver, &mut NoObserver)
}

/// Up to [`EFFECT_LANES`] models as the lanes of one batch against `reference`, every tick to
/// `obs`, with a kernel made for the one library effect the lanes switch on when they switch on
/// exactly one (a diagnosis screens the library one effect at a time) and the configuration is
/// the usual one ([`builds::run_single_effect`]); else through the effect set or the bare plant.
/// The same numbers either way, bit for bit, the first several times faster
/// ([`vshake_kernel::effects::EffectFn`]).
pub fn run_lanes_single(
    models: &[&ModelParams],
    reference: &Reference,
    solver: &Solver,
    obs: &mut dyn Observer<EFFECT_LANES>,
) -> Result<[LaneResult; EFFECT_LANES], SetupError> {
    if let [id] = effects_on(models)[..] {
        if let Some(done) = builds::run_single_effect(id, models, reference, solver, obs) {
            return done;
        }
    }
    builds::run_effect_lanes(models, &[reference; EFFECT_LANES], solver, obs)
}

/// The reference of one excitation for `model`. A record's columns (its time and displacement
/// or acceleration) come in `record`, read by the caller; rounded time is rebuilt into its
/// uniform grid (a gap or a drift is refused), and a displacement beyond the stroke is refused
/// at its row. A generated motion's noise is stream 0 of `seed` unless it names its own
/// realisation ([`crate::runs::quake`]). Every reference but a sine carries the default response
/// spectrum, and is checked against the table's limits.
pub fn reference_for(
    excitation: &ExcitationSpec,
    model: &ModelParams,
    record: Option<&NumTable>,
    seed: u64,
) -> Result<Reference, DataProblem> {
    let f_s = model.controller.f_s;
    let r = match (excitation, record) {
        (ExcitationSpec::Sine { sine, .. }, _) => return Ok(sine.reference(f_s)),
        (
            ExcitationSpec::Record {
                column,
                time_column,
                f_ref_hz,
                scale,
                unit,
                pga_g,
                processing,
                signal,
                ..
            },
            Some(t),
        ) => {
            let grid = t.time_base(time_column)?;
            let values = quake::scaled(
                t.column(column).expect("the record's column was read"),
                *unit,
                *scale,
                *pga_g,
            );
            let r = if unit.is_acceleration() {
                quake::from_acceleration(
                    &values,
                    grid.time(0.0),
                    1.0 / grid.rate_hz,
                    processing,
                    (*f_ref_hz, *signal),
                    f_s,
                )
            } else {
                let l = model.actuator.l;
                if let Some((row, d)) = values.iter().enumerate().find(|(_, d)| d.abs() >= l) {
                    return Err(t.problem(Some(column), Some(row + 1), format!("displacement {d} m (after unit {} and scale {scale}) exceeds the stroke (half stroke actuator.l = {l} m)", unit.name())));
                }
                Record {
                    time_s: (0..t.rows()).map(|i| grid.time(i as f64)).collect(),
                    disp_m: values,
                    f_ref_hz: *f_ref_hz,
                    signal: *signal,
                }
                .reference(f_s)
            };
            crate::runs::limits::check_limits(&r, model)
                .map_err(|m| t.problem(Some(column), None, m))?;
            r
        }
        (ExcitationSpec::Record { file, .. }, None) => panic!(
            "the record {} was not read before its reference was built",
            file.display()
        ),
        (generated, _) => {
            quake::generated(generated, model, seed, 0).map_err(|message| DataProblem {
                file: format!("excitation ({})", generated.describe()),
                place: String::new(),
                message,
            })?
        }
    };
    Ok(r.with_spectrum(crate::runs::quake_spec::default_spectrum()))
}

/// Runs `spec` against a prepared reference (sine or record).
pub fn run_sim(spec: &SimSpec, reference: &Reference) -> Result<SimOutcome, SetupError> {
    let mut history = History::with_capacity(reference.len());
    let result = run_one(&spec.model, reference, &spec.solver, &mut history)?;
    Ok(SimOutcome { result, history })
}

/// Runs `model` against `reference` and samples its channels at the model times `tau`
/// ([`vshake_kernel::resample`]).
pub fn run_sampled(
    model: &ModelParams,
    reference: &Reference,
    solver: &Solver,
    tau: &[f64],
) -> Result<(LaneResult, Resampler<1>), SetupError> {
    let mut rs = Resampler::<1>::new(tau);
    let result = run_one(model, reference, solver, &mut rs)?;
    Ok((result, rs))
}

/// What a data-acquisition system records of `reference` at `rate` Hz after `pre_rows` rows at
/// rest, read back as the tracked reference (`signal = "reference"`, docs/model.md §4): x_r at
/// the file's times is the record, its derivatives the zero-phase filter's with corner
/// `f_ref_hz`. A model run on it and the same record read from the file agree at the numerical
/// floor, whatever generator made x_r.
pub fn tracked_record(reference: &Reference, rate: f64, pre_rows: usize, f_ref_hz: f64) -> Record {
    let f_s = reference.f_s;
    let n = (reference.len() as f64 / f_s * rate).round() as usize;
    let x0 = reference.x[0];
    let disp_m: Vec<f64> = std::iter::repeat_n(x0, pre_rows)
        .chain((0..n).map(|i| reference.at_time(&reference.x, i as f64 / rate)))
        .collect();
    Record {
        time_s: (0..disp_m.len()).map(|i| i as f64 / rate).collect(),
        disp_m,
        f_ref_hz,
        signal: vshake_kernel::excitation::Signal::Reference,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runs::spec::{ExcitationSpec, Realisation};
    use vshake_kernel::ground::Processing;

    /// A group with one effect on (a specimen whose frequency differs per lane) against one
    /// reference runs through the kernel made for that effect: the effect set's numbers, bit
    /// for bit (compared through their full-precision Debug text, NaN included).
    #[test]
    fn a_group_with_one_effect_gives_the_effect_sets_numbers() {
        let exc = ExcitationSpec::Stochastic {
            duration_s: 5.0,
            realisation: Realisation::Fixed(0),
            seed: None,
            ground: vec![("pga_g", 0.4)],
            processing: Processing::default(),
            f_ref_hz: 50.0,
        };
        let models: Vec<ModelParams> = (0..11)
            .map(|i| {
                let mut m = ModelParams::default();
                m.effects.specimen = true;
                m.effect_params.specimen.f1 = 1.0 + 0.5 * i as f64;
                m
            })
            .collect();
        let r = crate::runs::quake::generated(&exc, &models[0], 3, 0).unwrap();
        let lanes: Vec<&ModelParams> = models.iter().collect();
        let solver = Solver::default();
        let got = run_group(&lanes, &[&r], &solver).unwrap();
        let mut want = Vec::new();
        for chunk in lanes.chunks(EFFECT_LANES) {
            let w = builds::run_effect_lanes(chunk, &[&r; EFFECT_LANES], &solver, &mut NoObserver)
                .unwrap();
            want.extend_from_slice(&w[..chunk.len()]);
        }
        assert_eq!(format!("{got:?}"), format!("{want:?}"));
        assert!(got
            .iter()
            .all(|l| matches!(l.status, vshake_kernel::simulate::LaneStatus::Ok)));
    }
}
