//! Iso-lines of a field sampled on a rectangular grid (marching squares), the round levels to
//! draw them at, and the field between the samples (bilinear).
//!
//! In: the grid's coordinates `xs` (increasing) and `ys` (increasing) and its values, row-major
//! with x fastest (`values[i + j * xs.len()]` at `(xs[i], ys[j])`); a non-finite value is a hole.
//! Out: line segments `[[x, y], [x, y]]` where the field, linear along each cell edge, equals a
//! level. A cell with a hole at a corner has no segment; a saddle cell is split by the mean of
//! its corners. Along a cell's edges the segments are exact for a field linear there, so the
//! iso-line of a plane lies on the plane's line.

/// One iso-line segment.
pub type Segment = [[f64; 2]; 2];

/// The value of the grid at corner (i, j).
fn at(values: &[f64], nx: usize, i: usize, j: usize) -> f64 {
    values[i + j * nx]
}

/// The segments where the field equals `level`.
pub fn iso_segments(xs: &[f64], ys: &[f64], values: &[f64], level: f64) -> Vec<Segment> {
    let (nx, ny) = (xs.len(), ys.len());
    assert_eq!(values.len(), nx * ny, "a grid's values are one per point");
    let mut out = Vec::new();
    for j in 0..ny.saturating_sub(1) {
        for i in 0..nx.saturating_sub(1) {
            // corners counter-clockwise from (i, j): 00, 10, 11, 01
            let c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
            let v = c.map(|(a, b)| at(values, nx, a, b));
            if v.iter().any(|x| !x.is_finite()) {
                continue;
            }
            let p = c.map(|(a, b)| [xs[a], ys[b]]);
            let above = v.map(|x| x >= level);
            // edge k joins corner k and corner k + 1: bottom, right, top, left
            let cross = |k: usize| -> Option<[f64; 2]> {
                let (a, b) = (k, (k + 1) % 4);
                (above[a] != above[b]).then(|| {
                    let t = (level - v[a]) / (v[b] - v[a]);
                    [p[a][0] + t * (p[b][0] - p[a][0]), p[a][1] + t * (p[b][1] - p[a][1])]
                })
            };
            let e: Vec<(usize, [f64; 2])> = (0..4).filter_map(|k| cross(k).map(|q| (k, q))).collect();
            match e.len() {
                2 => out.push([e[0].1, e[1].1]),
                4 => {
                    // a saddle: 00 and 11 on one side, 10 and 01 on the other; the centre's side
                    // joins its corners, and the segments cut off the other two
                    let centre = v.iter().sum::<f64>() / 4.0;
                    let q = |k: usize| e[k].1;
                    if (centre >= level) == above[0] {
                        out.push([q(0), q(1)]); // cuts off 10
                        out.push([q(2), q(3)]); // cuts off 01
                    } else {
                        out.push([q(3), q(0)]); // cuts off 00
                        out.push([q(1), q(2)]); // cuts off 11
                    }
                }
                _ => {}
            }
        }
    }
    out
}

/// About `n` round levels (1, 2, 2.5 or 5 times a power of ten apart) strictly between `lo` and
/// `hi`; none when the range is empty or not finite.
pub fn round_levels(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite() && hi > lo) || n == 0 {
        return Vec::new();
    }
    let raw = (hi - lo) / n as f64;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0].iter().map(|m| m * power).find(|s| *s >= raw).unwrap_or(10.0 * power);
    let first = (lo / step).floor() as i64 + 1;
    (first..).map(|k| k as f64 * step).take_while(|v| *v < hi).filter(|v| *v > lo).collect()
}

/// The field at (x, y), bilinear in the cell that holds it; NaN outside the grid or when a
/// corner is a hole.
pub fn bilinear(xs: &[f64], ys: &[f64], values: &[f64], [x, y]: [f64; 2]) -> f64 {
    let cell = |c: &[f64], v: f64| -> Option<(usize, f64)> {
        if c.len() < 2 || !(v >= c[0] && v <= c[c.len() - 1]) {
            return None;
        }
        let k = c.partition_point(|a| *a <= v).clamp(1, c.len() - 1) - 1;
        Some((k, (v - c[k]) / (c[k + 1] - c[k])))
    };
    let (Some((i, s)), Some((j, t))) = (cell(xs, x), cell(ys, y)) else { return f64::NAN };
    let nx = xs.len();
    let v = |a, b| at(values, nx, a, b);
    (1.0 - s) * (1.0 - t) * v(i, j) + s * (1.0 - t) * v(i + 1, j) + s * t * v(i + 1, j + 1) + (1.0 - s) * t * v(i, j + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(nx: usize, ny: usize, f: impl Fn(f64, f64) -> f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let xs: Vec<f64> = (0..nx).map(|i| 0.1 * i as f64).collect();
        let ys: Vec<f64> = (0..ny).map(|j| 2.0 + 0.25 * j as f64 * j as f64).collect();
        let v = ys.iter().flat_map(|y| xs.iter().map(|x| f(*x, *y)).collect::<Vec<_>>()).collect();
        (xs, ys, v)
    }

    #[test]
    fn the_contour_of_a_plane_lies_on_its_line_and_spans_the_grid() {
        // f = 3 x + 0.5 y on x in [0, 0.5], y in [2, 8.25] (uneven rows): f = 2.5 is the line
        // y = 5 - 6 x, which crosses the grid from (0, 5) to (0.5, 2)
        let f = |x: f64, y: f64| 3.0 * x + 0.5 * y;
        let (xs, ys, v) = grid(6, 6, f);
        let segs = iso_segments(&xs, &ys, &v, 2.5);
        assert!(!segs.is_empty());
        for s in &segs {
            for p in s {
                assert!((f(p[0], p[1]) - 2.5).abs() < 1e-12, "{p:?} is off the line");
            }
        }
        let length: f64 = segs.iter().map(|[a, b]| ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()).sum();
        let whole = (0.5f64.powi(2) + 3.0f64.powi(2)).sqrt();
        assert!((length / whole - 1.0).abs() < 1e-12, "{length} against {whole}");
        // a level outside the field's range has no line
        assert!(iso_segments(&xs, &ys, &v, 100.0).is_empty());
    }

    #[test]
    fn a_hole_drops_its_cells_and_a_saddle_splits_by_its_centre() {
        let (xs, ys, mut v) = grid(3, 3, |x, y| x + y);
        v[4] = f64::NAN; // the middle point touches all four cells
        assert!(iso_segments(&xs, &ys, &v, 2.3).is_empty());
        // corners 1, 0, 1, 0 counter-clockwise; centre 0.5: above 0.4 joins 00 and 11 through it
        let (xs, ys) = (vec![0.0, 1.0], vec![0.0, 1.0]);
        let v = [1.0, 0.0, 0.0, 1.0];
        let up = iso_segments(&xs, &ys, &v, 0.4);
        let down = iso_segments(&xs, &ys, &v, 0.6);
        assert_eq!((up.len(), down.len()), (2, 2));
        let near = |s: &[Segment], c: [f64; 2]| s.iter().any(|[a, b]| ((a[0] + b[0]) / 2.0 - c[0]).abs() < 0.5 && ((a[1] + b[1]) / 2.0 - c[1]).abs() < 0.5);
        // at 0.4 the low corners 10 and 01 are cut off; at 0.6 the high corners 00 and 11
        assert!(near(&up, [1.0, 0.0]) && near(&up, [0.0, 1.0]), "{up:?}");
        assert!(near(&down, [0.0, 0.0]) && near(&down, [1.0, 1.0]), "{down:?}");
    }

    #[test]
    fn levels_are_round_and_inside_the_range_and_bilinear_is_exact_on_a_plane() {
        let l = round_levels(0.0, 1.0, 5);
        assert!(l.len() == 4 && l.iter().zip([0.2, 0.4, 0.6, 0.8]).all(|(a, b)| (a - b).abs() < 1e-12), "{l:?}");
        let l = round_levels(13.2, 17.9, 6);
        assert!(l.iter().all(|v| *v > 13.2 && *v < 17.9) && l.len() >= 4, "{l:?}");
        assert!(l.windows(2).all(|w| ((w[1] - w[0]) - 1.0).abs() < 1e-9), "{l:?}");
        assert!(round_levels(1.0, 1.0, 5).is_empty() && round_levels(f64::NAN, 1.0, 5).is_empty());
        let f = |x: f64, y: f64| 3.0 * x - 0.5 * y + 1.0;
        let (xs, ys, v) = grid(4, 5, f);
        for p in [[0.05, 2.1], [0.3, 6.0], [0.0, 2.0], [0.3, 6.0]] {
            assert!((bilinear(&xs, &ys, &v, p) - f(p[0], p[1])).abs() < 1e-12, "{p:?}");
        }
        assert!(bilinear(&xs, &ys, &v, [-0.01, 3.0]).is_nan());
    }
}
