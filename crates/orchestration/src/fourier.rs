//! Spectra of a sampled record: a radix-2 FFT of the zero-padded series, the white-noise level
//! of its top band, and its energy by frequency band.
//!
//! With x zero-padded to N = 2^m ≥ n samples, X_k = Σ x_j e^{−2πi jk/N}. For white noise of
//! standard deviation σ, E|X_k|² = n·σ² at every bin (zero padding adds no energy), and |X_k|²
//! is exponentially distributed for 0 < k < N/2, so its median is ln 2 · n·σ² (with a window w,
//! n becomes Σ w_j²). Parseval:
//! Σ_k |X_k|² = N Σ_j x_j².

use std::f64::consts::PI;

/// The fraction of the Nyquist band (from its top) whose spectrum gives the noise level:
/// [chosen: from 0.4 to 0.5 of the sample rate. A shake table's motion is band-limited by its
/// reference filter (50 Hz, 4th order) and its plant; at 500 Hz and above that band holds
/// (f/50)⁴ ≥ 256 times less of the motion than the pass band, so it is the sensors' noise.]
pub const NOISE_BAND: (f64, f64) = (0.4, 0.5);

/// In-place radix-2 FFT of (re, im), length a power of two.
pub(crate) fn fft(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    debug_assert!(n.is_power_of_two() && im.len() == n);
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let (ws, wc) = (-2.0 * PI / len as f64).sin_cos();
        for start in (0..n).step_by(len) {
            let (mut cr, mut ci) = (1.0, 0.0);
            for k in 0..len / 2 {
                let (a, b) = (start + k, start + k + len / 2);
                let (tr, ti) = (re[b] * cr - im[b] * ci, re[b] * ci + im[b] * cr);
                re[b] = re[a] - tr;
                im[b] = im[a] - ti;
                re[a] += tr;
                im[a] += ti;
                (cr, ci) = (cr * wc - ci * ws, cr * ws + ci * wc);
            }
        }
        len <<= 1;
    }
}

/// |X_k|² for k = 0…N/2 of `x` (its mean removed, times the window `w`) zero-padded to N, and N.
pub(crate) fn power_windowed(x: &[f64], w: impl Fn(usize) -> f64) -> (Vec<f64>, usize) {
    let n_fft = x.len().max(2).next_power_of_two();
    let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
    let mut re: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(j, v)| (v - mean) * w(j))
        .collect();
    re.resize(n_fft, 0.0);
    let mut im = vec![0.0; n_fft];
    fft(&mut re, &mut im);
    let p = (0..=n_fft / 2)
        .map(|k| re[k] * re[k] + im[k] * im[k])
        .collect();
    (p, n_fft)
}

/// |X_k|² for k = 0…N/2 of `x` (its mean removed) zero-padded to N, and N.
pub fn power(x: &[f64]) -> (Vec<f64>, usize) {
    power_windowed(x, |_| 1.0)
}

/// σ of white noise in `x` from the median of its power in [`NOISE_BAND`], under a Hann window
/// (the record's ends, cut off by the zero padding, would leak the motion's power into the band
/// as 1/f²; the window's leakage falls as 1/f⁶), for which E|X_k|² = σ² Σ w_j²; None when the
/// band holds fewer than 16 bins.
pub fn noise_sigma(x: &[f64]) -> Option<f64> {
    let n = x.len();
    let hann = |j: usize| (PI * (j as f64 + 0.5) / n as f64).sin().powi(2);
    let sum_w2: f64 = (0..n).map(|j| hann(j).powi(2)).sum();
    let (p, n_fft) = power_windowed(x, hann);
    let lo = (NOISE_BAND.0 * n_fft as f64).ceil() as usize;
    let hi = ((NOISE_BAND.1 * n_fft as f64) as usize).min(n_fft / 2 - 1);
    if hi < lo + 16 {
        return None;
    }
    let mut band = p[lo..=hi].to_vec();
    band.sort_by(|a, b| a.total_cmp(b));
    let median = band[band.len() / 2];
    Some((median / (2f64.ln() * sum_w2)).sqrt())
}

/// The edges of the octave bands reported for a record's residual [Hz]: [chosen: octaves from
/// 0.25 Hz, where earthquake records start, to the Nyquist frequency].
pub fn octave_edges(rate_hz: f64) -> Vec<f64> {
    let mut e = vec![0.0, 0.25];
    while *e.last().unwrap() * 2.0 < 0.5 * rate_hz {
        e.push(e.last().unwrap() * 2.0);
    }
    e.push(0.5 * rate_hz);
    e
}

/// Σ x² of `x` by frequency band (`edges` in Hz, sampled at `rate_hz`), by Parseval; the bands
/// sum to Σ (x − mean)², and the mean's part goes to the first band.
pub fn band_energy(x: &[f64], rate_hz: f64, edges: &[f64]) -> Vec<f64> {
    let (p, n_fft) = power(x);
    let mut e = vec![0.0; edges.len().saturating_sub(1)];
    for (k, pk) in p.iter().enumerate() {
        let f = k as f64 * rate_hz / n_fft as f64;
        let w = if k == 0 || k == n_fft / 2 { 1.0 } else { 2.0 };
        let b = edges.partition_point(|&edge| edge <= f).saturating_sub(1);
        if let Some(slot) = e.get_mut(b.min(edges.len().saturating_sub(2))) {
            *slot += w * pk / n_fft as f64;
        }
    }
    let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
    if let Some(first) = e.first_mut() {
        *first += x.len() as f64 * mean * mean;
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parseval_and_a_tone_in_its_band() {
        let rate = 1000.0;
        let x: Vec<f64> = (0..3000)
            .map(|i| 0.5 + (2.0 * PI * 10.0 * i as f64 / rate).sin())
            .collect();
        let edges = octave_edges(rate);
        let e = band_energy(&x, rate, &edges);
        let total: f64 = x.iter().map(|v| v * v).sum();
        assert!((e.iter().sum::<f64>() / total - 1.0).abs() < 1e-9);
        // 10 Hz lies in the 8–16 Hz octave; the leakage of the zero padding stays small.
        let b = edges.iter().position(|&f| f == 8.0).unwrap();
        assert!(e[b] > 0.9 * 1500.0, "{e:?}");
    }

    #[test]
    fn white_noise_level_under_a_low_band_signal() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = chacha20::ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, 0.03).unwrap();
        let x: Vec<f64> = (0..20000)
            .map(|i| 5.0 * (2.0 * PI * 7.0 * i as f64 / 1024.0).sin() + noise.sample(&mut rng))
            .collect();
        let s = noise_sigma(&x).unwrap();
        assert!((s / 0.03 - 1.0).abs() < 0.05, "{s}");
    }
}
