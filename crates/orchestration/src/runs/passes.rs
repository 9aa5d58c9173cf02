//! Offline passes of a test (issue 52): the same run repeated on the virtual table, each pass's
//! learned inverse (`adaptive_inverse`: its taps at the pass's last tick, the run's `aic_w_*`
//! channels) the next pass's inverse in use, as a lab would learn a compensator in passes before
//! the real test. The first pass starts from the model's taps. The inverse to run the real test
//! with is the one the best pass used: a pass's fit is of the loop under that pass's drive, and a
//! later pass is not always better (on some records the error rises again after the second).

use crate::runs::single::{self, SimOutcome};
use crate::runs::spec::SimSpec;
use vshake_kernel::effects::{adaptive_inverse, EffectId};
use vshake_kernel::excitation::Reference;
use vshake_kernel::simulate::{LaneStatus, SetupError};

/// The passes of a run: each one's outcome and the spec it ran (its inverse in use).
pub struct Passes {
    pub runs: Vec<SimOutcome>,
    pub used: Vec<SimSpec>,
}

impl Passes {
    /// The pass with the lowest rms acceleration error (its inverse in use is the one to run the
    /// real test with; a later pass is not always better); None where every pass failed.
    pub fn best(&self) -> Option<usize> {
        let error = |out: &SimOutcome| {
            let ok = out.result.status == LaneStatus::Ok;
            let m = out.result.metrics.columns_for(false);
            let e = m
                .iter()
                .find(|(n, _)| *n == "rms_err_accel_ratio")
                .map(|(_, v)| *v);
            e.filter(|v| ok && v.is_finite())
        };
        let errors = self
            .runs
            .iter()
            .enumerate()
            .filter_map(|(i, r)| Some((i, error(r)?)));
        errors.min_by(|a, b| a.1.total_cmp(&b.1)).map(|(i, _)| i)
    }
}

/// The taps a run learned: its `aic_w_*` channels at the last tick (None where the compensator
/// was off or the run failed).
pub fn learned_taps(out: &SimOutcome) -> Option<[f64; adaptive_inverse::TAPS]> {
    if out.result.status != LaneStatus::Ok {
        return None;
    }
    let mut taps = [0.0; adaptive_inverse::TAPS];
    for (w, name) in taps.iter_mut().zip(adaptive_inverse::LEARNED) {
        *w = *out.history.channel(name)?.last()?;
    }
    Some(taps)
}

/// `spec` with `adaptive_inverse`'s taps in use set to `taps`.
pub fn with_taps(spec: &SimSpec, taps: &[f64; adaptive_inverse::TAPS]) -> SimSpec {
    let mut next = spec.clone();
    let id = EffectId::AdaptiveInverse;
    let table = next.model.effect_params.table_mut(id);
    for (i, field) in id.info().params.iter().enumerate() {
        if let Some(k) = adaptive_inverse::LEARNED
            .iter()
            .position(|n| n[4..] == field.name[..])
        {
            table.set_field(i, taps[k]);
        }
    }
    next
}

/// Runs `n` passes of `spec` against `reference`, each from the last one's learned taps; stops
/// early where a pass fails (its outcome is the last).
pub fn passes(spec: &SimSpec, reference: &Reference, n: usize) -> Result<Passes, SetupError> {
    let (mut runs, mut used) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut current = spec.clone();
    for _ in 0..n {
        let out = single::run_sim(&current, reference)?;
        let taps = learned_taps(&out);
        runs.push(out);
        used.push(current.clone());
        match taps {
            Some(t) => current = with_taps(&current, &t),
            None => break,
        }
    }
    Ok(Passes { runs, used })
}
