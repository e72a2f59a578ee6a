//! Point-list toolpaths, as robot post-processors export them instead of G-code.
//!
//! A CSV file in SI units: a header `x, y, z, speed, flow`, then one row per point the nozzle
//! outlet passes, `x, y, z` its world position [m], `speed` the nozzle speed of the straight
//! move arriving at it [m/s] and `flow` the pump's flow during that move [m³/s]. The first row
//! places the nozzle at t = 0 (its speed and flow are checked, not used). A move with flow > 0
//! prints at U = flow / outlet area; flow = 0 is a travel. A row at the previous point moves
//! nothing: with flow 0 it is dropped, with flow > 0 it is refused (strand lays material only
//! while the nozzle moves). Blank lines and lines starting with `#` are comments. Any other row
//! that is not five finite numbers (speed > 0, flow >= 0) is refused, naming its line.

use super::toolpath::{Move, MoveKind, Toolpath, ToolpathError};

/// The header's columns, in order.
const COLUMNS: [&str; 5] = ["x", "y", "z", "speed", "flow"];

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PointsError {
    /// A line that is not a usable header or row; `line` is 1-based.
    #[error("points line {line}: {message} ({text:?})")]
    Line { line: usize, message: String, text: String },
    #[error("points: no header line `x, y, z, speed, flow`")]
    NoHeader,
    #[error("points: {0}")]
    Toolpath(#[from] ToolpathError),
}

/// Read a point list into a toolpath starting at t = 0, for a nozzle whose outlet has area
/// `outlet_area` [m²].
pub fn parse_points(text: &str, outlet_area: f64) -> Result<Toolpath, PointsError> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !(l.trim().is_empty() || l.trim_start().starts_with('#')));
    let (i, header) = lines.next().ok_or(PointsError::NoHeader)?;
    let bad = |i: usize, raw: &str, message: String| PointsError::Line { line: i + 1, message, text: raw.trim().to_string() };
    let names: Vec<String> = header.split(',').map(|c| c.trim().to_ascii_lowercase()).collect();
    if names != COLUMNS {
        return Err(bad(i, header, format!("the header must be `{}`", COLUMNS.join(", "))));
    }
    let (mut t, mut at): (f64, Option<[f64; 3]>) = (0.0, None);
    let mut moves = Vec::new();
    for (i, raw) in lines {
        let [x, y, z, speed, flow] = row(raw).map_err(|m| bad(i, raw, m))?;
        let to = [x, y, z];
        let Some(from) = at else {
            at = Some(to); // the start
            continue;
        };
        let length = (0..3).map(|k| (to[k] - from[k]).powi(2)).sum::<f64>().sqrt();
        if length == 0.0 {
            if flow > 0.0 {
                return Err(bad(i, raw, format!("flow {flow} m³/s at the previous point: strand lays material only while the nozzle moves")));
            }
            continue;
        }
        let t1 = t + length / speed;
        let kind = if flow > 0.0 { MoveKind::Print } else { MoveKind::Travel };
        moves.push(Move { t0: t, t1, from, to, extrusion_speed: flow / outlet_area, kind });
        (t, at) = (t1, Some(to));
    }
    Ok(Toolpath::from_moves(moves)?)
}

/// One row's five numbers, or what is wrong with it.
fn row(raw: &str) -> Result<[f64; 5], String> {
    let cells: Vec<&str> = raw.split(',').map(str::trim).collect();
    if cells.len() != COLUMNS.len() {
        return Err(format!("{} values, expected 5 ({})", cells.len(), COLUMNS.join(", ")));
    }
    let mut v = [0.0; 5];
    for (k, cell) in cells.iter().enumerate() {
        v[k] = cell
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{} = {cell:?} is not a finite number", COLUMNS[k]))?;
    }
    if !(v[3] > 0.0) {
        return Err(format!("speed = {} m/s must be > 0", v[3]));
    }
    if v[4] < 0.0 {
        return Err(format!("flow = {} m³/s must be >= 0", v[4]));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_become_timed_moves() {
        let text = "# robot export\nx, y, z, speed, flow\n0, 0, 0.01, 0.05, 0\n0.1, 0, 0.01, 0.05, 2e-5\n\n0.1, 0, 0.01, 0.05, 0\n0.1, 0.02, 0.02, 0.1, 0\n";
        let p = parse_points(text, 4e-4).unwrap();
        let m = p.moves();
        assert_eq!(m.len(), 2, "{m:?}");
        assert_eq!((m[0].kind, m[0].from, m[0].to, m[0].t0), (MoveKind::Print, [0.0, 0.0, 0.01], [0.1, 0.0, 0.01], 0.0));
        assert!((m[0].t1 - 2.0).abs() < 1e-12 && (m[0].extrusion_speed - 0.05).abs() < 1e-12, "{:?}", m[0]);
        assert_eq!(m[1].kind, MoveKind::Travel);
        assert!((m[1].duration() - 0.02f64.hypot(0.01) / 0.1).abs() < 1e-12);
        assert!((p.total_extruded_length() * 4e-4 - 4e-5).abs() < 1e-15); // flow × time
        let upper = parse_points("X , Y, Z ,Speed,FLOW\n0,0,0,1,0\n1,0,0,1,0\n", 1.0).unwrap();
        assert_eq!(upper.moves().len(), 1);
    }

    #[test]
    fn bad_rows_name_their_line() {
        let head = "x, y, z, speed, flow\n0, 0, 0, 0.05, 0\n";
        for (row, needle) in [
            ("0.1, 0, 0, 0.05", "4 values, expected 5"),
            ("0.1, 0, 0, 0.05, 0, 1", "6 values"),
            ("0.1, 0, abc, 0.05, 0", "z = \"abc\" is not a finite number"),
            ("0.1, 0, 0, inf, 0", "speed = \"inf\" is not a finite number"),
            ("0.1, 0, 0, 0, 0", "speed = 0 m/s must be > 0"),
            ("0.1, 0, 0, 0.05, -1e-5", "flow = -0.00001 m³/s must be >= 0"),
            ("0, 0, 0, 0.05, 1e-5", "only while the nozzle moves"),
        ] {
            match parse_points(&format!("{head}{row}\n"), 1e-4) {
                Err(PointsError::Line { line: 3, message, text }) => {
                    assert!(message.contains(needle), "{row}: {message}");
                    assert_eq!(text, row);
                }
                other => panic!("{row}: {other:?}"),
            }
        }
        let e = parse_points("x, y, z, flow, speed\n", 1.0).unwrap_err();
        assert_eq!(e.to_string(), "points line 1: the header must be `x, y, z, speed, flow` (\"x, y, z, flow, speed\")");
        assert_eq!(parse_points("# nothing\n", 1.0).unwrap_err(), PointsError::NoHeader);
        assert!(matches!(parse_points(head, 1.0), Err(PointsError::Toolpath(ToolpathError::Empty))));
    }
}
