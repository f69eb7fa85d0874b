//! [`SceneGeometry`]: the vertex-dependent part of a render, made once and shaded many
//! times, on the covered-pixel or the dense path.

use burn::tensor::Tensor;

use super::dense::DenseGeometry;
use super::{Camera, Material, PointLight, RenderSettings, Scene, phong, vertex_normals};
use crate::error::RenderError;
use crate::ops::{
    AntialiasPlan, Raster, TexturePlan, Topology, float_tensor, index_tensor, interpolate,
    interpolate_with_faces, rasterize,
};
use bitt_texture::TextureLayout;

/// Everything of a render that depends only on the meshes' vertices, the camera, the depth
/// range, the antialiasing switch and the textures' sizes: the raster, the per-mesh masks,
/// per covered pixel its world position, interpolated normal, direction to the camera and
/// texel footprint, the pixel order of the meshes, and the silhouette pairs with their
/// blend weights. [`SceneGeometry::shade`] turns textures and a light into an image with
/// tensor operations only (no host work, no read-back).
///
/// Made from vertex tensors that carry gradients, its tensors keep them (shading is then
/// differentiable in the vertices, as [`render`] is), and it serves one backward pass (burn
/// keeps no graph after one): shade it as often as needed within one loss. Made from
/// constants, it can be reused for every render of a fixed geometry, over any number of
/// steps.
///
/// # Two paths
/// * **Covered pixels** (flex, ndarray, any device without the CubeCL rasterizer): the
///   clip positions are read back once, [`rasterize`] lists the covered pixels and the
///   per-pixel tensors have one row per covered pixel.
/// * **Dense** (wgpu, CUDA: where [`crate::rasterize_dense`] runs its CubeCL kernel): the
///   face ids stay on the device and the per-pixel tensors cover all `H W` pixels with
///   per-mesh masks ([`crate::dense_barycentrics`], [`crate::interpolate_dense`],
///   [`AntialiasPlan::from_dense`]); making and shading the geometry reads nothing back,
///   even when the vertices change every step. The host [`Raster`] is then built only when
///   [`SceneGeometry::raster`] is called (one readback).
///
/// Both give the same image and gradients (up to float rounding, and up to silhouette
/// decisions within rounding of a tie, which the dense path makes in `f32`).
#[derive(Debug, Clone)]
pub struct SceneGeometry {
    /// Per mesh, its visible pixels `[H, W]` (1/0) after the shared depth test.
    pub masks: Vec<Tensor<2>>,
    /// The clip positions of all vertices `[sum V, 4]`.
    pub clip: Tensor<2>,
    /// The host raster: made at once on the covered path, on demand on the dense path.
    raster: std::sync::OnceLock<Raster>,
    /// The concatenated topology, kept on the dense path to make the raster on demand.
    topology: Option<Topology>,
    size: [usize; 2],
    texture_sizes: Vec<[usize; 2]>,
    /// Per mesh, the texel count `T_i` of its compact texture when the geometry samples
    /// compact textures ([`SceneGeometry::with_compact_textures`]); `None`: texture images.
    compact: Option<Vec<usize>>,
    pixels: Pixels,
    antialias: Option<AntialiasPlan>,
}

/// Which per-pixel layout a [`SceneGeometry`] uses.
#[derive(Debug, Clone)]
enum Pixels {
    /// No pixel is covered (covered path).
    Empty,
    /// One row per covered pixel.
    Covered(PixelGeometry),
    /// One row per pixel of the image.
    Dense(DenseGeometry),
}

/// Which per-pixel layout a [`SceneGeometry`] uses. The dense one needs no host readback on
/// a device where the CubeCL rasterizer runs; the covered one does less work per shade and
/// has the host [`Raster`] at once (what unwrapping and scoring read).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeometryPath {
    /// Dense where the CubeCL rasterizer runs, covered pixels elsewhere.
    Auto,
    /// Covered pixels everywhere.
    Covered,
    /// Dense everywhere (on the host rasterizer where the kernel cannot run).
    Dense,
}

/// The per-pixel part of a [`SceneGeometry`] (absent when no pixel is covered).
#[derive(Debug, Clone)]
struct PixelGeometry {
    /// `[N, 3]` each.
    normals: Tensor<2>,
    points: Tensor<2>,
    to_camera: Tensor<2>,
    /// `[N, 1]`: the light visibility of each pixel, when the geometry has one.
    occlusion: Option<Tensor<2>>,
    /// Per mesh with covered pixels: its texel footprints (rows of that mesh's pixels).
    lookups: Vec<(usize, TexturePlan)>,
    /// Restores the pixel order after sampling mesh by mesh.
    inverse: Tensor<1, burn::tensor::Int>,
}

impl SceneGeometry {
    /// Rasterizes `scene` and prepares shading it with textures of `texture_sizes`
    /// (`[Ht, Wt]` per mesh); `settings` gives the depth range and whether to antialias
    /// (its material and background are [`SceneGeometry::shade`]'s arguments).
    ///
    /// # Shapes
    /// vertices: per mesh `[V_i, 3]` (world coordinates)
    ///
    /// # Errors
    /// Wrong counts or shapes, an unusable camera, non-finite positions, a zero texture size.
    pub fn new(
        scene: &Scene,
        vertices: &[Tensor<2>],
        camera: &Camera,
        settings: &RenderSettings,
        texture_sizes: &[[usize; 2]],
    ) -> Result<Self, RenderError> {
        Self::with_path(
            scene,
            vertices,
            camera,
            settings,
            texture_sizes,
            GeometryPath::Auto,
        )
    }

    /// [`SceneGeometry::new`] on a chosen path.
    ///
    /// # Errors
    /// As [`SceneGeometry::new`].
    pub(crate) fn with_path(
        scene: &Scene,
        vertices: &[Tensor<2>],
        camera: &Camera,
        settings: &RenderSettings,
        texture_sizes: &[[usize; 2]],
        path: GeometryPath,
    ) -> Result<Self, RenderError> {
        Self::with_occlusion(scene, vertices, None, camera, settings, texture_sizes, path)
    }

    /// [`SceneGeometry::with_path`] with a light visibility per vertex: `occlusion`
    /// `[sum V, 1]` (all meshes' vertices in order, values in `[0, 1]`, e.g. ambient
    /// occlusion) is interpolated over each pixel and scales its whole shaded colour, so a
    /// crease or a palm pressed against the other hand is shaded darker than [`phong`]
    /// alone would. `None`: every vertex fully lit.
    ///
    /// # Errors
    /// As [`SceneGeometry::new`], and an `occlusion` of another shape.
    pub fn with_occlusion(
        scene: &Scene,
        vertices: &[Tensor<2>],
        occlusion: Option<Tensor<2>>,
        camera: &Camera,
        settings: &RenderSettings,
        texture_sizes: &[[usize; 2]],
        path: GeometryPath,
    ) -> Result<Self, RenderError> {
        camera.validate()?;
        if let Some(o) = &occlusion {
            let want = scene.topology.num_vertices();
            crate::ops::check_shape("occlusion", o.dims(), [Some(want), Some(1)], || {
                format!("[V, 1] with V = {want} (all meshes' vertices)")
            })?;
        }
        let m = scene.num_meshes();
        crate::error::check_len("vertex tensors", vertices.len(), m)?;
        crate::error::check_len("texture sizes", texture_sizes.len(), m)?;
        for &[h, w] in texture_sizes {
            crate::error::check_image(w, h)?;
        }
        for (i, v) in vertices.iter().enumerate() {
            let want = scene.vertex_counts[i];
            crate::ops::check_shape("vertices", v.dims(), [Some(want), Some(3)], || {
                format!("[V, 3] with V = {want} for mesh {i}")
            })?;
        }
        let all = Tensor::cat(vertices.to_vec(), 0);
        let device = all.device();
        let clip = camera.clip_positions(all.clone(), settings.depth)?;
        let size = [camera.height(), camera.width()];
        let dense = match path {
            GeometryPath::Covered => None,
            GeometryPath::Auto => {
                crate::ops::dense::rasterize_on_device(&clip, &scene.topology, size[0], size[1])?
                    .ok()
            }
            GeometryPath::Dense => Some(crate::rasterize_dense(
                clip.clone(),
                &scene.topology,
                size[0],
                size[1],
            )?),
        };
        if let Some(dense) = dense {
            let (pixels, masks) = DenseGeometry::new(
                scene,
                all,
                occlusion,
                clip.clone(),
                &dense,
                camera,
                texture_sizes,
            )?;
            let antialias = settings
                .antialias
                .then(|| AntialiasPlan::from_dense(&dense, clip.clone(), &scene.topology))
                .transpose()?;
            return Ok(Self {
                masks,
                clip,
                raster: std::sync::OnceLock::new(),
                topology: Some(scene.topology.clone()),
                size,
                texture_sizes: texture_sizes.to_vec(),
                compact: None,
                pixels: Pixels::Dense(pixels),
                antialias,
            });
        }
        let raster = rasterize(
            clip.clone(),
            &scene.topology,
            camera.height(),
            camera.width(),
        )?;
        let n = raster.num_covered();
        let masks = (0..m)
            .map(|i| raster.face_range_mask(scene.face_range(i), &device))
            .collect();
        let pixels = if n == 0 {
            Pixels::Empty
        } else {
            let normals = vertex_normals(all.clone(), &scene.topology)?;
            let normals = interpolate(normals, &raster)?;
            let points = interpolate(all, &raster)?;
            let uvs: Vec<f32> = scene.uvs.iter().flatten().copied().collect();
            let uv_table = float_tensor(uvs, [scene.uvs.len(), 2], &device);
            let uv = interpolate_with_faces(uv_table, &scene.uv_faces, &raster)?;
            // Each mesh's pixels sample its own texture; `inverse` restores the pixel order.
            let faces = raster.covered_faces();
            let mut order = Vec::with_capacity(n);
            let mut lookups = Vec::new();
            for (i, &[h, w]) in texture_sizes.iter().enumerate() {
                let range = scene.face_range(i);
                let rows: Vec<i64> = (0..n)
                    .filter(|&k| range.contains(&faces[k]))
                    .map(|k| k as i64)
                    .collect();
                if rows.is_empty() {
                    continue;
                }
                order.extend(rows.iter().map(|&r| r as usize));
                let uv_i = uv.clone().select(0, index_tensor(rows, &device));
                lookups.push((i, TexturePlan::new(uv_i, h, w)?));
            }
            let mut inverse = vec![0i64; n];
            for (pos, &row) in order.iter().enumerate() {
                inverse[row] = pos as i64;
            }
            let to_camera = camera.directions_to_camera(points.clone());
            let occlusion = occlusion.map(|o| interpolate(o, &raster)).transpose()?;
            Pixels::Covered(PixelGeometry {
                normals,
                points,
                to_camera,
                occlusion,
                lookups,
                inverse: index_tensor(inverse, &device),
            })
        };
        let antialias = match (&pixels, settings.antialias) {
            (Pixels::Covered(_), true) => {
                Some(AntialiasPlan::new(&raster, clip.clone(), &scene.topology)?)
            }
            _ => None,
        };
        Ok(Self {
            masks,
            clip,
            raster: std::sync::OnceLock::from(raster),
            topology: None,
            size,
            texture_sizes: texture_sizes.to_vec(),
            compact: None,
            pixels,
            antialias,
        })
    }

    /// The raster of all meshes (depth buffer, face ids) on the host. On the dense path it
    /// is made on the first call from [`SceneGeometry::clip`] (one host readback) and kept.
    ///
    /// # Errors
    /// As [`rasterize`] (on the dense path only).
    pub fn raster(&self) -> Result<&Raster, RenderError> {
        if let Some(r) = self.raster.get() {
            return Ok(r);
        }
        let topology = self.topology.as_ref().ok_or(RenderError::BadLayout(
            "a covered-path geometry without its raster".into(),
        ))?;
        let raster = rasterize(self.clip.clone(), topology, self.size[0], self.size[1])?;
        Ok(self.raster.get_or_init(|| raster))
    }

    /// Whether the geometry is on the dense path (no host readback; see [`SceneGeometry`]).
    pub fn is_dense(&self) -> bool {
        matches!(self.pixels, Pixels::Dense(_))
    }

    /// Shades the geometry: per covered pixel the texel of its mesh's texture, lit by
    /// `light` with `material` ([`phong`]), `background` elsewhere, then antialiased if the
    /// geometry was made with antialiasing. Differentiable in the textures and the light
    /// (and in the vertices, if the geometry was made from vertices with gradients).
    ///
    /// # Shapes
    /// textures: per mesh `[3, Ht_i, Wt_i]` of the sizes the geometry was made for ->
    /// image `[3, H, W]`
    ///
    /// # Errors
    /// A texture count or size other than the geometry's.
    pub fn shade(
        &self,
        textures: &[Tensor<3>],
        light: &PointLight,
        material: &Material,
        background: [f32; 3],
    ) -> Result<Tensor<3>, RenderError> {
        if self.compact.is_some() {
            return Err(RenderError::BadLayout(
                "this geometry samples compact textures (SceneGeometry::shade_compact)".into(),
            ));
        }
        crate::error::check_len("textures", textures.len(), self.texture_sizes.len())?;
        for (i, (t, want)) in textures.iter().zip(&self.texture_sizes).enumerate() {
            let [_, th, tw] = t.dims();
            if [th, tw] != *want {
                return Err(RenderError::TensorShape {
                    what: "texture",
                    expected: format!("[3, {}, {}] for mesh {i}", want[0], want[1]),
                    actual: t.dims().to_vec(),
                });
            }
        }
        self.shade_prepared(textures, light, material, background)
    }

    /// This geometry prepared to sample compact textures: mesh `i`'s texture is given to
    /// [`SceneGeometry::shade_compact`] as the `[C, T_i]` texels of `layouts[i]` (its
    /// compact order), and the texels the layout does not use read 0, as they do in
    /// [`TextureLayout::compact_to_image`] with a black background. Shading then never
    /// expands a texture to its `Ht x Wt` image: the samples read the compact texels
    /// ([`TexturePlan::through_columns`]), and their gradient is scattered into `T_i`
    /// texels. The images are the same as [`SceneGeometry::shade`] gives on the expanded
    /// textures, and so are the gradients.
    ///
    /// # Errors
    /// A layout count other than the meshes', a layout of another size than the texture
    /// size the geometry was made for, or a geometry already prepared.
    pub fn with_compact_textures(
        mut self,
        layouts: &[&TextureLayout],
    ) -> Result<Self, RenderError> {
        if self.compact.is_some() {
            return Err(RenderError::BadLayout(
                "this geometry already samples compact textures".into(),
            ));
        }
        crate::error::check_len("layouts", layouts.len(), self.texture_sizes.len())?;
        let device = self.clip.device();
        let mut columns = Vec::with_capacity(layouts.len());
        for (i, (layout, &[h, w])) in layouts.iter().zip(&self.texture_sizes).enumerate() {
            if [layout.height, layout.width] != [h, w] {
                return Err(RenderError::BadLayout(format!(
                    "mesh {i}'s layout is {} x {} texels; the geometry was made for {h} x {w}",
                    layout.height, layout.width
                )));
            }
            // Unused texels read the column after the compact ones, which holds 0.
            let t = layout.num_texels();
            let index: Vec<i64> = (0..h * w)
                .map(|k| layout.compact_index(k / w, k % w).unwrap_or(t) as i64)
                .collect();
            columns.push((index_tensor(index, &device), t + 1));
        }
        let remap = |i: usize, plan: &TexturePlan| {
            let (index, len) = &columns[i];
            plan.through_columns(index, *len)
        };
        match &mut self.pixels {
            Pixels::Empty => {}
            Pixels::Covered(px) => {
                for (i, plan) in &mut px.lookups {
                    *plan = remap(*i, plan)?;
                }
            }
            Pixels::Dense(px) => px.remap_lookups(remap)?,
        }
        self.compact = Some(layouts.iter().map(|l| l.num_texels()).collect());
        Ok(self)
    }

    /// [`SceneGeometry::shade`] for a geometry made with
    /// [`SceneGeometry::with_compact_textures`]: the same image from compact textures.
    ///
    /// # Shapes
    /// textures: per mesh `[3, T_i]` (its layout's compact order) -> image `[3, H, W]`
    ///
    /// # Errors
    /// A geometry not made for compact textures, or a texture count or size other than its
    /// layouts'.
    pub fn shade_compact(
        &self,
        textures: &[Tensor<2>],
        light: &PointLight,
        material: &Material,
        background: [f32; 3],
    ) -> Result<Tensor<3>, RenderError> {
        let Some(texels) = &self.compact else {
            return Err(RenderError::BadLayout(
                "this geometry samples texture images (SceneGeometry::shade)".into(),
            ));
        };
        crate::error::check_len("textures", textures.len(), texels.len())?;
        let mut tables = Vec::with_capacity(textures.len());
        for (i, (t, &want)) in textures.iter().zip(texels).enumerate() {
            let [c, n] = t.dims();
            if n != want {
                return Err(RenderError::TensorShape {
                    what: "compact texture",
                    expected: format!("[3, {want}] for mesh {i}"),
                    actual: t.dims().to_vec(),
                });
            }
            // The unused texels' column.
            let unused = Tensor::<2>::zeros([c, 1], &t.device());
            tables.push(Tensor::cat(vec![t.clone(), unused], 1).reshape([c, 1, n + 1]));
        }
        self.shade_prepared(&tables, light, material, background)
    }

    /// Shading with textures whose sizes are checked (images, or compact tables `[C, 1,
    /// T_i + 1]`).
    fn shade_prepared(
        &self,
        textures: &[Tensor<3>],
        light: &PointLight,
        material: &Material,
        background: [f32; 3],
    ) -> Result<Tensor<3>, RenderError> {
        let device = self.clip.device();
        let [h, w] = self.size;
        let px = match &self.pixels {
            Pixels::Empty => {
                return Ok(float_tensor(background.to_vec(), [3, 1, 1], &device).repeat(&[1, h, w]));
            }
            Pixels::Dense(px) => {
                let image = px.shade(textures, light, material, background, self.size)?;
                return match &self.antialias {
                    Some(plan) => plan.apply(image),
                    None => Ok(image),
                };
            }
            Pixels::Covered(px) => px,
        };
        let mut parts = Vec::with_capacity(px.lookups.len());
        for (i, plan) in &px.lookups {
            parts.push(plan.sample(textures[*i].clone())?);
        }
        let texels = Tensor::cat(parts, 0).select(0, px.inverse.clone());
        let shaded = phong(
            texels,
            px.normals.clone(),
            px.points.clone(),
            px.to_camera.clone(),
            light,
            material,
        );
        let shaded = match &px.occlusion {
            Some(o) => shaded * o.clone(),
            None => shaded,
        };
        let image = self.raster()?.to_image(shaded, &background);
        match &self.antialias {
            Some(plan) => plan.apply(image),
            None => Ok(image),
        }
    }
}
