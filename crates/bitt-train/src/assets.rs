//! What every view of a run shares: the two hand models, their render meshes and the UV
//! texture layout, and one view's fixed geometry (posed vertices and camera).

use bitt_mesh::glam::DVec3;
use bitt_mesh::{HandPair, Side, TwoHandScene};
use bitt_render::scene::{
    Camera, DepthRange, GeometryPath, PointLight, RenderSettings, Scene, SceneGeometry,
    SceneRender, TexelSurface, TexturedMesh,
};
use bitt_texture::{LayoutGather, TextureLayout};
use std::sync::{Arc, Mutex};

use burn::tensor::{Device, Tensor, TensorData};

use crate::TrainError;

/// Gutter ring (texels) around the UV charts of the texture layouts (as `bitt render`).
pub const TEXTURE_GUTTER: usize = 2;

/// The hand models and everything derived from their UV layout, shared by every view.
#[derive(Debug, Clone)]
pub struct HandAssets {
    /// Left and right hand models.
    pub models: HandPair,
    /// Render meshes, left then right.
    pub meshes: [TexturedMesh; 2],
    /// Texture layouts of both hands (same texel order; each with its own texel faces).
    pub layouts: [TextureLayout; 2],
    /// Texel surfaces for unwrapping, left then right.
    pub surfaces: [TexelSurface; 2],
    /// Both hands as one render scene.
    pub scene: Scene,
    /// Side of the square UV textures.
    pub texture_size: usize,
}

impl HandAssets {
    /// Builds the meshes and `texture_size`-square layouts of `models` (both need a UV layout).
    pub fn new(models: HandPair, texture_size: usize) -> Result<Self, TrainError> {
        let mut meshes = Vec::new();
        let mut layouts = Vec::new();
        let mut surfaces = Vec::new();
        for side in [Side::Left, Side::Right] {
            let model = models.get(side);
            meshes.push(bitt_synth::textured_mesh(model)?);
            let uv = model.uv.as_ref().ok_or_else(|| {
                TrainError::Invalid(format!("the {side} hand model has no UV layout"))
            })?;
            let layout = TextureLayout::from_uv(uv, texture_size, texture_size, TEXTURE_GUTTER)?;
            surfaces.push(TexelSurface::new(
                &layout,
                &model.faces,
                model.num_vertices(),
            )?);
            layouts.push(layout);
        }
        if layouts[0].num_texels() != layouts[1].num_texels() {
            return Err(TrainError::Invalid(format!(
                "left and right texture layouts differ ({} vs {} texels)",
                layouts[0].num_texels(),
                layouts[1].num_texels()
            )));
        }
        let scene = Scene::new(&[&meshes[0], &meshes[1]])?;
        Ok(HandAssets {
            models,
            meshes: two(meshes),
            layouts: two(layouts),
            surfaces: two(surfaces),
            scene,
            texture_size,
        })
    }

    /// Texels per hand `T`.
    pub fn num_texels(&self) -> usize {
        self.layouts[0].num_texels()
    }

    /// Checks that a texture PCA covers these hands' layout (a prior fitted on another
    /// layout would give a basis of the wrong size).
    ///
    /// # Errors
    /// [`TrainError::Invalid`] naming both texel counts.
    pub fn check_prior(&self, pca: &bitt_texture::TexturePca) -> Result<(), TrainError> {
        if pca.layout.num_texels() == self.num_texels() {
            return Ok(());
        }
        Err(TrainError::Invalid(format!(
            "the texture PCA covers {} texels, the hands' layout {}",
            pca.layout.num_texels(),
            self.num_texels()
        )))
    }

    /// The compact <-> image index tensors on `device`.
    pub fn gather(&self, device: &Device) -> LayoutGather {
        self.layouts[0].gather(device)
    }
}

/// One view's fixed geometry: both hands posed in the camera frame, and the camera.
///
/// The vertices are constants (no gradient), so everything a render needs from them (the
/// raster, per-pixel positions, normals and texel footprints, silhouette pairs) is computed
/// once per depth range, antialiasing switch and texture size, on the first render, and
/// reused by every later render of the view and its clones: a training step only samples
/// textures, shades and blends.
#[derive(Debug, Clone)]
pub struct ViewGeometry {
    /// The render camera (camera-frame vertices, so identity extrinsics).
    pub camera: Camera,
    /// The scene's camera with its extrinsics (to move lights between views).
    pub scene_camera: bitt_mesh::PinholeCamera,
    /// Posed vertices in the camera frame, left then right.
    pub vertices_host: [Vec<DVec3>; 2],
    /// The same as `[V, 3]` tensors.
    pub vertices: [Tensor<2>; 2],
    /// The hands' parameters and camera the vertices were posed from, when they were (not
    /// for a view made from vertices alone).
    pub hands: Option<TwoHandScene>,
    /// The hands' light visibility (see [`ViewGeometry::with_occlusion`]), when shaded with
    /// it.
    occlusion: Option<Occlusion>,
    /// The render geometry made so far (see the type's docs).
    cache: GeometryCache,
}

/// The light visibility of a view's vertices: `1 - strength (1 - ao)` per vertex, with `ao`
/// the ambient occlusion of both hands together.
#[derive(Debug, Clone)]
struct Occlusion {
    strength: f64,
    /// Left then right hand's vertices.
    factors: Arc<Vec<f32>>,
}

/// What identifies a [`SceneGeometry`] of one view: depth range, antialiasing, per-pixel
/// layout (the texture size is the assets').
type CacheKey = (DepthRange, bool, GeometryPath);

/// The [`SceneGeometry`]s made so far, with their keys.
type CacheEntries = Vec<(CacheKey, Arc<SceneGeometry>)>;

/// The [`SceneGeometry`]s of one view, shared by its clones.
#[derive(Debug, Clone, Default)]
struct GeometryCache(Arc<Mutex<CacheEntries>>);

impl ViewGeometry {
    /// Poses both hands of `scene` (both must be present) on `device`.
    pub fn new(
        assets: &HandAssets,
        scene: &TwoHandScene,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let posed = scene.pose_in_camera(&assets.models)?;
        let mut host = Vec::new();
        for side in [Side::Left, Side::Right] {
            let hand = posed.get(side).ok_or_else(|| {
                TrainError::Invalid(format!("the scene has no {side} hand; BiTT needs both"))
            })?;
            host.push(hand.vertices.clone());
        }
        let host: [Vec<DVec3>; 2] = host.try_into().expect("two hands");
        let c = &scene.camera;
        let camera = Camera::Pinhole(bitt_mesh::PinholeCamera {
            rotation: bitt_mesh::glam::DMat3::IDENTITY,
            translation: DVec3::ZERO,
            ..*c
        });
        Ok(ViewGeometry {
            hands: Some(scene.clone()),
            ..Self::from_vertices(camera, *c, host, device)
        })
    }

    /// A view of camera-frame vertices (left, right) seen by `camera` (identity
    /// extrinsics); `scene_camera` is the scene's camera with its extrinsics.
    pub fn from_vertices(
        camera: Camera,
        scene_camera: bitt_mesh::PinholeCamera,
        vertices_host: [Vec<DVec3>; 2],
        device: &Device,
    ) -> Self {
        let vertices = [
            vertex_tensor(&vertices_host[0], device),
            vertex_tensor(&vertices_host[1], device),
        ];
        ViewGeometry {
            camera,
            scene_camera,
            vertices_host,
            vertices,
            hands: None,
            occlusion: None,
            cache: GeometryCache::default(),
        }
    }

    /// The same view shaded with ambient occlusion: every pixel's shaded colour is scaled by
    /// `1 - strength (1 - ao)`, with `ao` the fraction of its hemisphere from which light
    /// reaches the surface past both hands ([`bitt_mesh::occlusion`], interpolated from the
    /// vertices). Creases, the slits between touching fingers and a palm pressed against the
    /// other hand are shaded darker, as they are in a photo, instead of being painted dark
    /// into the albedo. `strength` 0 gives the paper's Phong shading.
    ///
    /// # Errors
    /// A strength outside `[0, 1]`, or vertices the rays cannot be cast over.
    pub fn with_occlusion(
        mut self,
        assets: &HandAssets,
        strength: f64,
    ) -> Result<Self, TrainError> {
        if !(0.0..=1.0).contains(&strength) {
            return Err(TrainError::Invalid(format!(
                "the occlusion strength must lie in [0, 1], not {strength}"
            )));
        }
        self.cache = GeometryCache::default();
        if strength == 0.0 {
            self.occlusion = None;
            return Ok(self);
        }
        let ao = self.vertex_occlusion(assets)?;
        let factors = ao
            .iter()
            .flatten()
            .map(|&a| (1.0 - strength * (1.0 - f64::from(a))) as f32)
            .collect();
        self.occlusion = Some(Occlusion {
            strength,
            factors: Arc::new(factors),
        });
        Ok(self)
    }

    /// The ambient occlusion of this view's hands (both together, full strength) at every
    /// texel, left then right: 1 where the texel's whole hemisphere is open, lower in creases
    /// and where the hands press together.
    ///
    /// # Errors
    /// Vertices the rays cannot be cast over.
    pub fn texel_occlusion(&self, assets: &HandAssets) -> Result<[Vec<f32>; 2], TrainError> {
        let ao = self.vertex_occlusion(assets)?;
        Ok([
            assets.surfaces[0].values(&ao[0])?,
            assets.surfaces[1].values(&ao[1])?,
        ])
    }

    /// The ambient occlusion of both hands' vertices, left then right.
    fn vertex_occlusion(&self, assets: &HandAssets) -> Result<Vec<Vec<f32>>, TrainError> {
        let faces = [0, 1].map(|i| assets.meshes[i].topology.faces());
        let meshes = [0, 1].map(|i| bitt_mesh::occlusion::OccluderMesh {
            vertices: &self.vertices_host[i],
            faces: faces[i],
        });
        Ok(bitt_mesh::occlusion::ambient_occlusion(
            &meshes,
            &bitt_mesh::occlusion::OcclusionSettings::default(),
        )?)
    }

    /// The strength this view is shaded with ambient occlusion ([`ViewGeometry::with_occlusion`];
    /// 0: none).
    pub fn occlusion_strength(&self) -> f64 {
        self.occlusion.as_ref().map_or(0.0, |o| o.strength)
    }

    /// Per vertex of both hands (left then right), the factor its shading is scaled by
    /// ([`ViewGeometry::with_occlusion`]); `None` without occlusion.
    pub fn occlusion_factors(&self) -> Option<&[f32]> {
        self.occlusion.as_ref().map(|o| o.factors.as_slice())
    }

    /// The render geometry of this view for `settings` and a per-pixel layout, prepared
    /// for the compact textures of `assets.layouts`
    /// ([`SceneGeometry::with_compact_textures`]), made on first use and then reused.
    ///
    /// # Errors
    /// As [`SceneGeometry::new`].
    fn compact_geometry(
        &self,
        assets: &HandAssets,
        settings: &RenderSettings,
        path: GeometryPath,
    ) -> Result<Arc<SceneGeometry>, TrainError> {
        let key = (settings.depth, settings.antialias, path);
        let mut cache = self.cache.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, g)) = cache.iter().find(|(k, _)| *k == key) {
            return Ok(g.clone());
        }
        let occlusion = self.occlusion.as_ref().map(|o| {
            let n = o.factors.len();
            Tensor::<2>::from_data(
                TensorData::new(o.factors.to_vec(), [n, 1]),
                &self.vertices[0].device(),
            )
        });
        let g = SceneGeometry::with_occlusion(
            &assets.scene,
            &self.vertices,
            occlusion,
            &self.camera,
            settings,
            &[[assets.texture_size; 2]; 2],
            path,
        )?
        .with_compact_textures(&[&assets.layouts[0], &assets.layouts[1]])?;
        let g = Arc::new(g);
        cache.push((key, g.clone()));
        Ok(g)
    }

    /// Image side lengths `[H, W]`.
    pub fn size(&self) -> [usize; 2] {
        [self.camera.height(), self.camera.width()]
    }

    /// Renders both hands with compact textures `[3, T]` (left, right) under `light`, with
    /// the host raster (the covered-pixel geometry, which has it at once: a view rendered
    /// for unwrapping or scores is rendered once).
    pub fn render(
        &self,
        assets: &HandAssets,
        textures: [Tensor<2>; 2],
        light: &PointLight,
        settings: &RenderSettings,
    ) -> Result<SceneRender, TrainError> {
        let g = self.compact_geometry(assets, settings, GeometryPath::Covered)?;
        Ok(SceneRender {
            image: g.shade_compact(&textures, light, &settings.material, settings.background)?,
            masks: g.masks.clone(),
            raster: g.raster()?.clone(),
            clip: g.clip.clone(),
        })
    }

    /// The image of [`ViewGeometry::render`] alone, `[3, H, W]` (nothing else is copied): the
    /// training step's render, on the dense geometry where the CubeCL rasterizer runs (no
    /// host readback), the covered one elsewhere.
    pub(crate) fn render_image(
        &self,
        assets: &HandAssets,
        textures: [Tensor<2>; 2],
        light: &PointLight,
        settings: &RenderSettings,
    ) -> Result<Tensor<3>, TrainError> {
        let g = self.compact_geometry(assets, settings, GeometryPath::Auto)?;
        Ok(g.shade_compact(&textures, light, &settings.material, settings.background)?)
    }
}

fn two<T: std::fmt::Debug>(v: Vec<T>) -> [T; 2] {
    v.try_into().expect("two hands")
}

/// `[V, 3]` `f32` tensor of points.
pub fn vertex_tensor(vertices: &[DVec3], device: &Device) -> Tensor<2> {
    let flat: Vec<f32> = vertices
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    Tensor::from_data(TensorData::new(flat, [vertices.len(), 3]), device)
}
