//! Small dense linear algebra shared by the kernel and the layers above it: the eigenvalues and
//! eigenvectors of a symmetric matrix, by cyclic Jacobi rotations (a building's modes,
//! `kernel::effects::building`; CMA-ES's covariance, `orchestration::preparation::cmaes`).

/// The eigenvalues (unsorted) and eigenvectors (as columns) of the symmetric matrix `a`, by
/// cyclic Jacobi rotations until the off-diagonal's squares sum to at most 1e-30 of the
/// diagonal's, or 100 sweeps.
pub fn symmetric_eigen(mut a: Vec<Vec<f64>>) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = a.len();
    let mut v: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| f64::from(u8::from(i == j))).collect())
        .collect();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let scale: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * scale || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                rotate(&mut a, &mut v, p, q);
            }
        }
    }
    ((0..n).map(|i| a[i][i]).collect(), v)
}

/// One Jacobi rotation zeroing a[p][q] (Golub & Van Loan, Algorithm 8.5.2), applied to the
/// eigenvector columns too.
fn rotate(a: &mut [Vec<f64>], v: &mut [Vec<f64>], p: usize, q: usize) {
    if a[p][q] == 0.0 {
        return;
    }
    let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
    let t = if theta == 0.0 { 1.0 } else { t };
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    let n = a.len();
    for k in 0..n {
        let (akp, akq) = (a[k][p], a[k][q]);
        a[k][p] = c * akp - s * akq;
        a[k][q] = s * akp + c * akq;
    }
    for k in 0..n {
        let (apk, aqk) = (a[p][k], a[q][k]);
        a[p][k] = c * apk - s * aqk;
        a[q][k] = s * apk + c * aqk;
    }
    for row in v.iter_mut() {
        let (vp, vq) = (row[p], row[q]);
        row[p] = c * vp - s * vq;
        row[q] = s * vp + c * vq;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The eigenpairs of a 4×4 symmetric matrix: A v = λ v for each column v, and the columns
    /// orthonormal; the eigenvalues sum to the trace.
    #[test]
    fn eigenpairs_satisfy_a_v_equals_lambda_v() {
        let a = vec![
            vec![4.0, 1.0, -2.0, 0.5],
            vec![1.0, 3.0, 0.0, 1.5],
            vec![-2.0, 0.0, 5.0, -1.0],
            vec![0.5, 1.5, -1.0, 2.0],
        ];
        let (lambda, v) = symmetric_eigen(a.clone());
        let n = a.len();
        for k in 0..n {
            for i in 0..n {
                let av: f64 = (0..n).map(|j| a[i][j] * v[j][k]).sum();
                assert!(
                    (av - lambda[k] * v[i][k]).abs() < 1e-12,
                    "pair {k}, row {i}"
                );
            }
            for m in 0..n {
                let dot: f64 = (0..n).map(|i| v[i][k] * v[i][m]).sum();
                let want = if k == m { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-12, "columns {k}, {m}: {dot}");
            }
        }
        assert!((lambda.iter().sum::<f64>() - 14.0).abs() < 1e-12);
    }
}
