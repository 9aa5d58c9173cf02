//! Dense output: the plant's channels at arbitrary times, e.g. at the samples of a measured file
//! whose rate is not the controller's.
//!
//! The controller holds its command over each tick [t_k, t_{k+1}), so inside a tick the plant is
//! an ODE with a constant input. For a time τ in the tick, the lane kernel takes the plant state
//! at the RK4 substep node t_j ≤ τ before it and integrates it to τ by one RK4 step of length
//! τ − t_j < h (the command held), then evaluates the channels there: the acceleration from the
//! right-hand side, the force from the pressures, the stroke and spool from the effects
//! ([`super::simulate::Observer::sample`]). Its accuracy is the integrator's own (a shorter step
//! of the same method), and the channels follow the model exactly where they are not smooth: the
//! viscous damping C·|v|^½ puts a square-root cusp into the acceleration at every velocity
//! reversal, which no interpolation between nodes resolves. A time on a node (to 1e-9 of a
//! substep) takes the node itself, so a file sampled at the controller's own ticks reads back
//! the tick values bit for bit. It costs four right-hand sides per sample off the nodes.
//! [chosen: integrating to the sample rather than band-limited resampling of the tick history:
//! no samples are needed beyond the run's ends, it is exact at the ticks, and it is as accurate
//! as the run.]

use super::simulate::{Observer, TickView};
use super::state::idx;

/// The channels a [`Resampler`] keeps, in the order of [`Resampler::channel`].
pub const CHANNELS: [&str; 8] = [
    "accel_mps2",
    "disp_m",
    "force_n",
    "p1_pa",
    "p2_pa",
    "valve_cmd_v",
    "spool_m",
    "vel_mps",
];

/// Index of a channel in [`CHANNELS`].
pub mod ch {
    pub const ACCEL: usize = 0;
    pub const DISP: usize = 1;
    pub const FORCE: usize = 2;
    pub const P1: usize = 3;
    pub const P2: usize = 4;
    pub const VALVE_CMD: usize = 5;
    pub const SPOOL: usize = 6;
    pub const VEL: usize = 7;
}

const C: usize = CHANNELS.len();

/// Collects every lane's channels at requested model times (s, ascending, ≥ 0): the run must last
/// at least one tick beyond the tick of the last time.
pub struct Resampler<const N: usize> {
    times: Vec<f64>,
    out: Vec<[[f64; N]; C]>,
}

impl<const N: usize> Resampler<N> {
    pub fn new(times: &[f64]) -> Self {
        debug_assert!(times.windows(2).all(|w| w[0] <= w[1]), "times ascending");
        Resampler {
            times: times.to_vec(),
            out: Vec::with_capacity(times.len()),
        }
    }
    /// Samples produced so far (all of them once the run has passed the last time).
    pub fn len(&self) -> usize {
        self.out.len()
    }
    pub fn is_empty(&self) -> bool {
        self.out.is_empty()
    }
    /// Whether every requested time has its sample.
    pub fn complete(&self) -> bool {
        self.out.len() == self.times.len()
    }
    /// Channel `c` ([`ch`]) of lane `l` at every requested time produced.
    pub fn channel(&self, c: usize, l: usize) -> Vec<f64> {
        self.out.iter().map(|row| row[c][l]).collect()
    }
    /// Channel `c` of every lane, in one pass over the samples (what N calls of
    /// [`Resampler::channel`] give, without reading the samples N times).
    pub fn lanes(&self, c: usize) -> [Vec<f64>; N] {
        let mut out: [Vec<f64>; N] = std::array::from_fn(|_| Vec::with_capacity(self.out.len()));
        for row in &self.out {
            for (o, &v) in out.iter_mut().zip(&row[c]) {
                o.push(v);
            }
        }
        out
    }
}

impl<const N: usize> Observer<N> for Resampler<N> {
    #[inline(always)]
    fn tick(&mut self, _v: &TickView<'_, N>) {}

    fn probe_times(&self) -> &[f64] {
        &self.times
    }

    fn probe(&mut self, v: &TickView<'_, N>) {
        let mut row = [[0.0; N]; C];
        row[ch::ACCEL] = *v.a;
        row[ch::DISP] = *v.x;
        row[ch::FORCE] = *v.f;
        row[ch::P1] = v.state[idx::P1[0]];
        row[ch::P2] = v.state[idx::P2[0]];
        row[ch::VALVE_CMD] = *v.u;
        row[ch::SPOOL] = *v.spool;
        row[ch::VEL] = v.state[idx::VEL];
        self.out.push(row);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Baseline;
    use crate::excitation::Sine;
    use crate::params::ModelParams;
    use crate::simulate::{run, LaneParams, Solver};

    fn sampled(times: &[f64], substeps: usize) -> Resampler<1> {
        let p = ModelParams::default();
        let lp = LaneParams::<1>::new(&[&p]).unwrap();
        let r = Sine {
            freq_hz: 8.0,
            amp_m: Sine::amp_from_g(1.5, 8.0),
            taper_s: 0.5,
            duration_s: 1.5,
            window_cycles: None,
        }
        .reference(1024.0);
        let mut rs = Resampler::<1>::new(times);
        assert!((rs.is_empty() && !rs.complete()) || times.is_empty());
        run(&lp, &Baseline, &r, &Solver { substeps }, &mut rs).unwrap();
        assert!(rs.complete());
        assert_eq!(rs.len(), times.len(), "a sample for every time");
        assert_eq!(rs.is_empty(), times.is_empty());
        rs
    }

    /// Max |difference| of channel `c` between two runs' samples, over the channel's rms.
    fn rel_err(a: &Resampler<1>, b: &Resampler<1>, c: usize) -> f64 {
        let (x, y) = (a.channel(c, 0), b.channel(c, 0));
        let rms = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
        x.iter()
            .zip(&y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
            / rms
    }

    /// [`Resampler::lanes`] gives each lane's channel as [`Resampler::channel`] does.
    #[test]
    fn every_lane_at_once_equals_each_lane_alone() {
        let mut rs = Resampler::<3>::new(&[0.0, 0.1, 0.2]);
        for k in 0..3 {
            let mut row = [[0.0; 3]; C];
            row[ch::DISP] = [k as f64, 10.0 + k as f64, 20.0 + k as f64];
            rs.out.push(row);
        }
        let all = rs.lanes(ch::DISP);
        for (l, lane) in all.iter().enumerate() {
            assert_eq!(*lane, rs.channel(ch::DISP, l));
            assert_eq!(lane[2], 10.0 * l as f64 + 2.0);
        }
    }

    /// Samples at 500 Hz (no common tick with 1024 Hz) from 8 substeps against the
    /// same run at 256 substeps: they agree as closely as the two runs' tick values do (the
    /// integrator's own convergence), far below any sensor noise.
    #[test]
    fn off_tick_samples_are_as_accurate_as_the_ticks() {
        let times: Vec<f64> = (0..700).map(|n| n as f64 / 500.0).collect();
        let ticks: Vec<f64> = (0..1430).map(|k| k as f64 / 1024.0).collect();
        let (a, b) = (sampled(&times, 8), sampled(&times, 256));
        let (ta, tb) = (sampled(&ticks, 8), sampled(&ticks, 256));
        for c in [ch::ACCEL, ch::DISP, ch::FORCE, ch::P1, ch::VEL] {
            let (off, on) = (rel_err(&a, &b, c), rel_err(&ta, &tb, c));
            assert!(
                off < 1e-5 && off < 3.0 * on.max(1e-9),
                "{}: off the ticks {off:e}, on the ticks {on:e}",
                CHANNELS[c]
            );
        }
        // The held valve command is the tick's value, exactly, at every substep count.
        let (u8, u256) = (a.channel(ch::VALVE_CMD, 0), b.channel(ch::VALVE_CMD, 0));
        let u_ticks = sampled(
            &times
                .iter()
                .map(|t| (t * 1024.0).floor() / 1024.0)
                .collect::<Vec<_>>(),
            8,
        )
        .channel(ch::VALVE_CMD, 0);
        assert_eq!(u8, u_ticks);
        assert!(
            u8.iter().zip(&u256).all(|(p, q)| (p - q).abs() < 1e-4),
            "the held commands of both runs agree to their convergence"
        );
    }

    /// Off the ticks, the effects' states are carried to the sample's time too: with a specimen
    /// (whose modes push on the platen, so the acceleration reads its states at once), samples
    /// at 500 Hz from 8 substeps agree with 256 substeps as closely as the ticks do.
    #[test]
    fn off_tick_samples_carry_the_effects_states() {
        use crate::effects::effect_set;
        let mut p = ModelParams::default();
        p.effects.specimen = true;
        for (path, v) in [("specimen.m1", 60_000.0), ("specimen.f1", 4.5)] {
            ModelParams::lookup(path).unwrap().set(&mut p, v);
        }
        let lp = LaneParams::<1>::new(&[&p]).unwrap();
        let set = effect_set::<1>(&[&p]);
        let r = Sine {
            freq_hz: 3.0,
            amp_m: Sine::amp_from_g(1.0, 3.0),
            taper_s: 0.5,
            duration_s: 1.5,
            window_cycles: None,
        }
        .reference(1024.0);
        let sampled = |times: &[f64], substeps| {
            let mut rs = Resampler::<1>::new(times);
            run(&lp, &set, &r, &Solver { substeps }, &mut rs).unwrap();
            assert_eq!(rs.len(), times.len());
            rs
        };
        let times: Vec<f64> = (0..700).map(|n| n as f64 / 500.0).collect();
        let ticks: Vec<f64> = (0..1430).map(|k| k as f64 / 1024.0).collect();
        let (a, b) = (sampled(&times, 8), sampled(&times, 256));
        let (ta, tb) = (sampled(&ticks, 8), sampled(&ticks, 256));
        let (off, on) = (rel_err(&a, &b, ch::ACCEL), rel_err(&ta, &tb, ch::ACCEL));
        assert!(
            off < 1e-5 && off < 3.0 * on.max(1e-9),
            "accel: off the ticks {off:e}, on the ticks {on:e}"
        );
    }

    /// Times on the ticks read back the tick values bit for bit, whatever else is sampled.
    #[test]
    fn tick_times_are_exact() {
        struct Ticks(Vec<[f64; 3]>);
        impl Observer<1> for Ticks {
            fn tick(&mut self, v: &TickView<'_, 1>) {
                self.0.push([v.a[0], v.x[0], v.f[0]]);
            }
        }
        let p = ModelParams::default();
        let lp = LaneParams::<1>::new(&[&p]).unwrap();
        let r = Sine {
            freq_hz: 8.0,
            amp_m: Sine::amp_from_g(1.5, 8.0),
            taper_s: 0.5,
            duration_s: 1.5,
            window_cycles: None,
        }
        .reference(1024.0);
        let mut ticks = Ticks(Vec::new());
        run(&lp, &Baseline, &r, &Solver::default(), &mut ticks).unwrap();
        let mut mixed: Vec<f64> = (0..1500)
            .flat_map(|k| [k as f64 / 1024.0, (k as f64 + 0.3) / 1024.0])
            .collect();
        mixed.truncate(2 * 1499);
        let both = sampled(&mixed, Solver::default().substeps);
        for (c, ci) in [ch::ACCEL, ch::DISP, ch::FORCE].into_iter().enumerate() {
            let y = both.channel(ci, 0);
            for k in 0..1499 {
                assert_eq!(
                    ticks.0[k][c].to_bits(),
                    y[2 * k].to_bits(),
                    "{} at tick {k}",
                    CHANNELS[ci]
                );
            }
        }
    }
}
