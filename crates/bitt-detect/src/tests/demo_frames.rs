//! The search on the two real InterHand2.6M demo frames (`../shared/data/interhand_demo`,
//! licensed, never in the repo: each test says SKIPPED without them), and on copies of them
//! made here: mirrored, resized, placed off-centre on a larger dark canvas, rotated.
//!
//! Ground truth: each hand's wrist and middle-finger base projected from the frame's
//! annotation (procedural hands posed with its MANO parameters and camera). A detected hand
//! must be of the right side: its wrist and middle base closer to its own side's annotated
//! ones than to the other hand's.

use std::path::{Path, PathBuf};

use bitt_mesh::glam::DVec2;
use bitt_mesh::{Side, load_bitt_annotation, procedural_pair};
use image::{Rgb, RgbImage};

use crate::{HandDetector, SearchConfig, TwoHandDetection, detect_hands};

fn demo(name: &str) -> Option<(RgbImage, PathBuf)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/interhand_demo");
    let image = dir.join(format!("{name}.jpg"));
    let pkl = dir.join(format!("{name}.pkl"));
    if !image.exists() || !pkl.exists() {
        eprintln!("SKIPPED demo frame {name}: {} not found", image.display());
        return None;
    }
    Some((image::open(&image).expect("demo frame").to_rgb8(), pkl))
}

/// `[wrist, middle base]` of each hand in pixels of the frame, from the annotation.
fn truth(pkl: &Path) -> [(Side, [DVec2; 2]); 2] {
    let scene = load_bitt_annotation(pkl, (256, 256)).expect("annotation");
    let posed = scene.pose_in_camera(&procedural_pair()).expect("posed");
    Side::BOTH.map(|side| {
        let j = &posed.get(side).expect("both hands annotated").joints;
        let p = |i: usize| scene.camera.camera_to_pixel(j[i]).expect("in front");
        (side, [p(0), p(9)])
    })
}

/// A transform of the frame: the new image and where a frame pixel lands in it.
struct Variant {
    name: &'static str,
    image: RgbImage,
    map: Box<dyn Fn(DVec2) -> DVec2>,
    mirrored: bool,
}

fn bilinear(img: &RgbImage, x: f64, y: f64) -> Rgb<u8> {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let mut out = [0f64; 3];
    for (dy, wy) in [(0, 1.0 - fy), (1, fy)] {
        for (dx, wx) in [(0, 1.0 - fx), (1, fx)] {
            let (xi, yi) = (x0 as i64 + dx, y0 as i64 + dy);
            if xi < 0 || yi < 0 || xi >= w || yi >= h {
                continue;
            }
            let p = img.get_pixel(xi as u32, yi as u32).0;
            for k in 0..3 {
                out[k] += wx * wy * p[k] as f64;
            }
        }
    }
    Rgb(out.map(|v| v.round().clamp(0.0, 255.0) as u8))
}

/// An image of `w x h` whose pixel `q` shows the frame at `inverse(q)` (black outside).
fn warp(img: &RgbImage, w: u32, h: u32, inverse: impl Fn(DVec2) -> DVec2) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| {
        let p = inverse(DVec2::new(x as f64, y as f64));
        bilinear(img, p.x, p.y)
    })
}

fn variants(img: &RgbImage) -> Vec<Variant> {
    let (w, h) = (img.width() as f64, img.height() as f64);
    let mut out = Vec::new();
    out.push(Variant {
        name: "mirrored",
        image: warp(img, img.width(), img.height(), move |q| {
            DVec2::new(w - 1.0 - q.x, q.y)
        }),
        map: Box::new(move |p| DVec2::new(w - 1.0 - p.x, p.y)),
        mirrored: true,
    });
    for (name, s) in [("resized 0.75", 0.75), ("resized 2.5", 2.5)] {
        let (nw, nh) = ((w * s).round() as u32, (h * s).round() as u32);
        out.push(Variant {
            name,
            image: warp(img, nw, nh, move |q| (q + 0.5) / s - 0.5),
            map: Box::new(move |p| (p + 0.5) * s - 0.5),
            mirrored: false,
        });
    }
    let off = DVec2::new(260.0, 40.0);
    out.push(Variant {
        name: "off-centre on 640x400",
        image: warp(img, 640, 400, move |q| q - off),
        map: Box::new(move |p| p + off),
        mirrored: false,
    });
    for deg in [-20.0f64, 20.0] {
        let (s, c) = deg.to_radians().sin_cos();
        let centre = DVec2::new((w - 1.0) / 2.0, (h - 1.0) / 2.0);
        let rot = move |p: DVec2, sign: f64| {
            let d = p - centre;
            centre + DVec2::new(c * d.x - sign * s * d.y, sign * s * d.x + c * d.y)
        };
        out.push(Variant {
            name: if deg < 0.0 {
                "rotated -20"
            } else {
                "rotated 20"
            },
            image: warp(img, img.width(), img.height(), move |q| rot(q, -1.0)),
            map: Box::new(move |p| rot(p, 1.0)),
            mirrored: false,
        });
    }
    // Degraded copies: Gaussian noise (sigma 12 of 255, a fixed generator) and a JPEG of
    // quality 25; the palm detector scores the palms of these under its threshold, and the
    // whole-photo stage finds the hands.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut uniform = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let mut noisy = img.clone();
    for p in noisy.pixels_mut() {
        for c in p.0.iter_mut() {
            let g = (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos();
            *c = (*c as f64 + 12.0 * g).round().clamp(0.0, 255.0) as u8;
        }
    }
    out.push(Variant {
        name: "noise 12",
        image: noisy,
        map: Box::new(|p| p),
        mirrored: false,
    });
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 25)
        .encode_image(img)
        .expect("jpeg");
    out.push(Variant {
        name: "jpeg 25",
        image: image::load_from_memory(&jpeg).expect("jpeg").to_rgb8(),
        map: Box::new(|p| p),
        mirrored: false,
    });
    out
}

/// Each found hand is of the correct side: its wrist and middle base lie closer to that
/// side's annotated ones than to the other side's. Returns the sides found by detection
/// (not by hypothesis).
fn check_sides(
    d: &TwoHandDetection,
    truth: &[(Side, [DVec2; 2]); 2],
    what: &str,
) -> Result<Vec<Side>, String> {
    let mut detected = Vec::new();
    for side in Side::BOTH {
        let hand = d
            .hand(side)
            .ok_or_else(|| format!("{what}: no {side} hand"))?;
        if hand.stage == "hypothesis" {
            continue;
        }
        let got = [0, 9].map(|i| DVec2::new(hand.points[i][0], hand.points[i][1]));
        let dist = |t: &[DVec2; 2]| got[0].distance(t[0]) + got[1].distance(t[1]);
        let own = truth.iter().find(|t| t.0 == side).expect("side").1;
        let other = truth.iter().find(|t| t.0 != side).expect("side").1;
        if dist(&own) >= dist(&other) {
            return Err(format!(
                "{what}: the {side} hand lies on the other hand ({:.0} px vs {:.0} px; stage {})",
                dist(&own),
                dist(&other),
                hand.stage
            ));
        }
        detected.push(side);
    }
    Ok(detected)
}

#[test]
fn demo_frames_give_both_hands_of_the_right_sides() {
    let det = HandDetector::builtin(&burn::tensor::Device::flex()).expect("weights");
    let config = SearchConfig::default();
    let mut failures = Vec::new();
    let mut both_detected = 0;
    for (name, want_detected) in [("01", 2), ("02", 1)] {
        let Some((img, pkl)) = demo(name) else {
            return;
        };
        let truth = truth(&pkl);
        let d = detect_hands(&det, &img, &config).expect("search");
        let found = check_sides(&d, &truth, name).unwrap_or_else(|e| panic!("{e}"));
        // 01: both hands detected; 02: the left hand is hidden behind the right one and
        // placed by hypothesis (docs/detection.md).
        assert_eq!(found.len(), want_detected, "{name}: detected {found:?}");
        for v in variants(&img) {
            let what = format!("{name} {}", v.name);
            let t = truth.map(|(side, [a, b])| {
                let side = if v.mirrored { side.mirrored() } else { side };
                (side, [(v.map)(a), (v.map)(b)])
            });
            let d = detect_hands(&det, &v.image, &config).expect("search");
            match check_sides(&d, &t, &what) {
                Ok(found) if !found.is_empty() => {
                    both_detected += usize::from(found.len() == 2);
                    eprintln!(
                        "{what}: detected {found:?}{}",
                        d.hypothesized()
                            .map_or(String::new(), |s| format!(", {s} by hypothesis"))
                    )
                }
                Ok(_) => failures.push(format!("{what}: nothing detected")),
                Err(e) => failures.push(e),
            }
        }
    }
    // Known miss (docs/detection.md, "Limits"): with noise on 02 the palms stage finds
    // nothing, and of the whole-photo stage's two readings the one read left lies between
    // the hands, nearer the right one's wrist and middle base (70 px against 84 px). The list
    // is exact, so a fix (or a new miss) shows.
    let known = ["02 noise 12"];
    let missed: Vec<&String> = failures
        .iter()
        .filter(|f| !known.iter().any(|k| f.starts_with(&format!("{k}:"))))
        .collect();
    assert!(missed.is_empty(), "new misses: {missed:#?}");
    assert_eq!(
        failures.len(),
        known.len(),
        "fewer misses than known: {failures:#?}"
    );
    // Both hands detected, on the right sides, in 9 of the 18 copies (7 of the 14 geometric
    // ones, and 01 with noise and as a JPEG): three of them (01
    // resized 0.75, off-centre, rotated -20) get their left hand from the look stage,
    // which the hypothesis placed before it; in 01 resized 2.5 the look stage finds the
    // left hand and relabels the found one right; in 01 rotated 20 two crops of the right
    // hand read left (0.96) and right (0.72) with wrists 0.38 palm apart, too close to be
    // a pair, and the look stage, started from the right reading, finds the left hand.
    assert!(
        both_detected >= 9,
        "both hands detected in {both_detected} copies"
    );
}
