//! `bitt render`: render both hands of a scene with a UV texture under a point light, and
//! optionally unwrap an image onto both hands' texels (the paper's visible texels and masks).
//!
//! Every input is read and checked before anything is rendered, and every output is made in
//! memory before the first file is written (each one atomically), so a bad input leaves no
//! half-written set of files behind.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use bitt::figure::{FigureHand, FigureImage, FigureOptions, default_light, render_figure};
use bitt::figure_inputs::{hand_uvs, image_tensor, procedural_textures, read_light};
use bitt_mesh::annotation::annotation_image_size;
use bitt_mesh::{HandPair, Side, UvLayout};
use bitt_texture::{ImageDifference, load_image};

use crate::device::DeviceName;

/// Arguments of `bitt render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// The hand models.
    #[command(flatten)]
    pub hands: crate::pose_hands::ModelArgs,
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
    #[arg(long, value_parser = crate::pose_hands::parse_size)]
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

/// `<stem><suffix>.png` next to `out` (e.g. `img.png` -> `img.left.png`).
pub fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "render".into());
    out.with_file_name(format!("{stem}.{suffix}.png"))
}

fn load_models(args: &RenderArgs) -> Result<(HandPair, [UvLayout; 2])> {
    let models = args.hands.models()?;
    let uvs = hand_uvs(&models, args.uvs.as_deref(), args.uvs_left.as_deref())?;
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
        .unwrap_or_else(|| annotation_image_size(path));
    Ok(bitt_mesh::load_bitt_annotation(path, size)?)
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
        Some(l) => read_light(l)?,
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
        hands.push(FigureHand {
            side,
            model: models.get(side).clone(),
            uv,
            vertices,
        });
    }
    let hands: [FigureHand; 2] = hands
        .try_into()
        .map_err(|_| anyhow!("two hands expected"))?;
    let textures = match &args.texture {
        Some(path) => {
            let (t, _) = image_tensor(path, "--texture", &device)?;
            vec![t.clone(), t]
        }
        None => procedural_textures(&models, &uvs, args.skin_seed, args.uv_size, &device)?,
    };
    let camera = &scene.camera;
    let unwrap = match &args.unwrap {
        Some(path) => {
            let (t, [h, w]) = image_tensor(path, "--unwrap", &device)?;
            if [h, w] != [camera.height as usize, camera.width as usize] {
                bail!(
                    "--unwrap {}: the image is {w}x{h}, but the camera renders {}x{}; \
                     unwrap an image of the camera's size",
                    path.display(),
                    camera.width,
                    camera.height
                );
            }
            Some(t)
        }
        None => None,
    };
    let options = FigureOptions {
        uv_size: args.uv_size,
        views: args.views,
        unwrap,
        antialias: !args.no_antialias,
    };
    let (images, stats) = render_figure(&hands, &textures, camera, &light, &options)?;
    write_all(&args.out, &images)?;
    if let Some(stats) = stats {
        println!("{}", serde_json::to_string_pretty(&stats)?);
    }
    Ok(())
}

/// Writes a figure's images: the main one at `out`, the others next to it ([`sibling`]).
fn write_all(out: &Path, images: &[FigureImage]) -> Result<()> {
    for o in images {
        let path = match &o.suffix {
            None => out.to_path_buf(),
            Some(suffix) => sibling(out, suffix),
        };
        bitt_texture::save_png8(&path, &o.data, o.width, o.height)
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {} ({}x{})", path.display(), o.width, o.height);
    }
    Ok(())
}

/// `bitt image-diff A B`: mean and largest absolute difference of two images of equal size
/// (values in `[0, 1]`), as JSON; used by `cargo xtask e2e` to compare backends.
pub fn image_diff(a: &Path, b: &Path) -> Result<()> {
    let ia = load_image(a).with_context(|| format!("cannot load {}", a.display()))?;
    let ib = load_image(b).with_context(|| format!("cannot load {}", b.display()))?;
    let Some(d) = ImageDifference::between(&ia, &ib) else {
        bail!(
            "{} is {}x{} but {} is {}x{}",
            a.display(),
            ia.width,
            ia.height,
            b.display(),
            ib.width,
            ib.height
        );
    };
    println!(
        "{}",
        serde_json::json!({
            "mean_abs_diff": d.mean_abs_diff,
            "max_abs_diff": d.max_abs_diff,
            "mean_a": d.mean_a,
            "mean_b": d.mean_b,
        })
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    type Cli = crate::test_args::Parsed<RenderArgs>;

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
