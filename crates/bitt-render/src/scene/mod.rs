//! Above the primitives: cameras, Phong lighting, several textured meshes in one depth test
//! (the two hands of a scene), image-to-UV unwrapping and texel visibility statistics.
//!
//! This layer knows meshes with a UV layout, cameras and lights; it does not know MANO,
//! hand models, texture PCA or networks. "Left" and "right" appear only in
//! [`TexelVisibilityStats`], the paper's Table 3 over a pair of meshes sharing one layout.

mod camera;
mod shading;
mod unwrap;

pub use camera::{Camera, DepthRange};
pub use shading::{LightValues, Material, PointLight, phong, vertex_normals};
pub use unwrap::{
    TexelSurface, TexelVisibilityStats, UnwrapPlan, UnwrapSettings, Unwrapped, unwrap,
};

use burn::tensor::Tensor;

use crate::error::RenderError;
use crate::ops::{
    AntialiasPlan, Raster, TexturePlan, Topology, float_tensor, index_tensor, interpolate,
    interpolate_with_faces, rasterize,
};

/// A mesh's connectivity and UV layout, prepared once and reused for every render.
#[derive(Debug, Clone, PartialEq)]
pub struct TexturedMesh {
    /// Faces over the mesh's vertices.
    pub topology: Topology,
    /// Per face, the rows of [`TexturedMesh::uvs`] of its corners.
    pub uv_faces: Vec<[u32; 3]>,
    /// UV coordinates (`v = 0` at the texture's bottom row).
    pub uvs: Vec<[f32; 2]>,
}

impl TexturedMesh {
    /// A mesh with `faces` over `num_vertices` vertices and a UV layout (`uv_faces` one
    /// triple per face into `uvs`).
    ///
    /// # Errors
    /// Out-of-range indices, or a UV face count different from the face count.
    pub fn new(
        faces: Vec<[u32; 3]>,
        num_vertices: usize,
        uv_faces: Vec<[u32; 3]>,
        uvs: Vec<[f32; 2]>,
    ) -> Result<Self, RenderError> {
        let topology = Topology::new(faces, num_vertices)?;
        if uv_faces.len() != topology.num_faces() {
            return Err(RenderError::BadLayout(format!(
                "{} UV faces for {} mesh faces",
                uv_faces.len(),
                topology.num_faces()
            )));
        }
        crate::error::check_faces(&uv_faces, uvs.len())?;
        if let Some(i) = uvs.iter().position(|uv| !uv.iter().all(|x| x.is_finite())) {
            return Err(RenderError::BadLayout(format!("uv {i} is {:?}", uvs[i])));
        }
        Ok(Self {
            topology,
            uv_faces,
            uvs,
        })
    }
}

/// Several textured meshes rendered together (faces and vertices concatenated in order), so
/// that one depth test resolves their mutual occlusion.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    topology: Topology,
    uv_faces: Vec<[u32; 3]>,
    uvs: Vec<[f32; 2]>,
    face_ranges: Vec<std::ops::Range<u32>>,
    vertex_counts: Vec<usize>,
}

impl Scene {
    /// Concatenates `meshes` (e.g. `[left hand, right hand]`).
    ///
    /// # Errors
    /// More faces than `i32` can address.
    pub fn new(meshes: &[&TexturedMesh]) -> Result<Self, RenderError> {
        let topology = Topology::concat(&meshes.iter().map(|m| &m.topology).collect::<Vec<_>>())?;
        let mut uv_faces = Vec::new();
        let mut uvs = Vec::new();
        let mut face_ranges = Vec::new();
        let mut first_face = 0u32;
        for m in meshes {
            let offset = uvs.len() as u32;
            uv_faces.extend(m.uv_faces.iter().map(|t| t.map(|i| i + offset)));
            uvs.extend_from_slice(&m.uvs);
            let end = first_face + m.topology.num_faces() as u32;
            face_ranges.push(first_face..end);
            first_face = end;
        }
        Ok(Self {
            topology,
            uv_faces,
            uvs,
            face_ranges,
            vertex_counts: meshes.iter().map(|m| m.topology.num_vertices()).collect(),
        })
    }

    /// The concatenated topology.
    pub fn topology(&self) -> &Topology {
        &self.topology
    }

    /// Number of meshes.
    pub fn num_meshes(&self) -> usize {
        self.face_ranges.len()
    }

    /// Faces of mesh `i` in the concatenated face numbering.
    pub fn face_range(&self, i: usize) -> std::ops::Range<u32> {
        self.face_ranges[i].clone()
    }
}

/// How to render: depth range, material, antialiasing and background.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RenderSettings {
    /// Depth range of the projection.
    pub depth: DepthRange,
    /// Material reflectances (the reference's by default).
    pub material: Material,
    /// Apply silhouette antialiasing (gives gradients to vertex positions at silhouettes).
    pub antialias: bool,
    /// Background colour (the reference renders on black).
    pub background: [f32; 3],
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            depth: DepthRange::default(),
            material: Material::default(),
            antialias: true,
            background: [0.0; 3],
        }
    }
}

/// The result of [`render`].
#[derive(Debug, Clone)]
pub struct SceneRender {
    /// Shaded image `[3, H, W]`.
    pub image: Tensor<3>,
    /// Per mesh, its visible pixels `[H, W]` (1/0) after the shared depth test.
    pub masks: Vec<Tensor<2>>,
    /// The raster of all meshes (depth buffer, face ids).
    pub raster: Raster,
    /// The clip positions of all vertices `[sum V, 4]`.
    pub clip: Tensor<2>,
}

/// Renders the meshes of `scene` with their textures under a point light.
///
/// Per pixel: the nearest face over all meshes; its UV, world position and interpolated
/// vertex normal; the texel from that mesh's texture; [`phong`] shading; then optional
/// [`crate::ops::antialias`]. Differentiable in the vertices, the textures and the light.
///
/// This is [`SceneGeometry::new`] followed by [`SceneGeometry::shade`]; when the vertices
/// and camera stay fixed over many renders (a training step renders one view up to five
/// times), make the geometry once and shade it each time.
///
/// # Shapes
/// vertices: per mesh `[V_i, 3]` (world coordinates); textures: per mesh `[3, Ht_i, Wt_i]`
/// -> image `[3, H, W]` with the camera's size
///
/// # Errors
/// Wrong counts or shapes, an unusable camera, non-finite positions.
pub fn render(
    scene: &Scene,
    vertices: &[Tensor<2>],
    textures: &[Tensor<3>],
    camera: &Camera,
    light: &PointLight,
    settings: &RenderSettings,
) -> Result<SceneRender, RenderError> {
    crate::error::check_len("textures", textures.len(), scene.num_meshes())?;
    let sizes: Vec<[usize; 2]> = textures
        .iter()
        .map(|t| {
            let [_, h, w] = t.dims();
            [h, w]
        })
        .collect();
    let geometry = SceneGeometry::new(scene, vertices, camera, settings, &sizes)?;
    let image = geometry.shade(textures, light, &settings.material, settings.background)?;
    let SceneGeometry {
        raster,
        masks,
        clip,
        ..
    } = geometry;
    Ok(SceneRender {
        image,
        masks,
        raster,
        clip,
    })
}

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
#[derive(Debug, Clone)]
pub struct SceneGeometry {
    /// The raster of all meshes (depth buffer, face ids).
    pub raster: Raster,
    /// Per mesh, its visible pixels `[H, W]` (1/0) after the shared depth test.
    pub masks: Vec<Tensor<2>>,
    /// The clip positions of all vertices `[sum V, 4]`.
    pub clip: Tensor<2>,
    texture_sizes: Vec<[usize; 2]>,
    pixels: Option<PixelGeometry>,
    antialias: Option<AntialiasPlan>,
}

/// The per-pixel part of a [`SceneGeometry`] (absent when no pixel is covered).
#[derive(Debug, Clone)]
struct PixelGeometry {
    /// `[N, 3]` each.
    normals: Tensor<2>,
    points: Tensor<2>,
    to_camera: Tensor<2>,
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
        camera.validate()?;
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
            None
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
            let to_camera = match camera {
                Camera::Pinhole(_) => {
                    let c = camera.center();
                    float_tensor(vec![c.x as f32, c.y as f32, c.z as f32], [1, 3], &device)
                        - points.clone()
                }
                Camera::Orthographic(_) => {
                    let d = camera.towards_camera(bitt_mesh::glam::DVec3::ZERO);
                    float_tensor(vec![d.x as f32, d.y as f32, d.z as f32], [1, 3], &device)
                        .repeat(&[n, 1])
                }
            };
            Some(PixelGeometry {
                normals,
                points,
                to_camera,
                lookups,
                inverse: index_tensor(inverse, &device),
            })
        };
        let antialias = match (&pixels, settings.antialias) {
            (Some(_), true) => Some(AntialiasPlan::new(&raster, clip.clone(), &scene.topology)?),
            _ => None,
        };
        Ok(Self {
            raster,
            masks,
            clip,
            texture_sizes: texture_sizes.to_vec(),
            pixels,
            antialias,
        })
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
        let device = self.clip.device();
        let (h, w) = (self.raster.height(), self.raster.width());
        let Some(px) = &self.pixels else {
            return Ok(float_tensor(background.to_vec(), [3, 1, 1], &device).repeat(&[1, h, w]));
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
        let image = self.raster.to_image(shaded, &background);
        match &self.antialias {
            Some(plan) => plan.apply(image),
            None => Ok(image),
        }
    }
}
