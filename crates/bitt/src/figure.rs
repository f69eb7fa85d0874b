//! The figures of `bitt render`: both hands of a scene rendered with UV textures under a
//! point light, each hand alone, their masks after the shared depth test, an image unwrapped
//! onto both hands' texels (the paper's visible texels, Table 3), and a grid of orthographic
//! views around the hands with an unwrap row. Everything is made in memory before the first
//! file is written ([`write_figure`]: each one atomically, next to the main one).

use bitt_render::scene::LightValuesExt;

use std::path::{Path, PathBuf};

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::{HandModel, OrthographicCamera, PinholeCamera, Side, UvLayout};
use bitt_render::scene::{
    Camera, LightValues, RenderSettings, Scene, SceneRender, TexelSurface, TexelVisibilityStats,
    TexturedMesh, UnwrapSettings, render, unwrap,
};
use bitt_texture::TextureLayout;
use burn::tensor::{Device, Tensor, TensorData};

use crate::BittError;
use crate::outputs::{contact_sheet_on, fill_hidden_texels};
use bitt_stdx::WithContext;
use bitt_stdx::to_host;

/// Side of each view of the `--views` grid.
pub(crate) const VIEW_SIZE: usize = 256;

/// The default light of `bitt render`: brighter than the reference's training default
/// (ambient 0.5, diffuse 0.1), from above and a little right of the camera (camera frame:
/// x right, y down, z forward).
pub fn default_light() -> LightValues {
    LightValues {
        ambient: [0.45; 3],
        diffuse: [0.7; 3],
        specular: [0.2; 3],
        location: [0.15, -0.35, 0.05],
    }
}

/// A hand ready to render: model, UV layout, posed camera-frame vertices.
#[derive(Debug, Clone)]
pub struct FigureHand {
    /// Which hand.
    pub side: Side,
    /// Its model (faces, vertex count).
    pub model: HandModel,
    /// Its UV layout (the model's, or HTML's for MANO).
    pub uv: UvLayout,
    /// Camera-frame vertices.
    pub vertices: Vec<DVec3>,
}

/// One image of a figure: `[3, H, W]` values in `[0, 1]`.
#[derive(Debug, Clone)]
pub struct FigureImage {
    /// What it shows, as the suffix of the file name (`None`: the main image; `left`,
    /// `mask_left`, `unwrap_left`, `visible_left`, and right).
    pub suffix: Option<String>,
    /// Planar RGB values.
    pub data: Vec<f32>,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

/// What to make besides the render of both hands.
#[derive(Debug, Clone)]
pub struct FigureOptions {
    /// Side of the UV images of unwrapped images.
    pub uv_size: usize,
    /// Instead of the scene's camera, this many orthographic views around the hands in one
    /// grid (three columns, the unwrap row under them).
    pub views: Option<usize>,
    /// An image of the camera's size to unwrap onto both hands.
    pub unwrap: Option<Tensor<3>>,
    /// Silhouette antialiasing.
    pub antialias: bool,
}

/// Checks `bitt render`'s options before anything is read: the UV size, the views grid (not
/// with an image to unwrap) and the output PNG, whose folder must exist.
///
/// # Errors
/// The first option out of range, naming it.
pub fn check_figure_options(
    uv_size: usize,
    views: Option<usize>,
    unwrap: bool,
    out: &Path,
) -> Result<(), BittError> {
    let invalid = |m: String| Err(BittError::Invalid(m));
    if !(64..=2048).contains(&uv_size) {
        return invalid(format!(
            "--uv-size must be between 64 and 2048 (got {uv_size})"
        ));
    }
    if views.is_some() && unwrap {
        return invalid("--views and --unwrap cannot be combined".into());
    }
    if let Some(n) = views
        && !(1..=12).contains(&n)
    {
        return invalid(format!("--views must be between 1 and 12 (got {n})"));
    }
    if out.extension().and_then(|e| e.to_str()) != Some("png") {
        return invalid(format!("--out {}: must be a .png file", out.display()));
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        return invalid(format!(
            "--out {}: folder {} does not exist",
            out.display(),
            dir.display()
        ));
    }
    Ok(())
}

/// `<stem>.<suffix>.png` next to `out` (e.g. `img.png` -> `img.left.png`).
pub fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "render".into());
    out.with_file_name(format!("{stem}.{suffix}.png"))
}

/// Writes a figure's images: the main one at `out`, the others next to it ([`sibling`]);
/// `written` is told each file after it is written.
///
/// # Errors
/// An image that cannot be written (the images before it are written).
pub fn write_figure(
    out: &Path,
    images: &[FigureImage],
    mut written: impl FnMut(&Path, &FigureImage),
) -> Result<(), BittError> {
    for o in images {
        let path = match &o.suffix {
            None => out.to_path_buf(),
            Some(suffix) => sibling(out, suffix),
        };
        bitt_texture::save_png8(&path, &o.data, o.width, o.height)
            .context_with(|| format!("writing {}", path.display()))?;
        written(&path, o);
    }
    Ok(())
}

/// The render mesh of a figure hand (its own UV layout, which may be HTML's).
fn mesh(hand: &FigureHand) -> Result<TexturedMesh, BittError> {
    Ok(bitt_synth::textured_mesh_with(&hand.model, &hand.uv)?)
}

fn vertex_tensor(vertices: &[DVec3], device: &Device) -> Tensor<2> {
    let flat = vertices
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    Tensor::from_data(TensorData::new(flat, [vertices.len(), 3]), device)
}

fn image(suffix: Option<String>, data: Vec<f32>, width: usize, height: usize) -> FigureImage {
    FigureImage {
        suffix,
        data,
        width,
        height,
    }
}

/// Renders the figure of `hands` with `textures` (one `[3, S, S]` image per hand) under
/// `light` (camera frame) through `scene_camera`'s intrinsics (the vertices are in its
/// frame): the images in the order they are to be written, and with
/// [`FigureOptions::unwrap`] the texel visibility statistics (Table 3).
///
/// # Errors
/// Invalid meshes or cameras, a views grid whose scene camera is not
/// [`VIEW_SIZE`] square, or left and right layouts with different texels.
pub fn render_figure(
    hands: &[FigureHand; 2],
    textures: &[Tensor<3>],
    scene_camera: &PinholeCamera,
    light: &LightValues,
    options: &FigureOptions,
) -> Result<(Vec<FigureImage>, Option<TexelVisibilityStats>), BittError> {
    let device = textures[0].device();
    let camera = Camera::Pinhole(PinholeCamera {
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        ..*scene_camera
    });
    let settings = RenderSettings {
        antialias: options.antialias,
        ..RenderSettings::default()
    };
    let meshes = [mesh(&hands[0])?, mesh(&hands[1])?];
    let vertex_tensors: Vec<Tensor<2>> = hands
        .iter()
        .map(|h| vertex_tensor(&h.vertices, &device))
        .collect();
    let both = Scene::new(&[&meshes[0], &meshes[1]])?;
    let light_t = light.to_light(&device);
    let full = render(
        &both,
        &vertex_tensors,
        textures,
        &camera,
        &light_t,
        &settings,
    )?;
    if let Some(n) = options.views {
        let mut panels =
            render_views(n, &both, &vertex_tensors, hands, textures, light, &settings)?;
        // Three columns; the unwrap row starts a row of its own.
        panels.resize(n.div_ceil(3) * 3, vec![0.0; 3 * VIEW_SIZE * VIEW_SIZE]);
        panels.extend(unwrap_row(&full, &camera, hands)?);
        let (data, height, width) = contact_sheet_on(&panels, VIEW_SIZE, VIEW_SIZE, 3, 0.0);
        return Ok((vec![image(None, data, width, height)], None));
    }
    let (w, h) = (camera.width(), camera.height());
    let mut out = vec![image(None, to_host(full.image.clone())?, w, h)];
    for (i, hand) in hands.iter().enumerate() {
        let alone = Scene::new(&[&meshes[i]])?;
        let r = render(
            &alone,
            &vertex_tensors[i..=i],
            &textures[i..=i],
            &camera,
            &light_t,
            &settings,
        )?;
        let name = hand.side.as_str();
        out.push(image(Some(name.into()), to_host(r.image)?, w, h));
        let mask = to_host(full.masks[i].clone())?.repeat(3);
        out.push(image(Some(format!("mask_{name}")), mask, w, h));
    }
    let Some(unwrapped) = &options.unwrap else {
        return Ok((out, None));
    };
    let mut visible = Vec::new();
    let s = options.uv_size;
    for hand in hands {
        let layout = TextureLayout::from_uv(&hand.uv, s, s, 0)?;
        let surface = TexelSurface::new(&layout, &hand.model.faces, hand.model.num_vertices())?;
        let u = unwrap(
            unwrapped.clone(),
            &camera,
            &surface,
            &hand.vertices,
            &full.raster,
            &UnwrapSettings::default(),
        )?;
        let name = hand.side.as_str();
        let texels = layout.compact_to_image(&to_host(u.texels)?, [0.0; 3])?;
        out.push(image(Some(format!("unwrap_{name}")), texels, s, s));
        let mask = layout.compact_to_image(&to_host(u.visible)?.repeat(3), [0.0; 3])?;
        out.push(image(Some(format!("visible_{name}")), mask, s, s));
        visible.push(u.visible_host);
    }
    if visible[0].len() != visible[1].len() {
        return Err(BittError::Invalid(format!(
            "the left and right UV layouts have different texels ({} vs {}); \
             the statistics need one layout shared by both hands",
            visible[0].len(),
            visible[1].len()
        )));
    }
    let stats = TexelVisibilityStats::from_masks(&visible[0], &visible[1])?;
    Ok((out, Some(stats)))
}

/// `n` orthographic views around the hands (rotating about the camera's vertical axis), each
/// lit from its own camera side, as `[3, VIEW_SIZE, VIEW_SIZE]` panels.
fn render_views(
    n: usize,
    scene: &Scene,
    vertices: &[Tensor<2>],
    hands: &[FigureHand; 2],
    textures: &[Tensor<3>],
    light: &LightValues,
    settings: &RenderSettings,
) -> Result<Vec<Vec<f32>>, BittError> {
    let device = vertices[0].device();
    let points: Vec<DVec3> = hands.iter().flat_map(|h| h.vertices.clone()).collect();
    let centre = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let mut panels = Vec::with_capacity(n);
    for k in 0..n {
        let angle = std::f64::consts::TAU * k as f64 / n as f64;
        let rotation = DMat3::from_rotation_y(angle);
        let ortho = OrthographicCamera::framing(
            &points,
            rotation,
            VIEW_SIZE as u32,
            VIEW_SIZE as u32,
            0.08,
        )?;
        let camera = Camera::Orthographic(ortho);
        // The light sits towards this view's camera and above it (y is down).
        let towards = camera.towards_camera(centre);
        let up = rotation.transpose() * DVec3::NEG_Y;
        let spot = centre + towards * 0.5 + up * 0.3 + rotation.transpose() * DVec3::X * 0.1;
        let view_light = LightValues {
            location: [spot.x as f32, spot.y as f32, spot.z as f32],
            ..*light
        };
        let r = render(
            scene,
            vertices,
            textures,
            &camera,
            &view_light.to_light(&device),
            settings,
        )?;
        panels.push(to_host(r.image)?);
    }
    Ok(panels)
}

/// The row under a views grid: the scene camera's render, then, per hand, that render
/// unwrapped onto the hand's UV layout (`VIEW_SIZE` texels a side): visible texels in their
/// unwrapped colour, hidden texels of the layout dark grey, unused texels black.
fn unwrap_row(
    full: &SceneRender,
    camera: &Camera,
    hands: &[FigureHand; 2],
) -> Result<Vec<Vec<f32>>, BittError> {
    let image = full.image.clone();
    let [_, h, w] = image.dims();
    if [h, w] != [VIEW_SIZE, VIEW_SIZE] {
        return Err(BittError::Invalid(format!(
            "--views needs a {VIEW_SIZE}x{VIEW_SIZE} scene camera for its unwrap row (got {w}x{h})"
        )));
    }
    let mut panels = vec![to_host(image.clone())?];
    for hand in hands {
        let layout = TextureLayout::from_uv(&hand.uv, VIEW_SIZE, VIEW_SIZE, 0)?;
        let surface = TexelSurface::new(&layout, &hand.model.faces, hand.model.num_vertices())?;
        let u = unwrap(
            image.clone(),
            camera,
            &surface,
            &hand.vertices,
            &full.raster,
            &UnwrapSettings::default(),
        )?;
        let mut texels = to_host(u.texels)?;
        fill_hidden_texels(&mut texels, &u.visible_host, 0.25);
        panels.push(layout.compact_to_image(&texels, [0.0; 3])?);
    }
    Ok(panels)
}
