//! UV texture layouts: which texels of a `W x H` texture a model uses, and in which order.
//!
//! Textures are stored *compact*: only the used texels, channel-major (`[3, T]`: all red
//! values, then all green, then all blue), in the order of [`TextureLayout::texels`]. The
//! image form is `[3, H, W]` with row 0 the **top** image row.
//!
//! # Texel positions in UV space
//!
//! The reference renderer samples a texture at `(2u - 1, 1 - 2v)` in `grid_sample`'s
//! `[-1, 1]` space with `align_corners = true` (see `shared/formats.md`): `v = 0` is the
//! bottom image row, and the texel centres sit exactly on the UV grid
//!
//! ```text
//! u = col / (W - 1),    v = 1 - row / (H - 1).
//! ```
//!
//! [`TextureLayout::from_uv`] rasterizes UV triangles with that convention, so a bilinear
//! sample inside a triangle reads the texels around it ([`texel_uv`] / [`uv_to_texel`]).

use bitt_mesh::UvLayout;
use bitt_mesh::glam::{DVec2, DVec3};
use burn::tensor::{Device, IndexingUpdateOp, Int, Tensor, TensorData};

use crate::TextureError;

/// Marks an unused texel in the dense index map.
const UNUSED: u32 = u32::MAX;

/// A UV texture layout: which texels of a `W x H` texture are used, in the compact order
/// textures are stored in.
///
/// Build it with [`TextureLayout::from_texels`] or [`TextureLayout::from_uv`]; the public
/// fields are for reading (changing them desynchronises the private texel index).
#[derive(Debug, Clone, PartialEq)]
pub struct TextureLayout {
    /// Texture width in texels.
    pub width: usize,
    /// Texture height in texels.
    pub height: usize,
    /// `(row, col)` of each compact texel; row 0 is the TOP image row (`v = 1`).
    pub texels: Vec<(u32, u32)>,
    /// Per-face UV triangles, when the layout comes from a mesh.
    pub uv: Option<UvLayout>,
    /// `[H * W]`: compact index of each image texel, [`UNUSED`] where unused.
    index_of: Vec<u32>,
    /// Face and barycentric coordinates of each compact texel (from [`Self::from_uv`]).
    texel_faces: Option<Vec<(u32, [f32; 3])>>,
}

/// UV coordinates of the centre of texel `(row, col)` in a `width x height` texture
/// (`align_corners = true`: `u = col / (W - 1)`, `v = 1 - row / (H - 1)`; a size of 1
/// maps to the middle, 0.5).
pub(crate) fn texel_uv(row: usize, col: usize, width: usize, height: usize) -> DVec2 {
    let axis = |i: usize, n: usize| {
        if n > 1 {
            i as f64 / (n - 1) as f64
        } else {
            0.5
        }
    };
    DVec2::new(axis(col, width), 1.0 - axis(row, height))
}

/// Continuous texel coordinates `(x, y) = (col, row)` of a UV point: the inverse of
/// [`texel_uv`] (`x = u (W - 1)`, `y = (1 - v) (H - 1)`).
pub fn uv_to_texel(uv: DVec2, width: usize, height: usize) -> DVec2 {
    DVec2::new(
        uv.x * width.saturating_sub(1) as f64,
        (1.0 - uv.y) * height.saturating_sub(1) as f64,
    )
}

impl TextureLayout {
    /// A layout from an explicit texel list (compact order = the order given).
    ///
    /// Fails on an empty size or texel list, a texel outside the texture, or a texel listed
    /// twice.
    pub fn from_texels(
        width: usize,
        height: usize,
        texels: Vec<(u32, u32)>,
        uv: Option<UvLayout>,
    ) -> Result<Self, TextureError> {
        let n = check_size(width, height)?;
        if texels.is_empty() {
            return Err(TextureError::Invalid(
                "a texture layout needs at least one texel".into(),
            ));
        }
        if texels.len() >= UNUSED as usize {
            return Err(TextureError::Invalid(format!(
                "{} texels are too many for a texture layout",
                texels.len()
            )));
        }
        let mut index_of = vec![UNUSED; n];
        for (t, &(r, c)) in texels.iter().enumerate() {
            let (r, c) = (r as usize, c as usize);
            if r >= height || c >= width {
                return Err(TextureError::Invalid(format!(
                    "texel {t} at (row {r}, col {c}) is outside the {width}x{height} texture"
                )));
            }
            let slot = &mut index_of[r * width + c];
            if *slot != UNUSED {
                return Err(TextureError::Invalid(format!(
                    "texel (row {r}, col {c}) is listed twice (entries {} and {t})",
                    *slot
                )));
            }
            *slot = t as u32;
        }
        Ok(TextureLayout {
            width,
            height,
            texels,
            uv,
            index_of,
            texel_faces: None,
        })
    }

    /// Rasterizes the UV triangles at `width x height`.
    ///
    /// A texel is valid when its centre (see the [module docs](crate::layout):
    /// `u = col / (W - 1)`,
    /// `v = 1 - row / (H - 1)`) lies in a UV triangle, boundary included; the face and the
    /// barycentric coordinates of each valid texel are recorded (where triangles overlap,
    /// the face the texel is deepest inside wins). Then a `gutter`-texel ring is added:
    /// texels outside every chart but within `gutter` texels (Chebyshev distance) of a chart
    /// texel, attached to the face of the nearest chart texel (Euclidean; ties go to the
    /// first in row-major order) with the barycentrics of the closest point of that face's
    /// triangle, so that bilinear sampling at chart borders reads valid data. Compact order:
    /// row-major scan (top row first).
    ///
    /// Fails when the size is below 2 x 2, a UV coordinate is not finite, a face indexes a
    /// missing UV vertex, or no texel is covered.
    pub fn from_uv(
        uv: &UvLayout,
        width: usize,
        height: usize,
        gutter: usize,
    ) -> Result<Self, TextureError> {
        let n = check_size(width, height)?;
        if width < 2 || height < 2 {
            return Err(TextureError::Invalid(format!(
                "a UV layout needs a texture of at least 2x2 texels, got {width}x{height}"
            )));
        }
        if let Some((i, p)) = uv.uvs.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(TextureError::Invalid(format!(
                "UV coordinate {i} is not finite: ({}, {})",
                p.x, p.y
            )));
        }
        // Per image texel: best face, its score (smallest barycentric) and barycentrics.
        let mut face_of = vec![UNUSED; n];
        let mut score = vec![f64::NEG_INFINITY; n];
        let mut bary = vec![[0f32; 3]; n];
        for (f, corners) in uv.faces.iter().enumerate() {
            let mut p = [DVec2::ZERO; 3];
            for (k, &i) in corners.iter().enumerate() {
                let q = uv.uvs.get(i as usize).ok_or_else(|| {
                    TextureError::Invalid(format!(
                        "UV face {f} uses UV vertex {i}, but there are only {}",
                        uv.uvs.len()
                    ))
                })?;
                p[k] = uv_to_texel(*q, width, height);
            }
            let Some(tri) = Triangle::new(p) else {
                continue; // degenerate in UV space: covers no area
            };
            let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            // Texel centres on the boundary count: widen the box by a rounding margin.
            let c0 = (lo.x - BOX_EPS).ceil().max(0.0) as usize;
            let r0 = (lo.y - BOX_EPS).ceil().max(0.0) as usize;
            let c1 = ((hi.x + BOX_EPS).floor().min((width - 1) as f64)).max(-1.0);
            let r1 = ((hi.y + BOX_EPS).floor().min((height - 1) as f64)).max(-1.0);
            if c1 < 0.0 || r1 < 0.0 {
                continue;
            }
            for r in r0..=r1 as usize {
                for c in c0..=c1 as usize {
                    let b = tri.barycentric(DVec2::new(c as f64, r as f64));
                    let s = b[0].min(b[1]).min(b[2]);
                    let idx = r * width + c;
                    if s >= -INSIDE_EPS && s > score[idx] {
                        score[idx] = s;
                        face_of[idx] = f as u32;
                        bary[idx] = [b[0] as f32, b[1] as f32, b[2] as f32];
                    }
                }
            }
        }
        let in_chart: Vec<bool> = face_of.iter().map(|&f| f != UNUSED).collect();
        if !in_chart.iter().any(|&x| x) {
            return Err(TextureError::Invalid(format!(
                "the UV layout covers no texel centre of a {width}x{height} texture"
            )));
        }
        if gutter > 0 {
            let g = gutter as isize;
            for r in 0..height {
                for c in 0..width {
                    let idx = r * width + c;
                    if in_chart[idx] {
                        continue;
                    }
                    let mut best: Option<(isize, usize)> = None;
                    for dr in -g..=g {
                        for dc in -g..=g {
                            let (rr, cc) = (r as isize + dr, c as isize + dc);
                            if rr < 0 || cc < 0 || rr >= height as isize || cc >= width as isize {
                                continue;
                            }
                            let j = rr as usize * width + cc as usize;
                            let d = dr * dr + dc * dc;
                            if in_chart[j] && best.is_none_or(|(bd, _)| d < bd) {
                                best = Some((d, j));
                            }
                        }
                    }
                    if let Some((_, j)) = best {
                        let f = face_of[j];
                        let corners = uv.faces[f as usize];
                        let p = corners.map(|i| uv_to_texel(uv.uvs[i as usize], width, height));
                        let b = closest_barycentric(p, DVec2::new(c as f64, r as f64));
                        face_of[idx] = f;
                        bary[idx] = [b[0] as f32, b[1] as f32, b[2] as f32];
                    }
                }
            }
        }
        let mut texels = Vec::new();
        let mut faces = Vec::new();
        for r in 0..height {
            for c in 0..width {
                let idx = r * width + c;
                if face_of[idx] != UNUSED {
                    texels.push((r as u32, c as u32));
                    faces.push((face_of[idx], bary[idx]));
                }
            }
        }
        let mut layout = Self::from_texels(width, height, texels, Some(uv.clone()))?;
        layout.texel_faces = Some(faces);
        Ok(layout)
    }

    /// A layout from texels and their faces and barycentrics (as [`Self::from_uv`] makes
    /// them); used when loading a stored layout.
    pub(crate) fn from_texel_faces(
        width: usize,
        height: usize,
        texels: Vec<(u32, u32)>,
        uv: Option<UvLayout>,
        texel_faces: Vec<(u32, [f32; 3])>,
    ) -> Result<Self, TextureError> {
        if texel_faces.len() != texels.len() {
            return Err(TextureError::Invalid(format!(
                "{} texel faces for {} texels",
                texel_faces.len(),
                texels.len()
            )));
        }
        if let Some((t, _)) = texel_faces
            .iter()
            .enumerate()
            .find(|(_, (_, b))| !b.iter().all(|x| x.is_finite()))
        {
            return Err(TextureError::Invalid(format!(
                "texel {t} has non-finite barycentric coordinates"
            )));
        }
        if let Some(uv) = &uv
            && let Some((t, (f, _))) = texel_faces
                .iter()
                .enumerate()
                .find(|(_, (f, _))| *f as usize >= uv.faces.len())
        {
            return Err(TextureError::Invalid(format!(
                "texel {t} lies on face {f}, but the UV layout has {} faces",
                uv.faces.len()
            )));
        }
        let mut layout = Self::from_texels(width, height, texels, uv)?;
        layout.texel_faces = Some(texel_faces);
        Ok(layout)
    }

    /// Number of used texels `T`.
    pub fn num_texels(&self) -> usize {
        self.texels.len()
    }

    /// Compact index of texel `(row, col)`, `None` when it is unused or outside.
    pub fn compact_index(&self, row: usize, col: usize) -> Option<usize> {
        if row >= self.height || col >= self.width {
            return None;
        }
        match self.index_of[row * self.width + col] {
            UNUSED => None,
            t => Some(t as usize),
        }
    }

    /// Face index and barycentric coordinates of each compact texel (layouts from
    /// [`Self::from_uv`] / [`Self::from_texel_faces`] only).
    pub fn texel_faces(&self) -> Option<&[(u32, [f32; 3])]> {
        self.texel_faces.as_deref()
    }

    /// 3D point of each compact texel on a mesh with the layout's faces (`mesh_faces[f]`
    /// are the vertex indices of face `f`, the face the UV triangle `f` belongs to), e.g.
    /// the rest template. `None` without texel faces, or when a face or vertex index is
    /// out of range.
    pub fn texel_points(&self, mesh_faces: &[[u32; 3]], vertices: &[DVec3]) -> Option<Vec<DVec3>> {
        self.texel_faces
            .as_ref()?
            .iter()
            .map(|&(f, b)| {
                let face = mesh_faces.get(f as usize)?;
                let mut p = DVec3::ZERO;
                for (&v, &w) in face.iter().zip(&b) {
                    p += *vertices.get(v as usize)? * f64::from(w);
                }
                Some(p)
            })
            .collect()
    }

    /// A 64-bit FNV-1a fingerprint of the size and the texel list, to check that a stored
    /// texture belongs to this layout.
    pub(crate) fn fingerprint(&self) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |x: u64| {
            for b in x.to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        eat(self.width as u64);
        eat(self.height as u64);
        for &(r, c) in &self.texels {
            eat((u64::from(r) << 32) | u64::from(c));
        }
        h
    }

    /// Scatters a compact texture `[3, T]` (channel-major) into an image `[3, H, W]` (row 0
    /// = top); unused texels get `background`. Fails on a wrong length.
    pub fn compact_to_image(
        &self,
        compact: &[f32],
        background: [f32; 3],
    ) -> Result<Vec<f32>, TextureError> {
        let t = self.num_texels();
        self.check_len("compact texture", compact.len(), 3 * t)?;
        let hw = self.width * self.height;
        let mut image = Vec::with_capacity(3 * hw);
        for bg in background {
            image.extend(std::iter::repeat_n(bg, hw));
        }
        for (ch, values) in compact.chunks_exact(t).enumerate() {
            let plane = &mut image[ch * hw..(ch + 1) * hw];
            for (&(r, c), &v) in self.texels.iter().zip(values) {
                plane[r as usize * self.width + c as usize] = v;
            }
        }
        Ok(image)
    }

    /// Gathers the used texels of an image `[3, H, W]` into a compact texture `[3, T]`.
    /// Fails on a wrong length.
    pub fn image_to_compact(&self, image: &[f32]) -> Result<Vec<f32>, TextureError> {
        let hw = self.width * self.height;
        self.check_len("texture image", image.len(), 3 * hw)?;
        let mut compact = Vec::with_capacity(3 * self.num_texels());
        for plane in image.chunks_exact(hw) {
            compact.extend(
                self.texels
                    .iter()
                    .map(|&(r, c)| plane[r as usize * self.width + c as usize]),
            );
        }
        Ok(compact)
    }

    /// [`Self::compact_to_image`] as differentiable burn ops (a gather, works on any device,
    /// autodiff included; the gradient reaches the compact texels).
    ///
    /// # Shapes
    /// compact `[3, T]` -> image `[3, H, W]`
    ///
    /// # Panics
    /// When `compact` is not `[3, T]`.
    pub fn compact_to_image_tensor(&self, compact: Tensor<2>, background: [f32; 3]) -> Tensor<3> {
        self.gather(&compact.device())
            .compact_to_image(compact, background)
    }

    /// [`Self::image_to_compact`] as differentiable burn ops.
    ///
    /// # Shapes
    /// image `[3, H, W]` -> compact `[3, T]`
    ///
    /// # Panics
    /// When `image` is not `[3, H, W]`.
    pub fn image_to_compact_tensor(&self, image: Tensor<3>) -> Tensor<2> {
        self.gather(&image.device()).image_to_compact(image)
    }

    /// The index tensors of both conversions, uploaded once to `device` (use the device the
    /// textures live on, the autodiff one when gradients are needed).
    pub fn gather(&self, device: &Device) -> LayoutGather {
        let t = self.num_texels();
        let unused: Vec<f32> = self
            .index_of
            .iter()
            .map(|&i| if i == UNUSED { 1.0 } else { 0.0 })
            .collect();
        let compact_index: Vec<i64> = self
            .texels
            .iter()
            .map(|&(r, c)| (r as usize * self.width + c as usize) as i64)
            .collect();
        let hw = unused.len();
        LayoutGather {
            width: self.width,
            height: self.height,
            num_texels: t,
            unused: Tensor::from_data(TensorData::new(unused, [1, hw]), device),
            compact_index: Tensor::from_data(TensorData::new(compact_index, [t]), device),
        }
    }

    /// Valid-texel mask image `[H, W]` (1 = used, 0 = unused).
    pub fn mask_image(&self) -> Vec<f32> {
        self.index_of
            .iter()
            .map(|&i| if i == UNUSED { 0.0 } else { 1.0 })
            .collect()
    }

    fn check_len(&self, what: &str, got: usize, want: usize) -> Result<(), TextureError> {
        if got == want {
            Ok(())
        } else {
            Err(TextureError::Invalid(format!(
                "{what} has {got} values, expected {want} for a {}x{} layout with {} texels",
                self.width,
                self.height,
                self.num_texels()
            )))
        }
    }
}

/// The index tensors of a [`TextureLayout`] on one device, for repeated conversions between
/// compact textures and images without re-uploading the indices (see
/// [`TextureLayout::gather`]).
#[derive(Debug, Clone)]
pub struct LayoutGather {
    width: usize,
    height: usize,
    num_texels: usize,
    /// `[1, H * W]`: 1 at the unused image texels, 0 at the used ones.
    unused: Tensor<2>,
    /// `[T]`: flat image index `row * W + col` of each compact texel.
    compact_index: Tensor<1, Int>,
}

impl LayoutGather {
    /// Scatters a compact texture into an image; unused texels get `background`.
    ///
    /// Written as "the background at the unused texels, zeros elsewhere, plus each compact
    /// texel added at its one image position" (`select_assign`), so that the gradient is a
    /// gather of the image gradient at the used texels rather than a scatter over the whole
    /// image (as the gradient of a `select` over the image would be). The values are the same.
    ///
    /// # Shapes
    /// compact `[3, T]` -> image `[3, H, W]`
    ///
    /// # Panics
    /// When `compact` is not `[3, T]`.
    pub fn compact_to_image(&self, compact: Tensor<2>, background: [f32; 3]) -> Tensor<3> {
        let dims = compact.dims();
        assert_eq!(
            dims,
            [3, self.num_texels],
            "compact texture must be [3, {}]",
            self.num_texels
        );
        let device = compact.device();
        let base = if background == [0.0; 3] {
            Tensor::<2>::zeros([3, self.height * self.width], &device)
        } else {
            Tensor::cat(
                background
                    .iter()
                    .map(|&b| self.unused.clone().mul_scalar(b))
                    .collect(),
                0,
            )
        };
        base.select_assign(
            1,
            self.compact_index.clone(),
            compact,
            IndexingUpdateOp::Add,
        )
        .reshape([3, self.height, self.width])
    }

    /// Gathers the used texels of an image.
    ///
    /// # Shapes
    /// image `[3, H, W]` -> compact `[3, T]`
    ///
    /// # Panics
    /// When `image` is not `[3, H, W]`.
    pub fn image_to_compact(&self, image: Tensor<3>) -> Tensor<2> {
        let dims = image.dims();
        assert_eq!(
            dims,
            [3, self.height, self.width],
            "texture image must be [3, {}, {}]",
            self.height,
            self.width
        );
        image
            .reshape([3, self.height * self.width])
            .select(1, self.compact_index.clone())
    }
}

fn check_size(width: usize, height: usize) -> Result<usize, TextureError> {
    match width.checked_mul(height) {
        Some(n) if n > 0 && n < UNUSED as usize => Ok(n),
        _ => Err(TextureError::Invalid(format!(
            "texture size {width}x{height} is empty or too large"
        ))),
    }
}

/// Tolerance on barycentric coordinates for "on the boundary".
const INSIDE_EPS: f64 = 1e-9;
/// Margin (in texels) of a triangle's bounding box.
const BOX_EPS: f64 = 1e-6;

/// A non-degenerate 2D triangle.
struct Triangle {
    p: [DVec2; 3],
    area2: f64,
}

impl Triangle {
    fn new(p: [DVec2; 3]) -> Option<Self> {
        let area2 = (p[1] - p[0]).perp_dot(p[2] - p[0]);
        let scale = (p[1] - p[0]).length() * (p[2] - p[0]).length();
        (area2.abs() > 1e-12 * scale.max(1e-300)).then_some(Triangle { p, area2 })
    }

    fn barycentric(&self, q: DVec2) -> [f64; 3] {
        let [a, b, c] = self.p;
        let w0 = (c - b).perp_dot(q - b) / self.area2;
        let w1 = (a - c).perp_dot(q - c) / self.area2;
        [w0, w1, 1.0 - w0 - w1]
    }
}

/// Barycentric coordinates of the point of triangle `p` closest to `q` (all in `[0, 1]`).
/// A degenerate triangle gives the closest point of its edges.
fn closest_barycentric(p: [DVec2; 3], q: DVec2) -> [f64; 3] {
    if let Some(tri) = Triangle::new(p) {
        let b = tri.barycentric(q);
        if b.iter().all(|&x| x >= 0.0) {
            return b;
        }
    }
    let mut best = (f64::INFINITY, [1.0, 0.0, 0.0]);
    for (i, j) in [(0, 1), (1, 2), (2, 0)] {
        let e = p[j] - p[i];
        let len2 = e.length_squared();
        let s = if len2 > 0.0 {
            ((q - p[i]).dot(e) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (p[i] + e * s - q).length_squared();
        if d < best.0 {
            let mut b = [0.0; 3];
            b[i] = 1.0 - s;
            b[j] = s;
            best = (d, b);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_testkit::{assert_close, devices, to_vec};

    /// Two triangles: the unit square split along its diagonal, covering a 5x5 texture
    /// completely, and a small triangle in a corner of an 8x8 texture.
    fn square() -> UvLayout {
        UvLayout {
            uvs: vec![
                DVec2::new(0.0, 0.0),
                DVec2::new(1.0, 0.0),
                DVec2::new(1.0, 1.0),
                DVec2::new(0.0, 1.0),
            ],
            faces: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    /// Two triangles in a 9x9 texture (texel pitch 1/8): the lower-left half-square
    /// `u + v <= 0.5` (in texels: x + (8 - y) <= 4) and a right triangle near the top right.
    fn two_charts() -> UvLayout {
        UvLayout {
            uvs: vec![
                DVec2::new(0.0, 0.0),
                DVec2::new(0.5, 0.0),
                DVec2::new(0.0, 0.5),
                DVec2::new(0.75, 0.75),
                DVec2::new(1.0, 0.75),
                DVec2::new(1.0, 1.0),
            ],
            faces: vec![[0, 1, 2], [3, 4, 5]],
        }
    }

    #[test]
    fn texel_uv_conventions() {
        assert_eq!(texel_uv(0, 0, 5, 5), DVec2::new(0.0, 1.0));
        assert_eq!(texel_uv(4, 4, 5, 5), DVec2::new(1.0, 0.0));
        assert_eq!(texel_uv(2, 1, 5, 3), DVec2::new(0.25, 0.0));
        let p = uv_to_texel(DVec2::new(0.25, 0.0), 5, 3);
        assert_eq!(p, DVec2::new(1.0, 2.0));
    }

    #[test]
    fn from_uv_covers_the_expected_texels() {
        let l = TextureLayout::from_uv(&two_charts(), 9, 9, 0).unwrap();
        // Chart 1: x + (8 - y) <= 4  <=>  y >= x + 4, x, y in 0..9.
        // Chart 2: u in [0.75, 1], v in [0.75, u] -> x in [6, 8], y = 8 (1 - v) with
        // v <= u  <=>  y >= 8 - x, and y <= 2.
        let mut want = Vec::new();
        for r in 0..9u32 {
            for c in 0..9u32 {
                let a = r >= c + 4;
                let b = (6..=8).contains(&c) && r <= 2 && r + c >= 8;
                if a || b {
                    want.push((r, c));
                }
            }
        }
        assert_eq!(l.texels, want);
        assert_eq!(l.num_texels(), 15 + 6);
        let faces = l.texel_faces().unwrap();
        for (&(r, c), &(f, b)) in l.texels.iter().zip(faces) {
            assert_eq!(f, u32::from(r <= 2), "texel ({r}, {c})");
            assert!(b.iter().all(|&x| x >= -1e-6) && (b.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        // Texel (8, 0) is UV vertex 0 of face 0: barycentrics (1, 0, 0).
        let t = l.compact_index(8, 0).unwrap();
        assert_close(&faces[t].1, &[1.0, 0.0, 0.0], 1e-6, "barycentrics");
        // Texel (6, 1): u = 1/8, v = 2/8 -> b1 = u / 0.5, b2 = v / 0.5.
        let t = l.compact_index(6, 1).unwrap();
        assert_close(&faces[t].1, &[0.25, 0.25, 0.5], 1e-6, "barycentrics");
        assert_eq!(l.compact_index(0, 0), None);
        assert_eq!(l.compact_index(9, 0), None);
        let mask = l.mask_image();
        assert_eq!(mask.iter().sum::<f32>(), 21.0);
        assert_eq!(mask[8 * 9], 1.0);
    }

    #[test]
    fn gutter_adds_a_ring_with_clamped_barycentrics() {
        let uv = two_charts();
        let l0 = TextureLayout::from_uv(&uv, 9, 9, 0).unwrap();
        let l1 = TextureLayout::from_uv(&uv, 9, 9, 1).unwrap();
        let charts: Vec<bool> = l0.mask_image().iter().map(|&m| m > 0.0).collect();
        let mut want = Vec::new();
        for r in 0..9usize {
            for c in 0..9usize {
                let near = (r.saturating_sub(1)..=(r + 1).min(8))
                    .any(|rr| (c.saturating_sub(1)..=(c + 1).min(8)).any(|cc| charts[rr * 9 + cc]));
                if near {
                    want.push((r as u32, c as u32));
                }
            }
        }
        assert_eq!(l1.texels, want);
        let faces = l1.texel_faces().unwrap();
        for &(_, b) in faces {
            assert!(b.iter().all(|&x| (-1e-6..=1.0 + 1e-6).contains(&x)));
            assert!((b.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        // Chart texels keep their data.
        for (t, &(r, c)) in l0.texels.iter().enumerate() {
            let t1 = l1.compact_index(r as usize, c as usize).unwrap();
            assert_eq!(faces[t1], l0.texel_faces().unwrap()[t]);
        }
        // (3, 0) is one row above chart 1's top vertex (4, 0): attached to face 0 at that
        // vertex, barycentrics (0, 0, 1).
        let t = l1.compact_index(3, 0).unwrap();
        assert_eq!(faces[t].0, 0);
        assert_close(&faces[t].1, &[0.0, 0.0, 1.0], 1e-6, "gutter barycentrics");
        // (3, 6) is left of chart 2's texel (2, 6) (UV vertex 3): face 1, vertex 3.
        let t = l1.compact_index(3, 6).unwrap();
        assert_eq!(faces[t].0, 1);
        assert_close(&faces[t].1, &[1.0, 0.0, 0.0], 1e-6, "barycentrics");
        // (5, 2), i.e. (x, y) = (2, 5), lies beyond chart 1's hypotenuse y = x + 4; its
        // nearest chart texel is (5, 1).
        let t = l1.compact_index(5, 2).unwrap();
        assert_eq!(faces[t].0, 0);
        let b = faces[t].1;
        assert!(b[0].abs() < 1e-6, "{b:?}");
        // Closest point on the edge from (4, 8) to (0, 4) to (2, 5) is (1.5, 5.5).
        assert_close(
            &b,
            &[0.0, 1.5 / 4.0, 2.5 / 4.0],
            1e-6,
            "clamped barycentrics",
        );
    }

    #[test]
    fn texel_points_reproduce_vertices() {
        let uv = square();
        let l = TextureLayout::from_uv(&uv, 5, 5, 0).unwrap();
        assert_eq!(l.num_texels(), 25);
        let verts = vec![
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(-1.0, 0.5, 0.0),
            DVec3::new(0.0, 0.0, 2.0),
            DVec3::new(4.0, 1.0, -1.0),
        ];
        let pts = l.texel_points(&uv.faces, &verts).unwrap();
        // Texel (4, 0) is UV (0, 0) = vertex 0; (0, 4) is UV (1, 1) = vertex 2; (0, 0) is
        // UV (0, 1) = vertex 3.
        let at = |r, c| pts[l.compact_index(r, c).unwrap()];
        assert!((at(4, 0) - verts[0]).length() < 1e-6);
        assert!((at(0, 4) - verts[2]).length() < 1e-6);
        assert!((at(0, 0) - verts[3]).length() < 1e-6);
        assert!((at(4, 4) - verts[1]).length() < 1e-6);
        // The centre (2, 2) is UV (0.5, 0.5), halfway between vertices 0 and 2.
        assert!((at(2, 2) - (verts[0] + verts[2]) * 0.5).length() < 1e-6);
        assert_eq!(l.texel_points(&uv.faces[..1], &verts), None);
        let plain = TextureLayout::from_texels(5, 5, vec![(0, 0)], None).unwrap();
        assert_eq!(plain.texel_points(&uv.faces, &verts), None);
    }

    #[test]
    fn bad_layouts_are_refused() {
        let e = |r: Result<TextureLayout, TextureError>| r.unwrap_err().to_string();
        assert!(e(TextureLayout::from_texels(4, 4, vec![], None)).contains("at least one"));
        assert!(e(TextureLayout::from_texels(4, 4, vec![(4, 0)], None)).contains("outside"));
        assert!(e(TextureLayout::from_texels(4, 4, vec![(1, 2), (1, 2)], None)).contains("twice"));
        assert!(e(TextureLayout::from_texels(0, 4, vec![(0, 0)], None)).contains("empty"));
        let mut uv = square();
        uv.faces.push([0, 1, 7]);
        assert!(e(TextureLayout::from_uv(&uv, 4, 4, 0)).contains("UV vertex 7"));
        let mut uv = square();
        uv.uvs[1].x = f64::NAN;
        assert!(e(TextureLayout::from_uv(&uv, 4, 4, 0)).contains("not finite"));
        let tiny = UvLayout {
            uvs: vec![
                DVec2::new(0.1, 0.1),
                DVec2::new(0.2, 0.1),
                DVec2::new(0.1, 0.2),
            ],
            faces: vec![[0, 1, 2]],
        };
        assert!(e(TextureLayout::from_uv(&tiny, 4, 4, 0)).contains("covers no texel"));
        let l = TextureLayout::from_texels(4, 4, vec![(0, 0), (3, 3)], None).unwrap();
        assert!(
            l.compact_to_image(&[0.0; 5], [0.0; 3])
                .unwrap_err()
                .to_string()
                .contains("has 5 values, expected 6")
        );
        assert!(l.image_to_compact(&[0.0; 47]).is_err());
    }

    /// The procedural hand's UV layout at 512 x 512 with a 2-texel gutter: the texel nearest
    /// to each UV corner maps back onto (near) that corner's mesh vertex.
    #[test]
    fn procedural_hand_texels_map_onto_the_mesh() {
        let hand = bitt_mesh::default_hand(bitt_mesh::Side::Right);
        let uv = hand.uv.as_ref().expect("the procedural hand has UVs");
        let (w, h) = (512, 512);
        let start = std::time::Instant::now();
        let l = TextureLayout::from_uv(uv, w, h, 2).unwrap();
        let seconds = start.elapsed().as_secs_f64();
        assert!(seconds < 5.0, "from_uv took {seconds} s");
        let pts = l.texel_points(&hand.faces, &hand.v_template).unwrap();
        assert_eq!(pts.len(), l.num_texels());
        let mut worst = 0f64;
        for (f, corners) in uv.faces.iter().enumerate() {
            for (k, &ui) in corners.iter().enumerate() {
                let p = uv_to_texel(uv.uvs[ui as usize], w, h);
                let (r, c) = (p.y.round() as usize, p.x.round() as usize);
                let t = l.compact_index(r, c).expect("texel at a UV corner");
                let v = hand.v_template[hand.faces[f][k] as usize];
                worst = worst.max((pts[t] - v).length());
            }
        }
        // Half a texel of UV error, stretched onto a ~0.2 m hand.
        assert!(worst < 3e-3, "worst distance {worst} m");
    }

    fn sample_layout() -> (TextureLayout, Vec<f32>) {
        // An irregular texel order, not row-major.
        let texels = vec![(2, 3), (0, 0), (1, 4), (3, 1), (2, 0), (0, 4)];
        let l = TextureLayout::from_texels(5, 4, texels, None).unwrap();
        let compact: Vec<f32> = (0..18).map(|i| 0.05 * i as f32 + 0.01).collect();
        (l, compact)
    }

    #[test]
    fn plain_round_trip_is_exact() {
        let (l, compact) = sample_layout();
        let bg = [0.25, 0.5, 0.75];
        let image = l.compact_to_image(&compact, bg).unwrap();
        assert_eq!(image.len(), 3 * 20);
        // Green (channel 1) of texel 2 at (row 1, col 4).
        assert_eq!(image[20 + 5 + 4], compact[6 + 2]);
        assert_eq!(image[2 * 20 + 3 * 5 + 1], compact[12 + 3]);
        assert_eq!(image[5 + 1], 0.25);
        assert_eq!(image[2 * 20 + 19], 0.75);
        assert_eq!(l.image_to_compact(&image).unwrap(), compact);
    }

    #[test]
    fn tensor_round_trip_matches_plain() {
        let (l, compact) = sample_layout();
        let bg = [0.25, 0.5, 0.75];
        let plain = l.compact_to_image(&compact, bg).unwrap();
        for (name, device) in devices() {
            let c = Tensor::<2>::from_data(TensorData::new(compact.clone(), [3, 6]), &device);
            let img = l.compact_to_image_tensor(c, bg);
            assert_eq!(img.dims(), [3, 4, 5], "{name}");
            assert_eq!(to_vec(img.clone()), plain, "{name}");
            let back = l.image_to_compact_tensor(img);
            assert_eq!(to_vec(back), compact, "{name}");
        }
    }

    #[test]
    fn gradient_of_an_image_loss_reaches_the_compact_texels() {
        let (l, compact) = sample_layout();
        let weights: Vec<f32> = (0..60).map(|i| ((i * 7) % 11) as f32 * 0.1 - 0.3).collect();
        // loss = sum(w * image^2): d loss / d compact[c, t] = 2 w[c, r, col] compact[c, t].
        let mut want = vec![0f32; 18];
        for c in 0..3 {
            for (t, &(r, col)) in l.texels.iter().enumerate() {
                let w = weights[c * 20 + r as usize * 5 + col as usize];
                want[c * 6 + t] = 2.0 * w * compact[c * 6 + t];
            }
        }
        for (name, device) in devices() {
            let ad = device.autodiff();
            let c = Tensor::<2>::from_data(TensorData::new(compact.clone(), [3, 6]), &ad)
                .require_grad();
            let w = Tensor::<3>::from_data(TensorData::new(weights.clone(), [3, 4, 5]), &ad);
            let img = l.compact_to_image_tensor(c.clone(), [0.3, 0.2, 0.1]);
            let loss = (img.clone() * img * w).sum();
            let grads = loss.backward();
            let g = c.grad(&grads).expect("gradient");
            assert_eq!(g.dims(), [3, 6], "{name}");
            assert_close(&to_vec(g), &want, 1e-6, name);
        }
    }
}
