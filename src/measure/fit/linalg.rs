//! The small dense algebra calibration and diagnosis need (a handful of parameters): the
//! pseudo-inverse of a symmetric positive semi-definite matrix, normal equations, and the upper
//! tails of the chi^2 and F distributions. The decomposition is nalgebra's symmetric eigen-solver
//! and the tails statrs's distributions; this file only adapts them to the row-major `Mat` the
//! fit code builds.

use nalgebra::{DMatrix, SymmetricEigen};
use statrs::distribution::{ChiSquared, ContinuousCDF, FisherSnedecor};

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

/// The Gauss-Newton step -A^+ g of the normal equations (A, g), eigenvalues of A below `rel`
/// times the largest dropped.
pub fn gauss_newton_step(a: &Mat, g: &[f64], rel: f64) -> Vec<f64> {
    let (inv, _) = pinv_sym(a, rel);
    inv.iter().map(|r| -r.iter().zip(g).map(|(a, b)| a * b).sum::<f64>()).collect()
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

/// P(X > f) for X ~ F(d1, d2) (1 for a zero degree of freedom, f <= 0 or NaN).
pub fn f_sf(f: f64, d1: usize, d2: usize) -> f64 {
    if d1 == 0 || d2 == 0 || f.is_nan() || f <= 0.0 {
        return 1.0;
    }
    FisherSnedecor::new(d1 as f64, d2 as f64).expect("d1, d2 > 0 degrees of freedom").sf(f)
}

/// Broyden's update of `jac` (at `from`) for a step to `to`, where the values went from `v0` to
/// `v1`: the least change, in the parameters' scales, after which the Jacobian maps the step onto
/// the values' change.
pub fn secant_update(
    jac: &[Vec<f64>],
    (from, to): (&[f64], &[f64]),
    scale: &[f64],
    (v0, v1): (&[f64], &[f64]),
) -> Vec<Vec<f64>> {
    let dx: Vec<f64> = to.iter().zip(from).map(|(b, a)| b - a).collect();
    let ds: Vec<f64> = dx.iter().zip(scale).map(|(d, s)| d / s).collect();
    let norm2: f64 = ds.iter().map(|d| d * d).sum();
    jac.iter()
        .zip(v0.iter().zip(v1))
        .map(|(row, (a, b))| {
            let miss = (b - a) - row.iter().zip(&dx).map(|(g, d)| g * d).sum::<f64>();
            row.iter().zip(ds.iter().zip(scale)).map(|(g, (d, s))| g + miss * d / (s * norm2)).collect()
        })
        .collect()
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
    fn f_tail_matches_tables() {
        // F(1, d2) = t(d2)^2; tabulated 5 % and 1 % points
        for (f, d1, d2, p) in [
            (4.964603, 1, 10, 0.05),
            (10.04429, 1, 10, 0.01),
            (3.708265, 3, 10, 0.05),
            (3.325835, 5, 10, 0.05),
            (2.866081, 4, 20, 0.05),
            (6.358873, 2, 15, 0.01),
        ] {
            assert!((f_sf(f, d1, d2) - p).abs() < 1e-6, "F({d1}, {d2}) at {f}: {}", f_sf(f, d1, d2));
        }
        // d1 = 2: (1 + 2 f / d2)^(-d2 / 2)
        assert!((f_sf(1.7, 2, 9) - (1.0 + 2.0 * 1.7 / 9.0f64).powf(-4.5)).abs() < 1e-12);
        assert_eq!(f_sf(0.0, 2, 9), 1.0);
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
