//! The small dense algebra calibration and diagnosis need (a handful of parameters): the
//! pseudo-inverse of a symmetric positive semi-definite matrix, normal equations, and the chi^2
//! distribution's upper tail. The decomposition is nalgebra's symmetric eigen-solver and the
//! tail statrs's chi^2 distribution; this file only adapts them to the row-major `Mat` the
//! fit code builds.

use nalgebra::{DMatrix, SymmetricEigen};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// A row-major square matrix.
pub type Mat = Vec<Vec<f64>>;

/// The pseudo-inverse of the symmetric positive semi-definite `a`, dropping eigenvalues below
/// `rel` times the largest, and the rank kept.
pub fn pinv_sym(a: &Mat, rel: f64) -> (Mat, usize) {
    let n = a.len();
    if n == 0 {
        return (Vec::new(), 0);
    }
    let eig = SymmetricEigen::new(DMatrix::from_fn(n, n, |i, j| a[i][j]));
    let top = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let mut out = vec![vec![0.0; n]; n];
    let mut rank = 0;
    for (k, &wk) in eig.eigenvalues.iter().enumerate() {
        if wk > rel * top && wk > 0.0 {
            rank += 1;
            let v = eig.eigenvectors.column(k);
            for i in 0..n {
                for j in 0..n {
                    out[i][j] += v[i] * v[j] / wk;
                }
            }
        }
    }
    (out, rank)
}

pub fn mat_vec(a: &Mat, x: &[f64]) -> Vec<f64> {
    a.iter().map(|r| r.iter().zip(x).map(|(a, b)| a * b).sum()).collect()
}

/// J^T J and J^T z for the columns `cols` of J (rows are observations).
pub fn normal_equations(j: &[Vec<f64>], z: &[f64], cols: &[usize]) -> (Mat, Vec<f64>) {
    let n = cols.len();
    let mut a = vec![vec![0.0; n]; n];
    let mut g = vec![0.0; n];
    for (row, zi) in j.iter().zip(z) {
        for (p, &cp) in cols.iter().enumerate() {
            g[p] += row[cp] * zi;
            for (q, &cq) in cols.iter().enumerate() {
                a[p][q] += row[cp] * row[cq];
            }
        }
    }
    (a, g)
}

/// P(X > x) for X ~ chi^2 with k degrees of freedom (1 for k = 0 or x <= 0).
pub fn chi2_sf(x: f64, k: usize) -> f64 {
    if k == 0 || x <= 0.0 {
        return 1.0;
    }
    ChiSquared::new(k as f64).expect("k > 0 degrees of freedom").sf(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigen_and_pseudo_inverse_reconstruct() {
        let a: Mat = vec![vec![4.0, 1.0, 0.5], vec![1.0, 3.0, 0.2], vec![0.5, 0.2, 2.0]];
        let (p, rank) = pinv_sym(&a, 1e-12);
        assert_eq!(rank, 3);
        for i in 0..3 {
            let row: Vec<f64> = (0..3).map(|j| (0..3).map(|k| a[i][k] * p[k][j]).sum()).collect();
            for (j, v) in row.iter().enumerate() {
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12, "{row:?}");
            }
        }
        // rank one: u u^T, pinv = u u^T / |u|^4
        let u = [1.0, 2.0, 2.0];
        let a: Mat = (0..3).map(|i| (0..3).map(|j| u[i] * u[j]).collect()).collect();
        let (p, rank) = pinv_sym(&a, 1e-10);
        assert_eq!(rank, 1);
        assert!((p[1][2] - 4.0 / 81.0).abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn chi2_tail_matches_closed_forms() {
        // k = 2: exp(-x/2); k = 1: erfc(sqrt(x/2)), e.g. P(X > 3.841459) = 0.05
        for x in [0.1, 1.0, 5.0, 30.0] {
            assert!((chi2_sf(x, 2) - (-x / 2.0).exp()).abs() < 1e-12);
        }
        assert!((chi2_sf(3.841_459, 1) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(6.634_897, 1) - 0.01).abs() < 1e-6);
        assert!((chi2_sf(18.307_04, 10) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(124.342, 100) - 0.05).abs() < 1e-5);
    }
}
