//! `tests-data/reference.py` ran MediaPipe Hands' TFLite models through LiteRT on two
//! synthetic patterns and wrote the expected outputs into `reference_values.rs`; these tests
//! rebuild the same inputs and run the built-in weights on flex, ndarray and wgpu.

use burn::tensor::{Tensor, TensorData};

use super::reference_values::*;
use crate::HandDetector;
use crate::detector::{LandmarkOutput, PalmOutput};

/// The reference script's input pattern `p` as NCHW planes `[3, h, w]`.
fn pattern(h: usize, w: usize, p: usize) -> Vec<f32> {
    let mut out = vec![0f32; 3 * h * w];
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                let (xf, yf, cf) = (x as f64, y as f64, c as f64);
                let v = if p == 0 {
                    0.5 + ((0.5 * (((0.11 * xf) + (0.07 * yf)) + (1.3 * cf)).sin())
                        * (((0.05 * xf) - (0.09 * yf)) + (0.7 * cf)).cos())
                } else {
                    let t = ((xf * 0.618034) + (yf * 0.414214)) + (cf * 0.333333);
                    t - t.floor()
                };
                out[c * h * w + y * w + x] = v as f32;
            }
        }
    }
    out
}

/// `|a - b| <= tol · max(1, |b|)`.
fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

#[test]
fn input_patterns_match_the_script() {
    for (p, size, want) in [
        (0, 192, PALM_P0_INPUT_SUM),
        (1, 192, PALM_P1_INPUT_SUM),
        (0, 224, LANDMARK_P0_INPUT_SUM),
        (1, 224, LANDMARK_P1_INPUT_SUM),
    ] {
        let sum: f64 = pattern(size, size, p).iter().map(|&v| v as f64).sum();
        assert!(
            (sum - want).abs() < 1e-6 * want,
            "pattern {p} at {size}: {sum} vs {want}"
        );
    }
}

#[test]
fn palm_detector_matches_tflite() {
    let cases = [
        (
            0,
            &PALM_P0_ANCHORS[..],
            &PALM_P0_REGRESSORS[..],
            &PALM_P0_LOGITS[..],
            PALM_P0_REGRESSOR_SUM,
            PALM_P0_LOGIT_SUM,
        ),
        (
            1,
            &PALM_P1_ANCHORS[..],
            &PALM_P1_REGRESSORS[..],
            &PALM_P1_LOGITS[..],
            PALM_P1_REGRESSOR_SUM,
            PALM_P1_LOGIT_SUM,
        ),
    ];
    for (name, device) in bitt_testkit::devices() {
        let det = HandDetector::builtin(&device).unwrap();
        let planes: Vec<f32> = cases.iter().flat_map(|c| pattern(192, 192, c.0)).collect();
        let input = Tensor::from_data(TensorData::new(planes, [2, 3, 192, 192]), &device);
        let out = det.palm_raw(input).unwrap();
        for (
            (p, anchors, regs, logits, reg_sum, logit_sum),
            PalmOutput {
                regressors: reg,
                logits: logit,
            },
        ) in cases.iter().zip(&out)
        {
            let mut worst = 0f32;
            for (k, &a) in anchors.iter().enumerate() {
                for j in 0..18 {
                    let (got, want) = (reg[a * 18 + j], regs[k][j]);
                    worst = worst.max((got - want).abs() / want.abs().max(1.0));
                    assert!(
                        close(got, want, 1e-3),
                        "{name} p{p} anchor {a} value {j}: {got} vs {want}"
                    );
                }
                assert!(
                    close(logit[a], logits[k], 1e-3),
                    "{name} p{p} anchor {a} logit: {} vs {}",
                    logit[a],
                    logits[k]
                );
            }
            let rs: f64 = reg.iter().map(|&v| v as f64).sum();
            let ls: f64 = logit.iter().map(|&v| v as f64).sum();
            // Sums over 36,288 and 2,016 values: 1e-3 of the sum of magnitudes.
            let rmag: f64 = reg.iter().map(|&v| v.abs() as f64).sum();
            let lmag: f64 = logit.iter().map(|&v| v.abs() as f64).sum();
            assert!(
                (rs - reg_sum).abs() < 1e-4 * rmag,
                "{name} p{p} regressor sum {rs} vs {reg_sum}"
            );
            assert!(
                (ls - logit_sum).abs() < 1e-4 * lmag,
                "{name} p{p} logit sum {ls} vs {logit_sum}"
            );
            eprintln!("{name} palm p{p}: worst relative difference {worst:.2e}");
        }
    }
}

#[test]
fn landmark_model_matches_tflite() {
    let cases = [
        (
            0,
            &LANDMARK_P0_SCREEN,
            LANDMARK_P0_PRESENCE,
            LANDMARK_P0_HANDEDNESS,
            &LANDMARK_P0_WORLD,
        ),
        (
            1,
            &LANDMARK_P1_SCREEN,
            LANDMARK_P1_PRESENCE,
            LANDMARK_P1_HANDEDNESS,
            &LANDMARK_P1_WORLD,
        ),
    ];
    for (name, device) in bitt_testkit::devices() {
        let det = HandDetector::builtin(&device).unwrap();
        let planes: Vec<f32> = cases.iter().flat_map(|c| pattern(224, 224, c.0)).collect();
        let input = Tensor::from_data(TensorData::new(planes, [2, 3, 224, 224]), &device);
        let out = det.landmark_raw(input).unwrap();
        for (
            (p, screen, presence, handedness, world),
            LandmarkOutput {
                screen: s,
                presence: pr,
                selfie_left: hd,
                world: wd,
            },
        ) in cases.iter().zip(&out)
        {
            let mut worst = 0f32;
            for j in 0..63 {
                worst = worst.max((s[j] - screen[j]).abs() / screen[j].abs().max(1.0));
                assert!(
                    close(s[j], screen[j], 1e-3),
                    "{name} p{p} screen {j}: {} vs {}",
                    s[j],
                    screen[j]
                );
                assert!(
                    close(wd[j], world[j], 1e-3),
                    "{name} p{p} world {j}: {} vs {}",
                    wd[j],
                    world[j]
                );
            }
            assert!(
                close(*pr, *presence, 1e-3),
                "{name} p{p} presence {pr} vs {presence}"
            );
            assert!(
                close(*hd, *handedness, 1e-3),
                "{name} p{p} handedness {hd} vs {handedness}"
            );
            eprintln!("{name} landmarks p{p}: worst relative difference {worst:.2e}");
        }
    }
}
