//! Effect `building`: a shear building of 1–10 storeys on the platen (docs/model.md, "The
//! building"), whose storeys are linear, bilinear (kinematic hardening) or Bouc–Wen. Floor i
//! (mass m_i) moves by u_i relative to the platen; storey i's drift is d_i = u_i − u_{i−1}
//! (u_0 = 0) and its shear V_i = R_i + c_i ḋ_i. With a the platen's acceleration:
//!
//! ```text
//! m_i (ü_i + a) = −V_i + V_{i+1}        (V_{N+1} = 0)
//! R_i = α k_i d_i + (1 − α) r_i          r_i: the storey's hysteretic force, N
//! ṙ_i = k_i ḋ_i g_i                      (linear: g = 1; bilinear: g = 0 while |r_i| is at F_y,i
//!                                         and the drift moves away; Bouc–Wen, z = r/F_y:
//!                                         g = A − |z|^n (β + γ sgn(ḋ z)))
//! c_i = (2ζ/ω_1) k_i                     (stiffness-proportional damping: mode 1 has ζ)
//! F_building = V_1                       (the base shear, on the platen)
//! ```
//!
//! The bilinear law's force is r clamped to ±F_y (an integration step may carry r a little past
//! it; the clamp keeps the force on the yield line). Bouc–Wen with A = 1, β + γ = 1 keeps
//! |z| ≤ 1, and n → ∞ approaches the bilinear law. With every storey linear the building is the
//! modal specimen of its modes ([`modes`]; `tests/building.rs` checks it). Its signature on the
//! table: the modal specimen's anti-resonance, and once a storey yields, a softening (the
//! frequency falls) with odd harmonics and a loss of the force at the peaks.

use super::{hook, Effect, EffectInfo, LibraryEffect, ModelView, PlantView, Stage};
use crate::metrics::SpecimenAcc;
use crate::param_table::{params, ParamIssue, Range};

/// Most storeys.
pub const MAX_STOREYS: usize = 10;

/// The effect's entry in the library.
pub const INFO: EffectInfo = EffectInfo {
    name: super::module_name(module_path!()),
    family: "specimen",
    summary:
        "a shear building of 1-10 storeys (linear, bilinear or Bouc-Wen storeys) on the platen",
    params: Params::FIELDS,
    // [chosen] A fit frees first the first storey's stiffness and yield force: the storey that
    // yields first under a base motion, and the one the base shear measures. A diagnosis's
    // forward selection may then add every other storey's stiffness and yield force and the
    // damping (a building whose storeys all differ from the design); a storey above the
    // building's `storeys` is not freed (`unused`).
    stages: &[
        Stage {
            label: "storey 1",
            free: &["k1", "fy1"],
            scan: None,
            size: None,
            shape: None,
            start: &[],
        },
        Stage {
            label: "every storey and the damping",
            free: &[
                "k2", "k3", "k4", "k5", "k6", "k7", "k8", "k9", "k10", "fy2", "fy3", "fy4", "fy5",
                "fy6", "fy7", "fy8", "fy9", "fy10", "zeta",
            ],
            scan: None,
            size: None,
            shape: None,
            start: &[],
        },
    ],
};

params! {
    /// Effect `building`: a shear building on the platen, storeys 1 (bottom) to `storeys`; the
    /// parameters of storeys above `storeys` are not used.
    pub struct Params {
        storeys: "-", "", 3.0, Range::closed(1.0, 10.0), Chosen,
            "Number of storeys, a whole number 1-10 [chosen: the 3-storey frame of docs/guide.md].";
        law: "-", "", 1.0, Range::closed(0.0, 2.0), Chosen,
            "Storey law: 0 linear, 1 bilinear (kinematic hardening), 2 Bouc-Wen [chosen: bilinear, a steel frame's].";
        alpha: "-", "", 0.05, Range::closed(0.0, 1.0), Chosen,
            "Post-yield stiffness ratio of every storey [chosen: 5 %, a steel moment frame's].";
        zeta: "-", "", 0.02, Range::closed(0.0, 0.5), Chosen,
            "Damping ratio of mode 1 (stiffness-proportional damping from the initial stiffness: mode j has zeta f_j/f_1) [chosen: 2 %, a steel frame].";
        height: "m", "m", 3.0, Range::gt(0.0), Chosen,
            "Storey height, for the drift ratio only [chosen: 3 m].";
        bw_a: "-", "", 1.0, Range::gt(0.0), Literature,
            "Bouc-Wen A [Wen, J. Eng. Mech. Div. ASCE 102(2), 1976; A = 1: the initial stiffness is k].";
        bw_beta: "-", "", 0.5, Range::any(), Literature,
            "Bouc-Wen beta [Wen 1976; beta = gamma = 0.5 with A = 1: |z| <= 1].";
        bw_gamma: "-", "", 0.5, Range::any(), Literature,
            "Bouc-Wen gamma [Wen 1976].";
        bw_n: "-", "", 2.0, Range::closed(1.0, 50.0), Literature,
            "Bouc-Wen exponent n: the sharpness of the yield (n -> inf: bilinear) [Wen 1976; 2].";
        m1: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 1 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m2: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 2 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m3: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 3 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m4: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 4 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m5: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 5 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m6: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 6 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m7: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 7 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m8: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 8 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m9: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 9 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        m10: "kg", "kg", 30.0e3, Range::gt(0.0), Chosen,
            "Mass of floor 10 [chosen: 30 t, a floor of a reduced-scale steel frame on the LHPOST].";
        k1: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 1 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k2: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 2 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k3: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 3 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k4: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 4 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k5: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 5 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k6: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 6 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k7: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 7 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k8: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 8 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k9: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 9 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        k10: "N/m", "n_per_m", 24.0e6, Range::gt(0.0), Chosen,
            "Initial (elastic) stiffness of storey 10 [chosen: with 30 t floors, 3 storeys have f1 = 2.0 Hz].";
        fy1: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 1 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy2: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 2 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy3: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 3 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy4: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 4 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy5: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 5 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy6: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 6 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy7: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 7 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy8: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 8 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy9: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 9 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
        fy10: "N", "n", 250.0e3, Range::gt(0.0), Chosen,
            "Yield force of storey 10 (bilinear, Bouc–Wen) [chosen: 0.28 of 3 floors' weight, drift at yield 10 mm].";
    }
}

/// The storey whose floor mass, stiffness or yield force parameter `name` is (`k5`: 5), if it is
/// one of those.
pub fn storey_of(name: &str) -> Option<usize> {
    ["m", "k", "fy"]
        .iter()
        .find_map(|pre| name.strip_prefix(pre)?.parse::<usize>().ok())
}

/// Why parameter `name` changes nothing in the building `p`: a storey above its `storeys`.
pub fn unused(name: &str, p: &Params) -> Option<String> {
    let storey = storey_of(name)?;
    let storeys = p.storeys as usize;
    (storey > storeys).then(|| {
        format!(
            "building.{name} is storey {storey}'s, but the building has {storeys} storeys \
             (building.storeys): it would change nothing"
        )
    })
}

/// The building's storeys of `p`: floor masses, initial stiffnesses and yield forces, bottom up.
pub fn storeys(p: &Params) -> Vec<(f64, f64, f64)> {
    let m = [p.m1, p.m2, p.m3, p.m4, p.m5, p.m6, p.m7, p.m8, p.m9, p.m10];
    let k = [p.k1, p.k2, p.k3, p.k4, p.k5, p.k6, p.k7, p.k8, p.k9, p.k10];
    let fy = [
        p.fy1, p.fy2, p.fy3, p.fy4, p.fy5, p.fy6, p.fy7, p.fy8, p.fy9, p.fy10,
    ];
    (0..(p.storeys as usize).clamp(1, MAX_STOREYS))
        .map(|i| (m[i], k[i], fy[i]))
        .collect()
}

/// What a model's building parameters break beyond their ranges: a count or a law that is not
/// a whole number.
pub fn check(p: &Params) -> Vec<ParamIssue> {
    [("storeys", p.storeys), ("law", p.law)]
        .into_iter()
        .filter(|(_, v)| v.fract() != 0.0)
        .map(|(name, v)| ParamIssue {
            path: format!("building.{name}"),
            message: format!("{v} is not a whole number"),
        })
        .collect()
}

/// A mode of the building's initial (elastic) stiffness.
#[derive(Debug, Clone, PartialEq)]
pub struct Mode {
    /// Natural frequency, Hz.
    pub freq_hz: f64,
    /// Effective modal mass for a base motion, kg (the modes' sum is the building's mass).
    pub mass: f64,
    /// Shape: floor displacements, the largest 1.
    pub shape: Vec<f64>,
}

/// The modes of a shear building of floor masses and storey stiffnesses `storeys` (bottom up),
/// lowest first: K φ = ω² M φ, solved by Jacobi rotations of M^-1/2 K M^-1/2.
pub fn modes(storeys: &[(f64, f64, f64)]) -> Vec<Mode> {
    let n = storeys.len();
    let sm: Vec<f64> = storeys.iter().map(|s| s.0.sqrt()).collect();
    let k = |i: usize| storeys.get(i).map_or(0.0, |s| s.1);
    let mut a = vec![vec![0.0; n]; n];
    for i in 0..n {
        a[i][i] = (k(i) + k(i + 1)) / (sm[i] * sm[i]);
        if i + 1 < n {
            a[i][i + 1] = -k(i + 1) / (sm[i] * sm[i + 1]);
            a[i + 1][i] = a[i][i + 1];
        }
    }
    let (w2, v) = crate::linalg::symmetric_eigen(a);
    let mut out: Vec<Mode> = (0..n)
        .map(|j| {
            let psi: Vec<f64> = (0..n).map(|i| v[i][j] / sm[i]).collect();
            let l: f64 = (0..n).map(|i| sm[i] * v[i][j]).sum();
            let top = psi
                .iter()
                .fold(0.0_f64, |t, x| if x.abs() > t.abs() { *x } else { t });
            Mode {
                freq_hz: w2[j].max(0.0).sqrt() / (2.0 * std::f64::consts::PI),
                mass: l * l,
                shape: psi.iter().map(|x| x / top).collect(),
            }
        })
        .collect();
    out.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    out
}

/// State indices of storey i: floor displacement relative to the platen, m; its velocity, m/s;
/// the hysteretic force r, N; the storey's work ∫ R dd, J.
const fn u(i: usize) -> usize {
    4 * i
}
const fn v(i: usize) -> usize {
    4 * i + 1
}
const fn r(i: usize) -> usize {
    4 * i + 2
}
const fn w(i: usize) -> usize {
    4 * i + 3
}

/// The bilinear storey law (`law`; 0 linear, 2 Bouc–Wen).
const BILINEAR: f64 = 1.0;

/// The building of every lane, storey by storey as arrays of lanes (zeros where a lane has no
/// such storey or the effect is off, so that those states stand still without a branch).
pub struct Building<const N: usize> {
    /// Storeys of the tallest building of the batch (0 when no lane has one).
    top: usize,
    /// Whether some lane's storeys are Bouc–Wen (only then is its law evaluated).
    any_bouc_wen: bool,
    /// Per lane: the law (0 where the effect is off), α, the Bouc–Wen A, β, γ, n.
    law: [f64; N],
    alpha: [f64; N],
    bw: [[f64; N]; 4],
    /// Per storey and lane: 1 where the floor exists, 1/m, k, c, F_y (1 where absent), and
    /// where the bilinear law holds the hysteretic force (F_y; infinite for the other laws, so
    /// that one branch-free expression serves every lane).
    present: [[f64; N]; MAX_STOREYS],
    inv_m: [[f64; N]; MAX_STOREYS],
    k: [[f64; N]; MAX_STOREYS],
    c: [[f64; N]; MAX_STOREYS],
    fy: [[f64; N]; MAX_STOREYS],
    cap: [[f64; N]; MAX_STOREYS],
    /// Per lane: 1 / the storey height, 1/m (for the drift ratio only).
    inv_h: [f64; N],
}

/// A lane's building, storey by storey: m, k, c, F_y.
fn lane_storeys(p: &Params) -> Vec<[f64; 4]> {
    let st = storeys(p);
    let w1 = 2.0 * std::f64::consts::PI * modes(&st)[0].freq_hz;
    let a1 = 2.0 * p.zeta / w1;
    st.iter().map(|s| [s.0, s.1, a1 * s.1, s.2]).collect()
}

impl<const N: usize> LibraryEffect<N> for Building<N> {
    fn new(p: [&dyn ModelView; N]) -> Self {
        let on = super::lane_mask::<N, Self>(&p);
        let q = p.map(Params::of);
        let lanes: [Vec<[f64; 4]>; N] = std::array::from_fn(|l| {
            if on[l] > 0.0 {
                lane_storeys(q[l])
            } else {
                vec![]
            }
        });
        let table = |f: usize, absent: f64| -> [[f64; N]; MAX_STOREYS] {
            std::array::from_fn(|i| {
                std::array::from_fn(|l| lanes[l].get(i).map_or(absent, |s| s[f]))
            })
        };
        Building {
            top: lanes.iter().map(Vec::len).max().unwrap_or(0),
            any_bouc_wen: (0..N).any(|l| on[l] > 0.0 && q[l].law > BILINEAR),
            law: std::array::from_fn(|l| if on[l] > 0.0 { q[l].law } else { 0.0 }),
            alpha: std::array::from_fn(|l| q[l].alpha),
            bw: [
                std::array::from_fn(|l| q[l].bw_a),
                std::array::from_fn(|l| q[l].bw_beta),
                std::array::from_fn(|l| q[l].bw_gamma),
                std::array::from_fn(|l| q[l].bw_n),
            ],
            present: std::array::from_fn(|i| {
                std::array::from_fn(|l| f64::from(u8::from(i < lanes[l].len())))
            }),
            inv_m: std::array::from_fn(|i| {
                std::array::from_fn(|l| lanes[l].get(i).map_or(0.0, |s| 1.0 / s[0]))
            }),
            k: table(1, 0.0),
            c: table(2, 0.0),
            fy: table(3, 1.0),
            cap: std::array::from_fn(|i| {
                std::array::from_fn(|l| match lanes[l].get(i) {
                    Some(s) if q[l].law == BILINEAR => s[3],
                    _ => f64::INFINITY,
                })
            }),
            inv_h: std::array::from_fn(|l| 1.0 / q[l].height),
        }
    }
}

impl<const N: usize> Building<N> {
    /// Lane `l`'s coefficients in the order the CUDA kernel reads them (lane.cu `VS_BLD`): the
    /// law (0 where the effect is off), α, the Bouc–Wen A, β, γ, n, then per storey 1/m (0 where
    /// the lane has no such storey), k, c, F_y, and last 1 / the storey height.
    pub fn lane(&self, l: usize) -> [f64; 7 + 4 * MAX_STOREYS] {
        let mut out = [0.0; 7 + 4 * MAX_STOREYS];
        out[6 + 4 * MAX_STOREYS] = self.inv_h[l];
        out[..6].copy_from_slice(&[
            self.law[l],
            self.alpha[l],
            self.bw[0][l],
            self.bw[1][l],
            self.bw[2][l],
            self.bw[3][l],
        ]);
        for i in 0..MAX_STOREYS {
            let at = 6 + 4 * i;
            out[at..at + 4].copy_from_slice(&[
                self.inv_m[i][l],
                self.k[i][l],
                self.c[i][l],
                self.fy[i][l],
            ]);
        }
        out
    }

    /// Storey i's drift and drift rate in lane l.
    #[inline(always)]
    fn drift(s: &[[f64; N]; 4 * MAX_STOREYS], i: usize, l: usize) -> (f64, f64) {
        if i == 0 {
            (s[u(0)][l], s[v(0)][l])
        } else {
            (s[u(i)][l] - s[u(i - 1)][l], s[v(i)][l] - s[v(i - 1)][l])
        }
    }

    /// The hysteretic force as the storey's force takes it: clamped to ±F_y for the bilinear law.
    #[inline(always)]
    fn held(&self, i: usize, l: usize, r: f64) -> f64 {
        r.max(-self.cap[i][l]).min(self.cap[i][l])
    }

    /// Storey i's restoring force R in lane l at drift d and hysteretic force r, N.
    #[inline(always)]
    fn restoring(&self, i: usize, l: usize, d: f64, r: f64) -> f64 {
        let a = self.alpha[l];
        a * self.k[i][l] * d + (1.0 - a) * self.held(i, l, r)
    }

    /// Storey i's shear V = R + c ḋ in lane l, N.
    #[inline(always)]
    fn shear(&self, s: &[[f64; N]; 4 * MAX_STOREYS], i: usize, l: usize) -> f64 {
        let (d, dd) = Self::drift(s, i, l);
        self.restoring(i, l, d, s[r(i)][l]) + self.c[i][l] * dd
    }

    /// The Bouc–Wen law's dr/dd over k in lane l (storey i): A − |z|^n (β + γ sgn(ḋ z)),
    /// z = r/F_y.
    #[inline(always)]
    fn bouc_wen(&self, i: usize, l: usize, r: f64, dd: f64) -> f64 {
        let z = r / self.fy[i][l];
        let sign = if dd * z > 0.0 {
            1.0
        } else if dd * z < 0.0 {
            -1.0
        } else {
            0.0
        };
        self.bw[0][l] - z.abs().powf(self.bw[3][l]) * (self.bw[1][l] + self.bw[2][l] * sign)
    }
}

/// The response channels' names, storey by storey ([`Effect::responses`]).
const DRIFT: [&str; MAX_STOREYS] = [
    "drift_1_m",
    "drift_2_m",
    "drift_3_m",
    "drift_4_m",
    "drift_5_m",
    "drift_6_m",
    "drift_7_m",
    "drift_8_m",
    "drift_9_m",
    "drift_10_m",
];
const FORCE: [&str; MAX_STOREYS] = [
    "storey_force_1_n",
    "storey_force_2_n",
    "storey_force_3_n",
    "storey_force_4_n",
    "storey_force_5_n",
    "storey_force_6_n",
    "storey_force_7_n",
    "storey_force_8_n",
    "storey_force_9_n",
    "storey_force_10_n",
];
const FLOOR_ACCEL: [&str; MAX_STOREYS] = [
    "floor_accel_1_mps2",
    "floor_accel_2_mps2",
    "floor_accel_3_mps2",
    "floor_accel_4_mps2",
    "floor_accel_5_mps2",
    "floor_accel_6_mps2",
    "floor_accel_7_mps2",
    "floor_accel_8_mps2",
    "floor_accel_9_mps2",
    "floor_accel_10_mps2",
];
const ENERGY: [&str; MAX_STOREYS] = [
    "energy_1_j",
    "energy_2_j",
    "energy_3_j",
    "energy_4_j",
    "energy_5_j",
    "energy_6_j",
    "energy_7_j",
    "energy_8_j",
    "energy_9_j",
    "energy_10_j",
];

impl<const N: usize> Effect<N> for Building<N> {
    type State = [[f64; N]; 4 * MAX_STOREYS];
    const HYDRAULIC: bool = false; // a force on the platen alone

    fn initial_state(&self) -> Self::State {
        [[0.0; N]; 4 * MAX_STOREYS]
    }

    /// The storeys of the tallest building of the batch (those above it stand still).
    #[inline(always)]
    fn live_states(&self) -> usize {
        4 * self.top
    }

    /// The base shear V_1 on the platen, N.
    #[inline(always)]
    fn extra_force(&self, c: hook::Motion, s: &Self::State) -> f64 {
        self.shear(s, 0, c.lane)
    }

    #[inline(always)]
    fn derivs(&self, plant: &PlantView<'_, N>, s: &Self::State, ds: &mut Self::State) {
        let (mut above, rest) = ([0.0; N], [0.0; N]);
        // Storey by storey, its lanes in one branch-free pass (they vectorise): the floor below
        // as rows (the platen's: zeros, and x − 0 = x, so the drift is the same bits).
        for i in (0..self.top).rev() {
            let (below_u, below_v) = match i {
                0 => (&rest, &rest),
                _ => (&s[u(i - 1)], &s[v(i - 1)]),
            };
            let [su, sv, sr, _]: &[[f64; N]; 4] = s[4 * i..4 * i + 4].try_into().unwrap();
            let [du, dv, dr, dw]: &mut [[f64; N]; 4] =
                (&mut ds[4 * i..4 * i + 4]).try_into().unwrap();
            let (k, c, cap) = (&self.k[i], &self.c[i], &self.cap[i]);
            for l in 0..N {
                let (d, dd, x) = (su[l] - below_u[l], sv[l] - below_v[l], sr[l]);
                let a = self.alpha[l];
                let restoring = a * k[l] * d + (1.0 - a) * x.max(-cap[l]).min(cap[l]);
                let shear = restoring + c[l] * dd;
                du[l] = sv[l];
                dv[l] = (above[l] - shear) * self.inv_m[i][l] - plant.accel[l] * self.present[i][l];
                // The linear and bilinear laws' dr/dd over k: 0 while the force is held at ±F_y
                // and the drift moves outwards, else 1 (without a short-circuit or a branch).
                let out = ((x >= cap[l]) & (dd > 0.0)) | ((x <= -cap[l]) & (dd < 0.0));
                dr[l] = k[l] * dd * if out { 0.0 } else { 1.0 };
                dw[l] = restoring * dd;
                above[l] = shear;
            }
        }
        if self.any_bouc_wen {
            for i in 0..self.top {
                for l in (0..N).filter(|&l| self.law[l] > BILINEAR) {
                    let (_, dd) = Self::drift(s, i, l);
                    ds[r(i)][l] = self.k[i][l] * dd * self.bouc_wen(i, l, s[r(i)][l], dd);
                }
            }
        }
    }

    /// The peaks of the drift ratio, the base shear and the ductility demand, and the energy the
    /// storeys dissipated: their work ∫R dd less the elastic energy they hold,
    /// α k d²/2 + (1 − α) r²/(2k) (0 for a linear storey, whatever its drift). Storey by storey,
    /// its lanes in one pass without a branch (they vectorise); a lane's absent storeys count 0.
    #[inline(always)]
    fn watch(&self, s: &Self::State, acc: &mut SpecimenAcc<N>) {
        let (mut drift, mut ductility, mut energy) = ([0.0f64; N], [0.0f64; N], [0.0f64; N]);
        let rest = [0.0; N];
        for i in 0..self.top {
            let below = if i == 0 { &rest } else { &s[u(i - 1)] };
            let (su, sr, sw) = (&s[u(i)], &s[r(i)], &s[w(i)]);
            let (k, fy, cap, present) = (&self.k[i], &self.fy[i], &self.cap[i], &self.present[i]);
            for l in 0..N {
                let on = present[l] > 0.0;
                let (d, a) = (su[l] - below[l], self.alpha[l]);
                let held = sr[l].max(-cap[l]).min(cap[l]);
                let size = if on { d.abs() } else { 0.0 };
                drift[l] = drift[l].max(size);
                ductility[l] = ductility[l].max(size * k[l] / fy[l]);
                let lost = sw[l] - 0.5 * a * k[l] * d * d - 0.5 * (1.0 - a) * held * held / k[l];
                energy[l] += if on { lost } else { 0.0 };
            }
        }
        for l in 0..N {
            if self.present[0][l] > 0.0 {
                acc.drift_ratio[l] = acc.drift_ratio[l].max(drift[l] * self.inv_h[l]);
                acc.base_shear[l] = acc.base_shear[l].max(self.shear(s, 0, l).abs());
                // A linear storey has no yield, so no ductility demand (NaN, as in `study sim`'s
                // table).
                if self.law[l] > 0.0 {
                    acc.ductility[l] = acc.ductility[l].max(ductility[l]);
                }
                acc.energy[l] = energy[l];
            }
        }
    }

    fn responses(&self, lane: usize, s: &Self::State, out: &mut dyn FnMut(&'static str, f64)) {
        let l = lane;
        let floors = (0..self.top).filter(|&i| self.present[i][l] > 0.0).count();
        if floors == 0 {
            return;
        }
        let shear = |i: usize| if i < floors { self.shear(s, i, l) } else { 0.0 };
        out("base_shear_n", shear(0));
        for i in 0..floors {
            let (d, _) = Self::drift(s, i, l);
            out(DRIFT[i], d);
            out(FORCE[i], self.restoring(i, l, d, s[r(i)][l]));
            out(FLOOR_ACCEL[i], (shear(i + 1) - shear(i)) * self.inv_m[i][l]);
            out(ENERGY[i], s[w(i)][l]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A storey's parameters are told by their number, whatever the prefix; the others by
    /// nothing; and one above the building's storeys is said to change nothing.
    #[test]
    fn a_storeys_parameters_are_told_by_their_number() {
        for (name, storey) in [("m1", Some(1)), ("k5", Some(5)), ("fy10", Some(10))] {
            assert_eq!(storey_of(name), storey, "{name}");
        }
        for name in ["zeta", "alpha", "storeys", "height", "law"] {
            assert_eq!(storey_of(name), None, "{name}");
        }
        let p = Params {
            storeys: 3.0,
            ..Params::default()
        };
        assert_eq!(unused("k3", &p), None);
        assert_eq!(unused("zeta", &p), None);
        let why = unused("fy7", &p).expect("storey 7 of 3");
        assert!(
            why.contains("storey 7's") && why.contains("3 storeys"),
            "{why}"
        );
    }

    /// A building's channels are the documented ones at the state it is in (docs/model.md,
    /// the building): a storey's restoring force R = αk·d + (1 − α)·r (bilinear, r within ±F_y),
    /// its shear V = R + c·ḋ with c = (2ζ/ω₁)·k, a floor's acceleration (V_above − V)/m, the
    /// base shear V₁ and each storey's work as its state holds it. The expected values are
    /// computed here from those laws, ω₁ from the 2-storey eigenproblem in closed form.
    #[test]
    fn a_buildings_channels_follow_the_storey_laws() {
        let (m1, m2, k1, k2, alpha, zeta) = (20.0e3, 10.0e3, 30.0e6, 20.0e6, 0.1, 0.05);
        let mut m = super::super::tests::Defaults::default();
        m.effects.building = true;
        let p = &mut m.effect_params.building;
        (p.storeys, p.law, p.alpha, p.zeta) = (2.0, BILINEAR, alpha, zeta);
        (p.m1, p.m2, p.k1, p.k2, p.fy1, p.fy2) = (m1, m2, k1, k2, 200.0e3, 150.0e3);
        let b = Building::<1>::new([&m as &dyn ModelView]);
        // m1·m2·λ² − (m1·k2 + m2·(k1 + k2))·λ + k1·k2 = 0, λ = ω².
        let (qa, qb, qc) = (m1 * m2, m1 * k2 + m2 * (k1 + k2), k1 * k2);
        let w1 = ((qb - (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa)).sqrt();
        let (c1, c2) = (2.0 * zeta / w1 * k1, 2.0 * zeta / w1 * k2);
        let mut s = b.initial_state();
        let (u1, u2, v1, v2, r1, r2) = (0.01, 0.025, 0.1, 0.3, 150.0e3, 100.0e3);
        (s[u(0)][0], s[u(1)][0], s[v(0)][0], s[v(1)][0]) = (u1, u2, v1, v2);
        (s[r(0)][0], s[r(1)][0], s[w(0)][0], s[w(1)][0]) = (r1, r2, 123.0, 45.0);
        let (d1, d2) = (u1, u2 - u1);
        let f1 = alpha * k1 * d1 + (1.0 - alpha) * r1;
        let f2 = alpha * k2 * d2 + (1.0 - alpha) * r2;
        let (s1, s2) = (f1 + c1 * v1, f2 + c2 * (v2 - v1));
        let want = [
            ("base_shear_n", s1),
            ("drift_1_m", d1),
            ("storey_force_1_n", f1),
            ("floor_accel_1_mps2", (s2 - s1) / m1),
            ("energy_1_j", 123.0),
            ("drift_2_m", d2),
            ("storey_force_2_n", f2),
            ("floor_accel_2_mps2", -s2 / m2),
            ("energy_2_j", 45.0),
        ];
        let mut got = Vec::new();
        b.responses(0, &s, &mut |name, value| got.push((name, value)));
        assert_eq!(got.len(), want.len(), "{got:?}");
        for ((name, value), (w_name, w_value)) in got.iter().zip(want) {
            assert_eq!(*name, w_name);
            let tol = 1e-12 * w_value.abs().max(1.0);
            assert!(
                (value - w_value).abs() <= tol,
                "{name}: {value} not {w_value}"
            );
        }
        // Off: no channels.
        m.effects.building = false;
        let off = Building::<1>::new([&m as &dyn ModelView]);
        let mut none = 0;
        off.responses(0, &off.initial_state(), &mut |_, _| none += 1);
        assert_eq!(none, 0);
    }
}
