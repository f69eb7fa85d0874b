//! `bitt metrics A.png B.png` (the image metrics of one pair as JSON) and `bitt
//! convert-lpips` (the `lpips` package's VGG weights to the safetensors file LPIPS reads).

use std::path::PathBuf;

use anyhow::Result;
use bitt::lpips;
use bitt::lpips_convert::{self, torch_state_dict};
use bitt::metrics::SsimWindow;
use bitt::pair_metrics::{compare_images, lpips_weights, no_lpips_note, pair_lpips, pair_report};
use serde_json::json;

use crate::device::DeviceName;

/// SSIM window (`--ssim-window`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WindowChoice {
    /// pytorch_msssim's float32 window (BiTT's reference; the default).
    PytorchMsssim,
    /// The exact Gaussian (scikit-image).
    Exact,
}

impl From<WindowChoice> for SsimWindow {
    fn from(w: WindowChoice) -> Self {
        match w {
            WindowChoice::PytorchMsssim => SsimWindow::PytorchMsssim,
            WindowChoice::Exact => SsimWindow::Exact,
        }
    }
}

/// Arguments of `bitt metrics`.
#[derive(Debug, clap::Args)]
pub struct MetricsArgs {
    /// The first image (e.g. a render), PNG or JPEG.
    a: PathBuf,
    /// The second image (e.g. the ground truth), the same size.
    b: PathBuf,
    /// A mask image of the same size: pixels whose grey level (mean of RGB) is at least 0.5
    /// count. L1 and PSNR use the masked pixels only; SSIM, MS-SSIM and LPIPS use both
    /// images multiplied by the mask (black background).
    #[arg(long)]
    mask: Option<PathBuf>,
    /// LPIPS-VGG weights (safetensors from `bitt convert-lpips`). Default:
    /// $BITT_LPIPS_WEIGHTS, else ~/.cache/bitt/lpips_vgg.safetensors when it exists; without
    /// weights `lpips` is null.
    #[arg(long)]
    lpips: Option<PathBuf>,
    /// Device for LPIPS: flex, ndarray, wgpu or cuda.
    #[arg(long, default_value = "flex")]
    device: DeviceName,
    /// SSIM / MS-SSIM window.
    #[arg(long, value_enum, default_value = "pytorch-msssim")]
    ssim_window: WindowChoice,
}

/// Arguments of `bitt convert-lpips`.
#[derive(Debug, clap::Args)]
pub struct ConvertLpipsArgs {
    /// The `lpips` package's linear-layer weights, `lpips/weights/v0.1/vgg.pth` in its
    /// install folder (`python3 -c "import lpips, os; print(os.path.dirname(lpips.__file__))"`),
    /// or a whole `lpips.LPIPS(net='vgg').state_dict()` saved with `torch.save` (then
    /// `--vgg` is not needed).
    #[arg(long)]
    lin: PathBuf,
    /// torchvision's VGG16 weights, `vgg16-397923af.pth`
    /// (https://download.pytorch.org/models/vgg16-397923af.pth; torch keeps a copy in
    /// ~/.cache/torch/hub/checkpoints/). Default: that cache path.
    #[arg(long)]
    vgg: Option<PathBuf>,
    /// Output safetensors file. Default: $BITT_LPIPS_WEIGHTS, else
    /// ~/.cache/bitt/lpips_vgg.safetensors.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// `bitt metrics`.
pub fn run(args: &MetricsArgs) -> Result<()> {
    let value = compute(args, lpips::default_weights_path())?;
    println!("{}", serde_json::to_string_pretty(&value)?);
    Ok(())
}

/// The JSON of `bitt metrics`; `default_weights` is where LPIPS weights are looked for
/// without `--lpips`.
fn compute(args: &MetricsArgs, default_weights: Option<PathBuf>) -> Result<serde_json::Value> {
    let window = SsimWindow::from(args.ssim_window);
    let pair = compare_images(&args.a, &args.b, args.mask.as_deref(), window)?;
    let (lpips_value, lpips_note) =
        match lpips_weights(args.lpips.as_deref(), default_weights.as_deref()) {
            None => (None, no_lpips_note(default_weights.as_deref())),
            Some(p) => {
                let (d, note) = pair_lpips(&pair, &p, &args.device.device()?)?;
                (Some(d), note)
            }
        };
    Ok(pair_report(
        &args.a,
        &args.b,
        args.mask.as_deref(),
        &pair,
        window,
        lpips_value,
        &lpips_note,
    ))
}

/// `bitt convert-lpips`.
pub fn convert(args: &ConvertLpipsArgs) -> Result<()> {
    let done = lpips_convert::convert(
        &args.lin,
        args.vgg.as_deref(),
        args.out.as_deref(),
        torch_state_dict,
        &burn::tensor::Device::flex(),
    )?;
    println!(
        "{}",
        json!({"written": done.path.display().to_string(), "tensors": done.tensors})
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    type Cli = crate::test_args::Parsed<MetricsArgs>;

    fn scratch(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("bitt-metrics-test-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn parse(extra: &[&str]) -> MetricsArgs {
        let mut all = vec!["bitt"];
        all.extend_from_slice(extra);
        Cli::try_parse_from(all).unwrap().args
    }

    fn ramp(w: usize, h: usize, k: f32) -> Vec<f32> {
        (0..3 * w * h)
            .map(|i| ((i % w) as f32 / w as f32 * k + (i / w % h) as f32 / h as f32) / 2.0)
            .collect()
    }

    #[test]
    fn metrics_json_and_errors() {
        let dir = scratch("json");
        let (a, b, m, small) = (
            dir.join("a.png"),
            dir.join("b.png"),
            dir.join("m.png"),
            dir.join("small.png"),
        );
        bitt_texture::save_png8(&a, &ramp(40, 30, 1.0), 40, 30).unwrap();
        bitt_texture::save_png8(&b, &ramp(40, 30, 0.8), 40, 30).unwrap();
        let mask: Vec<f32> = (0..3 * 40 * 30)
            .map(|i| if i % 40 < 20 { 1.0 } else { 0.0 })
            .collect();
        bitt_texture::save_png8(&m, &mask, 40, 30).unwrap();
        bitt_texture::save_png8(&small, &ramp(20, 30, 1.0), 20, 30).unwrap();
        let s = |p: &Path| p.to_str().unwrap().to_string();
        let missing = dir.join("none.safetensors");
        // No LPIPS weights: null with a note.
        let v = compute(&parse(&[&s(&a), &s(&b), "--lpips", &s(&missing)]), None);
        let e = format!("{:#}", v.unwrap_err());
        assert!(e.contains("none.safetensors"), "{e}");
        let v = compute(&parse(&[&s(&a), &s(&b)]), Some(missing.clone())).unwrap();
        assert!(v["lpips"].is_null());
        assert!(v["lpips_note"].as_str().unwrap().contains("unavailable"));
        assert!(v["l1"].as_f64().unwrap() > 0.0);
        assert!(v["psnr"].as_f64().unwrap() > 10.0);
        assert!(v["ssim"].as_f64().unwrap() < 1.0);
        assert!(v["ms_ssim"].is_null());
        // Identical images: PSNR null with a note, SSIM 1.
        let v = compute(&parse(&[&s(&a), &s(&a)]), None).unwrap();
        assert!(v["psnr"].is_null() && v["psnr_note"].is_string());
        assert!((v["ssim"].as_f64().unwrap() - 1.0).abs() < 1e-6);
        // Mask: the left half of the pixels.
        let v = compute(&parse(&[&s(&a), &s(&b), "--mask", &s(&m)]), None).unwrap();
        assert_eq!(v["mask_pixels"].as_u64(), Some(20 * 30));
        // Different sizes and unreadable files name the file.
        let e = format!(
            "{:#}",
            compute(&parse(&[&s(&a), &s(&small)]), None).unwrap_err()
        );
        assert!(e.contains("small.png") && e.contains("20x30"), "{e}");
        let e = format!(
            "{:#}",
            compute(&parse(&[&s(&a), &s(&b), "--mask", &s(&small)]), None).unwrap_err()
        );
        assert!(e.contains("small.png"), "{e}");
        let junk = dir.join("junk.png");
        std::fs::write(&junk, b"not an image").unwrap();
        let e = format!(
            "{:#}",
            compute(&parse(&[&s(&junk), &s(&b)]), None).unwrap_err()
        );
        assert!(e.contains("junk.png"), "{e}");
        let e = format!(
            "{:#}",
            compute(&parse(&[&s(&dir.join("gone.png")), &s(&b)]), None).unwrap_err()
        );
        assert!(e.contains("gone.png"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
