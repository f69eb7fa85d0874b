//! The dense path of [`super::SceneGeometry`]: per-pixel tensors over all `H W` pixels from
//! [`crate::rasterize_dense`]'s outputs, with per-mesh masks, so that making and shading a
//! geometry on a GPU needs no host readback.

use burn::tensor::{Bool, Tensor};

use super::{Camera, Material, PointLight, Scene, phong, vertex_normals};
use crate::error::RenderError;
use crate::ops::{
    DenseRaster, TexturePlan, dense_barycentrics, float_tensor, interpolate_dense,
    interpolate_dense_with_faces,
};

/// The per-pixel part of a dense [`super::SceneGeometry`], rows = all pixels, row-major.
#[derive(Debug, Clone)]
pub(super) struct DenseGeometry {
    /// `[H W, 3]`: true on empty pixels.
    empty: Tensor<2, Bool>,
    /// `[H W, 3]` each; normals and directions to the camera are `(0, 0, 1)` on empty pixels
    /// so that normalizing them stays finite (a NaN there would reach the gradients).
    normals: Tensor<2>,
    points: Tensor<2>,
    to_camera: Tensor<2>,
    /// `[H W, 1]`: the light visibility of each pixel, when the geometry has one.
    occlusion: Option<Tensor<2>>,
    /// Per mesh: `[H W, 1]` its visible pixels (1/0), and its texel footprints at every pixel.
    lookups: Vec<(Tensor<2>, TexturePlan)>,
}

/// Fills the rows of `values [N, 3]` where `empty` is true with `(0, 0, 1)`.
fn fill_empty(values: Tensor<2>, empty: &Tensor<2, Bool>) -> Tensor<2> {
    let n = values.dims()[0];
    let unit = float_tensor(vec![0.0, 0.0, 1.0], [1, 3], &values.device()).expand([n, 3]);
    values.mask_where(empty.clone(), unit)
}

impl DenseGeometry {
    /// Builds the per-pixel tensors and the per-mesh masks `[H, W]` (1/0).
    ///
    /// # Shapes
    /// all vertices `[V, 3]`, occlusion `[V, 1]`, clip `[V, 4]`
    pub(super) fn new(
        scene: &Scene,
        all: Tensor<2>,
        occlusion: Option<Tensor<2>>,
        clip: Tensor<2>,
        dense: &DenseRaster,
        camera: &Camera,
        texture_sizes: &[[usize; 2]],
    ) -> Result<(Self, Vec<Tensor<2>>), RenderError> {
        let device = all.device();
        let [h, w] = dense.face.dims();
        let n = h * w;
        let raster = dense_barycentrics(dense, clip, &scene.topology)?;
        let face = dense.face.clone();
        let masks: Vec<Tensor<2>> = (0..scene.num_meshes())
            .map(|i| {
                let range = scene.face_range(i);
                face.clone()
                    .greater_equal_elem(i64::from(range.start))
                    .bool_and(face.clone().lower_elem(i64::from(range.end)))
                    .float()
            })
            .collect();
        let empty = raster.covered().bool_not().reshape([n, 1]).expand([n, 3]);
        let normals = vertex_normals(all.clone(), &scene.topology)?;
        let normals = fill_empty(interpolate_dense(normals, &raster)?, &empty);
        let points = interpolate_dense(all, &raster)?;
        let occlusion = occlusion
            .map(|o| interpolate_dense(o, &raster))
            .transpose()?;
        let uvs: Vec<f32> = scene.uvs.iter().flatten().copied().collect();
        let uv_table = float_tensor(uvs, [scene.uvs.len(), 2], &device);
        let uv = interpolate_dense_with_faces(uv_table, &scene.uv_faces, &raster)?;
        let mut lookups = Vec::with_capacity(texture_sizes.len());
        for (mask, &[th, tw]) in masks.iter().zip(texture_sizes) {
            let plan = TexturePlan::new(uv.clone(), th, tw)?;
            lookups.push((mask.clone().reshape([n, 1]), plan));
        }
        let to_camera = fill_empty(camera.directions_to_camera(points.clone()), &empty);
        Ok((
            Self {
                empty,
                normals,
                points,
                to_camera,
                occlusion,
                lookups,
            },
            masks,
        ))
    }

    /// Replaces mesh `i`'s texture plan by `remap(i, plan)` ([`SceneGeometry::with_compact_textures`]).
    ///
    /// [`SceneGeometry::with_compact_textures`]: super::SceneGeometry::with_compact_textures
    pub(super) fn remap_lookups(
        &mut self,
        remap: impl Fn(usize, &TexturePlan) -> Result<TexturePlan, RenderError>,
    ) -> Result<(), RenderError> {
        for (i, (_, plan)) in self.lookups.iter_mut().enumerate() {
            *plan = remap(i, plan)?;
        }
        Ok(())
    }

    /// Shades every pixel (each mesh's pixels from its own texture) and puts `background` on
    /// empty pixels.
    ///
    /// # Shapes
    /// textures: per mesh `[3, Ht_i, Wt_i]` -> image `[3, H, W]`
    pub(super) fn shade(
        &self,
        textures: &[Tensor<3>],
        light: &PointLight,
        material: &Material,
        background: [f32; 3],
        [h, w]: [usize; 2],
    ) -> Result<Tensor<3>, RenderError> {
        let n = h * w;
        let device = self.points.device();
        let mut texels: Option<Tensor<2>> = None;
        for ((mask, plan), texture) in self.lookups.iter().zip(textures) {
            let part = plan.sample(texture.clone())? * mask.clone();
            texels = Some(match texels {
                Some(sum) => sum + part,
                None => part,
            });
        }
        let texels = texels.unwrap_or_else(|| Tensor::zeros([n, 3], &device));
        // On empty pixels the point sits at unit distance from the light (a constant, no
        // gradient), so the light direction stays finite there.
        let beside_light = light.location.clone().detach().reshape([1, 3])
            - float_tensor(vec![0.0, 0.0, 1.0], [1, 3], &device);
        let points = self
            .points
            .clone()
            .mask_where(self.empty.clone(), beside_light.expand([n, 3]));
        let shaded = phong(
            texels,
            self.normals.clone(),
            points,
            self.to_camera.clone(),
            light,
            material,
        );
        let shaded = match &self.occlusion {
            Some(o) => shaded * o.clone(),
            None => shaded,
        };
        let bg = float_tensor(background.to_vec(), [1, 3], &device).expand([n, 3]);
        Ok(shaded
            .mask_where(self.empty.clone(), bg)
            .swap_dims(0, 1)
            .reshape([3, h, w]))
    }
}
