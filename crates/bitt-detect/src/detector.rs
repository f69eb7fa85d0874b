//! [`HandDetector`]: the two networks on one device, run in batches on crops of a photo.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use image::RgbImage;

use crate::crop::{Border, Rect, resample};
use crate::exec::Network;
use crate::graph::{self, LANDMARK, PALM};
use crate::palm::{PALM_ANCHORS, PALM_INPUT, PALM_VALUES, Palm, decode};
use crate::{DetectError, NUM_LANDMARKS};

/// The weights built into the binary: MediaPipe Hands' full palm detector and hand landmark
/// model (Apache-2.0, mediapipe 0.10.21), fp16, converted by `cargo xtask convert-mediapipe`.
pub(crate) const BUILTIN_WEIGHTS: &[u8] = include_bytes!("../assets/mediapipe_hands.safetensors");

/// What names the built-in weights in errors.
pub(crate) const BUILTIN_NAME: &str = "<built-in MediaPipe Hands weights>";

/// Input side of the hand landmark model.
pub(crate) const LANDMARK_INPUT: usize = 224;

/// One hand as the landmark model sees it in one crop.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HandLandmarks {
    /// The crop it was found in.
    pub rect: Rect,
    /// 21 points `[x, y, z]` in continuous pixels of the photo (MediaPipe's order; `z`
    /// relative depth in pixels, smaller is nearer).
    pub points: Vec<[f64; 3]>,
    /// The model's hand presence score in `[0, 1]`.
    pub presence: f64,
    /// The probability that this is a **right** hand as it appears in the photo (the
    /// model's "Left" score: it labels hands as in a mirrored selfie).
    pub right: f64,
}

/// The palm detector's raw outputs for one image.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PalmOutput {
    /// `[2016 · 18]`: per anchor the box (x, y, w, h) and 7 keypoints, in input pixels
    /// relative to the anchor.
    pub regressors: Vec<f32>,
    /// `[2016]`: per anchor the score's logit.
    pub logits: Vec<f32>,
}

/// The landmark model's raw outputs for one image.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LandmarkOutput {
    /// `[21 · 3]`: x, y in crop pixels and a relative depth.
    pub screen: Vec<f32>,
    /// Hand presence, a probability.
    pub presence: f32,
    /// MediaPipe's "Left" score, in its mirrored (selfie) convention: the probability that
    /// the hand in an ordinary photo is a right hand.
    pub selfie_left: f32,
    /// `[21 · 3]`: world coordinates (metres, about the hand's centre).
    pub world: Vec<f32>,
}

/// MediaPipe Hands' two networks on one burn device.
#[derive(Debug, Clone)]
pub struct HandDetector {
    palm: Network,
    landmark: Network,
}

impl HandDetector {
    /// The built-in weights on `device`.
    ///
    /// # Errors
    /// Never for the shipped file; an error names the file if it were damaged.
    pub fn builtin(device: &Device) -> Result<Self, DetectError> {
        Self::from_weights(BUILTIN_WEIGHTS, Path::new(BUILTIN_NAME), device)
    }

    /// Weights from a file written by [`graph::to_safetensors`]; `origin` names it in errors.
    ///
    /// # Errors
    /// A malformed file, or networks of the wrong input or output shapes.
    pub(crate) fn from_weights(
        bytes: &[u8],
        origin: &Path,
        device: &Device,
    ) -> Result<Self, DetectError> {
        let palm = Network::new(
            graph::from_safetensors(bytes, PALM, origin)?,
            device,
            origin,
        )?;
        let landmark = Network::new(
            graph::from_safetensors(bytes, LANDMARK, origin)?,
            device,
            origin,
        )?;
        let check =
            |net: &Network, size: usize, outputs: &[(&str, usize)]| -> Result<(), DetectError> {
                if net.input_size() != [size, size] {
                    return Err(DetectError::model(
                        origin,
                        format!(
                            "a network takes {:?}, expected {size}x{size}",
                            net.input_size()
                        ),
                    ));
                }
                for (name, n) in outputs {
                    let id =
                        net.graph().outputs.get(*name).ok_or_else(|| {
                            DetectError::model(origin, format!("no output {name}"))
                        })?;
                    let got: usize = net.graph().shapes.get(id).map_or(0, |s| s.iter().product());
                    if got != *n {
                        return Err(DetectError::model(
                            origin,
                            format!("output {name} has {got} values, expected {n}"),
                        ));
                    }
                }
                Ok(())
            };
        check(
            &palm,
            PALM_INPUT,
            &[
                ("Identity", PALM_ANCHORS * PALM_VALUES),
                ("Identity_1", PALM_ANCHORS),
            ],
        )?;
        check(
            &landmark,
            LANDMARK_INPUT,
            &[
                ("Identity", 3 * NUM_LANDMARKS),
                ("Identity_1", 1),
                ("Identity_2", 1),
            ],
        )?;
        Ok(HandDetector { palm, landmark })
    }

    /// The device the networks run on.
    pub fn device(&self) -> &Device {
        self.palm.device()
    }

    /// The raw outputs of the palm detector on a batch of NCHW inputs, one per image.
    ///
    /// # Shapes
    /// - `input`: `[N, 3, 192, 192]`, values in `[0, 1]`
    ///
    /// # Errors
    /// A wrongly sized input, or a failed readback.
    pub(crate) fn palm_raw(&self, input: Tensor<4>) -> Result<Vec<PalmOutput>, DetectError> {
        let n = input.dims()[0];
        let mut out = self.palm.forward(input)?;
        let reg = bitt_stdx::to_host(out.remove("Identity").expect("checked output"))?;
        let logits = bitt_stdx::to_host(out.remove("Identity_1").expect("checked output"))?;
        let per = PALM_ANCHORS * PALM_VALUES;
        Ok((0..n)
            .map(|i| PalmOutput {
                regressors: reg[i * per..(i + 1) * per].to_vec(),
                logits: logits[i * PALM_ANCHORS..(i + 1) * PALM_ANCHORS].to_vec(),
            })
            .collect())
    }

    /// The raw outputs of the landmark model on a batch of NCHW inputs, one per image.
    ///
    /// # Shapes
    /// - `input`: `[N, 3, 224, 224]`, values in `[0, 1]`
    ///
    /// # Errors
    /// A wrongly sized input, or a failed readback.
    pub(crate) fn landmark_raw(
        &self,
        input: Tensor<4>,
    ) -> Result<Vec<LandmarkOutput>, DetectError> {
        let n = input.dims()[0];
        let mut out = self.landmark.forward(input)?;
        let mut take = |name: &str| -> Result<Vec<f32>, DetectError> {
            match out.remove(name) {
                Some(t) => Ok(bitt_stdx::to_host(t)?),
                None => Ok(vec![0.0; n * 3 * NUM_LANDMARKS]),
            }
        };
        let screen = take("Identity")?;
        let presence = take("Identity_1")?;
        let left = take("Identity_2")?;
        let world = take("Identity_3")?;
        let k = 3 * NUM_LANDMARKS;
        Ok((0..n)
            .map(|i| LandmarkOutput {
                screen: screen[i * k..(i + 1) * k].to_vec(),
                presence: presence[i],
                selfie_left: left[i],
                world: world[i * k..(i + 1) * k].to_vec(),
            })
            .collect())
    }

    fn batch(&self, planes: Vec<f32>, n: usize, size: usize) -> Tensor<4> {
        Tensor::from_data(TensorData::new(planes, [n, 3, size, size]), self.device())
    }

    /// Palms in each crop `views` of `image` (for the whole photo, [`crate::palm::letterbox`]),
    /// scoring at least `min_score`, after weighted NMS; in continuous photo pixels.
    ///
    /// # Errors
    /// A failed readback.
    pub fn palms(
        &self,
        image: &RgbImage,
        views: &[Rect],
        min_score: f64,
    ) -> Result<Vec<Vec<Palm>>, DetectError> {
        if views.is_empty() {
            return Ok(Vec::new());
        }
        let planes: Vec<f32> = views
            .iter()
            .flat_map(|v| resample(image, v, PALM_INPUT, Border::Zero))
            .collect();
        let raw = self.palm_raw(self.batch(planes, views.len(), PALM_INPUT))?;
        Ok(raw
            .iter()
            .zip(views)
            .map(|(out, view)| decode(&out.regressors, &out.logits, view, min_score))
            .collect())
    }

    /// The landmark model on each crop `rects` of `image`.
    ///
    /// # Errors
    /// A failed readback.
    pub fn landmarks(
        &self,
        image: &RgbImage,
        rects: &[Rect],
    ) -> Result<Vec<HandLandmarks>, DetectError> {
        if rects.is_empty() {
            return Ok(Vec::new());
        }
        let planes: Vec<f32> = rects
            .iter()
            .flat_map(|r| resample(image, r, LANDMARK_INPUT, Border::Replicate))
            .collect();
        let raw = self.landmark_raw(self.batch(planes, rects.len(), LANDMARK_INPUT))?;
        let s = LANDMARK_INPUT as f64;
        Ok(raw
            .into_iter()
            .zip(rects)
            .map(|(out, rect)| {
                let points = out
                    .screen
                    .chunks_exact(3)
                    .map(|p| {
                        let [x, y] = rect.to_image(p[0] as f64 / s, p[1] as f64 / s);
                        [x, y, p[2] as f64 / s * rect.size[0]]
                    })
                    .collect();
                HandLandmarks {
                    rect: *rect,
                    points,
                    presence: out.presence as f64,
                    right: out.selfie_left as f64,
                }
            })
            .collect())
    }
}
