//! The trainer's configuration: networks, texture model, schedule and loss weights, with the
//! named presets `paper`, `quick` and `tiny`. Saved next to every run as `config.json`.

use bitt_nets::{BittNetsConfig, Preset};
use bitt_texture::ProceduralTextureConfig;

use crate::TrainError;
use bitt_stdx::FileErrorExt;

/// BTR's widths for `quick` on a real photo ([`TrainConfig::preset_for_photo`]): the `quick`
/// preset's widths until 2026-12-06, when the demo's BTR was narrowed to train in 2 minutes
/// (issue 37). The photo runs train at 256 px and are not held to that.
pub const QUICK_PHOTO_BTR_CHANNELS: [usize; 4] = [8, 16, 32, 64];

/// The largest learning rate a configuration may ask for (Adam steps of this size already
/// destroy the networks; the paper's is 1e-3).
pub(crate) const MAX_LEARNING_RATE: f64 = 1.0;

/// The largest loss weight a configuration may give a term (the paper's are at most 1).
pub(crate) const MAX_LOSS_WEIGHT: f64 = 1e3;

/// The interval a configuration number must lie in, for [`check_field`]: every
/// configuration of the project (training, refinement, keypoint fit) checks its numbers
/// through it, so each refusal names the field and the allowed range the same way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    lo: f64,
    lo_open: bool,
    hi: f64,
    hi_open: bool,
    why: &'static str,
}

impl Bounds {
    /// Finite and above 0.
    pub const POSITIVE: Bounds = Bounds::new(0.0, true, f64::INFINITY, true);
    /// Finite and at least 0.
    pub const NON_NEGATIVE: Bounds = Bounds::new(0.0, false, f64::INFINITY, true);
    /// `[0, 1]`.
    pub const UNIT: Bounds = Bounds::new(0.0, false, 1.0, false);

    /// `lo` to `hi`, each end open or closed.
    pub const fn new(lo: f64, lo_open: bool, hi: f64, hi_open: bool) -> Self {
        Bounds {
            lo,
            lo_open,
            hi,
            hi_open,
            why: "",
        }
    }

    /// The same bounds, with the reason given after the range in a refusal.
    pub const fn because(self, why: &'static str) -> Self {
        Bounds { why, ..self }
    }

    /// Whether `value` lies within (NaN and infinities never do).
    pub fn contains(&self, value: f64) -> bool {
        value.is_finite()
            && if self.lo_open {
                value > self.lo
            } else {
                value >= self.lo
            }
            && if self.hi_open {
                value < self.hi
            } else {
                value <= self.hi
            }
    }
}

impl std::fmt::Display for Bounds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.hi.is_infinite() {
            let op = if self.lo_open { "above" } else { "at least" };
            write!(f, "finite and {op} {}", self.lo)?;
        } else {
            let (l, r) = (
                if self.lo_open { '(' } else { '[' },
                if self.hi_open { ')' } else { ']' },
            );
            write!(f, "in {l}{}, {}{r}", self.lo, self.hi)?;
        }
        if !self.why.is_empty() {
            write!(f, " ({})", self.why)?;
        }
        Ok(())
    }
}

/// Checks one configuration number: `Ok` within `bounds`, else an error naming `field` (its
/// dotted path, `optim.learning_rate`), the value and the allowed range.
///
/// # Errors
/// [`TrainError::Invalid`] when `value` lies outside `bounds` or is not finite.
pub fn check_field(field: &str, value: f64, bounds: Bounds) -> Result<(), TrainError> {
    if bounds.contains(value) {
        Ok(())
    } else {
        Err(TrainError::Invalid(format!(
            "{field} = {value} is out of range: it must be {bounds}"
        )))
    }
}

/// [`check_field`] for several fields of one section: `{section}.{name}` each, all within
/// `bounds`; the first out of range is refused.
///
/// # Errors
/// As [`check_field`].
pub fn check_fields(
    section: &str,
    fields: &[(&str, f64)],
    bounds: Bounds,
) -> Result<(), TrainError> {
    for (name, value) in fields {
        check_field(&format!("{section}.{name}"), *value, bounds)?;
    }
    Ok(())
}

/// Reads a configuration file's `text` as `T`, refusing fields `T` does not have (a typo
/// would otherwise be silently ignored) and naming `path` and the field (`optim.learnig_rate`).
/// Works for any nesting and any derive (the read value is written back and its keys
/// compared), so every configuration file of the project goes through it.
pub fn read_config<T>(text: &str, path: &std::path::Path, what: &str) -> Result<T, TrainError>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let raw: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| TrainError::format(path, format!("not {what}: {e}")))?;
    let value: T = serde_json::from_value(raw.clone())
        .map_err(|e| TrainError::format(path, format!("not {what}: {e}")))?;
    let known = serde_json::to_value(&value)
        .map_err(|e| TrainError::format(path, format!("not {what}: {e}")))?;
    let mut unknown = Vec::new();
    unknown_fields(&raw, &known, "", &mut unknown);
    if !unknown.is_empty() {
        return Err(TrainError::format(
            path,
            format!(
                "unknown field{} {} in {what} (misspelt? the fields are those of a run's \
                 config.json)",
                if unknown.len() == 1 { "" } else { "s" },
                unknown.join(", ")
            ),
        ));
    }
    Ok(value)
}

/// Keys of `raw` (dotted paths below `prefix`) that `known` does not have.
fn unknown_fields(
    raw: &serde_json::Value,
    known: &serde_json::Value,
    prefix: &str,
    out: &mut Vec<String>,
) {
    if let (Some(raw), Some(known)) = (raw.as_object(), known.as_object()) {
        for (k, v) in raw {
            let path = if prefix.is_empty() {
                format!("`{k}`")
            } else {
                format!("`{}.{k}`", prefix.trim_matches('`'))
            };
            match known.get(k) {
                Some(kv) => unknown_fields(v, kv, &path, out),
                None => out.push(path),
            }
        }
    }
}

/// The loss weights of paper Sec. 3.4 (eq. 6-10). Every term is a mean absolute difference
/// (the reference's `L1Loss`, mean reduction).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossWeights {
    /// `lambda_rec` on `|I - I_fine|` (1: the paper gives it no other value).
    pub rec: f64,
    /// `lambda_rec^coarse` on `|I - I_coarse|` (Sec. 3.4: 0.8).
    pub rec_coarse: f64,
    /// `lambda_rec^albedo` on `|I - I_albedo|` (Sec. 3.4: 0.4).
    pub rec_albedo: f64,
    /// `lambda_nv` on `sum_i |(T(h_i) - t_i)(1 - v_i)|` (Sec. 3.4: 0.2).
    pub nv: f64,
    /// `lambda_alb` on the albedo consistency loss (Sec. 3.4: 0.2).
    pub alb: f64,
    /// `lambda_sym` on `|t_l - t_r|` (Sec. 3.4: 0.3).
    pub sym: f64,
    /// Let the albedo consistency loss reach the light and HTML networks through the relit
    /// coarse renders (default `true`, as the paper's Fig. 2 graph and the reference code).
    /// `false` makes the renders constants, so `L_alb` trains only the albedo network; on the
    /// demo scene that measured no better (see `docs/training.md`).
    #[serde(default = "yes")]
    pub alb_through_scene: bool,
    /// Real photos only: the photo is trusted at the pixels whose mean RGB is above this
    /// (the refinement's hand-mask rule, 0.15); where the meshes cover a darker pixel
    /// (background they overhang, or a shadow) the reconstruction losses ignore it and no
    /// texel is unwrapped from it (`TrainingView::trust_photo`). 0 trusts every pixel, as
    /// the paper and the reference do. Not from the paper: it stops background and shadow
    /// from going into the albedo (issue 34).
    #[serde(default = "photo_mask_default")]
    pub photo_mask: f64,
    /// Real photos only: the estimated light has one colour (that of its three parts
    /// together), each part an intensity of it (`LightParams::one_colour`). `false`
    /// gives each part its own colour, as the paper does. Not from the paper: with three
    /// colours the demo photos' green cast went into a green diffuse light over a grey
    /// ambient one, and the albedo took a purple tint that shows as bruise-like blotches at
    /// novel poses (issue 34; docs/results/photos.md).
    #[serde(default = "yes")]
    pub photo_light: bool,
    /// Real photos only: the point light's location is chosen once from the photo's shading
    /// and held there (`bitt_train::light_search`); the colours too with
    /// `photo_light_colours`. `false` lets the network estimate the location, as the paper
    /// does. Not from the paper: on the demo photos, lit from every side, the estimated location ended in
    /// a corner of its box that small changes of the meshes flipped, one corner 2.5 dB worse
    /// at the other photo's pose (issue 34; docs/results/photos.md, The light's location).
    /// A `config.json` written before this option reads `false`, so older runs resume and
    /// render as they were trained.
    #[serde(default)]
    pub photo_light_search: bool,
    /// Real photos only: the light's ambient and diffuse colours come from the same fit as
    /// its location (`bitt_train::light_search`) and are held; the light network is not
    /// used. Needs `photo_light_search`. `false` lets the network estimate the colours, as
    /// the paper does. Not from the paper: on the demo photos the network pushed most of its
    /// nine colour outputs to an end of their range (`0.6 ± 0.4 tanh(1)`), where they have no
    /// gradient left, and which end depended on the seed: the light was another one in
    /// every run, and the run on `01` ended in one of two places, one 1.3 dB worse at the
    /// other photo's pose (issue 34; docs/results/photos.md, The light's colours). A
    /// `config.json` written before this option reads `false`, so older runs resume and
    /// render as they were trained.
    #[serde(default)]
    pub photo_light_colours: bool,
    /// Real photos only: how strongly the scene is shaded with ambient occlusion between and
    /// within the hands (`ViewGeometry::with_occlusion`): every pixel's shaded colour is
    /// scaled by `1 - photo_occlusion (1 - ao)`, in training and in every render of the
    /// avatar. 0 gives the paper's Phong shading, which cannot explain the shadow in a
    /// crease, so the photo's shadows go into the albedo. Not from the paper: issue 34
    /// (shadows in the albedo); HARP shades with shadows, and the BiTT supplement names
    /// self-shadowing as a limit. Off (0) by default: on the demo photos, lit from every side
    /// by the capture rig, the photo is not darker where the meshes' occlusion is, and 0.8
    /// cost 0.9 dB at novel poses (docs/results/photos.md, Shadows). For photos under one
    /// lamp or a window.
    #[serde(default)]
    pub photo_occlusion: f64,
    /// Real photos only: the non-visible term (eq. 7) holds BTR's texture to the prior
    /// times one gain per colour channel: the seen texels' unwrapped albedo over the prior
    /// there, both hands together (`TrainingView::prior_colour_gain`); the prior is still
    /// held to BTR's texture as the paper holds it. `false` (the default) holds BTR's texture
    /// to the prior itself, as the paper does. Not from the paper: on the demo photos the
    /// texture PCA does not reach the person's olive skin (the prior came out about 10 %
    /// redder than the seen albedo), so the texels the photo does not show keep the prior's
    /// orange, which shows as orange fingers at the other photo's pose. With the gain they
    /// take the photo's colour, but the pair's scores fell on average (issue 34;
    /// docs/results/photos.md, The prior's colour), so it is off.
    #[serde(default)]
    pub photo_prior_colour: bool,
}

fn photo_mask_default() -> f64 {
    0.15
}

impl Default for LossWeights {
    fn default() -> Self {
        LossWeights {
            rec: 1.0,
            rec_coarse: 0.8,
            rec_albedo: 0.4,
            nv: 0.2,
            alb: 0.2,
            sym: 0.3,
            alb_through_scene: true,
            photo_mask: photo_mask_default(),
            photo_light: true,
            photo_light_search: true,
            photo_light_colours: true,
            photo_occlusion: 0.0,
            photo_prior_colour: false,
        }
    }
}

fn yes() -> bool {
    true
}

impl LossWeights {
    /// How the forward pass builds the albedo consistency renders for these weights.
    pub fn consistency(&self) -> crate::pipeline::Consistency {
        use crate::pipeline::Consistency;
        if self.alb <= 0.0 {
            Consistency::Off
        } else if self.alb_through_scene {
            Consistency::ThroughScene
        } else {
            Consistency::AlbedoOnly
        }
    }
}

/// Adam and its step schedule (paper Sec. 4.1 and the reference trainer).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OptimConfig {
    /// Initial learning rate (Sec. 4.1: 1e-3).
    pub learning_rate: f64,
    /// Adam beta1 (PyTorch default 0.9).
    pub beta1: f64,
    /// Adam beta2 (PyTorch default 0.999).
    pub beta2: f64,
    /// Adam epsilon (PyTorch default 1e-8).
    pub epsilon: f64,
    /// The learning rate is multiplied by `decay_gamma` every `decay_step` iterations
    /// (Sec. 4.1: halved every 200).
    pub decay_step: usize,
    /// See `decay_step` (0.5).
    pub decay_gamma: f64,
    /// Floor of the learning rate (the reference's `LEARNING_RATE_CLIP`, 1e-5).
    pub min_learning_rate: f64,
}

impl Default for OptimConfig {
    fn default() -> Self {
        OptimConfig {
            learning_rate: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            decay_step: 200,
            decay_gamma: 0.5,
            min_learning_rate: 1e-5,
        }
    }
}

impl OptimConfig {
    /// The learning rate of iteration `i` (0-based), before any NaN back-off.
    pub fn learning_rate_at(&self, i: usize) -> f64 {
        let decays = i.checked_div(self.decay_step).unwrap_or(0);
        (self.learning_rate * self.decay_gamma.powi(decays as i32)).max(self.min_learning_rate)
    }
}

/// Everything a per-scene training run needs besides its input.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TrainConfig {
    /// The preset this configuration started from.
    pub preset: Preset,
    /// The four networks; `nets.image_size` is the side every input image is cropped and
    /// resized to.
    pub nets: BittNetsConfig,
    /// The procedural texture PCA (used when no HTML model is given); its `resolution` is
    /// the UV texture side and its `components` the coefficients per hand of `H`.
    pub texture: ProceduralTextureConfig,
    /// Iterations (Sec. 4.1: 700).
    pub iterations: usize,
    /// Optimiser and schedule.
    pub optim: OptimConfig,
    /// Loss weights.
    pub loss: LossWeights,
    /// Write a checkpoint every this many iterations (and at the end).
    pub checkpoint_every: usize,
    /// Seed of the network initialisation.
    pub seed: u64,
}

impl TrainConfig {
    /// The synthetic scene generator's settings at this configuration's image and texture
    /// sizes (the demo scene's; callers change the novel views, poses or mesh noise).
    pub fn scene_config(&self) -> bitt_synth::SynthConfig {
        bitt_synth::SynthConfig {
            size: self.nets.image_size as u32,
            texture_size: self.texture.resolution,
            ..bitt_synth::SynthConfig::default()
        }
    }

    /// The named configuration.
    ///
    /// - `paper`: the paper's networks at 256 x 256, 700 iterations, 1024 x 1024 textures
    ///   (the size of HTML's UV map) and a 101-component texture PCA (HTML's count).
    /// - `quick`: the CPU demo: 128 x 128 images, 256 x 256 textures, narrower networks
    ///   (`BittNetsConfig::preset`), and the paper's whole schedule (Sec. 4.1: 700
    ///   iterations, the learning rate halved at 200, 400 and 600). At 200 iterations (this
    ///   preset's former length) the fine stage was barely ahead of the coarse one and on
    ///   one machine behind it on the texels symmetry should fix; at 700 it is clearly ahead
    ///   (`docs/training.md`). Compressing the schedule instead (halving every 30) measured
    ///   worse: 54% of the summed step size.
    /// - `tiny`: tests and backend checks.
    pub fn preset(preset: Preset) -> Self {
        let mut nets = BittNetsConfig::preset(preset);
        let (resolution, identities, components, iterations, decay_step, checkpoint_every) =
            match preset {
                Preset::Paper => (1024, 64, 101, 700, 200, 50),
                Preset::Quick => (256, 40, 24, 700, 200, 50),
                Preset::Tiny => (128, 8, 8, 6, 4, 2),
            };
        nets.html.coefficients_per_hand = components;
        TrainConfig {
            preset,
            nets,
            texture: ProceduralTextureConfig {
                resolution,
                identities,
                held_out: 2,
                components,
                ..ProceduralTextureConfig::default()
            },
            iterations,
            optim: OptimConfig {
                decay_step,
                ..OptimConfig::default()
            },
            loss: LossWeights::default(),
            checkpoint_every,
            seed: 0,
        }
    }

    /// The named preset for a real photo: as [`TrainConfig::preset`], but `quick` trains at
    /// the photo's crop size, [`bitt_mesh::annotation::BITT_CROP_SIZE`] (256, the paper's image size,
    /// supplement A) rather than the 128 px the synthetic demo uses, so the avatar keeps the
    /// photo's detail (issue 34). Its texture is already 256 x 256. The step costs about 1.6x
    /// (0.23 -> 0.36 s per iteration on the demo frames, 2 cores); `paper` is at 256 anyway and
    /// `tiny` stays small for tests.
    ///
    /// `quick` on a photo also keeps BTR at [`QUICK_PHOTO_BTR_CHANNELS`], twice the demo's
    /// widths below the stem: on the demo pair the narrower BTR lost 1.3 dB at one novel pose
    /// and 1.2 / 0.3 dB at the input views (`docs/results/photos.md`, Scores).
    ///
    /// And `quick` on a photo trains without the albedo consistency loss (`loss.alb` 0, Sec.
    /// 3.4 gives 0.2). Not from the paper: `L_alb` asks the albedo network for the same output
    /// on the prior's smooth renders under three lights, and `quick`'s quarter-width network
    /// meets that in 700 iterations with a mosaic of 8 px blocks that has lost the photo's
    /// veins and hair, which the unwrap then copies into the texture. Without it the renders
    /// keep more of the photo's detail (`detail` 0.10-0.19 -> 0.14-0.24 at the input views of
    /// the demo pair, seeds 0-3) and score 0.1-0.4 dB higher there, with the novel poses the
    /// same within 0.08 dB where the seed's run lands in the same place (docs/results/photos.md,
    /// Detail). The paper preset keeps the paper's loss.
    pub fn preset_for_photo(preset: Preset) -> Self {
        let mut config = TrainConfig::preset(preset);
        if preset == Preset::Quick {
            config.loss.alb = 0.0;
            config.nets.btr.channels = QUICK_PHOTO_BTR_CHANNELS.to_vec();
            let size = bitt_mesh::annotation::BITT_CROP_SIZE as usize;
            config.nets.image_size = size;
            config.nets.light.image_size = size;
            config.nets.html.image_size = size;
        }
        config
    }

    /// This configuration with `iterations` and `seed` replaced where given (`--iterations`,
    /// `--seed`), checked ([`TrainConfig::validate`]).
    ///
    /// # Errors
    /// As [`TrainConfig::validate`].
    pub fn with_overrides(
        mut self,
        iterations: Option<usize>,
        seed: Option<u64>,
    ) -> Result<Self, TrainError> {
        self.iterations = iterations.unwrap_or(self.iterations);
        self.seed = seed.unwrap_or(self.seed);
        self.validate()?;
        Ok(self)
    }

    /// Checks ranges and that the parts fit together.
    pub fn validate(&self) -> Result<(), TrainError> {
        let bad = |m: String| Err(TrainError::Invalid(m));
        self.nets.validate()?;
        self.texture.validate()?;
        if self.nets.html.coefficients_per_hand != self.texture.components {
            return bad(format!(
                "the HTML network predicts {} coefficients per hand but the texture PCA has {}",
                self.nets.html.coefficients_per_hand, self.texture.components
            ));
        }
        if self.iterations == 0 {
            return bad("iterations must be at least 1".into());
        }
        if self.checkpoint_every == 0 {
            return bad("checkpoint_every must be at least 1".into());
        }
        let o = &self.optim;
        let lr = Bounds::new(0.0, true, MAX_LEARNING_RATE, false).because("the paper's is 1e-3");
        check_field("optim.learning_rate", o.learning_rate, lr)?;
        let below_one = Bounds::new(0.0, false, 1.0, true);
        check_field("optim.beta1", o.beta1, below_one)?;
        check_field("optim.beta2", o.beta2, below_one)?;
        let up_to_one = Bounds::new(0.0, true, 1.0, false);
        check_field("optim.epsilon", o.epsilon, up_to_one)?;
        check_field("optim.decay_gamma", o.decay_gamma, up_to_one)?;
        let floor =
            Bounds::new(0.0, false, o.learning_rate, false).because("at most the learning rate");
        check_field("optim.min_learning_rate", o.min_learning_rate, floor)?;
        let w = &self.loss;
        let weight = Bounds::new(0.0, false, MAX_LOSS_WEIGHT, false);
        let terms = [
            ("rec", w.rec),
            ("rec_coarse", w.rec_coarse),
            ("rec_albedo", w.rec_albedo),
            ("nv", w.nv),
            ("alb", w.alb),
            ("sym", w.sym),
        ];
        check_fields("loss", &terms, weight)?;
        check_field("loss.photo_mask", w.photo_mask, Bounds::UNIT)?;
        check_field("loss.photo_occlusion", w.photo_occlusion, Bounds::UNIT)?;
        if w.photo_light_colours && !w.photo_light_search {
            return bad(
                "loss.photo_light_colours needs loss.photo_light_search: the colours are \
                 fitted at the location the search chooses"
                    .into(),
            );
        }
        Ok(())
    }

    /// Reads a `config.json`: unknown fields and out-of-range values are refused, naming
    /// the file and the field.
    pub fn from_json(text: &str, path: &std::path::Path) -> Result<Self, TrainError> {
        let c: TrainConfig = read_config(text, path, "a training config")?;
        c.validate()
            .map_err(|e| TrainError::format(path, e.to_string()))?;
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate_and_round_trip_through_json() {
        for p in Preset::ALL {
            let c = TrainConfig::preset(p);
            c.validate().unwrap();
            let text = serde_json::to_string(&c).unwrap();
            let back = TrainConfig::from_json(&text, std::path::Path::new("c.json")).unwrap();
            assert_eq!(serde_json::to_string(&back).unwrap(), text);
        }
        let paper = TrainConfig::preset(Preset::Paper);
        assert_eq!(paper.iterations, 700);
        assert_eq!(paper.nets.html.coefficients_per_hand, 101);
    }

    #[test]
    fn photos_train_quick_at_their_crop_size() {
        let photo = TrainConfig::preset_for_photo(Preset::Quick);
        photo.validate().unwrap();
        assert_eq!(photo.nets.image_size, 256);
        assert_eq!(photo.nets.light.image_size, 256);
        assert_eq!(photo.nets.html.image_size, 256);
        assert_eq!(photo.texture.resolution, 256);
        assert_eq!(photo.nets.btr.channels, QUICK_PHOTO_BTR_CHANNELS);
        assert_eq!(photo.loss.alb, 0.0);
        let demo = TrainConfig::preset(Preset::Quick);
        assert_eq!(demo.loss.alb, 0.2);
        assert_eq!(demo.nets.image_size, 128);
        assert_eq!(demo.nets.btr.channels, [8, 8, 16, 32]);
        for p in [Preset::Paper, Preset::Tiny] {
            let (a, b) = (TrainConfig::preset_for_photo(p), TrainConfig::preset(p));
            assert_eq!(
                serde_json::to_value(a).unwrap(),
                serde_json::to_value(b).unwrap()
            );
        }
    }

    #[test]
    fn schedule_halves_every_decay_step_down_to_the_floor() {
        let o = OptimConfig::default();
        assert_eq!(o.learning_rate_at(0), 1e-3);
        assert_eq!(o.learning_rate_at(199), 1e-3);
        assert_eq!(o.learning_rate_at(200), 5e-4);
        assert_eq!(o.learning_rate_at(699), 1.25e-4);
        assert_eq!(o.learning_rate_at(200 * 20), 1e-5);
    }

    /// The occlusion strength and the photo mask are refused outside [0, 1], naming the
    /// field; a config written before the occlusion existed reads as 0 (those runs were
    /// trained without it), the prior's colour gain is off unless asked for, and the light's
    /// colours are held only with the location search.
    #[test]
    fn photo_shading_fields_are_checked_and_old_configs_keep_phong() {
        let mut c = TrainConfig::preset(Preset::Quick);
        assert_eq!(c.loss.photo_occlusion, 0.0);
        for (occlusion, mask) in [(1.5, 0.15), (-0.1, 0.15), (f64::NAN, 0.15), (0.5, 2.0)] {
            c.loss.photo_occlusion = occlusion;
            c.loss.photo_mask = mask;
            let e = c.validate().unwrap_err().to_string();
            let field = if mask > 1.0 {
                "photo_mask"
            } else {
                "photo_occlusion"
            };
            assert!(e.contains(field) && e.contains("[0, 1]"), "{e}");
        }
        let mut value = serde_json::to_value(TrainConfig::preset(Preset::Quick)).unwrap();
        value["loss"]
            .as_object_mut()
            .unwrap()
            .remove("photo_occlusion");
        let old =
            TrainConfig::from_json(&value.to_string(), std::path::Path::new("c.json")).unwrap();
        assert_eq!(old.loss.photo_occlusion, 0.0);
        // The prior's colour gain is off unless asked for, also in a config from before it.
        assert!(!TrainConfig::preset(Preset::Quick).loss.photo_prior_colour);
        value["loss"]
            .as_object_mut()
            .unwrap()
            .remove("photo_prior_colour");
        let old =
            TrainConfig::from_json(&value.to_string(), std::path::Path::new("c.json")).unwrap();
        assert!(!old.loss.photo_prior_colour);
        // The light's colours are held by default, refused without the location search
        // they are fitted with, and a config from before them lets the network give them.
        let mut c = TrainConfig::preset(Preset::Quick);
        assert!(c.loss.photo_light_search && c.loss.photo_light_colours);
        c.loss.photo_light_search = false;
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("photo_light_colours needs loss.photo_light_search"),
            "{e}"
        );
        c.loss.photo_light_colours = false;
        c.validate().unwrap();
        value["loss"]
            .as_object_mut()
            .unwrap()
            .remove("photo_light_colours");
        let old =
            TrainConfig::from_json(&value.to_string(), std::path::Path::new("c.json")).unwrap();
        assert!(!old.loss.photo_light_colours);
    }

    /// Every configuration's numbers are refused the same way: the field, the value and the
    /// range, open and closed ends told apart, NaN and infinities never inside.
    #[test]
    fn bounds_name_the_field_and_the_range() {
        let e = |f, v, b| check_field(f, v, b).unwrap_err().to_string();
        assert_eq!(
            e("a.b", -1.0, Bounds::POSITIVE),
            "a.b = -1 is out of range: it must be finite and above 0"
        );
        assert_eq!(
            e("w", f64::INFINITY, Bounds::NON_NEGATIVE),
            "w = inf is out of range: it must be finite and at least 0"
        );
        assert_eq!(
            e("m", 1.5, Bounds::UNIT),
            "m = 1.5 is out of range: it must be in [0, 1]"
        );
        let b = Bounds::new(0.0, false, 1.0, true).because("Adam's");
        assert_eq!(
            e("beta", 1.0, b),
            "beta = 1 is out of range: it must be in [0, 1) (Adam's)"
        );
        assert!(check_field("beta", 0.0, b).is_ok());
        assert!(check_field("p", 0.0, Bounds::POSITIVE).is_err());
        assert!(check_field("p", f64::NAN, Bounds::UNIT).is_err());
        assert!(check_field("p", 0.0, Bounds::NON_NEGATIVE).is_ok());
    }

    #[test]
    fn mismatched_coefficients_are_rejected() {
        let mut c = TrainConfig::preset(Preset::Tiny);
        c.texture.components = 5;
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("coefficients")
        );
    }
}
