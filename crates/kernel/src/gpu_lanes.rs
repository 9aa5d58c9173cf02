//! The flat records of the CUDA lane kernel (`crates/kernel/src/cuda/lane.cu`): the parameters it reads,
//! the run it shares between lanes, and the sums it returns, turned back into [`LaneResult`]s.
//!
//! Pure data: no device, no I/O. The device engine (`shell::gpu`) uploads these arrays; the
//! kernel's host build in `tests/cuda_host.rs` takes the same arrays, so what is tested without
//! a GPU is what the GPU runs. The CUDA kernel covers the baseline model (both valve laws, every
//! damping exponent), every library effect ([`EFFECT_BITS`]), every drive, one
//! reference for every lane or one per lane, with the harmonic, error, peak, valve and
//! response-spectrum metrics; [`unsupported`] names what it does not.

use super::effects::{self, Effect, EffectId, LibraryEffect, ModelView};
use super::excitation::{Drive, Reference};
use super::metrics::{Basis, LaneSums, Metrics, MetricsAcc, N_HARM};
use super::params::{ModelParams, ValveLaw};
use super::simulate::{self, Failure, LaneParams, LaneResult, LaneStatus, SetupError, Solver};
use super::spectrum::oscillators;

/// The kernel's CUDA C++ source.
pub const SOURCE: &str = include_str!("cuda/lane.cu");

/// Float64 fields per lane in the parameter record (lane.cu: `VS_LANE_FIELDS`).
pub const LANE_FIELDS: usize = 223;

/// The library effects the CUDA kernel has, with their bit in its `effects` argument and build
/// (lane.cu: `VS_E_*`, in this order). A library effect not listed here (one a user adds) runs
/// on the CPU: [`unsupported`] names it, and a study with it on takes the CPU engine.
pub const EFFECT_BITS: [(EffectId, i64); 21] = [
    (EffectId::TransportDelay, 1),
    (EffectId::SpoolDynamics, 1 << 1),
    (EffectId::FlowSaturation, 1 << 2),
    (EffectId::FlowGain, 1 << 3),
    (EffectId::Asymmetry, 1 << 4),
    (EffectId::Leakage, 1 << 5),
    (EffectId::Supply, 1 << 6),
    (EffectId::SealFriction, 1 << 7),
    (EffectId::Compressibility, 1 << 8),
    (EffectId::BulkCurve, 1 << 9),
    (EffectId::ReactionMass, 1 << 10),
    (EffectId::HoldDown, 1 << 11),
    (EffectId::Specimen, 1 << 12),
    (EffectId::AccelSensor, 1 << 13),
    (EffectId::DispSensor, 1 << 14),
    (EffectId::ForceSensor, 1 << 15),
    (EffectId::Building, 1 << 16),
    (EffectId::ValveCompensator, 1 << 17),
    (EffectId::AmplitudePhase, 1 << 18),
    (EffectId::HarmonicCancellation, 1 << 19),
    (EffectId::AdaptiveInverse, 1 << 20),
];

/// The bit saying that the two actuators differ in some lane (lane.cu: `VS_E_TWO`): the kernel
/// then integrates both, else one stands for both.
pub const TWO_ACTUATORS: i64 = 1 << 21;

/// The `effects` bits of a launch: every covered effect some lane switches on, and
/// [`TWO_ACTUATORS`] where some lane's actuators differ.
pub fn effect_bits(models: &[&ModelParams]) -> i64 {
    // One pass over the models (a study's launch has many, each a few kilobytes).
    models.iter().fold(0, |bits, m| {
        let two = !effects::asymmetry::Asymmetry::<1>::new([*m as &dyn ModelView]).symmetric();
        EFFECT_BITS
            .iter()
            .filter(|(id, _)| m.effects.get(*id))
            .fold(if two { TWO_ACTUATORS } else { 0 }, |b, (_, bit)| b | bit)
            | bits
    })
}

/// Most response-spectrum periods a lane accumulates (lane.cu: `VS_MAX_OSC`).
pub const MAX_OSC: usize = 128;

/// The first of the specimen's four metrics in the output (lane.cu: `VS_SPECIMEN`).
const OUT_SPECIMEN: usize = 42;

/// Output fields before the oscillator peaks (lane.cu: `VS_OSC_PEAK`).
const OUT_FIXED: usize = OUT_SPECIMEN + 4;

/// Output fields per lane for a run with `n_osc` response-spectrum periods.
pub fn out_fields(n_osc: usize) -> usize {
    OUT_FIXED + n_osc
}

/// Why the CUDA kernel cannot run these models on this reference, or `None` when it can.
pub fn unsupported(models: &[&ModelParams], reference: &Reference) -> Option<String> {
    let covered = |e: EffectId| EFFECT_BITS.iter().any(|(id, _)| *id == e);
    let on: Vec<&str> = EffectId::ALL
        .into_iter()
        .filter(|&e| !covered(e) && models.iter().any(|m| m.effects.get(e)))
        .map(EffectId::name)
        .collect();
    if !on.is_empty() {
        let has: Vec<&str> = EFFECT_BITS.iter().map(|(id, _)| id.name()).collect();
        return Some(format!(
            "the effect{} {} (the CUDA kernel has the baseline and {})",
            if on.len() > 1 { "s" } else { "" },
            on.join(", "),
            has.join(", ")
        ));
    }
    let periods = reference
        .spectrum
        .as_ref()
        .map_or(0, |(s, _)| s.periods.len());
    if periods > MAX_OSC {
        return Some(format!(
            "a response spectrum of {periods} periods (the CUDA kernel takes up to {MAX_OSC})"
        ));
    }
    None
}

/// The parameter records of `models`, field-major (field f of lane l at `f * n + l`).
pub fn pack_params(models: &[&ModelParams]) -> Result<Vec<f64>, SetupError> {
    let n = models.len();
    let mut p = vec![0.0; LANE_FIELDS * n];
    for (l, m) in models.iter().enumerate() {
        if m.controller.f_s != models[0].controller.f_s || m.valve_law != models[0].valve_law {
            return Err(SetupError::NotUniform { lane: l });
        }
        for (f, v) in record(m)?.into_iter().enumerate() {
            p[f * n + l] = v;
        }
    }
    Ok(p)
}

/// One model's parameter record, in lane.cu's field order.
pub fn record(m: &ModelParams) -> Result<[f64; LANE_FIELDS], SetupError> {
    Ok(lane_record(&LaneParams::<1>::new(&[m])?, m))
}

/// The fields of a launch's parameter records that every lane shares, which the kernel reads
/// from its constant `vs_u`; the others it reads from the launch's records of the varying
/// fields alone (lane.cu: `vs_p`).
#[derive(Debug, Clone, PartialEq)]
pub struct Uniform {
    /// Bit f (of word f / 64) set where field f differs between lanes (lane.cu: `VS_VARY0..3`).
    pub vary: [u64; MASK_WORDS],
    /// Every field's value in the first lane (`vs_u`; the varying ones are not read).
    pub values: Vec<f64>,
}

const _: () = assert!(LANE_FIELDS <= MASK_WORDS * 64, "the mask holds 256 fields");

/// Words of the mask of varying fields (lane.cu: `VS_VARY0..3`).
pub const MASK_WORDS: usize = 4;

impl Uniform {
    /// Which fields of `params` (n lanes, field-major, as [`pack_params`] writes them) vary,
    /// comparing bits (so -0.0 and 0.0 differ, and a NaN equals itself).
    pub fn of(params: &[f64], n: usize) -> Uniform {
        let vary = mask((0..LANE_FIELDS).filter(|&f| {
            let lanes = &params[f * n..(f + 1) * n];
            lanes.iter().any(|v| v.to_bits() != lanes[0].to_bits())
        }));
        let values = (0..LANE_FIELDS).map(|f| params[f * n]).collect();
        Uniform { vary, values }
    }

    /// The bits of the fields where `record` differs from `first`.
    pub fn differing(first: &[f64; LANE_FIELDS], record: &[f64; LANE_FIELDS]) -> [u64; MASK_WORDS] {
        mask((0..LANE_FIELDS).filter(|&f| first[f].to_bits() != record[f].to_bits()))
    }

    /// Whether field `f` is read from each lane's record.
    pub fn varies(&self, f: usize) -> bool {
        bit(self.vary, f)
    }

    /// The varying fields, in order (their rows in [`Uniform::compact`]).
    pub fn varying(&self) -> Vec<usize> {
        fields(self.vary)
    }

    /// The records of the varying fields alone, field-major (the kernel's `P`), from the whole
    /// records `params` of n lanes.
    pub fn compact(&self, params: &[f64], n: usize) -> Vec<f64> {
        self.varying()
            .into_iter()
            .flat_map(|f| params[f * n..(f + 1) * n].iter().copied())
            .collect()
    }
}

/// The mask of `fields`: bit f of word f / 64 ([`Uniform::vary`]).
fn mask(fields: impl Iterator<Item = usize>) -> [u64; MASK_WORDS] {
    let mut vary = [0u64; MASK_WORDS];
    for f in fields {
        vary[f / 64] |= 1 << (f % 64);
    }
    vary
}

/// Whether field `f` is set in the mask `vary`.
fn bit(vary: [u64; MASK_WORDS], f: usize) -> bool {
    vary[f / 64] >> (f % 64) & 1 == 1
}

/// The fields set in `vary`, in order (at most [`LANE_FIELDS`]).
pub fn fields(vary: [u64; MASK_WORDS]) -> Vec<usize> {
    (0..LANE_FIELDS).filter(|&f| bit(vary, f)).collect()
}

/// The fields set in either mask.
pub fn union(a: [u64; MASK_WORDS], b: [u64; MASK_WORDS]) -> [u64; MASK_WORDS] {
    std::array::from_fn(|w| a[w] | b[w])
}

/// One lane's record, in lane.cu's field order: the baseline's, then the covered effects'
/// coefficients (each effect's own `lane`, neutral where it is off).
fn lane_record(lp: &LaneParams<1>, m: &ModelParams) -> [f64; LANE_FIELDS] {
    let (v, a, pl, fr, c) = (
        lp.valve.lane(0),
        lp.act.lane(0),
        lp.platen.lane(0),
        lp.friction.lane(0),
        &lp.ctrl[0],
    );
    let mut r = Vec::with_capacity(LANE_FIELDS);
    r.extend([
        v.kw1, v.kw2, v.kw3, v.kw4, v.p_r, v.p_tr2, v.kq1, v.kq2, lp.p_s[0],
    ]);
    r.extend([a.beta, a.a1, a.a2, a.l, a.vd1, a.vd2]);
    r.extend([pl.inv_m, pl.k, pl.c, pl.alpha, pl.mu]);
    r.extend([fr.inv_y, fr.kappa, fr.kappa_neg]);
    let (ff, force) = (&c.feedforward, &c.force);
    r.extend([c.feedback.c_fb, ff.c_d, ff.c_v, ff.c_a, ff.c_j]);
    r.extend([force.c_f, force.hp_b, force.hp_a]);
    r.extend(c.notches.q.iter().flatten());
    r.extend([c.u_lim, c.k_sp, lp.p0[0].0, lp.p0[0].1]);
    use effects::*;
    r.extend(transport_delay::TransportDelay::<1>::new([m]).lane(0));
    r.extend(spool_dynamics::SpoolDynamics::<1>::new([m]).lane(0));
    r.extend(flow_saturation::FlowSaturation::<1>::new([m]).lane(0));
    r.extend(flow_gain::FlowGain::<1>::new([m]).lane(0));
    r.extend(asymmetry::Asymmetry::<1>::new([m]).lane(0));
    r.extend(leakage::Leakage::<1>::new([m]).lane(0));
    r.extend(supply::Supply::<1>::new([m]).lane(0));
    r.extend(seal_friction::SealFriction::<1>::new([m]).lane(0));
    r.extend(compressibility::Compressibility::<1>::new([m]).lane(0));
    r.extend(bulk_curve::BulkCurve::<1>::new([m]).lane(0));
    r.extend(reaction_mass::ReactionMass::<1>::new([m]).lane(0));
    r.extend(hold_down::HoldDown::<1>::new([m]).lane(0));
    r.extend(specimen::Specimen::<1>::new([m]).lane(0));
    r.extend(accel_sensor::AccelSensor::<1>::new([m]).lane(0));
    r.extend(disp_sensor::DispSensor::<1>::new([m]).lane(0));
    r.extend(force_sensor::ForceSensor::<1>::new([m]).lane(0));
    r.extend(building::Building::<1>::new([m]).lane(0));
    r.extend(valve_compensator::ValveCompensator::<1>::new([m]).lane(0));
    r.extend(amplitude_phase::AmplitudePhase::<1>::new([m]).lane(0));
    r.extend(harmonic_cancellation::HarmonicCancellation::<1>::new([m]).lane(0));
    r.extend(adaptive_inverse::AdaptiveInverse::<1>::new([m]).lane(0));
    r.try_into().expect("LANE_FIELDS fields")
}

/// The run every lane shares: its integers (in the kernel's argument order), rate and arrays.
#[derive(Debug, Clone)]
pub struct Shared {
    /// ticks, substeps, window start, window end, has basis, drive, linear valve, oscillators,
    /// reference stride (0: one reference for every lane; else the ticks: one per lane), the
    /// effects' bits ([`EFFECT_BITS`]).
    pub ints: [i64; 10],
    pub f_s: f64,
    /// The reference x, v, a, j per tick (lane after lane when each has its own).
    pub refs: [Vec<f64>; 4],
    /// The open-loop drive per tick (one zero in closed loop).
    pub drive: Vec<f64>,
    /// Per window tick: cos and sin of harmonics 1..9 (one zero without a fundamental).
    pub basis: Vec<f64>,
    /// Per period: the oscillator's [a00, a01, a10, a11, b00, b01, b10, b11] (one zero: none).
    pub osc: Vec<f64>,
}

impl Shared {
    /// The run of `models` on `refs` (one for every lane, or one per lane, which must agree in
    /// rate, length, window, fundamental and spectrum, in closed loop); the checks of
    /// [`simulate::check`] first.
    pub fn new(
        models: &[&ModelParams],
        refs: &[&Reference],
        solver: &Solver,
    ) -> Result<Self, SetupError> {
        let first = models[0];
        simulate::check(first.controller.f_s, refs, solver)?;
        let reference = refs[0];
        let (w0, w1) = reference.window;
        let (drive_code, drive) = match &reference.drive {
            Drive::ClosedLoop => (0, vec![0.0]),
            Drive::ValveCommand(d) => (1, d.clone()),
            Drive::Spool(d) => (2, d.clone()),
        };
        let mut basis = Vec::new();
        if let Some(f0) = reference.fundamental_hz {
            for k in w0..w1 {
                let b = Basis::at(k, reference.f_s, f0);
                basis.extend(b.cos.iter().chain(&b.sin));
            }
        }
        let mut osc = Vec::new();
        if let Some((spec, _)) = &reference.spectrum {
            for o in oscillators(spec, 1.0 / reference.f_s) {
                osc.extend(o.a.iter().flatten().chain(o.b.iter().flatten()));
            }
        }
        let n_osc = osc.len() / 8;
        let linear = first.valve_law == ValveLaw::Linear;
        Ok(Shared {
            ints: [
                reference.len() as i64,
                solver.substeps as i64,
                w0 as i64,
                w1 as i64,
                i64::from(reference.fundamental_hz.is_some()),
                drive_code,
                i64::from(linear),
                n_osc as i64,
                if refs.len() > 1 {
                    reference.len() as i64
                } else {
                    0
                },
                effect_bits(models),
            ],
            f_s: reference.f_s,
            refs: [
                refs.iter().flat_map(|r| r.x.iter().copied()).collect(),
                refs.iter().flat_map(|r| r.v.iter().copied()).collect(),
                refs.iter().flat_map(|r| r.a.iter().copied()).collect(),
                refs.iter().flat_map(|r| r.j.iter().copied()).collect(),
            ],
            drive,
            basis: non_empty(basis),
            osc: non_empty(osc),
        })
    }

    /// Response-spectrum periods accumulated.
    pub fn n_osc(&self) -> usize {
        self.ints[7] as usize
    }
}

/// A device buffer cannot be empty: one zero stands for none.
fn non_empty(v: Vec<f64>) -> Vec<f64> {
    if v.is_empty() {
        vec![0.0]
    } else {
        v
    }
}

/// Turns the kernel's output into [`LaneResult`]s, finished as the CPU kernel does: made once per
/// launch (the response-spectrum oscillators are built here, not per lane).
pub struct Finisher {
    template: MetricsAcc<1>,
    n_osc: usize,
}

impl Finisher {
    /// For a launch on references like `reference` (they share rate and spectrum).
    pub fn new(reference: &Reference, n_osc: usize) -> Self {
        let spectrum = reference.spectrum.as_ref();
        Finisher {
            template: MetricsAcc::<1>::new(spectrum.map(|(s, _)| (s, 1.0 / reference.f_s))),
            n_osc,
        }
    }

    /// Lane `l`'s result from the output `out` (n lanes) on its own `reference`.
    pub fn lane(&self, out: &[f64], n: usize, l: usize, reference: &Reference) -> LaneResult {
        let o = |f: usize| out[f * n + l];
        let status = lane_status(o(0), o(1), o(2), o(3), reference);
        if status != LaneStatus::Ok {
            return LaneResult {
                status,
                metrics: Metrics::NAN,
            };
        }
        let sums = LaneSums {
            n: o(4) as usize,
            max_u: o(5),
            err_a2: o(6),
            err_x2: o(7),
            peak_err_a: o(8),
            peak_err_x: o(9),
            peak: [o(10), o(11), o(12)],
            peak_r: [o(13), o(14), o(15)],
            ar_re: o(16),
            ar_im: o(17),
            xr_re: o(18),
            xr_im: o(19),
            ar2: o(20),
            xr2: o(21),
            x_re: o(22),
            x_im: o(23),
            a_re: std::array::from_fn(|h| o(24 + h)),
            a_im: std::array::from_fn(|h| o(24 + N_HARM + h)),
            osc_peak: (0..self.n_osc).map(|i| o(OUT_FIXED + i)).collect(),
            specimen: std::array::from_fn(|i| o(OUT_SPECIMEN + i)),
        };
        let harmonics = reference
            .fundamental_hz
            .map(|f0| Metrics::highest_harmonic(f0, reference.f_s));
        let target = reference
            .spectrum
            .as_ref()
            .map(|(s, psa)| (s, psa.as_slice()));
        LaneResult {
            status,
            metrics: self
                .template
                .with_sums(&sums)
                .finish(0, harmonics, target)
                .with_specimen(sums.specimen),
        }
    }
}

/// A lane's status from the kernel's status code, failure tick, value and chamber.
fn lane_status(code: f64, tick: f64, value: f64, chamber: f64, r: &Reference) -> LaneStatus {
    let reason = match code as u8 {
        0 => return LaneStatus::Ok,
        1 => Failure::NonFinite,
        2 => Failure::StrokeLimit { disp_m: value },
        // Chambers 1, 2 of actuator 0, then 3, 4 of actuator 1.
        _ => Failure::Pressure {
            actuator: (chamber as usize - 1) / 2,
            chamber: (chamber as usize - 1) % 2 + 1,
            pa: value,
        },
    };
    LaneStatus::Failed {
        time_s: r.time(tick as usize),
        reason,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The union of two masks holds a field set in either or both, word by word.
    #[test]
    fn a_union_holds_the_fields_of_either_mask() {
        let (a, b) = (
            mask([0, 3, 64, 130].into_iter()),
            mask([3, 65, 130].into_iter()),
        );
        assert_eq!(fields(union(a, b)), [0, 3, 64, 65, 130]);
    }

    /// Each effect the CUDA kernel has holds the bit lane.cu gives it (`VS_E_*`, bit i for the
    /// i-th), listed once and in registry order (the order both kernels compose the hooks in),
    /// the two actuators' bit above them; and the record's length is what lane.cu says. An effect
    /// added to the registry and not to lane.cu is not listed, and runs on the CPU.
    #[test]
    fn every_covered_effect_has_the_bit_lane_cu_gives_it() {
        // lane.cu's `VS_E_* = bit` list, in order, the two actuators' bit last.
        let source = SOURCE.replace(' ', "");
        let start = source.find("VS_E_DELAY=").unwrap();
        let end = source[start..].find('}').unwrap() + start;
        let bits: Vec<i64> = source[start..end]
            .split(',')
            .map(|d| d.split('=').nth(1).unwrap().trim().parse().unwrap())
            .collect();
        assert_eq!(bits.len(), EFFECT_BITS.len() + 1);
        for (i, (id, bit)) in EFFECT_BITS.iter().enumerate() {
            assert_eq!((*bit, bits[i]), (1 << i, 1 << i), "{id}");
            if i > 0 {
                assert!(
                    EFFECT_BITS[i - 1].0 < *id,
                    "{id}: listed in registry order, once"
                );
            }
        }
        assert_eq!(TWO_ACTUATORS, 1 << EFFECT_BITS.len());
        assert_eq!(bits[EFFECT_BITS.len()], TWO_ACTUATORS);
        assert!(source.contains("VS_VCOMP=VS_BLD+7+4*10"));
        assert!(source.contains("VS_APC=VS_VCOMP+8"));
        assert!(source.contains("VS_AHC=VS_APC+6"));
        assert!(source.contains("VS_AIC=VS_AHC+6"));
        assert!(source.contains("VS_LANE_FIELDS=VS_AIC+25"));
        let m = ModelParams::default();
        assert_eq!(pack_params(&[&m]).unwrap().len(), LANE_FIELDS);
    }

    /// A field varies when some lane's value differs from the first lane's, bit for bit.
    #[test]
    fn the_shared_fields_are_those_equal_in_every_lane() {
        let a = ModelParams::default();
        let mut b = a.clone();
        b.controller.g_d *= 1.1;
        b.controller.l_a *= 0.9;
        let p = pack_params(&[&a, &b, &a]).unwrap();
        let u = Uniform::of(&p, 3);
        let varying: Vec<usize> = (0..LANE_FIELDS).filter(|&f| u.varies(f)).collect();
        // The displacement gain and the acceleration lead: c_fb and c_a, fields 23 and 26.
        assert_eq!(varying, [23, 26]);
        assert_eq!(u.values.len(), LANE_FIELDS);
        assert_eq!(u.values[9], p[9 * 3], "beta, shared");
        assert_eq!(u.compact(&p, 3), [&p[69..72], &p[78..81]].concat());
        let (ra, rb) = (record(&a).unwrap(), record(&b).unwrap());
        assert_eq!(Uniform::differing(&ra, &rb), u.vary);
        assert_eq!(
            Uniform::of(&pack_params(&[&a]).unwrap(), 1).vary,
            [0; MASK_WORDS]
        );
    }
}
