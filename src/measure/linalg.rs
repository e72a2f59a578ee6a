//! The small dense algebra calibration and diagnosis need (a handful of parameters): symmetric
//! eigen-decomposition by cyclic Jacobi rotations, the pseudo-inverse built on it, and the chi^2
//! distribution's upper tail.

/// A row-major square matrix.
pub type Mat = Vec<Vec<f64>>;

/// Eigenvalues and eigenvectors (as columns of `v`) of the symmetric `a`.
pub fn sym_eigen(a: &Mat) -> (Vec<f64>, Mat) {
    let n = a.len();
    let mut a = a.clone();
    let mut v: Mat = (0..n).map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect()).collect();
    for _sweep in 0..100 {
        let off: f64 = (0..n).flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j))).map(|(i, j)| a[i][j] * a[i][j]).sum();
        let diag: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * diag.max(1e-300) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
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
        }
    }
    ((0..n).map(|i| a[i][i]).collect(), v)
}

/// The pseudo-inverse of the symmetric positive semi-definite `a`, dropping eigenvalues below
/// `rel` times the largest, and the rank kept.
pub fn pinv_sym(a: &Mat, rel: f64) -> (Mat, usize) {
    let n = a.len();
    let (w, v) = sym_eigen(a);
    let top = w.iter().cloned().fold(0.0, f64::max);
    let mut out = vec![vec![0.0; n]; n];
    let mut rank = 0;
    for (k, &wk) in w.iter().enumerate() {
        if wk > rel * top && wk > 0.0 {
            rank += 1;
            for i in 0..n {
                for j in 0..n {
                    out[i][j] += v[i][k] * v[j][k] / wk;
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

/// P(X > x) for X ~ chi^2 with k degrees of freedom (the regularised upper incomplete gamma
/// function Q(k/2, x/2), by its series below a + 1 and its continued fraction above).
pub fn chi2_sf(x: f64, k: usize) -> f64 {
    if k == 0 {
        return 1.0;
    }
    if x <= 0.0 {
        return 1.0;
    }
    let (a, x) = (k as f64 / 2.0, x / 2.0);
    let ln_front = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..1000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        (1.0 - sum * ln_front.exp()).max(0.0)
    } else {
        // Lentz's method
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..1000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (ln_front.exp() * h).min(1.0)
    }
}

/// P(X > f) for X ~ F(d1, d2): the regularised incomplete beta I_x(d2/2, d1/2) at
/// x = d2 / (d2 + d1 f).
pub fn f_sf(f: f64, d1: usize, d2: usize) -> f64 {
    if d1 == 0 || d2 == 0 || f.is_nan() {
        return 1.0;
    }
    if f <= 0.0 {
        return 1.0;
    }
    let (a, b) = (d2 as f64 / 2.0, d1 as f64 / 2.0);
    incomplete_beta(d2 as f64 / (d2 as f64 + d1 as f64 * f), a, b)
}

/// The regularised incomplete beta function I_x(a, b), by its continued fraction (Lentz) on the
/// side where it converges fast.
fn incomplete_beta(x: f64, a: f64, b: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    if x > (a + 1.0) / (a + b + 2.0) {
        return 1.0 - incomplete_beta(1.0 - x, b, a);
    }
    let tiny = 1e-300;
    let (mut c, mut d) = (1.0, 1.0 - (a + b) * x / (a + 1.0));
    if d.abs() < tiny {
        d = tiny;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..1000 {
        let m = m as f64;
        for num in [m * (b - m) * x / ((a + 2.0 * m - 1.0) * (a + 2.0 * m)), -(a + m) * (a + b + m) * x / ((a + 2.0 * m) * (a + 2.0 * m + 1.0))] {
            d = 1.0 + num * d;
            if d.abs() < tiny {
                d = tiny;
            }
            c = 1.0 + num / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            h *= d * c;
        }
        if (d * c - 1.0).abs() < 1e-15 {
            break;
        }
    }
    (ln_front.exp() * h / a).clamp(0.0, 1.0)
}

/// ln Gamma(x) for x > 0 (Lanczos, g = 7, 9 terms).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = G[0];
    let t = x + 7.5;
    for (i, g) in G.iter().enumerate().skip(1) {
        a += g / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
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
        for (f, d1, d2, p) in [(4.964603, 1, 10, 0.05), (10.04429, 1, 10, 0.01), (3.708265, 3, 10, 0.05), (3.325835, 5, 10, 0.05), (2.866081, 4, 20, 0.05), (6.358873, 2, 15, 0.01)] {
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
