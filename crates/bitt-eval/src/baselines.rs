//! The paper's texture baselines (Tables 1 and 2), rebuilt in this framework so that every
//! method is trained on the same view with the same renderer, light model and loss:
//!
//! - **HARP-like** ([`Baseline::HarpLike`], Karunratanakul et al. 2023): the UV texture itself
//!   is the parameter, optimised with the light from the visible pixels only. No prior:
//!   texels the camera never sees keep their uniform initial colour (the mean colour of the
//!   hand pixels), which is what the paper observes of HARP ("merely displaying a uniform
//!   color in those areas", Sec. 4.2).
//! - **S2Hand-like** ([`Baseline::S2HandLike`], Chen et al. 2021): one colour per mesh
//!   vertex, interpolated across each face (the texture of texel `t` is the barycentric mix of
//!   its face's three vertex colours). Smooth, so it cannot hold veins, wrinkles or hair, and
//!   vertices never seen keep the initial colour.
//!
//! Both optimise a Phong light (the light network's 12-number parametrisation, from zeros)
//! jointly with the colours, with Adam on `|I_hand - render|` (the paper's `L_rec`). The
//! HTML baseline needs no code here: it is BiTT's own coarse stage (see `benchmark`).

use bitt_nets::LightParams;
use bitt_render::scene::LightValues;
use burn::module::{Module, Param};
use burn::tensor::{Device, Int, Tensor, TensorData};

use crate::EvalError;
use bitt_stdx::to_host;
use bitt_train::config::OptimConfig;
use bitt_train::optim::Adam;
use bitt_train::pipeline::point_light;
use bitt_train::trainer::Trainer;

/// A baseline method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Baseline {
    /// Texels optimised directly (see the module docs).
    HarpLike,
    /// Per-vertex colours (see the module docs).
    S2HandLike,
}

/// Settings of a baseline optimisation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BaselineConfig {
    /// Adam iterations.
    pub iterations: usize,
    /// Adam learning rate on the colour logits and the raw light values.
    pub learning_rate: f64,
}

impl Default for BaselineConfig {
    /// 300 iterations at 0.02: both baselines have converged on the training view by then
    /// (their loss changes by less than 1 % over the last 50 iterations on the demo scene).
    fn default() -> Self {
        BaselineConfig {
            iterations: 300,
            learning_rate: 0.02,
        }
    }
}

/// What a baseline produced: compact textures `[3, T]` per hand and its light (in the
/// training camera's frame).
#[derive(Debug, Clone)]
pub struct BaselineResult {
    /// Left and right textures.
    pub textures: [Vec<f32>; 2],
    /// The optimised light.
    pub light: LightValues,
    /// Final `|I_hand - render|`.
    pub final_loss: f64,
}

/// The optimised quantities: colour logits (texels `[2, 3, T]` or vertices `[2, 3, V]`) and
/// the raw light `[1, 12]`.
#[derive(Module, Debug)]
struct Colours {
    logits: Param<Tensor<3>>,
    light: Param<Tensor<2>>,
}

/// Per-texel vertex indices `[3T]` (texel-major) and barycentric weights `[1, T, 3]` of one
/// hand: the texture of an S2Hand-like per-vertex colouring.
struct VertexToTexel {
    index: Tensor<1, Int>,
    weight: Tensor<3>,
}

impl VertexToTexel {
    fn new(trainer: &Trainer, hand: usize, device: &Device) -> Result<Self, EvalError> {
        let layout = &trainer.assets.layouts[hand];
        let faces = &trainer.assets.models.get(bitt_mesh::Side::BOTH[hand]).faces;
        let texel_faces = layout.texel_faces().ok_or_else(|| {
            EvalError::Invalid("the texture layout has no per-texel faces".into())
        })?;
        let t = texel_faces.len();
        let mut index = Vec::with_capacity(3 * t);
        let mut weight = Vec::with_capacity(3 * t);
        for &(f, bary) in texel_faces {
            let face = faces.get(f as usize).ok_or_else(|| {
                EvalError::Invalid(format!("texel face {f} is not a face of the mesh"))
            })?;
            for k in 0..3 {
                index.push(i64::from(face[k]));
                weight.push(bary[k]);
            }
        }
        Ok(VertexToTexel {
            index: Tensor::from_data(TensorData::new(index, [3 * t]), device),
            weight: Tensor::from_data(TensorData::new(weight, [1, t, 3]), device),
        })
    }

    /// Vertex colours `[3, V]` to the texture `[3, T]`.
    fn apply(&self, colours: Tensor<2>) -> Tensor<2> {
        let t = self.weight.dims()[1];
        let picked = colours.select(1, self.index.clone()).reshape([3, t, 3]);
        (picked * self.weight.clone()).sum_dim(2).reshape([3, t])
    }
}

/// Runs `baseline` on the trainer's training view (its image, mask, meshes and camera; the
/// trainer's networks are not used). `device` must be an autodiff device.
pub fn run_baseline(
    trainer: &Trainer,
    baseline: Baseline,
    config: &BaselineConfig,
    device: &Device,
) -> Result<BaselineResult, EvalError> {
    let view = &trainer.view;
    let t = trainer.assets.num_texels();
    let [_, _, h, w] = view.image.dims();
    // The uniform initial colour: the mean colour of the hand pixels.
    let image = to_host(view.image.clone().inner())?;
    let mask = to_host(view.mask.clone().inner())?;
    let covered: f64 = mask.iter().map(|&m| f64::from(m)).sum();
    if covered < 1.0 {
        return Err(EvalError::Invalid(
            "the training view shows no hand pixel".into(),
        ));
    }
    let mean: [f32; 3] = std::array::from_fn(|c| {
        let s: f64 = (0..h * w)
            .map(|p| f64::from(image[c * h * w + p] * mask[p]))
            .sum();
        (s / covered).clamp(0.05, 0.95) as f32
    });
    let logit = mean.map(|m| (m / (1.0 - m)).ln());
    let maps: Option<[VertexToTexel; 2]> = match baseline {
        Baseline::HarpLike => None,
        Baseline::S2HandLike => Some([
            VertexToTexel::new(trainer, 0, device)?,
            VertexToTexel::new(trainer, 1, device)?,
        ]),
    };
    let n = match baseline {
        Baseline::HarpLike => t,
        Baseline::S2HandLike => {
            let nl = trainer.assets.models.left.num_vertices();
            let nr = trainer.assets.models.right.num_vertices();
            if nl != nr {
                return Err(EvalError::Invalid(format!(
                    "the hands have {nl} and {nr} vertices; per-vertex colours need equal counts"
                )));
            }
            nl
        }
    };
    let init: Vec<f32> = (0..2)
        .flat_map(|_| logit.iter().flat_map(|&l| std::iter::repeat_n(l, n)))
        .collect();
    let mut colours = Colours {
        logits: Param::from_tensor(
            Tensor::<3>::from_data(TensorData::new(init, [2, 3, n]), device).require_grad(),
        ),
        light: Param::from_tensor(Tensor::<2>::zeros([1, 12], device).require_grad()),
    };
    let mut adam = Adam::new(OptimConfig {
        learning_rate: config.learning_rate,
        ..OptimConfig::default()
    });
    let textures = |c: &Colours| -> [Tensor<2>; 2] {
        let s = burn::tensor::activation::sigmoid(c.logits.val());
        let hand = |i: usize| s.clone().narrow(0, i, 1).reshape([3, n]);
        match &maps {
            None => [hand(0), hand(1)],
            Some(m) => [m[0].apply(hand(0)), m[1].apply(hand(1))],
        }
    };
    let target = view.hand_image.clone();
    let mut final_loss = f64::NAN;
    for _ in 0..config.iterations {
        let light = point_light(&LightParams::from_raw(colours.light.val()));
        let r = view.geometry.render(
            &trainer.assets,
            textures(&colours),
            &light,
            &trainer.settings,
        )?;
        let loss = (r.image.reshape([1, 3, h, w]) - target.clone())
            .abs()
            .mean();
        let value = f64::from(to_host(loss.clone().inner())?[0]);
        if !value.is_finite() {
            return Err(EvalError::NonFinite(format!(
                "{baseline:?} loss is {value}"
            )));
        }
        final_loss = value;
        let grads = loss.backward();
        colours = adam.step(colours, &grads, config.learning_rate);
    }
    let [l, r] = textures(&colours);
    let light = LightParams::from_raw(colours.light.val());
    let row = |x: &Tensor<2>| -> Result<[f32; 3], EvalError> {
        let v = to_host(x.clone().inner())?;
        Ok([v[0], v[1], v[2]])
    };
    let light = LightValues {
        ambient: row(&light.ambient)?,
        diffuse: row(&light.diffuse)?,
        specular: row(&light.specular)?,
        location: row(&light.location)?,
    };
    Ok(BaselineResult {
        textures: [to_host(l.inner())?, to_host(r.inner())?],
        light,
        final_loss,
    })
}
