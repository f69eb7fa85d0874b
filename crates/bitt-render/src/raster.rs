//! Forward rasterization: triangle setup in fixed point, top-left fill rule, z-buffer.

use crate::clip::{ClipVertex, clip_triangle};
use crate::error::{RenderError, check_faces, check_image, check_len, check_positions};

/// Sub-pixel precision of the snapped vertex positions used for coverage (1/65536 px).
const SUBPIXEL_BITS: u32 = 16;
const ONE: i64 = 1 << SUBPIXEL_BITS;
const HALF: i64 = ONE / 2;
/// Guard band: screen coordinates are clamped to +-2^30 pixels before snapping.
const GUARD_PX: f64 = (1u64 << 30) as f64;

/// Per-pixel rasterization output (row-major, `index = row * width + col`, row 0 at the top).
#[derive(Debug, Clone, PartialEq)]
pub struct Fragments {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Per pixel: face index or -1 (none).
    pub face: Vec<i32>,
    /// Per pixel: perspective-correct barycentrics (b0, b1, b2) of the ORIGINAL face's
    /// vertices (sum to 1), zero where no face.
    pub bary: Vec<[f32; 3]>,
    /// Per pixel: NDC depth z/w, +inf where empty.
    pub depth: Vec<f32>,
}

impl Fragments {
    /// An empty `width x height` buffer (no face anywhere).
    ///
    /// # Panics
    /// If `width * height` overflows `usize`.
    pub fn empty(width: usize, height: usize) -> Self {
        let n = width
            .checked_mul(height)
            .expect("image size overflows usize");
        Self {
            width,
            height,
            face: vec![-1; n],
            bary: vec![[0.0; 3]; n],
            depth: vec![f32::INFINITY; n],
        }
    }
}

/// Rasterizes `faces` over clip-space vertices `clip` into a `width x height` image.
///
/// Both windings are drawn (no culling). Each face is clipped against `w > 0` and the near
/// plane, then its pixels are found by edge functions over its tight bounding box with a
/// top-left fill rule; the nearest fragment (smallest NDC z/w) wins, ties go to the lower
/// face index, fragments with z/w > 1 are discarded.
///
/// # Errors
/// Zero-size or oversized image, non-finite positions, or out-of-range vertex indices.
pub fn rasterize(
    clip: &[[f32; 4]],
    faces: &[[u32; 3]],
    width: usize,
    height: usize,
) -> Result<Fragments, RenderError> {
    check_image(width, height)?;
    check_positions(clip)?;
    check_faces(faces, clip.len())?;
    let mut out = Fragments::empty(width, height);
    for (f, &face) in faces.iter().enumerate() {
        for_each_fragment(clip, face, width, height, |pixel, bary, depth| {
            let depth = depth as f32;
            // Strict `<` with faces visited in ascending order: ties keep the lower index.
            if depth < out.depth[pixel] {
                out.depth[pixel] = depth;
                out.face[pixel] = f as i32;
                out.bary[pixel] = bary.map(|b| b as f32);
            }
        });
    }
    Ok(out)
}

/// A clipped vertex mapped to the screen (pixel units, centre of pixel `c` at `c + 0.5`).
#[derive(Debug, Clone, Copy)]
struct ScreenVertex {
    /// Snapped fixed-point position, used for exact coverage decisions.
    fx: i64,
    fy: i64,
    /// Unsnapped position, used for barycentrics.
    sx: f64,
    sy: f64,
    clip: ClipVertex,
}

impl ScreenVertex {
    fn new(clip: ClipVertex, width: usize, height: usize) -> Self {
        let [x, y, _, w] = clip.pos;
        let sx = ((x / w + 1.0) * 0.5 * width as f64).clamp(-GUARD_PX, GUARD_PX);
        let sy = ((y / w + 1.0) * 0.5 * height as f64).clamp(-GUARD_PX, GUARD_PX);
        let snap = |s: f64| (s * ONE as f64).round() as i64;
        Self {
            fx: snap(sx),
            fy: snap(sy),
            sx,
            sy,
            clip,
        }
    }
}

/// Exact edge function of edge `a -> b` at fixed-point point `(px, py)`.
fn edge_fixed(a: &ScreenVertex, b: &ScreenVertex, px: i64, py: i64) -> i128 {
    let (dx, dy) = (i128::from(b.fx - a.fx), i128::from(b.fy - a.fy));
    dx * i128::from(py - a.fy) - dy * i128::from(px - a.fx)
}

/// Float edge function of edge `a -> b` at screen point `(px, py)`.
fn edge_float(a: &ScreenVertex, b: &ScreenVertex, px: f64, py: f64) -> f64 {
    (b.sx - a.sx) * (py - a.sy) - (b.sy - a.sy) * (px - a.sx)
}

/// Top-left rule for a positively oriented triangle (edge functions positive inside, y down).
///
/// The inward normal of edge `a -> b` is `(-dy, dx)`. A pixel centre exactly on the edge is
/// drawn iff that normal points down (`dx > 0`: a top edge) or, for a vertical edge, right
/// (`dy < 0`: a left edge). This equals nudging the sample by `(eps^2, eps)`, so triangles
/// tiling a region cover every sample in it exactly once, including shared vertices.
fn is_top_left(a: &ScreenVertex, b: &ScreenVertex) -> bool {
    let (dx, dy) = (b.fx - a.fx, b.fy - a.fy);
    dx > 0 || (dx == 0 && dy < 0)
}

/// Smallest `i` with `i * ONE + HALF >= v`.
fn first_centre(v: i64) -> i64 {
    (v - HALF).div_euclid(ONE) + i64::from((v - HALF).rem_euclid(ONE) != 0)
}

/// Largest `i` with `i * ONE + HALF <= v`.
fn last_centre(v: i64) -> i64 {
    (v - HALF).div_euclid(ONE)
}

/// Rasterizes one face (indices already validated) without a depth test, calling
/// `emit(pixel, bary, depth)` for each covered pixel with the perspective-correct barycentrics
/// of the original vertices and the NDC depth. Fragments beyond the far plane are skipped.
pub(crate) fn for_each_fragment(
    clip: &[[f32; 4]],
    face: [u32; 3],
    width: usize,
    height: usize,
    mut emit: impl FnMut(usize, [f64; 3], f64),
) {
    for tri in face_triangles(clip, face, width, height) {
        raster_rows(&tri, width, tri.row0, tri.row1, &mut emit);
    }
}

/// A clipped, snapped, positively oriented triangle with its pixel-centre bounds inside the
/// image (`col0..=col1`, `row0..=row1`, non-empty).
#[derive(Debug, Clone, Copy)]
struct Triangle {
    v: [ScreenVertex; 3],
    /// Per edge `k` (opposite vertex `k`): does the top-left rule draw centres on it?
    top_left: [bool; 3],
    col0: i64,
    col1: i64,
    row0: i64,
    row1: i64,
}

/// Edge `k` is opposite vertex `k`.
const EDGES: [(usize, usize); 3] = [(1, 2), (2, 0), (0, 1)];

/// The triangles one face rasterizes as: clipped against `w > 0` and the near plane, fanned
/// from the clipped polygon's first vertex, in fan order; degenerate triangles and those with
/// no pixel centre inside the image are left out.
fn face_triangles(
    clip: &[[f32; 4]],
    face: [u32; 3],
    width: usize,
    height: usize,
) -> impl Iterator<Item = Triangle> {
    let tri = face.map(|i| clip[i as usize].map(f64::from));
    let poly = clip_triangle(tri);
    let verts: Vec<_> = poly.vertices().to_vec();
    (1..verts.len().saturating_sub(1)).filter_map(move |k| {
        let sub = [verts[0], verts[k], verts[k + 1]].map(|v| ScreenVertex::new(v, width, height));
        setup_triangle(sub, width, height)
    })
}

/// Orients a screen triangle positively and finds its pixel-centre bounds; `None` when it is
/// degenerate after snapping or covers no pixel centre of the image.
fn setup_triangle(v: [ScreenVertex; 3], width: usize, height: usize) -> Option<Triangle> {
    let area = edge_fixed(&v[0], &v[1], v[2].fx, v[2].fy);
    if area == 0 {
        return None; // degenerate (after snapping): no pixels
    }
    // Orient positively so that all edge functions are positive inside.
    let v = if area > 0 { v } else { [v[0], v[2], v[1]] };
    let min_x = v.iter().map(|p| p.fx).min().unwrap_or(0);
    let max_x = v.iter().map(|p| p.fx).max().unwrap_or(0);
    let min_y = v.iter().map(|p| p.fy).min().unwrap_or(0);
    let max_y = v.iter().map(|p| p.fy).max().unwrap_or(0);
    let col0 = first_centre(min_x).max(0);
    let col1 = last_centre(max_x).min(width as i64 - 1);
    let row0 = first_centre(min_y).max(0);
    let row1 = last_centre(max_y).min(height as i64 - 1);
    (col0 <= col1 && row0 <= row1).then(|| Triangle {
        v,
        top_left: EDGES.map(|(a, b)| is_top_left(&v[a], &v[b])),
        col0,
        col1,
        row0,
        row1,
    })
}

/// Rasterizes rows `row0..=row1` of one triangle (clamped to its bounds).
fn raster_rows(
    t: &Triangle,
    width: usize,
    row0: i64,
    row1: i64,
    emit: &mut impl FnMut(usize, [f64; 3], f64),
) {
    let v = &t.v;
    for row in row0.max(t.row0)..=row1.min(t.row1) {
        let py = row * ONE + HALF;
        for col in t.col0..=t.col1 {
            let px = col * ONE + HALF;
            let e = EDGES.map(|(a, b)| edge_fixed(&v[a], &v[b], px, py));
            let inside = (0..3).all(|k| e[k] > 0 || (e[k] == 0 && t.top_left[k]));
            if !inside {
                continue;
            }
            let (fx, fy) = (col as f64 + 0.5, row as f64 + 0.5);
            let mut s = EDGES.map(|(a, b)| edge_float(&v[a], &v[b], fx, fy));
            let mut total = s[0] + s[1] + s[2];
            if !(total > 0.0 && total.is_finite()) {
                // Sliver below float precision: fall back to the exact snapped values.
                s = e.map(|x| x as f64);
                total = s[0] + s[1] + s[2];
            }
            if let Some((bary, depth)) = perspective(v, s.map(|x| x / total)) {
                emit((row as usize) * width + col as usize, bary, depth);
            }
        }
    }
}

/// [`rasterize`] on all cores: the image is cut into bands of rows, each band runs the same
/// per-pixel depth test over every face (in ascending order) that reaches it, so the result
/// is bit-identical to [`rasterize`] for any thread count.
///
/// # Errors
/// As [`rasterize`].
pub fn rasterize_parallel(
    clip: &[[f32; 4]],
    faces: &[[u32; 3]],
    width: usize,
    height: usize,
) -> Result<Fragments, RenderError> {
    use rayon::prelude::*;
    check_image(width, height)?;
    check_positions(clip)?;
    check_faces(faces, clip.len())?;
    // Triangle setup once per face, in face order (fan order within a face).
    let triangles: Vec<(i32, Triangle)> = faces
        .par_iter()
        .enumerate()
        .map(|(f, &face)| {
            face_triangles(clip, face, width, height)
                .map(|t| (f as i32, t))
                .collect::<Vec<_>>()
        })
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .collect();
    let mut out = Fragments::empty(width, height);
    let band_rows = height.div_ceil(4 * rayon::current_num_threads()).max(1);
    let band_len = band_rows * width;
    out.face
        .par_chunks_mut(band_len)
        .zip(out.bary.par_chunks_mut(band_len))
        .zip(out.depth.par_chunks_mut(band_len))
        .enumerate()
        .for_each(|(band, ((face_out, bary_out), depth_out))| {
            let row0 = (band * band_rows) as i64;
            let row1 = row0 + (face_out.len() / width) as i64 - 1;
            let start = band * band_len;
            for (f, t) in &triangles {
                if t.row1 < row0 || t.row0 > row1 {
                    continue;
                }
                raster_rows(t, width, row0, row1, &mut |pixel, bary, depth| {
                    let depth = depth as f32;
                    let p = pixel - start;
                    // As in `rasterize`: strict `<`, faces in ascending order.
                    if depth < depth_out[p] {
                        depth_out[p] = depth;
                        face_out[p] = *f;
                        bary_out[p] = bary.map(|b| b as f32);
                    }
                });
            }
        });
    Ok(out)
}

/// Screen-space barycentrics of a clipped triangle -> perspective-correct barycentrics of the
/// original face and NDC depth; `None` beyond the far plane or if not finite.
fn perspective(v: &[ScreenVertex; 3], screen: [f64; 3]) -> Option<([f64; 3], f64)> {
    // Divide by w per vertex and renormalise.
    let q: [f64; 3] = std::array::from_fn(|k| screen[k] / v[k].clip.pos[3]);
    let sum = q[0] + q[1] + q[2];
    let q = q.map(|x| x / sum);
    let bary: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| q[k] * v[k].clip.weights[i]).sum());
    let z: f64 = (0..3).map(|k| q[k] * v[k].clip.pos[2]).sum();
    let w: f64 = (0..3).map(|k| q[k] * v[k].clip.pos[3]).sum();
    let depth = z / w;
    let finite = depth.is_finite() && bary.iter().all(|b| b.is_finite());
    (finite && depth <= 1.0).then_some((bary, depth))
}

/// Checks a [`Fragments`] buffer's shape and face ids; returns the pixel count.
pub(crate) fn check_fragments(frags: &Fragments, num_faces: usize) -> Result<usize, RenderError> {
    let n = check_image(frags.width, frags.height)?;
    check_len("fragments.face", frags.face.len(), n)?;
    check_len("fragments.bary", frags.bary.len(), n)?;
    check_len("fragments.depth", frags.depth.len(), n)?;
    for (pixel, &face) in frags.face.iter().enumerate() {
        if face < -1 || (face >= 0 && face as usize >= num_faces) {
            return Err(RenderError::InvalidFragmentFace {
                pixel,
                face,
                num_faces,
            });
        }
    }
    Ok(n)
}
