//! [`antialias`]: analytic silhouette antialiasing (nvdiffrast's method), whose gradient moves
//! silhouette edges.
//!
//! # Method
//! Consider two horizontally or vertically adjacent pixels whose faces differ. The one whose
//! fragment is nearer (empty pixels are infinitely far) is the *front* pixel `P`, the other
//! the *back* pixel `Q`; let `F` be the front face. The segment from `P`'s centre to `Q`'s
//! centre leaves `F` through exactly one of its edges. If that edge is a *silhouette* edge
//! (no face across it, more than one, or the face across it has the opposite screen-space
//! orientation, i.e. one faces the camera and the other does not), the edge is where `F`
//! really ends, and its crossing point `t` in `(0, 1)` along `P -> Q` tells how much of the
//! two pixels' shared span `F` covers:
//!
//! * `t > 1/2`: `F` reaches into `Q`'s half; `Q`'s colour moves towards `P`'s by `t - 1/2`;
//! * `t < 1/2`: `F` stops short of the midpoint; `P`'s colour moves towards `Q`'s by
//!   `1/2 - t`.
//!
//! All blends read the input colours and add up per pixel. `t` is computed from the edge's
//! screen-space end points as a tensor expression, so autodiff gives the silhouette gradient
//! w.r.t. the edge's clip positions (x, y, w) besides the gradient w.r.t. the colours. Pairs
//! are found on the CPU core; only edges with both ends in front of the camera (w > 0)
//! take part.
//!
//! Screen coordinates here are pixels with pixel `(col, row)`'s centre at
//! `(col + 1/2, row + 1/2)` = `((x/w + 1) W / 2, (y/w + 1) H / 2)`.

use burn::tensor::{Bool, IndexingUpdateOp, Int, Tensor, activation::relu};

use super::{Raster, Topology, check_shape, float_tensor, index_tensor};
use crate::error::RenderError;

/// The discrete part of [`antialias`]: adjacent pixel pairs straddling a silhouette edge.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SilhouettePairs {
    /// Linear index of the front pixel `P` of each pair.
    pub front: Vec<u32>,
    /// Linear index of the back pixel `Q` of each pair.
    pub back: Vec<u32>,
    /// The silhouette edge crossed between them (vertex indices, in the front face's order).
    pub edges: Vec<[u32; 2]>,
}

impl SilhouettePairs {
    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.front.len()
    }

    /// Whether no pair straddles a silhouette.
    pub fn is_empty(&self) -> bool {
        self.front.is_empty()
    }
}

/// Finds the adjacent pixel pairs of `raster` that straddle a silhouette edge of `topology`
/// (see the module docs).
///
/// # Errors
/// When the raster was not made from a mesh with `topology`'s vertex count.
pub fn silhouette_pairs(
    raster: &Raster,
    topology: &Topology,
) -> Result<SilhouettePairs, RenderError> {
    crate::error::check_len(
        "raster clip positions",
        raster.clip_host.len(),
        topology.num_vertices(),
    )?;
    crate::raster::check_fragments(&raster.fragments, topology.num_faces())?;
    let (w, h) = (raster.width(), raster.height());
    let frags = &raster.fragments;
    let clip = &raster.clip_host;
    let faces = topology.faces();
    let screen = |v: u32| -> Option<[f64; 2]> {
        let c = clip[v as usize];
        let cw = f64::from(c[3]);
        (cw > 1e-6).then(|| {
            [
                (f64::from(c[0]) / cw + 1.0) * w as f64 / 2.0,
                (f64::from(c[1]) / cw + 1.0) * h as f64 / 2.0,
            ]
        })
    };
    let orientation = |f: usize| -> f64 {
        let [a, b, c] = faces[f].map(|i| {
            let p = clip[i as usize];
            [f64::from(p[0]), f64::from(p[1]), f64::from(p[3])]
        });
        a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0])
    };
    let centre = |pixel: usize| [(pixel % w) as f64 + 0.5, (pixel / w) as f64 + 0.5];
    let cross = |o: [f64; 2], d: [f64; 2], p: [f64; 2]| d[0] * (p[1] - o[1]) - d[1] * (p[0] - o[0]);

    let mut pairs = SilhouettePairs::default();
    let mut consider = |a: usize, b: usize| {
        let (fa, fb) = (frags.face[a], frags.face[b]);
        if fa == fb {
            return;
        }
        let (front, back) = if frags.depth[a] <= frags.depth[b] {
            (a, b)
        } else {
            (b, a)
        };
        let f = frags.face[front] as usize;
        let (p, q) = (centre(front), centre(back));
        let pq = [q[0] - p[0], q[1] - p[1]];
        let own = orientation(f);
        for k in 0..3 {
            let (va, vb) = (faces[f][k], faces[f][(k + 1) % 3]);
            let (Some(sa), Some(sb)) = (screen(va), screen(vb)) else {
                continue;
            };
            let d = [sb[0] - sa[0], sb[1] - sa[1]];
            let (fp, fq) = (cross(sa, d, p), cross(sa, d, q));
            let (ga, gb) = (cross(p, pq, sa), cross(p, pq, sb));
            if fp * fq >= 0.0 || ga * gb > 0.0 {
                continue;
            }
            let silhouette = match topology.neighbors()[f][k] {
                n if n < 0 => true,
                n => orientation(n as usize) * own <= 0.0,
            };
            if silhouette {
                pairs.front.push(front as u32);
                pairs.back.push(back as u32);
                pairs.edges.push([va, vb]);
            }
            break;
        }
    };
    for row in 0..h {
        for col in 0..w {
            let pixel = row * w + col;
            if col + 1 < w {
                consider(pixel, pixel + 1);
            }
            if row + 1 < h {
                consider(pixel, pixel + w);
            }
        }
    }
    Ok(pairs)
}

/// Antialiases a rendered image at silhouette edges; the backward pass gives gradients to
/// the colours and to the clip positions of silhouette edges' vertices (see the module docs).
///
/// `clip` must be the tensor `raster` was made from (the gradient flows into it).
///
/// # Shapes
/// color `[C, H, W]`, clip `[V, 4]` -> `[C, H, W]`
///
/// # Errors
/// Shapes that do not match the raster or the topology.
pub fn antialias(
    color: Tensor<3>,
    raster: &Raster,
    clip: Tensor<2>,
    topology: &Topology,
) -> Result<Tensor<3>, RenderError> {
    AntialiasPlan::new(raster, clip, topology)?.apply(color)
}

/// The part of [`antialias`] that depends only on the geometry: the silhouette pixel pairs
/// and how far each pair's edge reaches (`t`, a tensor expression of the clip positions, so
/// the plan keeps their gradient). Made once for a fixed geometry, it antialiases every
/// image rendered from it.
#[derive(Debug, Clone)]
pub struct AntialiasPlan {
    height: usize,
    width: usize,
    pairs: usize,
    front: Tensor<1, Int>,
    back: Tensor<1, Int>,
    /// `[1, K]`: how much of the front colour each back pixel takes (`relu(t - 1/2)`).
    to_back: Tensor<2>,
    /// `[1, K]`: how much of the back colour each front pixel takes (`relu(1/2 - t)`).
    to_front: Tensor<2>,
    /// A plan made on the device ([`AntialiasPlan::from_dense`]) evaluates every adjacent
    /// pixel pair: `[K]`, which of them straddle a silhouette, and `[K, 2]` the edge crossed.
    #[cfg_attr(not(test), allow(dead_code))] // read by the tests' pair comparison
    pub(super) dense_pairs: Option<(Tensor<1, Bool>, Tensor<2, Int>)>,
}

impl AntialiasPlan {
    /// Finds the silhouette pairs of `raster` and their blend weights.
    ///
    /// `clip` must be the tensor `raster` was made from (the gradient flows into it).
    ///
    /// # Shapes
    /// clip `[V, 4]`
    ///
    /// # Errors
    /// When `clip` or the raster does not match `topology`.
    pub fn new(raster: &Raster, clip: Tensor<2>, topology: &Topology) -> Result<Self, RenderError> {
        let v = topology.num_vertices();
        check_shape("clip", clip.dims(), [Some(v), Some(4)], || {
            format!("[V, 4] with V = {v}")
        })?;
        let pairs = silhouette_pairs(raster, topology)?;
        let (h, w) = (raster.height(), raster.width());
        let device = clip.device();
        let k = pairs.len();
        let front = index_tensor(pairs.front.iter().map(|&p| i64::from(p)).collect(), &device);
        let back = index_tensor(pairs.back.iter().map(|&p| i64::from(p)).collect(), &device);
        if k == 0 {
            return Ok(Self {
                height: h,
                width: w,
                pairs: 0,
                front,
                back,
                to_back: Tensor::zeros([1, 0], &device),
                to_front: Tensor::zeros([1, 0], &device),
                dense_pairs: None,
            });
        }
        let idx = |f: &dyn Fn(usize) -> u32| {
            index_tensor((0..k).map(|i| i64::from(f(i))).collect(), &device)
        };
        let a = clip.clone().select(0, idx(&|i| pairs.edges[i][0]));
        let b = clip.select(0, idx(&|i| pairs.edges[i][1]));
        let screen = |t: Tensor<2>| screen_xy(t, h, w);
        let (ax, ay) = screen(a);
        let (bx, by) = screen(b);
        let centres = |pixels: &[u32]| {
            let xs = pixels
                .iter()
                .map(|&p| (p as usize % w) as f32 + 0.5)
                .collect();
            let ys = pixels
                .iter()
                .map(|&p| (p as usize / w) as f32 + 0.5)
                .collect();
            (
                float_tensor(xs, [k, 1], &device),
                float_tensor(ys, [k, 1], &device),
            )
        };
        let (px, py) = centres(&pairs.front);
        let (qx, qy) = centres(&pairs.back);
        let (dx, dy) = (bx - ax.clone(), by - ay.clone());
        let side = |x: Tensor<2>, y: Tensor<2>| {
            dx.clone() * (y - ay.clone()) - dy.clone() * (x - ax.clone())
        };
        let fp = side(px, py);
        let fq = side(qx, qy);
        let t = (fp.clone() / (fp - fq)).clamp(0.0, 1.0).reshape([1, k]);
        Ok(Self {
            height: h,
            width: w,
            pairs: k,
            front,
            back,
            to_back: relu(t.clone() - 0.5),
            to_front: relu(t.neg() + 0.5),
            dense_pairs: None,
        })
    }

    /// Number of silhouette pixel pairs; for a plan made by [`AntialiasPlan::from_dense`],
    /// the number of adjacent pixel pairs evaluated (`H (W - 1) + (H - 1) W`), those off a
    /// silhouette with zero weights.
    pub fn num_pairs(&self) -> usize {
        self.pairs
    }

    /// Assembles a plan from its pairs and blend weights (`[K]` pixel indices, `[1, K]`
    /// weights).
    pub(super) fn from_parts(
        [height, width]: [usize; 2],
        [front, back]: [Tensor<1, Int>; 2],
        [to_back, to_front]: [Tensor<2>; 2],
        dense_pairs: Option<(Tensor<1, Bool>, Tensor<2, Int>)>,
    ) -> Self {
        Self {
            height,
            width,
            pairs: front.dims()[0],
            front,
            back,
            to_back,
            to_front,
            dense_pairs,
        }
    }

    /// For a plan made by [`AntialiasPlan::from_dense`]: the silhouette pairs it found as
    /// host lists (one counted readback of each of four tensors), for tests.
    #[cfg(test)]
    pub(crate) fn dense_pairs_on_host(&self) -> Option<SilhouettePairs> {
        let (found, edges) = self.dense_pairs.clone()?;
        let ints = |t: Tensor<1, Int>| -> Vec<i64> {
            super::count_readback();
            t.into_data()
                .convert::<i64>()
                .try_into_vec::<i64>()
                .unwrap_or_default()
        };
        let found = ints(found.int());
        let (front, back) = (ints(self.front.clone()), ints(self.back.clone()));
        let k = edges.dims()[0];
        let edges = ints(edges.reshape([2 * k]));
        let mut pairs = SilhouettePairs::default();
        for i in (0..found.len()).filter(|&i| found[i] != 0) {
            pairs.front.push(front[i] as u32);
            pairs.back.push(back[i] as u32);
            pairs
                .edges
                .push([edges[2 * i] as u32, edges[2 * i + 1] as u32]);
        }
        Some(pairs)
    }

    /// Antialiases `color`, an image of the plan's size.
    ///
    /// # Shapes
    /// color `[C, H, W]` -> `[C, H, W]`
    ///
    /// # Errors
    /// An image of another size than the raster's.
    pub fn apply(&self, color: Tensor<3>) -> Result<Tensor<3>, RenderError> {
        let [c, h, w] = color.dims();
        check_shape(
            "color",
            [c, h, w],
            [None, Some(self.height), Some(self.width)],
            || format!("[C, {}, {}] (the raster's size)", self.height, self.width),
        )?;
        if self.pairs == 0 {
            return Ok(color);
        }
        let flat = color.reshape([c, h * w]);
        let c_front = flat.clone().select(1, self.front.clone());
        let c_back = flat.clone().select(1, self.back.clone());
        let diff = c_front - c_back;
        let out = flat
            .select_assign(
                1,
                self.back.clone(),
                diff.clone() * self.to_back.clone(),
                IndexingUpdateOp::Add,
            )
            .select_assign(
                1,
                self.front.clone(),
                diff.neg() * self.to_front.clone(),
                IndexingUpdateOp::Add,
            );
        Ok(out.reshape([c, h, w]))
    }
}

/// Screen coordinates in pixels (pixel `(col, row)`'s centre at `(col + 1/2, row + 1/2)`) of
/// clip positions, as two columns.
///
/// # Shapes
/// clip `[K, 4]` -> x `[K, 1]`, y `[K, 1]`
pub(super) fn screen_xy(clip: Tensor<2>, h: usize, w: usize) -> (Tensor<2>, Tensor<2>) {
    let k = clip.dims()[0];
    let x = clip.clone().slice([0..k, 0..1]);
    let y = clip.clone().slice([0..k, 1..2]);
    let cw = clip.slice([0..k, 3..4]);
    (
        (x / cw.clone() + 1.0) * (w as f64 / 2.0),
        (y / cw + 1.0) * (h as f64 / 2.0),
    )
}
