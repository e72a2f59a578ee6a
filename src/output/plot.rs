//! PNG plots.
//!
//! Text is drawn with DejaVu Sans embedded in the binary (plotters' `ab_glyph` feature), so
//! plotting needs no system fonts and building needs no fontconfig headers.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

/// DejaVu Sans 2.37, unmodified; licence in `fixtures/fonts/LICENSE-DejaVu.txt`.
static FONT: &[u8] = include_bytes!("../../fixtures/fonts/DejaVuSans.ttf");
pub(super) const FAMILY: &str = "sans-serif";

const SIZE: (u32, u32) = (900, 500);

/// Why a plot was not written.
#[derive(Clone, Debug, thiserror::Error)]
pub enum PlotError {
    #[error("embedded font DejaVuSans.ttf could not be parsed")]
    Font,
    #[error("{}: plot file name must end in .png", path.display())]
    NotPng { path: PathBuf },
    /// Drawing or writing the PNG failed (plotters' message).
    #[error("{}: {message}", path.display())]
    Draw { path: PathBuf, message: String },
}

/// The drawing error `e` of the plot at `path`.
pub(super) fn draw_error(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError::Draw { path: path.to_path_buf(), message: e.to_string() }
}
const MARGIN: u32 = 15;
const X_LABEL_AREA: u32 = 45;
const Y_LABEL_AREA: u32 = 60;

/// Registers the embedded font once per process; plotters looks fonts up by family name.
pub(super) fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<Result<(), PlotError>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            register_font(FAMILY, FontStyle::Normal, FONT)
                .map_err(|_| PlotError::Font)
        })
        .clone()
}

/// Plots cross-section outlines to a PNG of 900 x 500 pixels.
///
/// Each entry of `sections` is a legend label and a (y, z) polyline in metres (for example
/// [`crate::observe::CrossSection::profile`]); `measured` points are drawn as black markers
/// labelled "measured". Axes are in millimetres. The scales are equal (true shape) unless
/// that would leave the data less than a quarter of the plot in one direction; then each
/// axis is fitted separately and the title says "not to scale". Non-finite points are
/// skipped. `path` must end in `.png`.
pub fn plot_cross_section(
    path: &Path,
    title: &str,
    sections: &[(String, Vec<[f64; 2]>)],
    measured: Option<&[[f64; 2]]>,
) -> Result<(), PlotError> {
    let is_png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        return Err(PlotError::NotPng { path: path.to_path_buf() });
    }
    ensure_font()?;
    let err = draw_error(path);

    let to_mm = |pts: &[[f64; 2]]| -> Vec<(f64, f64)> {
        pts.iter()
            .filter(|p| p[0].is_finite() && p[1].is_finite())
            .map(|p| (p[0] * 1e3, p[1] * 1e3))
            .collect()
    };
    let lines: Vec<(&str, Vec<(f64, f64)>)> = sections
        .iter()
        .map(|(l, p)| (l.as_str(), to_mm(p)))
        .collect();
    let marks = measured.map(to_mm).unwrap_or_default();

    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    // Title first, so the remaining area (and hence the plot's pixel size) is known for the aspect ratio.
    let body_probe = root.titled(title, (FAMILY, 22)).map_err(|e| err(&e))?;
    let (bw, bh) = body_probe.dim_in_pixel();
    let px = (
        bw.saturating_sub(2 * MARGIN + Y_LABEL_AREA).max(1) as f64,
        bh.saturating_sub(2 * MARGIN + X_LABEL_AREA).max(1) as f64,
    );
    let all = lines.iter().flat_map(|(_, p)| p.iter()).chain(marks.iter());
    let (yr, zr, to_scale) = ranges(all, px);

    // Redraw the title with the scale note only when needed; the probe's title is then covered.
    let body = if to_scale {
        body_probe
    } else {
        root.fill(&WHITE).map_err(|e| err(&e))?;
        root.titled(&format!("{title} (not to scale)"), (FAMILY, 22))
            .map_err(|e| err(&e))?
    };

    let mut chart = ChartBuilder::on(&body)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(yr.0..yr.1, zr.0..zr.1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("y [mm]")
        .y_desc("z [mm]")
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 16))
        .draw()
        .map_err(|e| err(&e))?;

    let mut labelled = false;
    for (i, (label, pts)) in lines.into_iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let series = chart
            .draw_series(LineSeries::new(pts, colour.stroke_width(2)))
            .map_err(|e| err(&e))?;
        if !label.is_empty() {
            series.label(label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
            labelled = true;
        }
    }
    if measured.is_some() {
        chart
            .draw_series(
                marks
                    .into_iter()
                    .map(|p| Cross::new(p, 4, BLACK.stroke_width(2))),
            )
            .map_err(|e| err(&e))?
            .label("measured")
            .legend(|(x, y)| Cross::new((x + 10, y), 4, BLACK.stroke_width(2)));
        labelled = true;
    }
    if labelled {
        draw_legend(&mut chart).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))
}

/// Plots series of (x, y) points to a PNG of 900 x 500 pixels, as lines with markers (`lines`)
/// or markers only; axes fitted to the data (5 % padding), non-finite points skipped.
pub fn plot_xy(path: &Path, title: &str, x_desc: &str, y_desc: &str, series: &[(String, Vec<[f64; 2]>)], lines: bool) -> Result<(), PlotError> {
    ensure_font()?;
    let err = draw_error(path);
    let (xr, yr) = fitted_ranges(series.iter().flat_map(|(_, p)| p.iter().copied()));
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let body = root.titled(title, (FAMILY, 22)).map_err(|e| err(&e))?;
    let mut chart = xy_chart(&body, xr, yr, x_desc, y_desc).map_err(|e| err(&e))?;
    for (i, (label, pts)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let pts: Vec<(f64, f64)> = pts.iter().filter(|p| finite(**p)).map(|p| (p[0], p[1])).collect();
        if lines {
            chart.draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2))).map_err(|e| err(&e))?;
        }
        chart
            .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, colour.filled())))
            .map_err(|e| err(&e))?
            .label(label.as_str())
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
    }
    draw_legend(&mut chart).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

/// One measurement and the model's value at the same x, for [`plot_measured_model`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredPoint {
    pub x: f64,
    pub measured: f64,
    pub uncertainty: f64,
    pub model: f64,
}

/// Plots groups of measurements against a model to a PNG of 900 x 500 pixels: in each group's
/// colour, the measurements as filled markers with +- uncertainty bars and the model as hollow
/// markers joined in order of x. Axes fitted to the bars and the model (5 % padding); points with
/// a non-finite coordinate skipped.
pub fn plot_measured_model(path: &Path, title: &str, x_desc: &str, y_desc: &str, groups: &[(String, Vec<MeasuredPoint>)]) -> Result<(), PlotError> {
    ensure_font()?;
    let err = draw_error(path);
    let usable = |p: &&MeasuredPoint| p.x.is_finite() && p.measured.is_finite() && p.uncertainty.is_finite() && p.model.is_finite();
    let extent = groups
        .iter()
        .flat_map(|(_, g)| g.iter().filter(usable))
        .flat_map(|p| [[p.x, p.measured - p.uncertainty], [p.x, p.measured + p.uncertainty], [p.x, p.model]]);
    let (xr, yr) = fitted_ranges(extent);
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let body = root.titled(title, (FAMILY, 22)).map_err(|e| err(&e))?;
    let mut chart = xy_chart(&body, xr, yr, x_desc, y_desc).map_err(|e| err(&e))?;
    for (i, (label, points)) in groups.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let mut points: Vec<MeasuredPoint> = points.iter().filter(usable).copied().collect();
        points.sort_by(|a, b| a.x.total_cmp(&b.x));
        let model: Vec<(f64, f64)> = points.iter().map(|p| (p.x, p.model)).collect();
        chart.draw_series(LineSeries::new(model.clone(), colour.stroke_width(1))).map_err(|e| err(&e))?;
        chart.draw_series(model.into_iter().map(|p| Circle::new(p, 5, colour.stroke_width(2)))).map_err(|e| err(&e))?;
        // Caps are offsets in pixels from the bar's ends, so they keep their size whatever the axes.
        let cap = move |x: f64, y: f64| EmptyElement::at((x, y)) + PathElement::new(vec![(-4, 0), (4, 0)], colour.stroke_width(2));
        chart
            .draw_series(points.iter().map(|p| PathElement::new(vec![(p.x, p.measured - p.uncertainty), (p.x, p.measured + p.uncertainty)], colour.stroke_width(2))))
            .map_err(|e| err(&e))?;
        chart.draw_series(points.iter().flat_map(|p| [cap(p.x, p.measured - p.uncertainty), cap(p.x, p.measured + p.uncertainty)])).map_err(|e| err(&e))?;
        chart
            .draw_series(points.iter().map(|p| Circle::new((p.x, p.measured), 4, colour.filled())))
            .map_err(|e| err(&e))?
            .label(label.as_str())
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
    }
    draw_legend(&mut chart).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

fn finite(p: [f64; 2]) -> bool {
    p[0].is_finite() && p[1].is_finite()
}

/// Axis ranges around the finite points, padded by 5 %; a lone value or none still gets a
/// non-empty range.
fn fitted_ranges(points: impl Iterator<Item = [f64; 2]>) -> (Range<f64>, Range<f64>) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points.filter(|p| finite(*p)) {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    if !(lo[0] <= hi[0]) {
        lo = [0.0; 2];
        hi = [1.0; 2];
    }
    let pad = |a: f64, b: f64| {
        let m = ((b - a) * 0.05).max(1e-3 * a.abs().max(b.abs())).max(1e-12);
        a - m..b + m
    };
    (pad(lo[0], hi[0]), pad(lo[1], hi[1]))
}

type XyChart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;
type DrawError<'b> = DrawingAreaErrorKind<<BitMapBackend<'b> as DrawingBackend>::ErrorType>;

/// The axes and grid of an x-y plot in `body`.
fn xy_chart<'a, 'b>(body: &'a DrawingArea<BitMapBackend<'b>, Shift>, xr: Range<f64>, yr: Range<f64>, x_desc: &str, y_desc: &str) -> Result<XyChart<'a, 'b>, DrawError<'b>> {
    // plotters' own default: at most 10 labels on the x axis
    xy_chart_with_x_labels(body, xr, yr, (x_desc, y_desc), 10)
}

/// [`xy_chart`] with at most `x_labels` tick labels on the x axis: a narrow panel (a contour map's)
/// has room for a few only.
pub(super) fn xy_chart_with_x_labels<'a, 'b>(
    body: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    xr: Range<f64>,
    yr: Range<f64>,
    (x_desc, y_desc): (&str, &str),
    x_labels: usize,
) -> Result<XyChart<'a, 'b>, DrawError<'b>> {
    let mut chart = ChartBuilder::on(body).margin(MARGIN).x_label_area_size(X_LABEL_AREA).y_label_area_size(Y_LABEL_AREA).build_cartesian_2d(xr, yr)?;
    chart.configure_mesh().x_desc(x_desc).y_desc(y_desc).x_labels(x_labels).label_style((FAMILY, 14)).axis_desc_style((FAMILY, 16)).draw()?;
    Ok(chart)
}

fn draw_legend<'a, 'b: 'a>(chart: &mut XyChart<'a, 'b>) -> Result<(), DrawError<'b>> {
    chart
        .configure_series_labels()
        .label_font((FAMILY, 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
}

/// Axis ranges (mm) for the points and whether they share one scale.
///
/// `px` is the plot's size in pixels. Ranges get 5% padding; with equal scales the shorter
/// direction is widened around its centre to the same mm per pixel.
fn ranges<'a>(
    pts: impl Iterator<Item = &'a (f64, f64)>,
    px: (f64, f64),
) -> ((f64, f64), (f64, f64), bool) {
    let mut lo = (f64::INFINITY, f64::INFINITY);
    let mut hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for &(y, z) in pts {
        lo = (lo.0.min(y), lo.1.min(z));
        hi = (hi.0.max(y), hi.1.max(z));
    }
    if !(lo.0 <= hi.0) {
        // Nothing to plot: show empty axes rather than fail.
        return ((0.0, 1.0), (0.0, 1.0), true);
    }
    let pad = |a: f64, b: f64| {
        // A single point or a flat line still needs a non-empty range.
        let m = ((b - a) * 0.05).max(1e-3 * a.abs().max(b.abs())).max(1e-6);
        (a - m, b + m)
    };
    let (y, z) = (pad(lo.0, hi.0), pad(lo.1, hi.1));
    let per_px = ((y.1 - y.0) / px.0).max((z.1 - z.0) / px.1);
    let widen = |r: (f64, f64), n: f64| {
        let c = (r.0 + r.1) / 2.0;
        (c - per_px * n / 2.0, c + per_px * n / 2.0)
    };
    let (ye, ze) = (widen(y, px.0), widen(z, px.1));
    let fill = ((y.1 - y.0) / (ye.1 - ye.0)).min((z.1 - z.0) / (ze.1 - ze.0));
    if fill >= 0.25 {
        (ye, ze, true)
    } else {
        (y, z, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png_size(bytes: &[u8]) -> Option<(u32, u32)> {
        const SIG: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];
        // The IHDR chunk must come first: length (4), "IHDR" (4), width (4), height (4).
        if bytes.len() < 24 || bytes[..8] != SIG || &bytes[12..16] != b"IHDR" {
            return None;
        }
        let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
        Some((be(&bytes[16..20]), be(&bytes[20..24])))
    }

    fn semicircle(r: f64, n: usize) -> Vec<[f64; 2]> {
        (0..=n)
            .map(|i| {
                let a = std::f64::consts::PI * i as f64 / n as f64;
                [-r * a.cos(), r * a.sin()]
            })
            .collect()
    }

    #[test]
    fn plot_writes_png_of_the_right_size() {
        let dir = tempfile::tempdir().unwrap();
        let sections = vec![
            ("t = 0 s".to_string(), semicircle(0.02, 40)),
            (
                "t = 10 s".to_string(),
                semicircle(0.025, 40)
                    .iter()
                    .map(|p| [p[0], p[1] * 0.7])
                    .collect(),
            ),
        ];
        let measured: Vec<[f64; 2]> = semicircle(0.024, 8)
            .iter()
            .map(|p| [p[0], p[1] * 0.75])
            .collect();
        // A wide, flat section takes the not-to-scale path too.
        let flat = vec![(
            "flat".to_string(),
            vec![[-0.2, 0.0], [-0.2, 0.004], [0.2, 0.004], [0.2, 0.0]],
        )];
        type Case<'a> = (
            &'a str,
            &'a [(String, Vec<[f64; 2]>)],
            Option<&'a [[f64; 2]]>,
        );
        let cases: [Case; 3] = [
            ("sections.png", &sections, Some(&measured)),
            ("flat.PNG", &flat, None),
            ("empty.png", &[], None),
        ];
        for (name, s, m) in cases {
            let path = dir.path().join(name);
            plot_cross_section(&path, "cross-section", s, m).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(png_size(&bytes), Some(SIZE), "{name}");
        }
    }

    #[test]
    fn measured_model_plot_writes_png_of_the_right_size() {
        let dir = tempfile::tempdir().unwrap();
        let point = |x: f64, measured: f64| MeasuredPoint { x, measured, uncertainty: 0.1 * measured, model: 1.1 * measured };
        let groups = [
            ("A".to_string(), vec![point(20.0, 500.0), point(1.0, 120.0), point(5.0, 200.0)]),
            ("B".to_string(), vec![point(f64::NAN, 1.0), point(3.0, 300.0)]),
        ];
        for (name, g) in [("groups.png", &groups[..]), ("none.png", &[])] {
            let path = dir.path().join(name);
            plot_measured_model(&path, "stress", "rate [1/s]", "stress [Pa]", g).unwrap();
            assert_eq!(png_size(&std::fs::read(&path).unwrap()), Some(SIZE), "{name}");
        }
    }

    #[test]
    fn plot_errors_instead_of_panicking() {
        let dir = tempfile::tempdir().unwrap();
        let s = vec![(
            "a".to_string(),
            vec![[0.0, 0.0], [f64::NAN, 1.0], [0.01, 0.01]],
        )];
        let e = plot_cross_section(&dir.path().join("x.jpg"), "t", &s, None).unwrap_err();
        assert!(e.to_string().contains(".png"), "{e}");
        let e =
            plot_cross_section(&dir.path().join("no/such/dir/x.png"), "t", &s, None).unwrap_err();
        assert!(e.to_string().contains("x.png"), "{e}");
    }

    #[test]
    fn equal_scale_ranges_have_equal_mm_per_pixel() {
        let pts = [(-20.0, 0.0), (20.0, 15.0)];
        let px = (800.0, 400.0);
        let (y, z, to_scale) = ranges(pts.iter(), px);
        assert!(to_scale);
        let (sy, sz) = ((y.1 - y.0) / px.0, (z.1 - z.0) / px.1);
        assert!((sy - sz).abs() < 1e-12 * sy, "{sy} vs {sz}");
        assert!(y.0 < -20.0 && y.1 > 20.0 && z.0 < 0.0 && z.1 > 15.0);
        // 400 mm wide, 4 mm high: equal scales would squash it, so each axis is fitted.
        let (_, z, to_scale) = ranges([(-200.0, 0.0), (200.0, 4.0)].iter(), px);
        assert!(!to_scale && z.1 - z.0 < 5.0, "{z:?}");
    }
}
