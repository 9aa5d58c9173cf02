//! The measurement chain of one recorded channel, shared by the effects `accel_sensor`,
//! `disp_sensor` and `force_sensor`: the sensor and its anti-alias filter as a second-order
//! low-pass (corner f_c, damping ζ), then a pure delay τ (conversion, buffering, a clock offset):
//!
//! ```text
//! ÿ = ω²(u − y) − 2ζω ẏ,   ω = 2π f_c;     recorded = y(t − τ)
//! ```
//!
//! with u the channel as the plant has it. It changes what the data-acquisition system records
//! (histories, compared samples, metrics), not the plant: the controller's feedback is the
//! plant's.
//!
//! The delay is realised by its (2,2) Padé all-pass, τ²/12·z̈ + τ/2·ż + z = y, recorded
//! = y − τ·ż (exact magnitude; phase error below 1e-6 rad at ωτ = 0.3), for τ ≥ [`TAU_MIN`]. Its
//! poles grow as √12/τ, so a shorter delay is realised by its Taylor series y − τẏ + τ²ÿ/2 (error
//! (ωτ)³/6, below 4e-5 at 20 Hz and τ = 0.5 ms) [chosen: the Padé poles of a shorter delay leave
//! the stability region of RK4 at the default 4 substeps per tick].

use super::PlantView;

/// Shortest delay realised by the Padé states, s (see the module docs).
pub const TAU_MIN: f64 = 0.5e-3;

/// State indices: the low-pass output and its rate, the Padé states.
const Y: usize = 0;
const YD: usize = 1;
const Z: usize = 2;
const ZD: usize = 3;

/// Its states per lane.
pub type State<const N: usize> = [[f64; N]; 4];

/// One channel's chain for N lanes.
pub struct Chain<const N: usize> {
    /// 1 where the effect is on, 0 where it is off (the recorded channel is then the plant's).
    on: [f64; N],
    w2: [f64; N],
    two_zw: [f64; N],
    tau: [f64; N],
    /// 1 where the delay is realised by the Padé states, 0 by its Taylor series.
    pade: [f64; N],
    /// 12/τ² and 6/τ where the Padé states run, 0 elsewhere (they then stay at rest).
    k12: [f64; N],
    k6: [f64; N],
}

impl<const N: usize> Chain<N> {
    /// The chain of each lane from (f_c, ζ, τ) where `on` is 1.
    pub fn new(on: [f64; N], lanes: [(f64, f64, f64); N]) -> Self {
        let w = lanes.map(|(f, _, _)| 2.0 * std::f64::consts::PI * f);
        let tau = lanes.map(|(_, _, t)| t);
        let pade: [f64; N] = tau.map(|t| if t >= TAU_MIN { 1.0 } else { 0.0 });
        Chain {
            on,
            w2: w.map(|w| w * w),
            two_zw: std::array::from_fn(|l| 2.0 * lanes[l].1 * w[l]),
            tau,
            pade,
            k12: std::array::from_fn(|l| {
                if pade[l] > 0.0 {
                    12.0 / (tau[l] * tau[l])
                } else {
                    0.0
                }
            }),
            k6: std::array::from_fn(|l| if pade[l] > 0.0 { 6.0 / tau[l] } else { 0.0 }),
        }
    }

    /// The derivatives of the chain's states driven by the plant's channel `u`.
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`).
    pub fn lane(&self, l: usize) -> [f64; 7] {
        [
            self.on[l],
            self.w2[l],
            self.two_zw[l],
            self.tau[l],
            self.pade[l],
            self.k12[l],
            self.k6[l],
        ]
    }

    #[inline(always)]
    pub fn derivs(&self, u: &[f64; N], s: &State<N>, ds: &mut State<N>) {
        for l in 0..N {
            ds[Y][l] = s[YD][l];
            ds[YD][l] = self.w2[l] * (u[l] - s[Y][l]) - self.two_zw[l] * s[YD][l];
            ds[Z][l] = s[ZD][l];
            ds[ZD][l] = self.k12[l] * (s[Y][l] - s[Z][l]) - self.k6[l] * s[ZD][l];
        }
    }

    /// The recorded value of lane `l` whose plant value is `u`.
    #[inline(always)]
    pub fn recorded(&self, l: usize, u: f64, s: &State<N>) -> f64 {
        let (y, yd, t) = (s[Y][l], s[YD][l], self.tau[l]);
        let pade = y - t * s[ZD][l];
        let ydd = self.w2[l] * (u - y) - self.two_zw[l] * yd;
        let taylor = y - t * yd + 0.5 * t * t * ydd;
        let chain = taylor + self.pade[l] * (pade - taylor);
        u + self.on[l] * (chain - u)
    }
}

/// The plant's value of recorded channel `c` ([`super::SENSED`] order) in a view of the plant.
#[inline(always)]
pub fn input<'a, const N: usize>(plant: &'a PlantView<'_, N>, c: usize) -> &'a [f64; N] {
    match c {
        0 => plant.accel,
        1 => plant.stroke,
        _ => plant.f_act,
    }
}

/// The effect type of one channel's chain: `sensor_effect!(AccelSensor, 0)` in a file that
/// defines `Params` (`f_c`, `zeta`, `delay`) by `params!`.
macro_rules! sensor_effect {
    ($Type:ident, $channel:expr) => {
        /// The chain of this channel (see `sensor_chain`).
        pub struct $Type<const N: usize>(super::sensor_chain::Chain<N>);

        impl<const N: usize> super::LibraryEffect<N> for $Type<N> {
            fn new(p: [&dyn super::ModelView; N]) -> Self {
                let on = super::lane_mask::<N, Self>(&p);
                let lanes = p.map(|m| {
                    let q = Params::of(m);
                    (q.f_c, q.zeta, q.delay)
                });
                $Type(super::sensor_chain::Chain::new(on, lanes))
            }
        }

        impl<const N: usize> $Type<N> {
            /// Lane `l`'s coefficients in the order the CUDA kernel reads them.
            pub fn lane(&self, l: usize) -> [f64; 7] {
                self.0.lane(l)
            }
        }

        impl<const N: usize> super::Effect<N> for $Type<N> {
            type State = super::sensor_chain::State<N>;
            const HYDRAULIC: bool = false; // the recording alone

            fn initial_state(&self) -> Self::State {
                [[0.0; N]; 4]
            }

            #[inline(always)]
            fn derivs(
                &self,
                plant: &super::PlantView<'_, N>,
                s: &Self::State,
                ds: &mut Self::State,
            ) {
                self.0
                    .derivs(super::sensor_chain::input(plant, $channel), s, ds)
            }

            #[inline(always)]
            fn sensed(&self, c: $crate::effects::hook::Sensed, s: &Self::State) -> [f64; 3] {
                let mut out = c.raw;
                out[$channel] = self.0.recorded(c.lane, c.raw[$channel], s);
                out
            }
        }
    };
}
pub(crate) use sensor_effect;
