//! The matrix exponential of a small dense matrix (the exact discretisations of the reference
//! filters, the ground-motion filters and the response-spectrum oscillators).

fn matmul<const M: usize>(a: &[[f64; M]; M], b: &[[f64; M]; M]) -> [[f64; M]; M] {
    let mut c = [[0.0; M]; M];
    for i in 0..M {
        for k in 0..M {
            for j in 0..M {
                c[i][j] += a[i][k] * b[k][j];
            }
        }
    }
    c
}

/// exp(m) by a 20-term Taylor series after scaling m to norm ≤ ¼, then squaring back.
pub(crate) fn expm<const M: usize>(m: &[[f64; M]; M]) -> [[f64; M]; M] {
    let norm = m
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let squarings = if norm > 0.25 {
        (norm / 0.25).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(squarings);
    let mut a = *m;
    a.iter_mut().flatten().for_each(|v| *v *= scale);
    let mut result = [[0.0; M]; M];
    let mut term = [[0.0; M]; M];
    for i in 0..M {
        result[i][i] = 1.0;
        term[i][i] = 1.0;
    }
    for n in 1..=20 {
        term = matmul(&term, &a);
        term.iter_mut().flatten().for_each(|v| *v /= n as f64);
        for i in 0..M {
            for j in 0..M {
                result[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..squarings {
        result = matmul(&result, &result);
    }
    result
}
