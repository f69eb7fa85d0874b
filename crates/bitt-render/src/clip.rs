//! Sutherland–Hodgman clipping of a triangle in homogeneous clip space.
//!
//! Two planes are used: `w >= W_EPSILON` (strictly in front of the eye) and the near
//! plane `z + w >= 0` (NDC z >= -1). Clipping is linear in clip space, so every output
//! vertex is a convex combination of the original three vertices; the weights of that
//! combination are carried along so barycentrics can be mapped back to the original face.

/// Smallest accepted `w`; geometry with `w` below this is clipped away.
pub(crate) const W_EPSILON: f64 = 1e-6;

/// Most vertices a triangle can have after clipping against two planes is 5.
const MAX_VERTS: usize = 8;

/// A clip-space vertex with barycentric weights of the original face's vertices.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ClipVertex {
    /// Clip-space position (x, y, z, w).
    pub pos: [f64; 4],
    /// Weights of the original vertices 0, 1, 2 (sum to 1).
    pub weights: [f64; 3],
}

/// A convex polygon of at most [`MAX_VERTS`] vertices (no allocation).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Polygon {
    verts: [ClipVertex; MAX_VERTS],
    len: usize,
}

impl Polygon {
    fn empty() -> Self {
        let zero = ClipVertex {
            pos: [0.0; 4],
            weights: [0.0; 3],
        };
        Self {
            verts: [zero; MAX_VERTS],
            len: 0,
        }
    }

    fn push(&mut self, v: ClipVertex) {
        self.verts[self.len] = v;
        self.len += 1;
    }

    /// The polygon's vertices, in order.
    pub fn vertices(&self) -> &[ClipVertex] {
        &self.verts[..self.len]
    }
}

/// Signed distance to the `w >= W_EPSILON` plane.
fn w_dist(p: &[f64; 4]) -> f64 {
    p[3] - W_EPSILON
}

/// Signed distance to the near plane `z + w >= 0`.
fn near_dist(p: &[f64; 4]) -> f64 {
    p[2] + p[3]
}

/// Clips one polygon against one plane (inside where `dist >= 0`).
fn clip_plane(input: &Polygon, dist: fn(&[f64; 4]) -> f64) -> Polygon {
    let mut out = Polygon::empty();
    let verts = input.vertices();
    for (i, a) in verts.iter().enumerate() {
        let b = &verts[(i + 1) % verts.len()];
        let (da, db) = (dist(&a.pos), dist(&b.pos));
        if da >= 0.0 {
            out.push(*a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            let lerp = |x: f64, y: f64| x + t * (y - x);
            out.push(ClipVertex {
                pos: std::array::from_fn(|k| lerp(a.pos[k], b.pos[k])),
                weights: std::array::from_fn(|k| lerp(a.weights[k], b.weights[k])),
            });
        }
    }
    out
}

/// Clips a triangle against `w >= W_EPSILON` and the near plane; the result is empty,
/// the unchanged triangle (identity weights), or a convex polygon of up to 5 vertices.
pub(crate) fn clip_triangle(tri: [[f64; 4]; 3]) -> Polygon {
    let mut poly = Polygon::empty();
    for (i, pos) in tri.into_iter().enumerate() {
        let mut weights = [0.0; 3];
        weights[i] = 1.0;
        poly.push(ClipVertex { pos, weights });
    }
    let inside = |p: &[f64; 4]| w_dist(p) >= 0.0 && near_dist(p) >= 0.0;
    if tri.iter().all(inside) {
        return poly;
    }
    for dist in [w_dist as fn(&[f64; 4]) -> f64, near_dist] {
        if poly.len < 3 {
            break;
        }
        poly = clip_plane(&poly, dist);
    }
    if poly.len < 3 { Polygon::empty() } else { poly }
}
