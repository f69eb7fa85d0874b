//! [`AntialiasPlan::from_dense`]: the silhouette-pair search of [`super::silhouette_pairs`]
//! as tensor operations over every adjacent pixel pair of a [`DenseRaster`], so that
//! antialiasing needs no host readback.

use burn::tensor::{Bool, Int, Tensor, TensorData, activation::relu};

use super::dense_diff::face_table;
use super::{AntialiasPlan, DenseRaster, Topology, check_shape, float_tensor, index_tensor};
use crate::error::RenderError;

/// Every horizontally and vertically adjacent pixel pair `(a, b)` of an `h x w` image
/// (horizontal pairs first), with the pixel centres (pixels, `col + 1/2`, `row + 1/2`).
struct Candidates {
    a: Vec<i64>,
    b: Vec<i64>,
}

impl Candidates {
    fn new(h: usize, w: usize) -> Self {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for row in 0..h {
            for col in 0..w.saturating_sub(1) {
                a.push((row * w + col) as i64);
                b.push((row * w + col + 1) as i64);
            }
        }
        for row in 0..h.saturating_sub(1) {
            for col in 0..w {
                a.push((row * w + col) as i64);
                b.push(((row + 1) * w + col) as i64);
            }
        }
        Self { a, b }
    }

    /// Centres `(x, y)` of the pixels `pixels`, as `[K]` tensors.
    fn centres(pixels: &[i64], w: usize, device: &burn::tensor::Device) -> [Tensor<1>; 2] {
        let k = pixels.len();
        let xs = pixels.iter().map(|&p| (p as usize % w) as f32 + 0.5);
        let ys = pixels.iter().map(|&p| (p as usize / w) as f32 + 0.5);
        [
            float_tensor(xs.collect(), [k], device),
            float_tensor(ys.collect(), [k], device),
        ]
    }
}

/// Rotates the three columns of `[K, 3]` left by one (column `j` gets column `j + 1 mod 3`):
/// the second end point of edge `j`.
fn next<K: burn::tensor::kind::Basic>(t: Tensor<2, K>) -> Tensor<2, K> {
    let k = t.dims()[0];
    Tensor::cat(
        vec![t.clone().slice([0..k, 1..3]), t.slice([0..k, 0..1])],
        1,
    )
}

/// Screen-space orientation of every face: the determinant of its corners' `(x, y, w)` (the
/// sign tells whether it faces the camera), as [`super::silhouette_pairs`] computes it.
///
/// # Shapes
/// clip `[V, 4]`, table `[F, 3]` -> `[F]`
fn orientations(clip: Tensor<2>, table: Tensor<2, Int>) -> Tensor<1> {
    let f = table.dims()[0];
    let c = clip.select(0, table.reshape([3 * f])).reshape([f, 3, 4]);
    let at = |v: usize, k: usize| c.clone().slice([0..f, v..v + 1, k..k + 1]).reshape([f]);
    let (a, b, cc) = (
        [at(0, 0), at(0, 1), at(0, 3)],
        [at(1, 0), at(1, 1), at(1, 3)],
        [at(2, 0), at(2, 1), at(2, 3)],
    );
    let minor = |i: usize, j: usize| b[i].clone() * cc[j].clone() - b[j].clone() * cc[i].clone();
    a[0].clone() * minor(1, 2) - a[1].clone() * minor(0, 2) + a[2].clone() * minor(0, 1)
}

impl AntialiasPlan {
    /// Finds the silhouette pairs of a dense raster on its device and their blend weights:
    /// the method of [`super::antialias`] evaluated for every horizontally and vertically
    /// adjacent pixel pair at once (faces differ, the nearer pixel is the front one, the
    /// first edge of the front face that the segment between the two centres crosses, the
    /// silhouette test with [`Topology::neighbors`] and per-face screen orientations, the
    /// crossing `t` in `(0, 1)`). Pairs off a silhouette keep zero weights, so
    /// [`AntialiasPlan::apply`] adds nothing for them. Nothing is read back to the host.
    ///
    /// The decisions are made in `f32` on the device where the host search uses `f64`:
    /// a pair whose segment passes within rounding of an edge's end point, or a face seen
    /// edge-on, can be decided differently.
    ///
    /// `clip` must be the tensor `dense` was made from (the gradient flows into it), with
    /// the same `topology` (the face ids are not checked, which would need a readback).
    ///
    /// # Shapes
    /// dense `face [H, W]`, `depth [H, W]`, clip `[V, 4]` -> a plan for `[C, H, W]` images
    ///
    /// # Errors
    /// When `clip` does not match `topology`, or the raster's tensors disagree in size.
    pub(crate) fn from_dense(
        dense: &DenseRaster,
        clip: Tensor<2>,
        topology: &Topology,
    ) -> Result<Self, RenderError> {
        let v = topology.num_vertices();
        check_shape("clip", clip.dims(), [Some(v), Some(4)], || {
            format!("[V, 4] with V = {v}")
        })?;
        let [h, w] = dense.face.dims();
        check_shape("depth", dense.depth.dims(), [Some(h), Some(w)], || {
            format!("[{h}, {w}] (the face ids' size)")
        })?;
        let device = clip.device();
        let cand = Candidates::new(h, w);
        let k = cand.a.len();
        if k == 0 || topology.num_faces() == 0 {
            let none = Tensor::<1, Int>::zeros([0], &device);
            let zero = Tensor::<2>::zeros([1, 0], &device);
            return Ok(Self::from_parts(
                [h, w],
                [none.clone(), none],
                [zero.clone(), zero],
                None,
            ));
        }
        let table = face_table(topology, &device);
        let nb: Vec<i64> = topology
            .neighbors()
            .iter()
            .flatten()
            .map(|&n| i64::from(n))
            .collect();
        let neighbors: Tensor<2, Int> =
            Tensor::from_data(TensorData::new(nb, [topology.num_faces(), 3]), &device);
        let (a, b) = (
            index_tensor(cand.a.clone(), &device),
            index_tensor(cand.b.clone(), &device),
        );
        let face = dense.face.clone().reshape([h * w]).cast(table.dtype());
        let depth = dense.depth.clone().reshape([h * w]);
        let (fa, fb) = (face.clone().select(0, a.clone()), face.select(0, b.clone()));
        let differ = fa.clone().not_equal(fb.clone());
        let a_front = depth
            .clone()
            .select(0, a.clone())
            .lower_equal(depth.select(0, b.clone()));
        let front = b.clone().mask_where(a_front.clone(), a.clone());
        let back = a.mask_where(a_front.clone(), b);
        let f = fb.mask_where(a_front.clone(), fa).clamp_min(0);
        let [ax, ay] = Candidates::centres(&cand.a, w, &device);
        let [bx, by] = Candidates::centres(&cand.b, w, &device);
        let px = bx.clone().mask_where(a_front.clone(), ax.clone());
        let py = by.clone().mask_where(a_front.clone(), ay.clone());
        let qx = ax.mask_where(a_front.clone(), bx);
        let qy = ay.mask_where(a_front, by);

        // The discrete part, without gradient: which edge of the front face the segment
        // P -> Q leaves through, and whether it is a silhouette.
        let detached = clip.clone().detach();
        let corners = table.clone().select(0, f.clone());
        let cc = detached
            .clone()
            .select(0, corners.clone().reshape([3 * k]))
            .reshape([k, 3, 4]);
        let coord = |i: usize| cc.clone().slice([0..k, 0..3, i..i + 1]).reshape([k, 3]);
        let cw = coord(3);
        let valid = cw.clone().greater_elem(1e-6);
        let cw = cw.mask_fill(valid.clone().bool_not(), 1.0);
        let sx = (coord(0) / cw.clone() + 1.0) * (w as f64 / 2.0);
        let sy = (coord(1) / cw + 1.0) * (h as f64 / 2.0);
        let (sx_n, sy_n) = (next(sx.clone()), next(sy.clone()));
        let (dx, dy) = (sx_n.clone() - sx.clone(), sy_n.clone() - sy.clone());
        let col = |t: &Tensor<1>| t.clone().reshape([k, 1]);
        let (px2, py2, qx2, qy2) = (col(&px), col(&py), col(&qx), col(&qy));
        let side = |x: Tensor<2>, y: Tensor<2>| {
            dx.clone() * (y - sy.clone()) - dy.clone() * (x - sx.clone())
        };
        let fp = side(px2.clone(), py2.clone());
        let fq = side(qx2.clone(), qy2.clone());
        let (pqx, pqy) = (qx2 - px2.clone(), qy2 - py2.clone());
        let g = |x: Tensor<2>, y: Tensor<2>| {
            pqx.clone() * (y - py2.clone()) - pqy.clone() * (x - px2.clone())
        };
        let ga = g(sx.clone(), sy.clone());
        let gb = g(sx_n, sy_n);
        let crosses = valid
            .clone()
            .bool_and(next(valid))
            .bool_and((fp * fq).lower_elem(0.0))
            .bool_and((ga * gb).greater_elem(0.0).bool_not());
        let edge_col = |j: usize| crosses.clone().slice([0..k, j..j + 1]).reshape([k]);
        let (c0, c1, c2) = (edge_col(0), edge_col(1), edge_col(2));
        let any = c0.clone().bool_or(c1.clone()).bool_or(c2);
        let first = Tensor::<1, Int>::full([k], 2, &device)
            .mask_fill(c1, 1)
            .mask_fill(c0, 0)
            .cast(table.dtype())
            .reshape([k, 1]);
        let across = neighbors
            .select(0, f.clone())
            .gather(1, first.clone())
            .reshape([k]);
        let orient = orientations(detached, table);
        let own = orient.clone().select(0, f);
        let other = orient.select(0, across.clone().clamp_min(0));
        let silhouette = across
            .lower_elem(0)
            .bool_or((own * other).lower_equal_elem(0.0));
        let found = differ.bool_and(any).bool_and(silhouette);

        // The differentiable part: the crossing of the chosen edge, as in `AntialiasPlan::new`.
        let va = corners.clone().gather(1, first.clone());
        let vb = next(corners).gather(1, first);
        let edges = Tensor::cat(vec![va.clone(), vb.clone()], 1);
        let missing: Tensor<2, Bool> = found.clone().bool_not().reshape([k, 1]).expand([k, 4]);
        let safe = float_tensor(vec![0.0, 0.0, 0.0, 1.0], [1, 4], &device).repeat_dim(0, k);
        let end = |vi: Tensor<2, Int>| {
            clip.clone()
                .select(0, vi.reshape([k]))
                .mask_where(missing.clone(), safe.clone())
        };
        let screen = |t: Tensor<2>| super::antialias::screen_xy(t, h, w);
        let (ex, ey) = screen(end(va));
        let (fx, fy) = screen(end(vb));
        let (dx, dy) = (fx - ex.clone(), fy - ey.clone());
        let side = |x: Tensor<2>, y: Tensor<2>| {
            dx.clone() * (y - ey.clone()) - dy.clone() * (x - ex.clone())
        };
        let fp = side(col(&px), col(&py));
        let fq = side(col(&qx), col(&qy));
        let off: Tensor<2, Bool> = found.clone().bool_not().reshape([k, 1]);
        let denom = (fp.clone() - fq).mask_fill(off.clone(), 1.0);
        let t = (fp / denom).clamp(0.0, 1.0);
        let to_back = relu(t.clone() - 0.5).mask_fill(off.clone(), 0.0);
        let to_front = relu(t.neg() + 0.5).mask_fill(off, 0.0);
        Ok(Self::from_parts(
            [h, w],
            [front, back],
            [to_back.reshape([1, k]), to_front.reshape([1, k])],
            Some((found, edges)),
        ))
    }
}
