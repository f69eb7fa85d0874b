//! `bitt render`: render both hands of a scene with a UV texture under a point light, and
//! optionally unwrap an image onto both hands' texels (the paper's visible texels and masks).
//!
//! Every input is read and checked before anything is rendered, and every output is made in
//! memory before the first file is written (each one atomically), so a bad input leaves no
//! half-written set of files behind.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use bitt::outputs::{contact_sheet_on, fill_hidden_texels};
use bitt_mesh::annotation::BITT_CROP_SIZE;
use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::{HandModel, HandPair, OrthographicCamera, PinholeCamera, Side, UvLayout};
use bitt_render::scene::{
    Camera, LightValues, RenderSettings, Scene, TexelSurface, TexelVisibilityStats, TexturedMesh,
    UnwrapSettings, render, unwrap,
};
use bitt_texture::{SkinIdentity, TextureLayout, generate_texture, load_html_uvs, load_image};
use burn::tensor::{Device, Tensor, TensorData};

use crate::device::DeviceName;

/// Arguments of `bitt render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Folder holding MANO_LEFT / MANO_RIGHT (`.pkl` or `.safetensors`); needs --uvs.
    #[arg(
        long,
        conflicts_with = "procedural",
        required_unless_present = "procedural"
    )]
    pub model_dir: Option<PathBuf>,
    /// Use the project's procedural hand model (it has its own UV layout).
    #[arg(long)]
    pub procedural: bool,
    /// HTML UV file (`uvs.pkl`, `uvs_right.pkl`) for models without a UV layout (MANO).
    #[arg(long)]
    pub uvs: Option<PathBuf>,
    /// HTML UV file for the left hand (default: the --uvs file).
    #[arg(long, requires = "uvs")]
    pub uvs_left: Option<PathBuf>,
    /// A BiTT/InterHand annotation pickle (the demo `NN.pkl` layout).
    #[arg(long, conflicts_with = "demo", required_unless_present = "demo")]
    pub annotation: Option<PathBuf>,
    /// The built-in demo scene (two procedural-pose hands, 256x256 camera).
    #[arg(long)]
    pub demo: bool,
    /// Image size `WxH` the annotation's intrinsics refer to. Default: the size of the image
    /// beside the annotation (same name, .jpg/.png), else 256x256 (the BiTT crop).
    #[arg(long, value_parser = parse_size)]
    pub image_size: Option<(u32, u32)>,
    /// A UV texture PNG/JPEG applied to both hands (row 0 at the top, `v = 0` at the
    /// bottom). Default: a procedural skin texture (see --skin-seed).
    #[arg(long)]
    pub texture: Option<PathBuf>,
    /// Person of the default procedural skin texture.
    #[arg(long, default_value_t = 7)]
    pub skin_seed: u64,
    /// Side of the UV layout (procedural texture and unwrapped images), 64 to 2048.
    #[arg(long, default_value_t = 512)]
    pub uv_size: usize,
    /// The light: a JSON file or inline JSON `{"ambient": [r, g, b], "diffuse": [..],
    /// "specular": [..], "location": [x, y, z]}` (camera frame, metres). Default: a soft
    /// light above the camera.
    #[arg(long)]
    pub light: Option<String>,
    /// PNG to write (both hands). Also writes `<stem>.left.png`, `<stem>.right.png` (each
    /// hand alone) and `<stem>.mask_left.png`, `<stem>.mask_right.png` (each hand's visible
    /// pixels after the shared depth test) next to it.
    #[arg(long)]
    pub out: PathBuf,
    /// Unwrap this image (the camera's size) onto both hands: writes
    /// `<stem>.unwrap_left.png`, `<stem>.visible_left.png` (and right) as UV images next to
    /// --out, and prints the texel visibility statistics (the paper's Table 3) as JSON.
    #[arg(long)]
    pub unwrap: Option<PathBuf>,
    /// Instead of the scene's camera, render N orthographic views around the hands (turning
    /// about the image's vertical axis) into one grid image at --out.
    #[arg(long)]
    pub views: Option<usize>,
    /// Turn off silhouette antialiasing.
    #[arg(long)]
    pub no_antialias: bool,
    /// Device to render on.
    #[arg(long, default_value = "flex")]
    pub device: DeviceName,
}

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

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WxH"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| (1..=4096).contains(&n))
            .ok_or_else(|| format!("`{s}` is not WxH with sides 1 to 4096"))
    };
    Ok((parse(w)?, parse(h)?))
}

/// Parses `--light`: inline JSON when it starts with `{`, else a JSON file.
pub fn parse_light(arg: &str) -> Result<LightValues> {
    // Inline JSON (an object, or anything else that parses as JSON and is not a file's
    // name) is read as such; `[1, 2]` is a wrong light, not a file name.
    let t = arg.trim_start();
    let inline = t.starts_with('{')
        || t.starts_with('[')
        || (!Path::new(arg).exists() && serde_json::from_str::<serde_json::Value>(arg).is_ok());
    let (text, source) = if inline {
        (arg.to_string(), "--light".to_string())
    } else {
        let text = std::fs::read_to_string(arg)
            .with_context(|| format!("--light: cannot read light file {arg}"))?;
        (text, arg.to_string())
    };
    let light: LightValues = serde_json::from_str(&text).with_context(|| {
        format!(
            "{source}: expected JSON {{\"ambient\": [r, g, b], \"diffuse\": [r, g, b], \
             \"specular\": [r, g, b], \"location\": [x, y, z]}}"
        )
    })?;
    light
        .validate()
        .map_err(|e| anyhow!("{source}: {e} (every light value must be finite)"))?;
    Ok(light)
}

/// `<stem><suffix>.png` next to `out` (e.g. `img.png` -> `img.left.png`).
pub fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "render".into());
    out.with_file_name(format!("{stem}.{suffix}.png"))
}

fn sibling_image_size(annotation: &Path) -> Option<(u32, u32)> {
    ["jpg", "jpeg", "png"]
        .iter()
        .map(|ext| annotation.with_extension(ext))
        .find(|p| p.is_file())
        .and_then(|p| image::image_dimensions(p).ok())
}

/// A hand ready to render: model, posed camera-frame vertices, UV layout.
struct Hand {
    side: Side,
    model: HandModel,
    uv: UvLayout,
    vertices: Vec<DVec3>,
}

/// An image made in memory, written at the end.
struct Output {
    path: PathBuf,
    data: Vec<f32>,
    width: usize,
    height: usize,
}

fn load_models(args: &RenderArgs) -> Result<(HandPair, [UvLayout; 2])> {
    let models = crate::pose_hands::models(args.model_dir.as_deref(), args.procedural)?;
    let uv_for = |side: Side, model: &HandModel| -> Result<UvLayout> {
        let file = match side {
            Side::Left => args.uvs_left.as_ref().or(args.uvs.as_ref()),
            Side::Right => args.uvs.as_ref(),
        };
        let uv = match (file, &model.uv) {
            (Some(f), _) => load_html_uvs(f)?,
            (None, Some(uv)) => uv.clone(),
            (None, None) => bail!(
                "the {side} hand model ({}) has no UV layout; give --uvs FILE (HTML's uvs.pkl)",
                model.source
            ),
        };
        if uv.faces.len() != model.faces.len() {
            bail!(
                "the {side} hand's UV layout has {} faces but its mesh has {}",
                uv.faces.len(),
                model.faces.len()
            );
        }
        Ok(uv)
    };
    let uvs = [
        uv_for(Side::Left, &models.left)?,
        uv_for(Side::Right, &models.right)?,
    ];
    Ok((models, uvs))
}

fn load_scene(args: &RenderArgs, models: &HandPair) -> Result<bitt_mesh::TwoHandScene> {
    if args.demo {
        return Ok(bitt::demo::demo_scene(models));
    }
    let Some(path) = &args.annotation else {
        bail!("give --annotation FILE or --demo");
    };
    let size = args
        .image_size
        .or_else(|| sibling_image_size(path))
        .unwrap_or((BITT_CROP_SIZE, BITT_CROP_SIZE));
    Ok(bitt_mesh::load_bitt_annotation(path, size)?)
}

/// Reads a planar `[3, H, W]` image tensor from a file.
fn image_tensor(path: &Path, what: &str, device: &Device) -> Result<(Tensor<3>, [usize; 2])> {
    let img =
        load_image(path).with_context(|| format!("{what}: cannot load {}", path.display()))?;
    let (w, h) = (img.width, img.height);
    if w < 2 || h < 2 {
        bail!(
            "{what}: {} is {w}x{h}; it must be at least 2x2",
            path.display()
        );
    }
    Ok((
        Tensor::from_data(TensorData::new(img.data, [3, h, w]), device),
        [h, w],
    ))
}

fn host<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>> {
    t.try_into_vec_as::<f32>()
        .map_err(|e| anyhow!("reading a tensor back from the device: {e:?}"))
}

/// The default per-hand textures: procedural skin of one person, `[3, S, S]` each.
fn procedural_textures(
    args: &RenderArgs,
    models: &HandPair,
    uvs: &[UvLayout; 2],
    device: &Device,
) -> Result<Vec<Tensor<3>>> {
    let id = SkinIdentity::sample(args.skin_seed);
    let s = args.uv_size;
    [Side::Left, Side::Right]
        .iter()
        .zip(uvs)
        .map(|(&side, uv)| {
            let layout = TextureLayout::from_uv(uv, s, s, 2)?;
            let compact =
                generate_texture(&layout, models.get(side), &id, side).with_context(|| {
                    format!(
                        "the procedural skin texture needs the procedural hand; \
                         give --texture FILE for the {side} hand of {}",
                        models.get(side).source
                    )
                })?;
            let image = layout.compact_to_image(&compact, [0.0; 3])?;
            Ok(Tensor::from_data(TensorData::new(image, [3, s, s]), device))
        })
        .collect()
}

fn textured_mesh(hand: &Hand) -> Result<TexturedMesh> {
    let uvs = hand
        .uv
        .uvs
        .iter()
        .map(|p| [p.x as f32, p.y as f32])
        .collect();
    Ok(TexturedMesh::new(
        hand.model.faces.clone(),
        hand.model.num_vertices(),
        hand.uv.faces.clone(),
        uvs,
    )?)
}

fn vertex_tensor(vertices: &[DVec3], device: &Device) -> Tensor<2> {
    let flat = vertices
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    Tensor::from_data(TensorData::new(flat, [vertices.len(), 3]), device)
}

/// `bitt render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    if !(64..=2048).contains(&args.uv_size) {
        bail!(
            "--uv-size must be between 64 and 2048 (got {})",
            args.uv_size
        );
    }
    if args.views.is_some() && args.unwrap.is_some() {
        bail!("--views and --unwrap cannot be combined");
    }
    if let Some(n) = args.views
        && !(1..=12).contains(&n)
    {
        bail!("--views must be between 1 and 12 (got {n})");
    }
    if args.out.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("--out {}: must be a .png file", args.out.display());
    }
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        bail!(
            "--out {}: folder {} does not exist",
            args.out.display(),
            dir.display()
        );
    }
    // Inputs first: light, models, scene, textures, the image to unwrap.
    let light = match &args.light {
        Some(l) => parse_light(l)?,
        None => default_light(),
    };
    let device = args.device.device()?;
    let (models, uvs) = load_models(args)?;
    let scene = load_scene(args, &models)?;
    let posed = scene.pose_in_camera(&models)?;
    let mut hands = Vec::new();
    for (side, uv) in [Side::Left, Side::Right].into_iter().zip(uvs.clone()) {
        let vertices = posed
            .get(side)
            .with_context(|| {
                format!(
                    "{}: the scene has no {side} hand; bitt render needs both",
                    args.annotation
                        .as_ref()
                        .map_or("the demo scene".into(), |p| p.display().to_string())
                )
            })?
            .vertices
            .clone();
        hands.push(Hand {
            side,
            model: models.get(side).clone(),
            uv,
            vertices,
        });
    }
    let textures = match &args.texture {
        Some(path) => {
            let (t, _) = image_tensor(path, "--texture", &device)?;
            vec![t.clone(), t]
        }
        None => procedural_textures(args, &models, &uvs, &device)?,
    };
    // Vertices are in the camera frame: render with the intrinsics and no extrinsics.
    let camera = Camera::Pinhole(PinholeCamera {
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        ..scene.camera
    });
    let unwrap_image = match &args.unwrap {
        Some(path) => {
            let (t, [h, w]) = image_tensor(path, "--unwrap", &device)?;
            if [h, w] != [camera.height(), camera.width()] {
                bail!(
                    "--unwrap {}: the image is {w}x{h}, but the camera renders {}x{}; \
                     unwrap an image of the camera's size",
                    path.display(),
                    camera.width(),
                    camera.height()
                );
            }
            Some(t)
        }
        None => None,
    };
    let settings = RenderSettings {
        antialias: !args.no_antialias,
        ..RenderSettings::default()
    };
    let meshes: Vec<TexturedMesh> = hands.iter().map(textured_mesh).collect::<Result<_>>()?;
    let vertex_tensors: Vec<Tensor<2>> = hands
        .iter()
        .map(|h| vertex_tensor(&h.vertices, &device))
        .collect();

    let both = Scene::new(&[&meshes[0], &meshes[1]])?;
    let light_t = light.to_light(&device);
    let full = render(
        &both,
        &vertex_tensors,
        &textures,
        &camera,
        &light_t,
        &settings,
    )?;
    let mut outputs = Vec::new();
    if let Some(n) = args.views {
        let mut panels = render_views(
            n,
            &meshes,
            &vertex_tensors,
            &hands,
            &textures,
            &light,
            &settings,
        )?;
        // Three columns; the unwrap row starts a row of its own.
        panels.resize(n.div_ceil(3) * 3, vec![0.0; 3 * VIEW_SIZE * VIEW_SIZE]);
        panels.extend(unwrap_row(&full, &camera, &hands)?);
        let (data, height, width) = contact_sheet_on(&panels, VIEW_SIZE, VIEW_SIZE, 3, 0.0);
        outputs.push(Output {
            path: args.out.clone(),
            data,
            width,
            height,
        });
        write_all(&outputs)?;
        return Ok(());
    }

    let (w, h) = (camera.width(), camera.height());
    outputs.push(Output {
        path: args.out.clone(),
        data: host(full.image.clone())?,
        width: w,
        height: h,
    });
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
        outputs.push(Output {
            path: sibling(&args.out, hand.side.as_str()),
            data: host(r.image)?,
            width: w,
            height: h,
        });
        let mask = host(full.masks[i].clone())?;
        outputs.push(Output {
            path: sibling(&args.out, &format!("mask_{}", hand.side.as_str())),
            data: mask.repeat(3),
            width: w,
            height: h,
        });
    }
    let mut stats = None;
    if let Some(image) = unwrap_image {
        let mut visible = Vec::new();
        let s = args.uv_size;
        for hand in &hands {
            let layout = TextureLayout::from_uv(&hand.uv, s, s, 0)?;
            let surface = TexelSurface::new(&layout, &hand.model.faces, hand.model.num_vertices())?;
            let u = unwrap(
                image.clone(),
                &camera,
                &surface,
                &hand.vertices,
                &full.raster,
                &UnwrapSettings::default(),
            )?;
            let name = hand.side.as_str();
            outputs.push(Output {
                path: sibling(&args.out, &format!("unwrap_{name}")),
                data: layout.compact_to_image(&host(u.texels)?, [0.0; 3])?,
                width: s,
                height: s,
            });
            let mask = host(u.visible)?.repeat(3);
            outputs.push(Output {
                path: sibling(&args.out, &format!("visible_{name}")),
                data: layout.compact_to_image(&mask, [0.0; 3])?,
                width: s,
                height: s,
            });
            visible.push(u.visible_host);
        }
        if visible[0].len() != visible[1].len() {
            bail!(
                "the left and right UV layouts have different texels ({} vs {}); \
                 the statistics need one layout shared by both hands",
                visible[0].len(),
                visible[1].len()
            );
        }
        stats = Some(TexelVisibilityStats::from_masks(&visible[0], &visible[1])?);
    }
    write_all(&outputs)?;
    if let Some(stats) = stats {
        println!("{}", serde_json::to_string_pretty(&stats)?);
    }
    Ok(())
}

fn write_all(outputs: &[Output]) -> Result<()> {
    for o in outputs {
        bitt_texture::save_png8(&o.path, &o.data, o.width, o.height)
            .with_context(|| format!("writing {}", o.path.display()))?;
        eprintln!("wrote {} ({}x{})", o.path.display(), o.width, o.height);
    }
    Ok(())
}

/// `bitt image-diff A B`: mean and largest absolute difference of two images of equal size
/// (values in `[0, 1]`), as JSON; used by `cargo xtask e2e` to compare backends.
pub fn image_diff(a: &Path, b: &Path) -> Result<()> {
    let ia = load_image(a).with_context(|| format!("cannot load {}", a.display()))?;
    let ib = load_image(b).with_context(|| format!("cannot load {}", b.display()))?;
    if (ia.width, ia.height) != (ib.width, ib.height) {
        bail!(
            "{} is {}x{} but {} is {}x{}",
            a.display(),
            ia.width,
            ia.height,
            b.display(),
            ib.width,
            ib.height
        );
    }
    let n = ia.data.len().max(1) as f64;
    let (sum, max) = ia
        .data
        .iter()
        .zip(&ib.data)
        .map(|(x, y)| f64::from((x - y).abs()))
        .fold((0.0, 0.0f64), |(s, m), d| (s + d, m.max(d)));
    let mean = |d: &[f32]| d.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    println!(
        "{}",
        serde_json::json!({
            "mean_abs_diff": sum / n,
            "max_abs_diff": max,
            "mean_a": mean(&ia.data),
            "mean_b": mean(&ib.data),
        })
    );
    Ok(())
}

/// Side of each view of the `--views` grid.
const VIEW_SIZE: usize = 256;

/// `n` orthographic views around the hands (rotating about the camera's vertical axis), each
/// lit from its own camera side, as `[3, VIEW_SIZE, VIEW_SIZE]` panels.
fn render_views(
    n: usize,
    meshes: &[TexturedMesh],
    vertices: &[Tensor<2>],
    hands: &[Hand],
    textures: &[Tensor<3>],
    light: &LightValues,
    settings: &RenderSettings,
) -> Result<Vec<Vec<f32>>> {
    let device = vertices[0].device();
    let scene = Scene::new(&[&meshes[0], &meshes[1]])?;
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
            &scene,
            vertices,
            textures,
            &camera,
            &view_light.to_light(&device),
            settings,
        )?;
        panels.push(host(r.image)?);
    }
    Ok(panels)
}

/// The row under a views grid: the scene camera's render, then, per hand, that render
/// unwrapped onto the hand's UV layout (`VIEW_SIZE` texels a side): visible texels in their
/// unwrapped colour, hidden texels of the layout dark grey, unused texels black.
fn unwrap_row(
    full: &bitt_render::scene::SceneRender,
    camera: &Camera,
    hands: &[Hand],
) -> Result<Vec<Vec<f32>>> {
    let image = full.image.clone();
    let [_, h, w] = image.dims();
    anyhow::ensure!(
        [h, w] == [VIEW_SIZE, VIEW_SIZE],
        "--views needs a {VIEW_SIZE}x{VIEW_SIZE} scene camera for its unwrap row (got {w}x{h})"
    );
    let mut panels = vec![host(image.clone())?];
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
        let mut texels = host(u.texels)?;
        fill_hidden_texels(&mut texels, &u.visible_host, 0.25);
        panels.push(layout.compact_to_image(&texels, [0.0; 3])?);
    }
    Ok(panels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: RenderArgs,
    }

    fn args(extra: &[&str]) -> RenderArgs {
        let mut all = vec!["bitt", "--procedural", "--demo", "--uv-size", "64"];
        all.extend_from_slice(extra);
        Cli::try_parse_from(all).unwrap().args
    }

    fn scratch(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("bitt-render-test-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn error_of(a: &RenderArgs) -> String {
        format!("{:#}", run(a).expect_err("must fail"))
    }

    #[test]
    fn light_json_is_checked() {
        let ok = parse_light(
            r#"{"ambient":[0.5,0.5,0.5],"diffuse":[0.1,0.1,0.1],"specular":[0,0,0],"location":[0,1,0]}"#,
        )
        .unwrap();
        assert_eq!(ok.location, [0.0, 1.0, 0.0]);
        let e = format!(
            "{:#}",
            parse_light(r#"{"ambient":[0.5,0.5,0.5]}"#).unwrap_err()
        );
        assert!(e.contains("--light") && e.contains("diffuse"), "{e}");
        let e = format!("{:#}", parse_light(r#"{"ambient":[NaN,0,0]}"#).unwrap_err());
        assert!(e.contains("--light"), "{e}");
        // Too large for f32: becomes infinite, which the check rejects.
        let e = format!(
            "{:#}",
            parse_light(
                r#"{"ambient":[1e39,0,0],"diffuse":[0,0,0],"specular":[0,0,0],"location":[0,1,0]}"#
            )
            .unwrap_err()
        );
        assert!(e.contains("ambient") && e.contains("finite"), "{e}");
        let e = format!("{:#}", parse_light("/nonexistent/light.json").unwrap_err());
        assert!(e.contains("/nonexistent/light.json"), "{e}");
        // Inline JSON that is not a light object is named as --light, not read as a file.
        for wrong in ["[1,2]", " [1, 2, 3]", "42", "\"sun\""] {
            let e = format!("{:#}", parse_light(wrong).unwrap_err());
            assert!(
                e.starts_with("--light: expected JSON") && !e.contains("cannot read"),
                "{wrong}: {e}"
            );
        }
    }

    #[test]
    fn bad_inputs_name_the_file_and_write_nothing() {
        let dir = scratch("bad");
        let out = dir.join("img.png");
        let out_s = out.to_str().unwrap();
        // Missing texture.
        let missing = dir.join("missing.png");
        let e = error_of(&args(&[
            "--out",
            out_s,
            "--texture",
            missing.to_str().unwrap(),
        ]));
        assert!(e.contains("missing.png"), "{e}");
        // Corrupt texture.
        let corrupt = dir.join("corrupt.png");
        std::fs::write(&corrupt, b"not a png").unwrap();
        let e = error_of(&args(&[
            "--out",
            out_s,
            "--texture",
            corrupt.to_str().unwrap(),
        ]));
        assert!(e.contains("corrupt.png") && e.contains("decode"), "{e}");
        // Unwrap image of the wrong size.
        let small = dir.join("small.png");
        bitt_texture::save_png8(&small, &[0.5; 3 * 16 * 8], 16, 8).unwrap();
        let e = error_of(&args(&[
            "--out",
            out_s,
            "--unwrap",
            small.to_str().unwrap(),
        ]));
        assert!(
            e.contains("small.png") && e.contains("16x8") && e.contains("256x256"),
            "{e}"
        );
        // Non-finite light.
        let e = error_of(&args(&[
            "--out",
            out_s,
            "--light",
            r#"{"ambient":[1e40,0,0],"diffuse":[0,0,0],"specular":[0,0,0],"location":[0,0,0]}"#,
        ]));
        assert!(e.contains("ambient"), "{e}");
        // Missing annotation.
        let cli = Cli::try_parse_from([
            "bitt",
            "--procedural",
            "--annotation",
            "/nonexistent/01.pkl",
            "--out",
            out_s,
        ])
        .unwrap();
        let e = error_of(&cli.args);
        assert!(e.contains("/nonexistent/01.pkl"), "{e}");
        // Output folder missing.
        let e = error_of(&args(&["--out", "/nonexistent/dir/img.png"]));
        assert!(e.contains("/nonexistent/dir"), "{e}");
        let written: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("img"))
            .collect();
        assert!(written.is_empty(), "failed runs wrote {written:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn demo_render_and_unwrap_write_every_file() {
        let dir = scratch("ok");
        let out = dir.join("img.png");
        run(&args(&["--out", out.to_str().unwrap()])).unwrap();
        let names = [
            "img.png",
            "img.left.png",
            "img.right.png",
            "img.mask_left.png",
            "img.mask_right.png",
        ];
        for n in names {
            assert!(dir.join(n).is_file(), "{n} missing");
        }
        // Unwrap the render itself: both hands see some texels, the masks are consistent.
        let again = args(&[
            "--out",
            dir.join("b.png").to_str().unwrap(),
            "--unwrap",
            out.to_str().unwrap(),
        ]);
        run(&again).unwrap();
        for n in [
            "b.unwrap_left.png",
            "b.visible_left.png",
            "b.unwrap_right.png",
            "b.visible_right.png",
        ] {
            assert!(dir.join(n).is_file(), "{n} missing");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
