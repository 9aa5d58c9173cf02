//! Metrics of docs/model.md §5, accumulated online at the controller ticks (no stored history).
//!
//! Over the analysis window of n ticks, harmonic k of a channel s is the running projection
//! H_k = (2/n) Σ s[n]·exp(−j 2π k f t_n). From it:
//!
//! - amplitude ratio |H_1(a)|/|H_1(a_r)| and phase error ∠H_1(a) − ∠H_1(a_r) (degrees);
//! - h_k = |H_k(a)|/|H_1(a)|, k = 2…9; THD_odd = √(Σ_{k=3,5,7,9} h_k²), THD_even = √(Σ_{k=2,4,6,8} h_k²);
//! - tracking errors rms(a − a_r)/rms(a_r), rms(x − x_r)/rms(x_r) and peak |a − a_r| over the window;
//! - max |u| over the whole run; the displacement amplitude ratio and phase (same projection on x);
//! - peak ratios over the window: PGA = max|a|/max|a_r|, PGV = max|v|/max|v_r| (v the platen
//!   velocity), PGD = max|x|/max|x_r|, and the peak displacement error max|x − x_r|;
//! - where the reference carries a response spectrum ([`super::spectrum`]): the spectrum of the
//!   achieved acceleration over the window, online, and the spectral error against the target's,
//!   mean and max |ln(PSA/PSA_target)| over the period band.
//!
//! For a record (no fundamental) the harmonic metrics are NaN and the window is the whole record.
//! Every lane has its own reference sums, so lanes may follow different references (stochastic
//! ground motions, one realisation per sample) with the same bits as a shared one.

use super::spectrum::{SpectrumAcc, SpectrumSpec};

/// Highest harmonic computed.
pub const N_HARM: usize = 9;

/// The metrics of one lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Metrics {
    pub amp_ratio: f64,
    pub phase_err_deg: f64,
    /// h_2 … h_9 (index 0 is h_2).
    pub h: [f64; N_HARM - 1],
    pub thd_odd: f64,
    pub thd_even: f64,
    pub rms_err_accel_ratio: f64,
    pub rms_err_disp_ratio: f64,
    pub peak_err_accel_mps2: f64,
    pub max_abs_u_v: f64,
    pub disp_amp_ratio: f64,
    pub disp_phase_err_deg: f64,
    pub peak_err_disp_m: f64,
    pub pga_ratio: f64,
    pub pgv_ratio: f64,
    pub pgd_ratio: f64,
    pub spectral_err_mean: f64,
    pub spectral_err_max: f64,
    /// What a building on the platen experiences over the whole run ([`SpecimenAcc`]; NaN
    /// without one): the largest storey drift over the storey height, the largest |base shear|
    /// (N), the largest storey drift over its yield drift F_y/k, and the energy its storeys
    /// dissipated (J).
    pub peak_drift_ratio: f64,
    pub peak_base_shear_n: f64,
    pub ductility_demand: f64,
    pub hysteretic_energy_j: f64,
}

impl Metrics {
    /// The highest harmonic k ≤ 9 of `f0` strictly below the Nyquist frequency f_s/2 (0 when
    /// even the fundamental is not).
    pub fn highest_harmonic(f0: f64, f_s: f64) -> usize {
        (1..=N_HARM)
            .take_while(|&k| (k as f64) * f0 < 0.5 * f_s)
            .last()
            .unwrap_or(0)
    }

    pub const NAN: Metrics = Metrics {
        amp_ratio: f64::NAN,
        phase_err_deg: f64::NAN,
        h: [f64::NAN; N_HARM - 1],
        thd_odd: f64::NAN,
        thd_even: f64::NAN,
        rms_err_accel_ratio: f64::NAN,
        rms_err_disp_ratio: f64::NAN,
        peak_err_accel_mps2: f64::NAN,
        max_abs_u_v: f64::NAN,
        disp_amp_ratio: f64::NAN,
        disp_phase_err_deg: f64::NAN,
        peak_err_disp_m: f64::NAN,
        pga_ratio: f64::NAN,
        pgv_ratio: f64::NAN,
        pgd_ratio: f64::NAN,
        spectral_err_mean: f64::NAN,
        spectral_err_max: f64::NAN,
        peak_drift_ratio: f64::NAN,
        peak_base_shear_n: f64::NAN,
        ductility_demand: f64::NAN,
        hysteretic_energy_j: f64::NAN,
    };

    /// The names of the specimen's metrics ([`SpecimenAcc`]), in column order.
    pub const SPECIMEN: [&'static str; 4] = [
        "peak_drift_ratio",
        "peak_base_shear_n",
        "ductility_demand",
        "hysteretic_energy_j",
    ];

    /// [`Metrics::columns`], without the specimen's unless the run carries one (`specimen`).
    pub fn columns_for(&self, specimen: bool) -> Vec<(&'static str, f64)> {
        let mut v = self.columns();
        if !specimen {
            v.retain(|(n, _)| !Self::SPECIMEN.contains(n));
        }
        v
    }

    /// These metrics with the specimen's, in [`Metrics::SPECIMEN`] order.
    pub fn with_specimen(mut self, v: [f64; 4]) -> Metrics {
        [
            self.peak_drift_ratio,
            self.peak_base_shear_n,
            self.ductility_demand,
            self.hysteretic_energy_j,
        ] = v;
        self
    }

    /// Every metric's bit pattern, in [`Metrics::columns`] order: to compare two runs bit for
    /// bit (`==` on the struct fails on the NaN of a metric that does not apply).
    pub fn bits(&self) -> Vec<u64> {
        self.columns()
            .into_iter()
            .map(|(_, v)| v.to_bits())
            .collect()
    }

    /// The metrics whose [`Metrics::bits`] are `bits` (None when the count differs): a stored
    /// run read back bit for bit.
    pub fn from_bits(bits: &[u64]) -> Option<Metrics> {
        let mut m = Metrics::NAN;
        let mut slots: Vec<&mut f64> = vec![&mut m.amp_ratio, &mut m.phase_err_deg];
        slots.extend(m.h.iter_mut());
        slots.extend([
            &mut m.thd_odd,
            &mut m.thd_even,
            &mut m.rms_err_accel_ratio,
            &mut m.rms_err_disp_ratio,
            &mut m.peak_err_accel_mps2,
            &mut m.max_abs_u_v,
            &mut m.disp_amp_ratio,
            &mut m.disp_phase_err_deg,
            &mut m.peak_err_disp_m,
            &mut m.pga_ratio,
            &mut m.pgv_ratio,
            &mut m.pgd_ratio,
            &mut m.spectral_err_mean,
            &mut m.spectral_err_max,
            &mut m.peak_drift_ratio,
            &mut m.peak_base_shear_n,
            &mut m.ductility_demand,
            &mut m.hysteretic_energy_j,
        ]);
        if slots.len() != bits.len() {
            return None;
        }
        for (slot, b) in slots.into_iter().zip(bits) {
            *slot = f64::from_bits(*b);
        }
        Some(m)
    }

    /// h_k for k = 2…9.
    pub fn h(&self, k: usize) -> f64 {
        self.h[k - 2]
    }

    /// (column name, value) pairs in a fixed order, as written to result tables.
    pub fn columns(&self) -> Vec<(&'static str, f64)> {
        let mut v = vec![
            ("amp_ratio", self.amp_ratio),
            ("phase_err_deg", self.phase_err_deg),
        ];
        const H: [&str; 8] = [
            "h2_ratio", "h3_ratio", "h4_ratio", "h5_ratio", "h6_ratio", "h7_ratio", "h8_ratio",
            "h9_ratio",
        ];
        v.extend(H.iter().zip(self.h.iter()).map(|(n, x)| (*n, *x)));
        v.extend([
            ("thd_odd_ratio", self.thd_odd),
            ("thd_even_ratio", self.thd_even),
            ("rms_err_accel_ratio", self.rms_err_accel_ratio),
            ("rms_err_disp_ratio", self.rms_err_disp_ratio),
            ("peak_err_accel_mps2", self.peak_err_accel_mps2),
            ("max_abs_valve_cmd_v", self.max_abs_u_v),
            ("disp_amp_ratio", self.disp_amp_ratio),
            ("disp_phase_err_deg", self.disp_phase_err_deg),
            ("peak_err_disp_m", self.peak_err_disp_m),
            ("pga_ratio", self.pga_ratio),
            ("pgv_ratio", self.pgv_ratio),
            ("pgd_ratio", self.pgd_ratio),
            ("spectral_err_mean", self.spectral_err_mean),
            ("spectral_err_max", self.spectral_err_max),
        ]);
        let specimen = [
            self.peak_drift_ratio,
            self.peak_base_shear_n,
            self.ductility_demand,
            self.hysteretic_energy_j,
        ];
        v.extend(Self::SPECIMEN.into_iter().zip(specimen));
        v
    }
}

/// A phase difference in degrees, wrapped to (−180°, 180°] (the one wrapping of every phase
/// metric: the kernel's, compare's and fit's).
pub fn wrap_deg(d: f64) -> f64 {
    let mut d = d % 360.0;
    if d > 180.0 {
        d -= 360.0;
    } else if d <= -180.0 {
        d += 360.0;
    }
    d
}

/// cos and sin of k·2πf·t for k = 1…9 at one tick (shared by every lane).
#[derive(Debug, Clone, Copy)]
pub struct Basis {
    pub cos: [f64; N_HARM],
    pub sin: [f64; N_HARM],
}

impl Basis {
    /// Basis at tick `k` of rate `f_s` for fundamental `f`: one sine and cosine of the
    /// fundamental's phase (reduced to one cycle first), the harmonics by the angle-addition
    /// recurrence cos kθ = cos θ·cos (k−1)θ − sin θ·sin (k−1)θ (and its sine twin). Nine
    /// sin_cos calls per tick cost as much as the rest of the tick; the recurrence is within
    /// 1e-14 of them (`recurrence_matches_sin_cos`).
    pub fn at(k: usize, f_s: f64, f: f64) -> Basis {
        let mut b = Basis {
            cos: [0.0; N_HARM],
            sin: [0.0; N_HARM],
        };
        let cycles = f * (k as f64) / f_s;
        let (s1, c1) = (2.0 * std::f64::consts::PI * (cycles - cycles.floor())).sin_cos();
        b.cos[0] = c1;
        b.sin[0] = s1;
        for h in 1..N_HARM {
            b.cos[h] = c1 * b.cos[h - 1] - s1 * b.sin[h - 1];
            b.sin[h] = s1 * b.cos[h - 1] + c1 * b.sin[h - 1];
        }
        b
    }
}

/// What a specimen experiences, per lane, over every tick of the run: NaN until an effect with a
/// specimen ([`crate::effects::Effect::watch`]) writes it, so lanes without one report NaN.
#[derive(Debug, Clone, Copy)]
pub struct SpecimenAcc<const N: usize> {
    /// max over ticks and storeys of |drift| / storey height.
    pub drift_ratio: [f64; N],
    /// max over ticks of |base shear|, N.
    pub base_shear: [f64; N],
    /// max over ticks and storeys of |drift| / (F_y / k).
    pub ductility: [f64; N],
    /// The energy dissipated by the storeys so far (their work less what they store), J.
    pub energy: [f64; N],
}

impl<const N: usize> Default for SpecimenAcc<N> {
    fn default() -> Self {
        SpecimenAcc {
            drift_ratio: [f64::NAN; N],
            base_shear: [f64::NAN; N],
            ductility: [f64::NAN; N],
            energy: [f64::NAN; N],
        }
    }
}

impl<const N: usize> SpecimenAcc<N> {
    /// Lane `l`'s values, in [`Metrics::SPECIMEN`] order.
    pub fn lane(&self, l: usize) -> [f64; 4] {
        [
            self.drift_ratio[l],
            self.base_shear[l],
            self.ductility[l],
            self.energy[l],
        ]
    }
}

/// Running sums of one batch.
#[derive(Debug, Clone)]
pub struct MetricsAcc<const N: usize> {
    n: usize,
    /// Σ a cos, Σ a sin for k = 1…9.
    a_re: [[f64; N]; N_HARM],
    a_im: [[f64; N]; N_HARM],
    x_re: [f64; N],
    x_im: [f64; N],
    err_a2: [f64; N],
    err_x2: [f64; N],
    peak_err_a: [f64; N],
    peak_err_x: [f64; N],
    max_u: [f64; N],
    /// Peaks of |a|, |v|, |x| and of |a_r|, |v_r|, |x_r| over the window.
    peak: [[f64; N]; 3],
    peak_r: [[f64; N]; 3],
    // Each lane's reference sums.
    ar_re: [f64; N],
    ar_im: [f64; N],
    xr_re: [f64; N],
    xr_im: [f64; N],
    ar2: [f64; N],
    xr2: [f64; N],
    spectrum: Option<SpectrumAcc<N>>,
}

/// One tick of the window: each lane's reference (a_r, v_r, x_r) and achieved (a, v, x).
pub struct WindowTick<'a, const N: usize> {
    pub a_r: &'a [f64; N],
    pub v_r: &'a [f64; N],
    pub x_r: &'a [f64; N],
    pub a: &'a [f64; N],
    pub v: &'a [f64; N],
    pub x: &'a [f64; N],
}

/// One lane's sums of [`MetricsAcc`], as another engine returns them (the CUDA kernel,
/// `crates/kernel/src/cuda/lane.cu`): the metrics are then finished by [`MetricsAcc::finish`] here.
#[derive(Debug, Clone, Default)]
pub struct LaneSums {
    pub n: usize,
    pub a_re: [f64; N_HARM],
    pub a_im: [f64; N_HARM],
    pub x_re: f64,
    pub x_im: f64,
    pub err_a2: f64,
    pub err_x2: f64,
    pub peak_err_a: f64,
    pub peak_err_x: f64,
    pub max_u: f64,
    /// Peaks of |a|, |v|, |x| and of the reference's.
    pub peak: [f64; 3],
    pub peak_r: [f64; 3],
    pub ar_re: f64,
    pub ar_im: f64,
    pub xr_re: f64,
    pub xr_im: f64,
    pub ar2: f64,
    pub xr2: f64,
    /// The response-spectrum oscillators' peak displacements, m (empty: no spectrum).
    pub osc_peak: Vec<f64>,
    /// The specimen's metrics ([`SpecimenAcc::lane`]).
    pub specimen: [f64; 4],
}

impl MetricsAcc<1> {
    /// The accumulator holding one lane's sums: `template` (a [`MetricsAcc::new`] made once for
    /// every lane, so its oscillators are not rebuilt per lane) with the sums in place.
    pub(crate) fn with_sums(&self, s: &LaneSums) -> Self {
        let mut acc = self.clone();
        acc.n = s.n;
        for h in 0..N_HARM {
            acc.a_re[h] = [s.a_re[h]];
            acc.a_im[h] = [s.a_im[h]];
        }
        (acc.x_re, acc.x_im) = ([s.x_re], [s.x_im]);
        (acc.err_a2, acc.err_x2) = ([s.err_a2], [s.err_x2]);
        (acc.peak_err_a, acc.peak_err_x) = ([s.peak_err_a], [s.peak_err_x]);
        acc.max_u = [s.max_u];
        acc.peak = s.peak.map(|p| [p]);
        acc.peak_r = s.peak_r.map(|p| [p]);
        (acc.ar_re, acc.ar_im) = ([s.ar_re], [s.ar_im]);
        (acc.xr_re, acc.xr_im) = ([s.xr_re], [s.xr_im]);
        (acc.ar2, acc.xr2) = ([s.ar2], [s.xr2]);
        if let Some(sp) = &mut acc.spectrum {
            sp.set_peaks(0, &s.osc_peak);
        }
        acc
    }
}

impl<const N: usize> Default for MetricsAcc<N> {
    fn default() -> Self {
        Self::new(None)
    }
}

impl<const N: usize> MetricsAcc<N> {
    /// Sums at zero; with a spectrum, its oscillators at tick `dt` s.
    pub fn new(spectrum: Option<(&SpectrumSpec, f64)>) -> Self {
        MetricsAcc {
            n: 0,
            a_re: [[0.0; N]; N_HARM],
            a_im: [[0.0; N]; N_HARM],
            x_re: [0.0; N],
            x_im: [0.0; N],
            err_a2: [0.0; N],
            err_x2: [0.0; N],
            peak_err_a: [0.0; N],
            peak_err_x: [0.0; N],
            max_u: [0.0; N],
            peak: [[0.0; N]; 3],
            peak_r: [[0.0; N]; 3],
            ar_re: [0.0; N],
            ar_im: [0.0; N],
            xr_re: [0.0; N],
            xr_im: [0.0; N],
            ar2: [0.0; N],
            xr2: [0.0; N],
            spectrum: spectrum.map(|(s, dt)| SpectrumAcc::new(s, dt)),
        }
    }

    /// Every tick: max |u|.
    #[inline(always)]
    pub(crate) fn every_tick(&mut self, u: &[f64; N]) {
        for l in 0..N {
            self.max_u[l] = self.max_u[l].max(u[l].abs());
        }
    }

    /// A tick inside the analysis window.
    #[inline(always)]
    pub(crate) fn window_tick(&mut self, basis: Option<&Basis>, w: &WindowTick<'_, N>) {
        self.n += 1;
        for l in 0..N {
            let (a_r, x_r) = (w.a_r[l], w.x_r[l]);
            self.ar2[l] += a_r * a_r;
            self.xr2[l] += x_r * x_r;
            let ea = w.a[l] - a_r;
            let ex = w.x[l] - x_r;
            self.err_a2[l] += ea * ea;
            self.err_x2[l] += ex * ex;
            self.peak_err_a[l] = self.peak_err_a[l].max(ea.abs());
            self.peak_err_x[l] = self.peak_err_x[l].max(ex.abs());
            for (c, (got, want)) in [(w.a, w.a_r), (w.v, w.v_r), (w.x, w.x_r)]
                .into_iter()
                .enumerate()
            {
                self.peak[c][l] = self.peak[c][l].max(got[l].abs());
                self.peak_r[c][l] = self.peak_r[c][l].max(want[l].abs());
            }
        }
        if let Some(s) = &mut self.spectrum {
            s.tick(w.a);
        }
        if let Some(b) = basis {
            for l in 0..N {
                self.ar_re[l] += w.a_r[l] * b.cos[0];
                self.ar_im[l] += w.a_r[l] * b.sin[0];
                self.xr_re[l] += w.x_r[l] * b.cos[0];
                self.xr_im[l] += w.x_r[l] * b.sin[0];
            }
            for h in 0..N_HARM {
                let (c, s) = (b.cos[h], b.sin[h]);
                for l in 0..N {
                    self.a_re[h][l] += w.a[l] * c;
                    self.a_im[h][l] += w.a[l] * s;
                }
            }
            for l in 0..N {
                self.x_re[l] += w.x[l] * b.cos[0];
                self.x_im[l] += w.x[l] * b.sin[0];
            }
        }
    }

    /// Lane `l`'s spectrum of the achieved acceleration (None without a spectrum).
    pub fn psa(&self, l: usize) -> Option<Vec<f64>> {
        self.spectrum.as_ref().map(|s| s.psa(l))
    }

    /// Final metrics of lane `l`. `harmonics` is the highest harmonic below the Nyquist
    /// frequency (None: no fundamental, no harmonic metrics). A harmonic at or above Nyquist
    /// would be an alias of a lower frequency, so its ratio is NaN and it is left out of the
    /// THD sums ([`Metrics::highest_harmonic`]). `target` is the lane's spectrum and its target
    /// PSA, when the reference has one.
    pub fn finish(
        &self,
        l: usize,
        harmonics: Option<usize>,
        target: Option<(&SpectrumSpec, &[f64])>,
    ) -> Metrics {
        // H_k = (2/n)(Σ s cos − j Σ s sin): magnitude and angle; the 2/n cancels in every ratio.
        let mag = |re: f64, im: f64| re.hypot(im);
        let ang = |re: f64, im: f64| (-im).atan2(re);
        let wrap = |d: f64| wrap_deg(d.to_degrees());
        let mut m = Metrics::NAN;
        m.max_abs_u_v = self.max_u[l];
        if self.n > 0 {
            m.rms_err_accel_ratio = (self.err_a2[l] / self.ar2[l]).sqrt();
            m.rms_err_disp_ratio = (self.err_x2[l] / self.xr2[l]).sqrt();
            m.peak_err_accel_mps2 = self.peak_err_a[l];
            m.peak_err_disp_m = self.peak_err_x[l];
            m.pga_ratio = self.peak[0][l] / self.peak_r[0][l];
            m.pgv_ratio = self.peak[1][l] / self.peak_r[1][l];
            m.pgd_ratio = self.peak[2][l] / self.peak_r[2][l];
            if let (Some((spec, want)), Some(got)) = (target, self.psa(l)) {
                (m.spectral_err_mean, m.spectral_err_max) = spec.error(&got, want);
            }
        }
        if let (Some(top), true) = (harmonics, self.n > 0) {
            let h1 = mag(self.a_re[0][l], self.a_im[0][l]);
            m.amp_ratio = h1 / mag(self.ar_re[l], self.ar_im[l]);
            m.phase_err_deg =
                wrap(ang(self.a_re[0][l], self.a_im[0][l]) - ang(self.ar_re[l], self.ar_im[l]));
            for k in 2..=top.min(N_HARM) {
                m.h[k - 2] = mag(self.a_re[k - 1][l], self.a_im[k - 1][l]) / h1;
            }
            let h = m.h;
            let thd = |ks: [usize; 4]| {
                ks.into_iter()
                    .filter(|&k| k <= top)
                    .map(|k| h[k - 2].powi(2))
                    .sum::<f64>()
                    .sqrt()
            };
            m.thd_odd = thd([3, 5, 7, 9]);
            m.thd_even = thd([2, 4, 6, 8]);
            m.disp_amp_ratio = mag(self.x_re[l], self.x_im[l]) / mag(self.xr_re[l], self.xr_im[l]);
            m.disp_phase_err_deg =
                wrap(ang(self.x_re[l], self.x_im[l]) - ang(self.xr_re[l], self.xr_im[l]));
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_read_back_from_their_bits_are_the_same_in_column_order() {
        let n = Metrics::NAN.columns().len();
        let bits: Vec<u64> = (0..n).map(|i| (1.5 + i as f64).to_bits()).collect();
        let m = Metrics::from_bits(&bits).unwrap();
        assert_eq!(m.bits(), bits);
        assert_eq!(m.columns()[3], ("h3_ratio", 4.5));
        assert!(Metrics::from_bits(&bits[1..]).is_none());
    }

    #[test]
    fn projection_recovers_a_known_signal() {
        // a = 2 sin(ωt + 0.1) + 0.1 sin(3ωt) + 0.04 cos(2ωt) over exactly 4 cycles of 1024 ticks.
        let (f_s, f) = (1024.0, 4.0);
        let w = 2.0 * std::f64::consts::PI * f;
        let mut acc = MetricsAcc::<1>::default();
        for k in 0..1024 {
            let t = k as f64 / f_s;
            let ar = (w * t).sin();
            let a =
                2.0 * (w * t + 0.1).sin() + 0.1 * (3.0 * w * t).sin() + 0.04 * (2.0 * w * t).cos();
            acc.window_tick(
                Some(&Basis::at(k, f_s, f)),
                &WindowTick {
                    a_r: &[ar],
                    v_r: &[ar],
                    x_r: &[ar],
                    a: &[a],
                    v: &[ar],
                    x: &[ar],
                },
            );
        }
        let m = acc.finish(0, Some(N_HARM), None);
        assert!((m.amp_ratio - 2.0).abs() < 1e-12);
        assert!((m.phase_err_deg - 0.1f64.to_degrees()).abs() < 1e-9);
        assert!((m.h(3) - 0.05).abs() < 1e-12);
        assert!((m.h(2) - 0.02).abs() < 1e-12);
        assert!(m.h(5).abs() < 1e-12);
        assert!((m.thd_odd - 0.05).abs() < 1e-12);
        assert!((m.rms_err_disp_ratio).abs() < 1e-15);
    }

    #[test]
    fn harmonics_at_or_above_nyquist_are_omitted() {
        assert_eq!(Metrics::highest_harmonic(3.0, 1024.0), 9);
        assert_eq!(Metrics::highest_harmonic(200.0, 1024.0), 2); // 600 Hz ≥ 512 Hz
        assert_eq!(Metrics::highest_harmonic(128.0, 1024.0), 3); // 512 Hz is not below 512 Hz
        assert_eq!(Metrics::highest_harmonic(600.0, 1024.0), 0);
        // 200 Hz at 1024 Hz: the 3rd harmonic (600 Hz) aliases onto 424 Hz; it must not be reported.
        let (f_s, f) = (1024.0, 200.0);
        let w = 2.0 * std::f64::consts::PI * f;
        let mut acc = MetricsAcc::<1>::default();
        for k in 0..1024 {
            let t = k as f64 / f_s;
            let ar = (w * t).sin();
            let a = ar + 0.1 * (3.0 * w * t).sin() + 0.05 * (2.0 * w * t).sin();
            acc.window_tick(
                Some(&Basis::at(k, f_s, f)),
                &WindowTick {
                    a_r: &[ar],
                    v_r: &[ar],
                    x_r: &[ar],
                    a: &[a],
                    v: &[ar],
                    x: &[ar],
                },
            );
        }
        let m = acc.finish(0, Some(Metrics::highest_harmonic(f, f_s)), None);
        assert!((m.h(2) - 0.05).abs() < 1e-9, "{}", m.h(2));
        assert!((3..=9).all(|k| m.h(k).is_nan()));
        assert_eq!(m.thd_odd, 0.0);
        assert!((m.thd_even - 0.05).abs() < 1e-9);
    }

    #[test]
    fn recurrence_matches_sin_cos() {
        for k in [0usize, 1, 17, 1000, 123_457] {
            // 3.75 Hz at 1024 Hz: every phase below is exact in binary, so only sin_cos rounds.
            let b = Basis::at(k, 1024.0, 3.75);
            for h in 0..N_HARM {
                let phase = 2.0
                    * std::f64::consts::PI
                    * ((h + 1) as f64 * 3.75 * k as f64 / 1024.0).fract();
                assert!(
                    (b.cos[h] - phase.cos()).abs() < 1e-14
                        && (b.sin[h] - phase.sin()).abs() < 1e-14,
                    "k {k} harmonic {}",
                    h + 1
                );
            }
        }
    }
}
