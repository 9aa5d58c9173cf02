//! Offline passes of a test (issue 52): the same run repeated on the virtual table, each pass's
//! learned inverse (`adaptive_inverse`: its taps at the pass's last tick, the run's `aic_w_*`
//! channels) the next pass's inverse in use, as a lab would learn a compensator in passes before
//! the real test. The first pass starts from the model's taps.

use crate::runs::single::{self, SimOutcome};
use crate::runs::spec::SimSpec;
use vshake_kernel::effects::{adaptive_inverse, EffectId};
use vshake_kernel::excitation::Reference;
use vshake_kernel::simulate::{LaneStatus, SetupError};

/// The passes of a run: each one's outcome, and the model the last pass learned (its taps in
/// `[model.adaptive_inverse]`), to run the real test with.
pub struct Passes {
    pub runs: Vec<SimOutcome>,
    pub learned: SimSpec,
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
    let mut runs = Vec::with_capacity(n);
    let mut current = spec.clone();
    for _ in 0..n {
        let out = single::run_sim(&current, reference)?;
        let taps = learned_taps(&out);
        runs.push(out);
        match taps {
            Some(t) => current = with_taps(&current, &t),
            None => break,
        }
    }
    Ok(Passes {
        runs,
        learned: current,
    })
}
