//! Triangles and the UV layout.
//!
//! Every tube is cut along two seams into a palm-side half and a back-side half; each half
//! unrolls into one chart: `u` is arc length around the ring (centred on the half's middle), `v`
//! is the mean distance travelled from row to row. Rows are horizontal lines in the chart and
//! `u` grows monotonically along each of them, so no chart folds over itself, and the triangles
//! keep the mesh's counter-clockwise orientation.
//!
//! All palm-side charts go to the left half of the texture, all back-side charts to the right
//! half, laid out like a hand print seen from that side (fingers up): the thumb at the bottom,
//! the palm above it, the four fingers in a row on top. One scale is shared by every chart so
//! texel density is uniform.

use std::collections::HashMap;

use glam::DVec2;

use super::tube::{Piece, Row, Tube};
use crate::model::UvLayout;

/// Blank border around the texture and between charts, in UV units.
const MARGIN: f64 = 0.012;
/// Gap between neighbouring charts, in UV units.
const GAP: f64 = 0.02;

/// The mesh triangles with their UV triangles.
#[derive(Debug, Clone)]
pub(super) struct Unwrapped {
    /// Mesh triangles (counter-clockwise from outside).
    pub faces: Vec<[u32; 3]>,
    /// The layout; `uv.faces[i]` belongs to `faces[i]`.
    pub uv: UvLayout,
}

/// One unrolled half-tube, in metres before packing.
struct Chart {
    piece: Piece,
    half: usize,
    uvs: Vec<DVec2>,
    /// Faces as `(mesh face index, chart-local UV indices)`.
    faces: Vec<(usize, [u32; 3])>,
}

impl Chart {
    fn bounds(&self) -> (DVec2, DVec2) {
        let lo = self
            .uvs
            .iter()
            .fold(DVec2::splat(f64::INFINITY), |a, b| a.min(*b));
        let hi = self
            .uvs
            .iter()
            .fold(DVec2::splat(f64::NEG_INFINITY), |a, b| a.max(*b));
        (lo, hi)
    }

    fn size(&self) -> DVec2 {
        let (lo, hi) = self.bounds();
        hi - lo
    }
}

/// Builds the triangles and UV layout of all tubes, tube after tube, each in the order of
/// [`Tube::faces`].
pub(super) fn unwrap(tubes: &[Tube]) -> Unwrapped {
    let mut faces = Vec::new();
    let mut charts = Vec::new();
    for tube in tubes {
        let tube_faces = tube.faces();
        let unrolled = [unroll(tube, 0), unroll(tube, 1)];
        let mut local: [Chart; 2] = [0, 1].map(|half| Chart {
            piece: tube.piece,
            half,
            uvs: Vec::new(),
            faces: Vec::new(),
        });
        let mut index: [HashMap<(usize, usize), u32>; 2] = [HashMap::new(), HashMap::new()];
        for face in tube_faces {
            let h = face.half;
            let corners = face.corners.map(|c| {
                *index[h].entry(c).or_insert_with(|| {
                    local[h].uvs.push(unrolled[h][&c]);
                    u32::try_from(local[h].uvs.len() - 1).expect("UV count fits in u32")
                })
            });
            local[h].faces.push((faces.len(), corners));
            faces.push(face.verts);
        }
        charts.extend(local.into_iter().filter(|c| !c.faces.is_empty()));
    }
    let uv = pack(&charts, faces.len());
    Unwrapped { faces, uv }
}

/// Unrolls half `h` of a tube: chart coordinates (metres) of each `(row, slot)`.
fn unroll(tube: &Tube, h: usize) -> HashMap<(usize, usize), DVec2> {
    let slots = tube.half_slots(h);
    let row_points = |row: &Row| -> Vec<glam::DVec3> {
        match row {
            Row::Pole { pos, .. } => vec![*pos],
            Row::Ring { pos, .. } => slots.iter().map(|&k| pos[k]).collect(),
        }
    };
    let mut out = HashMap::new();
    let mut v = 0.0;
    let mut previous: Option<Vec<glam::DVec3>> = None;
    for (r, row) in tube.rows.iter().enumerate() {
        let pts = row_points(row);
        if let Some(prev) = &previous {
            v += mean_step(prev, &pts);
        }
        let mut arc = vec![0.0];
        for w in pts.windows(2) {
            arc.push(arc[arc.len() - 1] + w[0].distance(w[1]));
        }
        let centre = 0.5 * arc[arc.len() - 1];
        match row {
            Row::Pole { .. } => {
                out.insert((r, 0), DVec2::new(0.0, v));
            }
            Row::Ring { .. } => {
                for (&k, a) in slots.iter().zip(&arc) {
                    out.insert((r, k), DVec2::new(a - centre, v));
                }
            }
        }
        previous = Some(pts);
    }
    out
}

/// Mean distance between corresponding points of two rows (a pole matches every point).
fn mean_step(a: &[glam::DVec3], b: &[glam::DVec3]) -> f64 {
    let n = a.len().max(b.len());
    let total: f64 = (0..n)
        .map(|i| a[i.min(a.len() - 1)].distance(b[i.min(b.len() - 1)]))
        .sum();
    total / n as f64
}

/// The charts of each texture half, row by row from the bottom, left to right: the thumb, the
/// palm, then the four fingers as seen from that side with the fingers up.
fn layout_rows(half: usize) -> [Vec<Piece>; 3] {
    use Piece::{Finger, Palm, Thumb};
    let fingers = if half == 0 {
        [3, 2, 1, 0]
    } else {
        [0, 1, 2, 3]
    };
    [vec![Thumb], vec![Palm], fingers.map(Finger).to_vec()]
}

/// Packs the charts into `[0, 1]^2` (palm side left, back side right) with one common scale.
fn pack(charts: &[Chart], face_count: usize) -> UvLayout {
    let find =
        |piece: Piece, half: usize| charts.iter().find(|c| c.piece == piece && c.half == half);
    let mut scale = f64::INFINITY;
    for half in 0..2 {
        let rows = layout_rows(half);
        let mut height = 0.0;
        for row in &rows {
            let sizes: Vec<DVec2> = row
                .iter()
                .filter_map(|&p| find(p, half))
                .map(Chart::size)
                .collect();
            let width: f64 = sizes.iter().map(|s| s.x).sum();
            let gaps = GAP * sizes.len().saturating_sub(1) as f64;
            scale = scale.min((0.5 - 2.0 * MARGIN - gaps) / width);
            height += sizes.iter().map(|s| s.y).fold(0.0, f64::max);
        }
        scale = scale.min((1.0 - 2.0 * MARGIN - GAP * (rows.len() - 1) as f64) / height);
    }

    let mut uvs = Vec::new();
    let mut faces = vec![[0u32; 3]; face_count];
    for half in 0..2 {
        let mut y = MARGIN;
        for row in layout_rows(half) {
            let placed: Vec<&Chart> = row.iter().filter_map(|&p| find(p, half)).collect();
            let width: f64 = placed.iter().map(|c| c.size().x * scale).sum::<f64>()
                + GAP * placed.len().saturating_sub(1) as f64;
            let mut x = 0.5 * half as f64 + 0.25 - 0.5 * width;
            let mut row_height: f64 = 0.0;
            for chart in placed {
                let (lo, _) = chart.bounds();
                let base = u32::try_from(uvs.len()).expect("UV count fits in u32");
                uvs.extend(
                    chart
                        .uvs
                        .iter()
                        .map(|p| DVec2::new(x, y) + (*p - lo) * scale),
                );
                for (face, local) in &chart.faces {
                    faces[*face] = local.map(|i| base + i);
                }
                x += chart.size().x * scale + GAP;
                row_height = row_height.max(chart.size().y * scale);
            }
            y += row_height + GAP;
        }
    }
    UvLayout { uvs, faces }
}
