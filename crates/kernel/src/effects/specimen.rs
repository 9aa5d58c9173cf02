//! Effect `specimen`: a linear structure bolted to the platen, as up to three modes, each a mass
//! on a spring and a dashpot relative to the platen (modal mass m_i, natural frequency f_i,
//! damping ratio ζ_i; a mode with m_i = 0 is absent):
//!
//! ```text
//! ü_i = −ω_i² u_i − 2 ζ_i ω_i u̇_i − a,          ω_i = 2π f_i,
//! F_specimen = Σ_i m_i (ω_i² u_i + 2 ζ_i ω_i u̇_i)   (the base shear, on the platen)
//! ```
//!
//! with u_i the mode's displacement relative to the platen and a the platen's acceleration. A
//! rigid mass on the platen is `platen.m`; the modes are what moves on it (for a shear building,
//! its effective modal masses). Its signature: the platen carries a force that resonates at f_i —
//! the acceleration drops near the specimen's frequency (an anti-resonance of the table) and the
//! actuator force grows — increasingly with the modal mass. A diagnosis frees mode 1 and scans its
//! frequency (a resonance makes the fit non-convex in it); forward selection may add mode 2, then
//! mode 3, the same way.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, PlantView, Stage};
use crate::param_table::{params, Range};

/// Start frequencies a diagnosis scans for a mode, Hz [chosen: 12 % apart (a 5 %-damped mode's
/// half-power band is 10 % wide, so the scan lands in its valley) over the band where a structure
/// on a shake table has its modes and the table's tests have energy].
const SCAN_HZ: &[f64] = &[
    0.5, 0.56, 0.63, 0.7, 0.79, 0.88, 0.99, 1.11, 1.24, 1.39, 1.55, 1.74, 1.95, 2.18, 2.44, 2.74,
    3.07, 3.43, 3.84, 4.31, 4.82, 5.4, 6.05, 6.78, 7.59, 8.5, 9.52, 10.7, 11.9, 13.4, 15.0, 16.8,
    18.8, 21.0, 23.6,
];

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "specimen",
    summary: "a linear structure on the platen: up to three modes (modal mass, frequency, damping)",
    params: Params::FIELDS,
    stages: &[
        Stage {
            label: "mode 1",
            free: &["m1", "f1", "zeta1"],
            scan: Some(("f1", SCAN_HZ)),
            size: Some("m1"),
            shape: Some(("zeta1", &[0.1, 0.3])),
            start: &[],
        },
        Stage {
            label: "mode 2",
            free: &["m2", "f2", "zeta2"],
            scan: Some(("f2", SCAN_HZ)),
            size: Some("m2"),
            shape: Some(("zeta2", &[0.1, 0.3])),
            // [chosen] A further mode starts at a quarter of mode 1's default mass.
            start: &[("m2", 5.0e3)],
        },
        Stage {
            label: "mode 3",
            free: &["m3", "f3", "zeta3"],
            scan: Some(("f3", SCAN_HZ)),
            size: Some("m3"),
            shape: Some(("zeta3", &[0.1, 0.3])),
            start: &[("m3", 5.0e3)],
        },
    ],
};

params! {
    /// Effect `specimen`: a linear structure on the platen, up to three modes relative to it,
    /// ü_i = −ω_i² u_i − 2ζ_iω_i u̇_i − a; the base shear Σ m_i(ω_i² u_i + 2ζ_iω_i u̇_i) acts on
    /// the platen. A mode with zero mass is absent.
    pub struct Params {
        m1: "kg", "kg", 20.0e3, Range::ge(0.0), Chosen,
            "Modal mass of mode 1 [chosen: 20 t, a mid-size specimen of the LHPOST (payload up to 2 000 t)].";
        f1: "Hz", "hz", 3.0, Range::closed(0.1, 100.0), Chosen,
            "Natural frequency of mode 1 (fixed base) [chosen: a low-rise structure].";
        zeta1: "-", "", 0.03, Range::closed(0.0, 1.0), Chosen,
            "Damping ratio of mode 1 [chosen: 3 %, a structure in its elastic range].";
        m2: "kg", "kg", 0.0, Range::ge(0.0), Chosen,
            "Modal mass of mode 2; 0: no second mode [chosen].";
        f2: "Hz", "hz", 9.0, Range::closed(0.1, 100.0), Chosen,
            "Natural frequency of mode 2 [chosen: three times mode 1, a shear building's ratio].";
        zeta2: "-", "", 0.03, Range::closed(0.0, 1.0), Chosen,
            "Damping ratio of mode 2 [chosen].";
        m3: "kg", "kg", 0.0, Range::ge(0.0), Chosen,
            "Modal mass of mode 3; 0: no third mode [chosen].";
        f3: "Hz", "hz", 15.0, Range::closed(0.1, 100.0), Chosen,
            "Natural frequency of mode 3 [chosen: five times mode 1].";
        zeta3: "-", "", 0.03, Range::closed(0.0, 1.0), Chosen,
            "Damping ratio of mode 3 [chosen].";
    }
}

/// Modes of the structure.
pub const MODES: usize = 3;
/// State indices: mode i's displacement relative to the platen at 2i, its velocity at 2i + 1.
pub const U: [usize; MODES] = [0, 2, 4];
pub const UD: [usize; MODES] = [1, 3, 5];

pub struct Specimen<const N: usize> {
    /// Per mode: modal mass (0 where the effect is off or the mode absent), ω², 2ζω.
    m: [[f64; N]; MODES],
    w2: [[f64; N]; MODES],
    two_zw: [[f64; N]; MODES],
}

impl<const N: usize> LibraryEffect<N> for Specimen<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        let q = p.map(Params::of);
        let modes = |l: usize| {
            let q = q[l];
            [
                (q.m1, q.f1, q.zeta1),
                (q.m2, q.f2, q.zeta2),
                (q.m3, q.f3, q.zeta3),
            ]
        };
        let w = |l: usize, i: usize| 2.0 * std::f64::consts::PI * modes(l)[i].1;
        Specimen {
            m: std::array::from_fn(|i| std::array::from_fn(|l| on[l] * modes(l)[i].0)),
            w2: std::array::from_fn(|i| std::array::from_fn(|l| w(l, i) * w(l, i))),
            two_zw: std::array::from_fn(|i| std::array::from_fn(|l| 2.0 * modes(l)[i].2 * w(l, i))),
        }
    }
}

impl<const N: usize> Specimen<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (`crates/kernel/src/cuda/lane.cu`):
    /// per mode, the modal mass (0 where the effect is off), ω² and 2ζω.
    pub fn lane(&self, l: usize) -> [f64; 3 * MODES] {
        std::array::from_fn(|f| [self.m, self.w2, self.two_zw][f % 3][f / 3][l])
    }
}

impl<const N: usize> Effect<N> for Specimen<N> {
    type State = [[f64; N]; 2 * MODES];
    const HYDRAULIC: bool = false; // a force on the platen alone

    fn initial_state(&self) -> Self::State {
        [[0.0; N]; 2 * MODES]
    }

    /// The base shear of the modes on the platen, N.
    #[inline(always)]
    fn extra_force(&self, c: hook::Motion, s: &Self::State) -> f64 {
        let l = c.lane;
        (0..MODES)
            .map(|i| self.m[i][l] * (self.w2[i][l] * s[U[i]][l] + self.two_zw[i][l] * s[UD[i]][l]))
            .sum()
    }

    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        for i in 0..MODES {
            for l in 0..N {
                ds[U[i]][l] = s[UD[i]][l];
                ds[UD[i]][l] =
                    -self.w2[i][l] * s[U[i]][l] - self.two_zw[i][l] * s[UD[i]][l] - plant.accel[l];
            }
        }
    }
}
