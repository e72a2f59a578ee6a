//! `layer_height@X:K` and `layer_width@X:K`: a printed layer's thickness and width at a station,
//! as the reporter's `layers.csv` gives them.

use super::objective::{Kind, Objective, Takes};
use super::state::{layer_tops, section_points, section_y, Seed, State};
use super::ObservableError;
use crate::kernels::Real;

/// Thickness [m] of printed layer `layer` (1 = the bottom one) at x = station, as
/// `observe::layer_heights` (the run's `layers.csv`) gives it: the slab's particles are
/// assigned to layers by their z against the toolpath's layer heights (the nominal tops);
/// a layer's top is its highest particle + h / 2, its thickness that top minus the top of
/// the nearest non-empty layer below (the base for the first); 0 for an empty layer. The
/// assignment and the top particles are held fixed.
pub(super) const LAYER_HEIGHT: Kind = Kind { name: "layer_height", takes: Takes::StationAndLayer, measured: true, evaluate: |s, o, seed| s.layer(o, o.station(), o.layer(), true, seed) };

/// Width [m] of printed layer `layer` at x = station (`observe::layer_widths`): the y
/// extent + h of the particles `layer_height` assigns to it; with `[observe] mirror_y`, of
/// them together with their mirror images; 0 for an empty layer.
pub(super) const LAYER_WIDTH: Kind = Kind { name: "layer_width", takes: Takes::StationAndLayer, measured: true, evaluate: |s, o, seed| s.layer(o, o.station(), o.layer(), false, seed) };

impl State<'_> {
    /// A printed layer's thickness (`height`) or width at a station.
    pub(super) fn layer(&self, what: &Objective, station: f64, layer: usize, height: bool, seed: Option<Seed>) -> Result<f64, ObservableError> {
        let frame = self.frame;
        let tops = layer_tops(self.sim).ok_or_else(|| ObservableError(format!("objective {}: the scenario prints no layers whose heights ascend (the toolpath's layer z, as layers.csv takes them)", what.name())))?;
        if layer == 0 || layer > tops.len() {
            return Err(ObservableError(format!("objective {}: layer {layer} is not one of the toolpath's layers 1..={}", what.name(), tops.len())));
        }
        let pts = section_points(self.sim, frame, station).ok_or_else(|| ObservableError(format!("objective {}: no particle within half a slab of x = {station} m", what.name())))?;
        let k = layer - 1;
        let layer_of = |pt: &(usize, f64)| crate::observe::layer_of(&tops, self.world(pt.0)[2]);
        let mine: Vec<(usize, f64)> = pts.iter().copied().filter(|pt| layer_of(pt) == k).collect();
        if mine.is_empty() {
            return Ok(0.0);
        }
        if height {
            // each layer's top particle in the slab (the first on ties; the mirror images,
            // listed after the originals, add nothing in z), then this layer's and the
            // nearest non-empty one's below it
            let mut top: Vec<Option<usize>> = vec![None; k + 1];
            for pt in &pts {
                let l = layer_of(pt);
                if l <= k && top[l].is_none_or(|b| self.world(pt.0)[2] > self.world(b)[2]) {
                    top[l] = Some(pt.0);
                }
            }
            let it = top[k].expect("the layer has particles");
            let below = top[..k].iter().rev().find_map(|&t| t);
            let value = self.world(it)[2] + 0.5 * frame.spacing - below.map_or(frame.base_z, |ib| self.world(ib)[2] + 0.5 * frame.spacing);
            if let Some(s) = seed {
                s.xg[it].z += self.scale;
                if let Some(ib) = below {
                    s.xg[ib].z -= self.scale;
                }
            }
            Ok(value)
        } else {
            let py = |pt: &(usize, f64)| section_y(frame, self.world(pt.0)[1], pt.1);
            let hi = mine.iter().fold(mine[0], |b, pt| if py(pt) > py(&b) { *pt } else { b });
            let lo = mine.iter().fold(mine[0], |b, pt| if py(pt) < py(&b) { *pt } else { b });
            if let Some(s) = seed {
                s.xg[hi.0].y += hi.1 as Real * self.scale;
                s.xg[lo.0].y -= lo.1 as Real * self.scale;
            }
            Ok(py(&hi) - py(&lo) + frame.spacing)
        }
    }
}
