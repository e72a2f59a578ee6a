//! Contour plots of fields on one grid, side by side in a PNG: each field's iso-lines at round
//! levels, labelled with their values; the region where every field lies within its band shaded;
//! each band's edges drawn bold; the samples dotted and a point crossed.
//!
//! In: a [`ContourMap`] (the grid, its axes' descriptions, the panels, the point). Out: the PNG
//! at a path ending in `.png`. The lines come from `contour.rs` (marching squares, linear along
//! the cells' edges); the shaded region from the fields bilinear within each cell, sampled
//! [`SHADE`] times across a cell each way, so the shading meets the bold band edges.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::contour::{bilinear, iso_segments, round_levels};
use super::plot::{draw_error, ensure_font, xy_chart_with_x_labels, PlotError, FAMILY};

/// Sub-cells across one grid cell, each way, for the shading.
pub const SHADE: usize = 12;

/// Iso-lines a panel aims at (round levels, so a few more or fewer).
const LEVELS: usize = 6;

/// One field of a [`ContourMap`]: its title, its values on the grid (x fastest; a non-finite
/// value is a hole) and the band `[lo, hi]` it must lie in (an end may be infinite).
pub struct ContourPanel {
    pub title: String,
    pub values: Vec<f64>,
    pub band: Option<[f64; 2]>,
}

/// Fields on one grid `xs` x `ys`, and a point to mark.
pub struct ContourMap {
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    pub x_desc: String,
    pub y_desc: String,
    pub panels: Vec<ContourPanel>,
    pub point: Option<[f64; 2]>,
}

impl ContourMap {
    /// Whether every panel with a band lies within it at `p`, the fields bilinear between the
    /// samples (false where one is a hole).
    pub fn within_bands(&self, p: [f64; 2]) -> bool {
        self.panels.iter().filter_map(|c| c.band.map(|b| (c, b))).all(|(c, [lo, hi])| {
            let v = bilinear(&self.xs, &self.ys, &c.values, p);
            v >= lo && v <= hi
        })
    }
}

/// The decimals that tell levels `step` apart.
fn decimals(step: f64) -> usize {
    if !(step > 0.0 && step.is_finite()) {
        return 3;
    }
    let mut d = (-step.log10().floor()).max(0.0) as usize;
    // 2.5 x 10^k needs one more
    if ((step / 10f64.powi(-(d as i32))) - (step / 10f64.powi(-(d as i32))).round()).abs() > 1e-6 {
        d += 1;
    }
    d
}

/// Writes `m` as contour plots side by side (420 x 440 pixels a panel) to `path` (`.png`).
pub fn plot_contour_maps(path: &Path, m: &ContourMap) -> Result<(), PlotError> {
    ensure_font()?;
    if path.extension().is_none_or(|e| !e.eq_ignore_ascii_case("png")) {
        return Err(PlotError::NotPng { path: path.to_path_buf() });
    }
    let err = draw_error(path);
    let (nx, ny) = (m.xs.len(), m.ys.len());
    if nx < 2 || ny < 2 || m.panels.iter().any(|p| p.values.len() != nx * ny) {
        return Err(PlotError::Draw { path: path.to_path_buf(), message: format!("a contour map needs at least 2 x 2 points and a value at each of its {nx} x {ny}") });
    }
    let panels = m.panels.len().max(1);
    let root = BitMapBackend::new(path, (420 * panels as u32, 440)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (x0, x1, y0, y1) = (m.xs[0], m.xs[nx - 1], m.ys[0], m.ys[ny - 1]);
    // the shading's sub-cells, the same in every panel
    let sub = |c: &[f64], k: usize| -> Vec<f64> { (0..=SHADE * (k - 1)).map(|s| { let (cell, f) = (s / SHADE, (s % SHADE) as f64 / SHADE as f64); if cell + 1 >= k { c[k - 1] } else { c[cell] + f * (c[cell + 1] - c[cell]) } }).collect() };
    let (sx, sy) = (sub(&m.xs, nx), sub(&m.ys, ny));
    let mut shaded = Vec::new();
    for j in 0..sy.len() - 1 {
        for i in 0..sx.len() - 1 {
            let centre = [0.5 * (sx[i] + sx[i + 1]), 0.5 * (sy[j] + sy[j + 1])];
            if m.panels.iter().any(|p| p.band.is_some()) && m.within_bands(centre) {
                shaded.push([(sx[i], sy[j]), (sx[i + 1], sy[j + 1])]);
            }
        }
    }
    let region = RGBColor(150, 220, 150).filled();
    let hole = RGBColor(210, 210, 210).filled();
    let line = RGBColor(40, 70, 160);
    for (area, p) in root.split_evenly((1, panels)).iter().zip(&m.panels) {
        let body = area.titled(&p.title, (FAMILY, 17)).map_err(|e| err(&e))?;
        let mut chart = xy_chart_with_x_labels(&body, x0..x1, y0..y1, (&m.x_desc, &m.y_desc), 4).map_err(|e| err(&e))?;
        chart.draw_series(shaded.iter().map(|r| Rectangle::new(*r, region))).map_err(|e| err(&e))?;
        // holes: the cells with a corner that has no value
        let cells = (0..ny - 1).flat_map(|j| (0..nx - 1).map(move |i| (i, j)));
        let holes = cells.filter(|&(i, j)| [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)].iter().any(|&(a, b)| !p.values[a + b * nx].is_finite()));
        chart.draw_series(holes.map(|(i, j)| Rectangle::new([(m.xs[i], m.ys[j]), (m.xs[i + 1], m.ys[j + 1])], hole))).map_err(|e| err(&e))?;
        let (lo, hi) = p.values.iter().filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
        let levels = round_levels(lo, hi, LEVELS);
        let digits = decimals(if levels.len() > 1 { levels[1] - levels[0] } else { (hi - lo).abs() });
        for level in &levels {
            let segs = iso_segments(&m.xs, &m.ys, &p.values, *level);
            chart.draw_series(segs.iter().map(|[a, b]| PathElement::new(vec![(a[0], a[1]), (b[0], b[1])], line.stroke_width(1)))).map_err(|e| err(&e))?;
            // the label on the segment farthest from the plot's edges, on a white patch
            let inner = |s: &&[[f64; 2]; 2]| {
                let c = [0.5 * (s[0][0] + s[1][0]), 0.5 * (s[0][1] + s[1][1])];
                ((c[0] - x0) / (x1 - x0)).min((x1 - c[0]) / (x1 - x0)).min((c[1] - y0) / (y1 - y0)).min((y1 - c[1]) / (y1 - y0))
            };
            if let Some(s) = segs.iter().max_by(|a, b| inner(a).total_cmp(&inner(b))) {
                let text = format!("{level:.digits$}");
                let half = 4 * text.len() as i32;
                let style = (FAMILY, 12).into_font().color(&line).pos(Pos::new(HPos::Center, VPos::Center));
                let label = EmptyElement::at((0.5 * (s[0][0] + s[1][0]), 0.5 * (s[0][1] + s[1][1]))) + Rectangle::new([(-half - 1, -7), (half + 1, 7)], WHITE.filled()) + Text::new(text, (0, 0), style);
                chart.draw_series(std::iter::once(label)).map_err(|e| err(&e))?;
            }
        }
        // the band's edges, bold
        for edge in p.band.iter().flatten().filter(|v| v.is_finite()) {
            let segs = iso_segments(&m.xs, &m.ys, &p.values, *edge);
            chart.draw_series(segs.iter().map(|[a, b]| PathElement::new(vec![(a[0], a[1]), (b[0], b[1])], BLACK.stroke_width(3)))).map_err(|e| err(&e))?;
        }
        let samples = m.ys.iter().flat_map(|y| m.xs.iter().map(move |x| (*x, *y)));
        chart.draw_series(samples.map(|q| Circle::new(q, 2, RGBColor(90, 90, 90).filled()))).map_err(|e| err(&e))?;
        if let Some([x, y]) = m.point {
            chart.draw_series(std::iter::once(Cross::new((x, y), 9, RED.stroke_width(3)))).map_err(|e| err(&e))?;
        }
    }
    root.present().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_contour_map_is_written_and_its_region_is_where_every_band_holds() {
        let (xs, ys) = (vec![0.0, 1.0, 2.0, 3.0], vec![10.0, 20.0, 30.0]);
        let plane = |a: f64, b: f64| ys.iter().flat_map(|y| xs.iter().map(move |x| a * x + b * y)).collect::<Vec<f64>>();
        let mut hole = plane(0.0, 1.0);
        hole[0] = f64::NAN;
        let m = ContourMap {
            xs: xs.clone(),
            ys: ys.clone(),
            x_desc: "x".into(),
            y_desc: "y".into(),
            panels: vec![
                ContourPanel { title: "x".into(), values: plane(1.0, 0.0), band: Some([0.5, 2.5]) },
                ContourPanel { title: "y".into(), values: hole, band: Some([15.0, f64::INFINITY]) },
            ],
            point: Some([1.5, 25.0]),
        };
        assert!(m.within_bands([1.5, 25.0]) && m.within_bands([2.4, 16.0]));
        assert!(!m.within_bands([2.6, 25.0]) && !m.within_bands([1.5, 14.0]) && !m.within_bands([0.2, 12.0]));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.png");
        plot_contour_maps(&path, &m).unwrap();
        assert!(std::fs::read(&path).unwrap().starts_with(b"\x89PNG"));
        assert!(plot_contour_maps(&dir.path().join("map.svg"), &m).is_err());
        assert_eq!((decimals(0.5), decimals(2.5), decimals(0.25), decimals(20.0)), (1, 1, 2, 0));
    }
}
