//! Above the primitives: cameras, Phong lighting, several textured meshes in one depth test
//! (the two hands of a scene), image-to-UV unwrapping and texel visibility statistics.
//!
//! This layer knows meshes with a UV layout, cameras and lights; it does not know MANO,
//! hand models, texture PCA or networks. "Left" and "right" appear only in
//! [`TexelVisibilityStats`], the paper's Table 3 over a pair of meshes sharing one layout.

mod camera;
mod dense;
mod geometry;
mod shading;
mod unwrap;

pub use camera::{Camera, DepthRange};
pub use geometry::{GeometryPath, SceneGeometry};
pub use shading::{LightValues, LightValuesExt, Material, PointLight, phong, vertex_normals};
pub use unwrap::{
    TexelSurface, TexelVisibilityStats, UnwrapPlan, UnwrapSettings, Unwrapped, unwrap,
};

use burn::tensor::Tensor;

use crate::error::RenderError;
use crate::ops::{Raster, Topology};

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
    pub(crate) fn num_meshes(&self) -> usize {
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
/// times), make the geometry once and shade it each time. Because [`SceneRender::raster`]
/// is a host raster, `render` always takes [`SceneGeometry`]'s covered-pixel path (one host
/// readback); for none, use [`SceneGeometry`] on a GPU.
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
    // The result carries the host raster, so the covered path (which makes it anyway) is
    // the cheaper one on every device.
    let geometry = SceneGeometry::with_path(
        scene,
        vertices,
        camera,
        settings,
        &sizes,
        GeometryPath::Covered,
    )?;
    let image = geometry.shade(textures, light, &settings.material, settings.background)?;
    let raster = geometry.raster()?.clone();
    let SceneGeometry { masks, clip, .. } = geometry;
    Ok(SceneRender {
        image,
        masks,
        raster,
        clip,
    })
}
