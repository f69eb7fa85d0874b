//! `cargo xtask bench detect`: the two-hand search against one pass of MediaPipe's own
//! pipeline (palm detector on the letterboxed photo, the landmark model on each palm found)
//! with the same networks, timed side by side in one process, on a 256 x 256 photo and on a
//! 1920 x 1080 one (the photo enlarged 3x, off-centre on a dark canvas).
//!
//! Usage: `bench_detect [--runs N] PHOTO...` (default: the demo frames in
//! `../shared/data/interhand_demo`, when present). Prints one JSON line per photo and size.

use std::path::PathBuf;
use std::time::Instant;

use bitt_detect::palm::letterbox;
use bitt_detect::{HandDetector, SearchConfig, detect_hands};
use image::{Rgb, RgbImage, imageops};

fn best_of(runs: usize, mut f: impl FnMut()) -> f64 {
    (0..runs)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut runs = 5;
    if let Some(i) = args.iter().position(|a| a == "--runs") {
        runs = args.get(i + 1).ok_or("--runs needs a number")?.parse()?;
        args.drain(i..i + 2);
    }
    let mut photos: Vec<PathBuf> = args.iter().map(PathBuf::from).collect();
    if photos.is_empty() {
        let dir =
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/interhand_demo");
        photos = ["01.jpg", "02.jpg"]
            .iter()
            .map(|n| dir.join(n))
            .filter(|p| p.exists())
            .collect();
        if photos.is_empty() {
            println!(
                "SKIPPED bench detect: no photo given and {} not found",
                dir.display()
            );
            return Ok(());
        }
    }
    let device = burn::tensor::Device::flex();
    let det = HandDetector::builtin(&device)?;
    let config = SearchConfig::default();
    for path in &photos {
        let photo = image::open(path)?.to_rgb8();
        let mut big = RgbImage::from_pixel(1920, 1080, Rgb([8, 8, 8]));
        let scaled = imageops::resize(
            &photo,
            photo.width() * 3,
            photo.height() * 3,
            imageops::FilterType::Triangle,
        );
        imageops::overlay(&mut big, &scaled, 1100, 200);
        for (label, img) in [("photo", photo), ("1920x1080", big)] {
            // warm-up, and the result
            let found = detect_hands(&det, &img, &config)?;
            let search = best_of(runs, || {
                detect_hands(&det, &img, &config).expect("search");
            });
            let single = best_of(runs, || {
                let palms = det
                    .palms(&img, &[letterbox(img.width(), img.height())], 0.5)
                    .expect("palms");
                let rects: Vec<_> = palms[0].iter().map(|p| p.hand_rect()).collect();
                det.landmarks(&img, &rects).expect("landmarks");
            });
            println!(
                "{}",
                serde_json::json!({
                    "photo": path.display().to_string(),
                    "size": format!("{}x{}", img.width(), img.height()),
                    "label": label,
                    "search_s": search,
                    "mediapipe_pass_s": single,
                    "ratio": search / single,
                    "left": found.left.as_ref().map(|h| &h.stage),
                    "right": found.right.as_ref().map(|h| &h.stage),
                    "stages": found.stages.iter().map(|s| &s.stage).collect::<Vec<_>>(),
                })
            );
        }
    }
    Ok(())
}
