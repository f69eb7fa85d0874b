//! `bitt render`: render both hands of a scene with a UV texture under a point light, and
//! optionally unwrap an image onto both hands' texels (the paper's visible texels and masks).
//!
//! Every input is read and checked before anything is rendered (`bitt::figure_inputs`), and
//! every output is made in memory before the first file is written (`bitt::figure`), so a
//! bad input leaves no half-written set of files behind.

use std::path::{Path, PathBuf};

use anyhow::Result;
use bitt::figure::{
    FigureOptions, check_figure_options, default_light, render_figure, write_figure,
};
use bitt::figure_inputs::{FigureFiles, figure_inputs, read_light};

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

/// `bitt render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    check_figure_options(args.uv_size, args.views, args.unwrap.is_some(), &args.out)?;
    // Inputs first: light, models, scene, textures, the image to unwrap.
    let light = match &args.light {
        Some(l) => read_light(l)?,
        None => default_light(),
    };
    let device = args.device.device()?;
    let models = args.hands.models()?;
    let files = FigureFiles {
        uvs: args.uvs.as_deref(),
        uvs_left: args.uvs_left.as_deref(),
        annotation: args.annotation.as_deref().filter(|_| !args.demo),
        image_size: args.image_size,
        texture: args.texture.as_deref(),
        skin_seed: args.skin_seed,
        uv_size: args.uv_size,
        unwrap: args.unwrap.as_deref(),
    };
    let inputs = figure_inputs(&models, &files, &device)?;
    let options = FigureOptions {
        uv_size: args.uv_size,
        views: args.views,
        unwrap: inputs.unwrap,
        antialias: !args.no_antialias,
    };
    let (images, stats) = render_figure(
        &inputs.hands,
        &inputs.textures,
        &inputs.camera,
        &light,
        &options,
    )?;
    write_figure(&args.out, &images, |path, o| {
        eprintln!("wrote {} ({}x{})", path.display(), o.width, o.height);
    })?;
    if let Some(stats) = stats {
        println!("{}", serde_json::to_string_pretty(&stats)?);
    }
    Ok(())
}

/// `bitt image-diff A B`: mean and largest absolute difference of two images of equal size,
/// as JSON (`bitt::pair_metrics::image_diff`); used by `cargo xtask e2e` to compare backends.
pub fn image_diff(a: &Path, b: &Path) -> Result<()> {
    println!("{}", bitt::pair_metrics::image_diff(a, b)?);
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
