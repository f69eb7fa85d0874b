//! Rendering a view: the exact recipe every image of a synthetic scene is made with.
//!
//! Both hands are posed with [`TwoHandScene::pose_in_camera`] (camera-frame vertices) and
//! rendered by [`bitt_render::scene::render`] with the view's intrinsics and identity
//! extrinsics, the GT textures as `[3, S, S]` images of the layouts (unused texels black),
//! [`RenderSettings::default`] (the reference's neutral material: ambient 1, diffuse 1,
//! specular 0; antialiasing on; black background) and the view's light, whose location is in
//! the **camera frame**. The image is then clamped to `[0, 1]`.

use bitt_render::scene::LightValuesExt;

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::{HandModel, HandPair, PinholeCamera, Side, TwoHandScene, UvLayout};
use bitt_render::scene::{
    Camera, LightValues, RenderSettings, Scene, SceneRender, TexturedMesh, render,
};
use bitt_texture::TextureLayout;
use burn::tensor::{Device, Tensor, TensorData};

use crate::SynthError;

/// The render mesh of a hand model: its faces and vertex count, with the texture
/// coordinates of its UV layout. The one way a [`HandModel`] becomes a [`TexturedMesh`]
/// (the synthetic scenes, the trainer's `HandAssets`, `bitt render`'s figures).
///
/// # Errors
/// A model without a UV layout, or a UV layout that does not fit its faces.
pub fn textured_mesh(model: &HandModel) -> Result<TexturedMesh, SynthError> {
    let side = model.side;
    let uv = model
        .uv
        .as_ref()
        .ok_or_else(|| SynthError::Generate(format!("the {side} hand model has no UV layout")))?;
    textured_mesh_with(model, uv)
}

/// [`textured_mesh`] with another UV layout than the model's own (HTML's for MANO).
///
/// # Errors
/// A UV layout that does not fit the model's faces.
pub fn textured_mesh_with(model: &HandModel, uv: &UvLayout) -> Result<TexturedMesh, SynthError> {
    let uvs = uv.uvs.iter().map(|p| [p.x as f32, p.y as f32]).collect();
    Ok(TexturedMesh::new(
        model.faces.clone(),
        model.num_vertices(),
        uv.faces.clone(),
        uvs,
    )?)
}

/// One rendered view.
#[derive(Debug, Clone)]
pub struct RenderedView {
    /// `[3, H, W]` in `[0, 1]`.
    pub image: Vec<f32>,
    /// Left and right `[H, W]` masks (1 where the hand is the nearest surface).
    pub masks: [Vec<f32>; 2],
    /// Camera-frame vertices of the left and right hand.
    pub vertices: [Vec<DVec3>; 2],
    /// The renderer's full output (depth buffer for unwrapping).
    pub render: SceneRender,
    /// The camera the render used (intrinsics of the view, identity extrinsics).
    pub camera: Camera,
}

/// The two procedural hands with their GT textures on a device, ready to render views.
#[derive(Debug, Clone)]
pub struct HandRenderer {
    models: HandPair,
    scene: Scene,
    textures: [Tensor<3>; 2],
    device: Device,
}

impl HandRenderer {
    /// Prepares `models` (with UV layouts) and the compact textures of `layouts` on `device`.
    ///
    /// # Errors
    /// A model without a UV layout, or textures of the wrong length.
    pub fn new(
        models: &HandPair,
        layouts: &[TextureLayout; 2],
        textures: &[Vec<f32>; 2],
        device: &Device,
    ) -> Result<Self, SynthError> {
        let mut meshes = Vec::new();
        let mut images = Vec::new();
        for (k, side) in Side::BOTH.into_iter().enumerate() {
            meshes.push(textured_mesh(models.get(side))?);
            let layout = &layouts[k];
            let image = layout.compact_to_image(&textures[k], [0.0; 3])?;
            images.push(Tensor::from_data(
                TensorData::new(image, [3, layout.height, layout.width]),
                device,
            ));
        }
        let scene = Scene::new(&[&meshes[0], &meshes[1]])?;
        let [l, r]: [Tensor<3>; 2] = images
            .try_into()
            .map_err(|_| SynthError::Generate("two textures expected".into()))?;
        Ok(HandRenderer {
            models: models.clone(),
            scene,
            textures: [l, r],
            device: device.clone(),
        })
    }

    /// Renders both hands of `hands` (both must be present) under `light` (camera frame).
    ///
    /// # Errors
    /// A missing hand, invalid parameters or camera, a non-finite light.
    pub fn render(
        &self,
        hands: &TwoHandScene,
        light: &LightValues,
    ) -> Result<RenderedView, SynthError> {
        light.validate()?;
        let posed = hands.pose_in_camera(&self.models)?;
        let mut vertices: [Vec<DVec3>; 2] = Default::default();
        for (k, side) in Side::BOTH.into_iter().enumerate() {
            vertices[k] = posed
                .get(side)
                .ok_or_else(|| {
                    SynthError::Generate(format!("the view has no {side} hand; both are needed"))
                })?
                .vertices
                .clone();
        }
        let camera = camera_frame_camera(&hands.camera);
        let tensors: Vec<Tensor<2>> = vertices
            .iter()
            .map(|v| {
                let flat = v
                    .iter()
                    .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
                    .collect();
                Tensor::from_data(TensorData::new(flat, [v.len(), 3]), &self.device)
            })
            .collect();
        let out = render(
            &self.scene,
            &tensors,
            &self.textures,
            &camera,
            &light.to_light(&self.device),
            &RenderSettings::default(),
        )?;
        let image = bitt_stdx::to_host(out.image.clone())?
            .into_iter()
            .map(|x| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) })
            .collect();
        let masks = [
            bitt_stdx::to_host(out.masks[0].clone())?,
            bitt_stdx::to_host(out.masks[1].clone())?,
        ];
        Ok(RenderedView {
            image,
            masks,
            vertices,
            render: out,
            camera,
        })
    }
}

/// The camera `render` uses for camera-frame vertices: the view's intrinsics and size,
/// identity extrinsics.
pub fn camera_frame_camera(camera: &PinholeCamera) -> Camera {
    Camera::Pinhole(PinholeCamera {
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        ..*camera
    })
}
