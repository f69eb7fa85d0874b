//! The training loss of paper Sec. 3.4 (eq. 6-10).
//!
//! Every `|.|_1` is a mean absolute difference over the elements involved (the reference's
//! `L1Loss`). Differences from the reference implementation, which we do not follow:
//! it adds `0.1 |t̂ - T(h)|` over all texels and an extra `L1(I_albedo, I)` inside the albedo
//! term, and weighs the consistency pairs 0.15 / 0.2 / 0.04 instead of the paper's plain
//! pairwise sum. See `docs/training.md`.

use burn::tensor::Tensor;

use crate::config::LossWeights;
use crate::pipeline::{Outputs, TrainingView};

/// The loss terms of one iteration: the differentiable total and every term's value.
#[derive(Debug, Clone)]
pub struct Loss {
    /// The weighted sum `L` (eq. 10), a one-element tensor.
    pub total: Tensor<1>,
    /// Unweighted terms, in the order of [`LossTerms::NAMES`].
    pub terms: Vec<Tensor<1>>,
}

/// Host values of the loss terms (unweighted) and the weighted total.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossTerms {
    /// `|I - I_fine|`.
    pub rec_fine: f64,
    /// `|I - I_coarse|`.
    pub rec_coarse: f64,
    /// `|I - I_albedo|`.
    pub rec_albedo: f64,
    /// `sum_i |(T(h_i) - t̂_i)(1 - v_i)|` (eq. 7).
    pub nv: f64,
    /// Albedo consistency (eq. 8), 0 when disabled.
    pub alb: f64,
    /// `|t̂_l - t̂_r|` (eq. 9).
    pub sym: f64,
    /// The weighted total.
    pub total: f64,
}

impl LossTerms {
    /// How many terms there are (the total aside). Everything that stores or draws the terms
    /// (the trainer's read-back, the checkpoint's history rows, the loss plot's colours) is
    /// sized by it, so adding a term means editing this type, [`Loss`] and the plot's colours.
    pub const COUNT: usize = 6;

    /// Names of the terms, as in `metrics.json`.
    pub const NAMES: [&'static str; Self::COUNT] =
        ["rec_fine", "rec_coarse", "rec_albedo", "nv", "alb", "sym"];

    /// From a row of [`LossTerms::values`]: the terms in [`LossTerms::NAMES`] order, then the
    /// total (`COUNT + 1` values).
    pub(crate) fn from_row(row: &[f64; Self::COUNT + 1]) -> Self {
        let (terms, total) = row.split_at(Self::COUNT);
        Self::from_values(terms, total[0])
    }

    /// From the values of [`Loss::terms`] and the total.
    pub fn from_values(v: &[f64], total: f64) -> Self {
        LossTerms {
            rec_fine: v[0],
            rec_coarse: v[1],
            rec_albedo: v[2],
            nv: v[3],
            alb: v[4],
            sym: v[5],
            total,
        }
    }

    /// The terms in [`LossTerms::NAMES`] order, then the total.
    pub fn values(&self) -> [f64; Self::COUNT + 1] {
        [
            self.rec_fine,
            self.rec_coarse,
            self.rec_albedo,
            self.nv,
            self.alb,
            self.sym,
            self.total,
        ]
    }

    /// Every value finite.
    pub fn is_finite(&self) -> bool {
        self.values().iter().all(|x| x.is_finite())
    }
}

fn l1<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> Tensor<1> {
    (a - b).abs().mean()
}

/// The range of [`prior_colour_gain`]: a photo's colour may differ from the prior's by a
/// factor of 2 per channel, no more (a seen region that small or that odd says more about
/// the meshes than about the skin).
pub const PRIOR_COLOUR_GAIN_RANGE: [f32; 2] = [0.5, 2.0];

/// One gain per colour channel that brings the prior's colour to the photo's: the seen
/// texels' unwrapped albedo over the prior's values at those texels, summed over both
/// hands, without gradient. A view that shows no texel gives 1: both sums start from one
/// texel's worth of grey (`+1`), which a few seen texels already outweigh.
///
/// # Shapes
/// - output: `[1, 3, 1]`
pub fn prior_colour_gain(outputs: &Outputs, view: &TrainingView) -> Tensor<3> {
    let sums = |t: &[Tensor<3>; 2]| {
        (0..2)
            .map(|i| (t[i].clone().detach() * view.visible[i].clone()).sum_dim(2))
            .reduce(|a, b| a + b)
            .expect("two hands")
            .add_scalar(1.0)
    };
    let [lo, hi] = PRIOR_COLOUR_GAIN_RANGE;
    (sums(&outputs.unwrapped) / sums(&outputs.coarse)).clamp(lo, hi)
}

/// The paper's total loss (eq. 10) for one forward pass.
///
/// - `L_rec = |I - I_fine| + 0.8 |I - I_coarse| + 0.4 |I - I_albedo|` with `I = I_hand`, the
///   input image times the hand mask (the renders are black off the hands), each pixel
///   times the view's weight (1, or 0 at a photo's untrusted pixels:
///   [`TrainingView::trust_photo`]);
/// - `L_nv = sum_i mean |(T(h_i) - t̂_i)(1 - v_i)|`; when the view asks for it (real photos,
///   `loss.photo_prior_colour`) `t̂_i` is held to `T(h_i)` times [`prior_colour_gain`]
///   instead, while `T(h_i)` is still held to `t̂_i`;
/// - `L_alb = sum_{i<j} mean |A(I_coarse,l_i) - A(I_coarse,l_j)|` over the three lights;
/// - `L_sym = mean |t̂_l - t̂_r|`.
pub fn loss(outputs: &Outputs, view: &TrainingView, w: &LossWeights) -> Loss {
    let target = view.hand_image.clone();
    let rec = |render: Tensor<4>| {
        let diff = render - target.clone();
        match &view.weight {
            Some(w) => (diff * w.clone()).abs().mean(),
            None => diff.abs().mean(),
        }
    };
    let rec_fine = rec(outputs.fine_image.clone());
    let rec_coarse = rec(outputs.coarse_image.clone());
    let rec_albedo = rec(outputs.albedo_render.clone());
    let gain = view
        .prior_colour_gain
        .then(|| prior_colour_gain(outputs, view));
    let nv = (0..2)
        .map(|i| {
            let hidden = view.visible[i].clone().neg().add_scalar(1.0);
            let (coarse, fine) = (outputs.coarse[i].clone(), outputs.fine[i].clone());
            match &gain {
                None => ((coarse - fine) * hidden).abs().mean(),
                Some(g) => {
                    // BTR is held to the gained prior, and the prior to BTR as the paper
                    // holds it. Were the prior held to BTR over the gain, the two would feed
                    // each other: a darker prior raises the gain, which asks the prior to be
                    // darker still (measured: the prior went brown and the gain to its end).
                    // The term's value is `|g T(h) - t̂|`; its gradient reaches t̂ through
                    // that and T(h) through `|T(h) - t̂|`.
                    let to_btr = ((coarse.clone().detach() * g.clone() - fine.clone())
                        * hidden.clone())
                    .abs()
                    .mean();
                    let to_prior = ((coarse - fine.detach()) * hidden).abs().mean();
                    to_btr + to_prior.clone() - to_prior.detach()
                }
            }
        })
        .reduce(|a, b| a + b)
        .expect("two hands");
    let alb = match &outputs.consistency_albedos {
        Some(a) => {
            // Each image sliced once: a slice's gradient is a zero-padded copy of the whole
            // batch, so six slices would cost six.
            let [a0, a1, a2] = [0, 1, 2].map(|i| a.clone().narrow(0, i, 1));
            l1(a0.clone(), a1.clone()) + l1(a0, a2.clone()) + l1(a1, a2)
        }
        None => rec_fine.zeros_like(),
    };
    let sym = l1(outputs.fine[0].clone(), outputs.fine[1].clone());
    let total = rec_fine.clone().mul_scalar(w.rec)
        + rec_coarse.clone().mul_scalar(w.rec_coarse)
        + rec_albedo.clone().mul_scalar(w.rec_albedo)
        + nv.clone().mul_scalar(w.nv)
        + alb.clone().mul_scalar(w.alb)
        + sym.clone().mul_scalar(w.sym);
    Loss {
        total,
        terms: vec![rec_fine, rec_coarse, rec_albedo, nv, alb, sym],
    }
}
