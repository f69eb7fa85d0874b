//! The BiTT forward pass (paper Fig. 2, Sec. 3.1-3.3): scene estimation, coarse stage and fine
//! stage on one training view, with every image the losses need.

use bitt_render::scene::LightValuesExt;

use bitt_nets::{BittNets, LightParams, compose_texels};
use bitt_render::scene::{PointLight, RenderSettings, UnwrapPlan, UnwrapSettings};
use bitt_stdx::to_host;
use bitt_texture::TexturePcaTensors;
use burn::tensor::{Device, Tensor, TensorData};

use crate::TrainError;
use crate::assets::{HandAssets, ViewGeometry};

/// The fixed inputs of one training view on the training device: the image `I`, the hand
/// mask, the hand image `I_hand = I * mask`, and where each texel lands in the image.
#[derive(Debug, Clone)]
pub struct TrainingView {
    /// Geometry of the view.
    pub geometry: ViewGeometry,
    /// The input image `I`, `[1, 3, S, S]`.
    pub image: Tensor<4>,
    /// The two-hand mask, `[1, 1, S, S]` in `{0, 1}`.
    pub mask: Tensor<4>,
    /// `I * mask`, `[1, 3, S, S]`.
    pub hand_image: Tensor<4>,
    /// Unwrap plans, left then right.
    pub plans: [UnwrapPlan; 2],
    /// Visible masks `v_i` `[1, 1, T]`, left then right.
    pub visible: [Tensor<3>; 2],
    /// Per-pixel weight of the reconstruction losses, `[1, 1, S, S]`: 1, except 0 where a
    /// photo's pixel is not trusted ([`TrainingView::trust_photo`]); `None` (every pixel 1,
    /// no multiply in the loss) until then.
    pub weight: Option<Tensor<4>>,
    /// The view is a photograph whose light has one colour: the forward pass uses
    /// [`LightParams::one_colour`] (`loss.photo_light`, real photos only). `false`: the
    /// paper's three light colours.
    pub one_colour_light: bool,
    /// Where the forward pass holds the point light (camera frame, metres) instead of the
    /// light network's location ([`TrainingView::light_colours`] holds the colours). `None`:
    /// the network's location, as the paper does. Real photos set it from
    /// [`Trainer::search_light_location`](crate::trainer::Trainer::search_light_location)
    /// (`loss.photo_light_search`).
    pub light_location: Option<[f32; 3]>,
    /// The ambient and diffuse colours the forward pass holds instead of the light
    /// network's (the specular part is held at 0: the material has none). `None`: the
    /// network's colours, as the paper does. Real photos set them from the same search as
    /// [`TrainingView::light_location`] (`loss.photo_light_colours`); with both set the
    /// light network is not used.
    pub light_colours: Option<[[f32; 3]; 2]>,
    /// The non-visible term compares BTR's texture with the prior times one gain per colour
    /// channel, the seen texels' colour over the prior's there ([`crate::losses`],
    /// `loss.photo_prior_colour`, real photos only). `false`: the prior as it is, as the
    /// paper does.
    pub prior_colour_gain: bool,
}

impl TrainingView {
    /// Prepares a view from its image `[3, S, S]` (values in `[0, 1]`, channel-major) and an
    /// optional mask `[S, S]`; without a mask, the silhouette of the given meshes is used
    /// (as the reference does).
    pub fn new(
        assets: &HandAssets,
        geometry: ViewGeometry,
        image: &[f32],
        mask: Option<&[f32]>,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let [h, w] = geometry.size();
        if image.len() != 3 * h * w {
            return Err(TrainError::Invalid(format!(
                "image has {} values; the camera needs 3 x {h} x {w}",
                image.len()
            )));
        }
        if let Some(i) = image.iter().position(|v| !v.is_finite()) {
            return Err(TrainError::Invalid(format!(
                "image value {i} is {}",
                image[i]
            )));
        }
        // The raster of both hands: depth buffer for unwrapping, silhouette for the mask.
        let light = bitt_render::scene::LightValues::default().to_light(device);
        let t = assets.num_texels();
        let zeros = Tensor::<2>::zeros([3, t], device);
        let settings = RenderSettings {
            antialias: false,
            ..RenderSettings::default()
        };
        let silhouette = geometry.render(assets, [zeros.clone(), zeros], &light, &settings)?;
        let unwrap = UnwrapSettings::default();
        let plan = |i: usize| {
            UnwrapPlan::new(
                &geometry.camera,
                &assets.surfaces[i],
                &geometry.vertices_host[i],
                &silhouette.raster,
                &unwrap,
            )
        };
        let plans = [plan(0)?, plan(1)?];
        let mask = match mask {
            Some(m) => {
                if m.len() != h * w {
                    return Err(TrainError::Invalid(format!(
                        "mask has {} values; the image is {h} x {w}",
                        m.len()
                    )));
                }
                let m: Vec<f32> = m.iter().map(|&v| if v > 0.5 { 1.0 } else { 0.0 }).collect();
                Tensor::<4>::from_data(TensorData::new(m, [1, 1, h, w]), device)
            }
            None => {
                let [l, r] = [silhouette.masks[0].clone(), silhouette.masks[1].clone()];
                (l + r).clamp(0.0, 1.0).reshape([1, 1, h, w])
            }
        };
        let image = Tensor::<4>::from_data(TensorData::new(image.to_vec(), [1, 3, h, w]), device);
        let hand_image = image.clone() * mask.clone();
        let visible = |p: &UnwrapPlan| {
            let v: Vec<f32> = p
                .visible()
                .iter()
                .map(|&b| if b { 1.0 } else { 0.0 })
                .collect();
            Tensor::<3>::from_data(TensorData::new(v, [1, 1, t]), device)
        };
        let visible = [visible(&plans[0]), visible(&plans[1])];
        Ok(TrainingView {
            geometry,
            image,
            weight: None,
            one_colour_light: false,
            prior_colour_gain: false,
            light_location: None,
            light_colours: None,
            mask,
            hand_image,
            plans,
            visible,
        })
    }

    /// Trusts the photo only at the pixels `keep` `[S * S]` (its hand pixels, for example mean
    /// RGB above a threshold): where the meshes cover a pixel that is not kept (background
    /// the mesh overhangs, or a shadow too dark to tell the skin) the reconstruction losses
    /// stop pulling the renders towards it, and no texel is unwrapped from it (it becomes
    /// not visible, so the coarse texture and BTR fill it). Returns the texels dropped per
    /// hand and the fraction of the meshes' pixels kept. A hand that would be left without a
    /// visible texel keeps its texels; a mask that keeps none of the meshes' pixels changes
    /// nothing.
    ///
    /// # Errors
    /// A mask of another size than the view's.
    pub fn trust_photo(&mut self, keep: &[bool]) -> Result<PhotoTrust, TrainError> {
        let [_, _, h, w] = self.mask.dims();
        if keep.len() != h * w {
            return Err(TrainError::Invalid(format!(
                "the photo mask has {} values; the view is {h} x {w}",
                keep.len()
            )));
        }
        let drawn = to_host(self.mask.clone().inner())?;
        let on_mesh = drawn.iter().filter(|&&m| m > 0.5).count();
        let kept = drawn
            .iter()
            .zip(keep)
            .filter(|&(&m, &k)| m > 0.5 && k)
            .count();
        let fraction = kept as f64 / on_mesh.max(1) as f64;
        if kept == 0 {
            // A photo dark all over the hands: nothing to trust, nothing changed.
            return Ok(PhotoTrust {
                applied: false,
                dropped: [0, 0],
                mesh_pixels_kept: fraction,
            });
        }
        let device = self.image.device();
        let mut dropped = [0, 0];
        for (i, dropped) in dropped.iter_mut().enumerate() {
            let mut plan = self.plans[i].clone();
            let n = plan.restrict(keep)?;
            // A hand the restriction would leave without a visible texel keeps its own.
            if plan.visible().iter().any(|&v| v) {
                let t = plan.num_texels();
                let v: Vec<f32> = plan
                    .visible()
                    .iter()
                    .map(|&b| f32::from(u8::from(b)))
                    .collect();
                self.visible[i] = Tensor::<3>::from_data(TensorData::new(v, [1, 1, t]), &device);
                self.plans[i] = plan;
                *dropped = n;
            }
        }
        let weight: Vec<f32> = drawn
            .iter()
            .zip(keep)
            .map(|(&m, &k)| if m > 0.5 && !k { 0.0 } else { 1.0 })
            .collect();
        self.weight = Some(Tensor::<4>::from_data(
            TensorData::new(weight, [1, 1, h, w]),
            &device,
        ));
        Ok(PhotoTrust {
            applied: true,
            dropped,
            mesh_pixels_kept: fraction,
        })
    }
}

/// What [`TrainingView::trust_photo`] did.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotoTrust {
    /// False when it changed nothing (the mask keeps none of the meshes' pixels).
    pub applied: bool,
    /// Visible texels dropped, left then right (0 for a hand that would have had none left,
    /// which keeps its own).
    pub dropped: [usize; 2],
    /// The fraction of the meshes' pixels the photo mask keeps.
    pub mesh_pixels_kept: f64,
}

impl TrainingView {
    /// Fraction of visible texels per hand.
    pub fn visible_fraction(&self) -> [f64; 2] {
        let f = |p: &UnwrapPlan| {
            p.visible().iter().filter(|&&v| v).count() as f64 / p.num_texels().max(1) as f64
        };
        [f(&self.plans[0]), f(&self.plans[1])]
    }
}

/// The scene light as the renderer's point light, from the light network's values.
pub fn point_light(light: &LightParams) -> PointLight {
    let row = |t: &Tensor<2>| t.clone().reshape([3]);
    PointLight {
        ambient: row(&light.ambient),
        diffuse: row(&light.diffuse),
        specular: row(&light.specular),
        location: row(&light.location),
    }
}

/// The two novel lights of the albedo consistency loss (supplement E): light 1 from below
/// at half the brightness of white light; light 2 as light 1 with the estimated light's
/// colour. "Below" is `+y` of the camera frame (image rows grow downwards), 1 m away, and
/// the diffuse and specular parts are the reference's relighting values (0.3, 0.2).
pub(crate) fn consistency_lights(estimated: &PointLight) -> [PointLight; 2] {
    let device = estimated.ambient.device();
    let c = |v: [f32; 3]| Tensor::<1>::from_data(TensorData::new(v.to_vec(), [3]), &device);
    let below = c([0.0, 1.0, 0.0]);
    let white = PointLight {
        ambient: c([0.5; 3]),
        diffuse: c([0.3; 3]),
        specular: c([0.2; 3]),
        location: below,
    };
    let coloured = PointLight {
        ambient: estimated.ambient.clone(),
        ..white.clone()
    };
    [white, coloured]
}

/// How the albedo consistency renders enter the forward pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Consistency {
    /// No consistency renders (`lambda_alb = 0`).
    Off,
    /// The relit coarse renders are constants: `L_alb` trains only the albedo network `A`.
    AlbedoOnly,
    /// The relit coarse renders keep their graph, so `L_alb` also reaches the light and HTML
    /// networks (the reference implementation).
    ThroughScene,
}

/// Everything one forward pass produces (batch 1; compact textures are `[1, 3, T]`).
#[derive(Debug, Clone)]
pub struct Outputs {
    /// The estimated light `l̂ = L(I)`.
    pub light: PointLight,
    /// The albedo image `A(I_hand)`, `[1, 3, S, S]`.
    pub albedo_image: Tensor<4>,
    /// Texture PCA coefficients `h_l, h_r`, `[1, K]` each.
    pub coefficients: [Tensor<2>; 2],
    /// Coarse textures `T(h_i)`, `[1, 3, T]`.
    pub coarse: [Tensor<3>; 2],
    /// Unwrapped visible albedo texels `u_i`, `[1, 3, T]` (zero where not visible).
    pub unwrapped: [Tensor<3>; 2],
    /// BTR inputs `t_i = T(h_i)(1 - v_i) + u_i`, `[1, 3, T]`.
    pub composed: [Tensor<3>; 2],
    /// Fine textures `t̂_i`, `[1, 3, T]`.
    pub fine: [Tensor<3>; 2],
    /// `I_fine`: the fine textures under `l̂`, `[1, 3, S, S]`.
    pub fine_image: Tensor<4>,
    /// `I_coarse`: the coarse textures under `l̂`.
    pub coarse_image: Tensor<4>,
    /// `I_albedo`: the visible albedo texels under `l̂`.
    pub albedo_render: Tensor<4>,
    /// `A(I_coarse, l)` for the three lights (estimated, white below, coloured below),
    /// masked by the hand mask; `[3, 3, S, S]`. `None` when the consistency weight is 0.
    pub consistency_albedos: Option<Tensor<4>>,
}

/// One forward pass of BiTT on a training view (paper Fig. 2).
///
/// `L(I)` gives the light; `H(I_hand)` the coarse textures `T(h_i)`; the coarse textures are
/// rendered under the estimated light and the two consistency lights; the albedo network
/// runs once on the batch `[I_hand, I_coarse under 3 lights]`; the albedo image is unwrapped
/// to `u_i`, composed with `T(h_i)` and refined by BTR; `I_fine` and `I_albedo` are rendered
/// under the estimated light.
#[allow(clippy::too_many_arguments)]
pub fn forward(
    nets: &BittNets,
    pca: &TexturePcaTensors,
    assets: &HandAssets,
    view: &TrainingView,
    settings: &RenderSettings,
    consistency: Consistency,
) -> Result<Outputs, TrainError> {
    let with_consistency = consistency != Consistency::Off;
    let [_, _, h, w] = view.image.dims();
    let device = view.image.device();
    let held = |v: [f32; 3]| Tensor::from_data(TensorData::new(v.to_vec(), [3]), &device);
    let estimated = || {
        let light = nets.light.predict(view.image.clone());
        point_light(&if view.one_colour_light {
            light.one_colour()
        } else {
            light
        })
    };
    let location = view.light_location.map(held);
    let light = match view.light_colours {
        // Held colours: the light network runs only for a location nothing holds.
        Some([ambient, diffuse]) => PointLight {
            ambient: held(ambient),
            diffuse: held(diffuse),
            specular: held([0.0; 3]),
            location: location.unwrap_or_else(|| estimated().location),
        },
        None => {
            let mut light = estimated();
            if let Some(location) = location {
                light.location = location;
            }
            light
        }
    };
    let coeffs = nets.html.predict(view.hand_image.clone());
    let t = assets.num_texels();
    let coarse_both = pca.textures(Tensor::cat(
        vec![coeffs.left.clone(), coeffs.right.clone()],
        0,
    ));
    let coarse = [
        coarse_both.clone().narrow(0, 0, 1),
        coarse_both.narrow(0, 1, 1),
    ];
    let compact = |x: &Tensor<3>| x.clone().reshape([3, t]);
    let render_with =
        |textures: [Tensor<3>; 2], light: &PointLight| -> Result<Tensor<4>, TrainError> {
            let image = view.geometry.render_image(
                assets,
                [compact(&textures[0]), compact(&textures[1])],
                light,
                settings,
            )?;
            Ok(image.reshape([1, 3, h, w]))
        };
    let coarse_image = render_with(coarse.clone(), &light)?;
    let mut albedo_batch = vec![view.hand_image.clone()];
    if with_consistency {
        let scene_graph = consistency == Consistency::ThroughScene;
        let keep = |x: Tensor<4>| if scene_graph { x } else { x.detach() };
        let (coarse_c, light_c) = if scene_graph {
            (coarse.clone(), light.clone())
        } else {
            (coarse.clone().map(Tensor::detach), light.detach())
        };
        albedo_batch.push(keep(coarse_image.clone()));
        for l in consistency_lights(&light_c) {
            albedo_batch.push(render_with(coarse_c.clone(), &l)?);
        }
    }
    let albedos = nets.albedo.forward(Tensor::cat(albedo_batch, 0));
    let albedo_image = albedos.clone().narrow(0, 0, 1);
    let consistency_albedos = with_consistency.then(|| albedos.narrow(0, 1, 3) * view.mask.clone());
    let albedo_chw = albedo_image.clone().reshape([3, h, w]);
    let unwrap = |i: usize| -> Result<Tensor<3>, TrainError> {
        Ok(view.plans[i]
            .apply(albedo_chw.clone())?
            .texels
            .reshape([1, 3, t]))
    };
    let unwrapped = [unwrap(0)?, unwrap(1)?];
    let composed = [
        compose_texels(
            coarse[0].clone(),
            unwrapped[0].clone(),
            view.visible[0].clone(),
        ),
        compose_texels(
            coarse[1].clone(),
            unwrapped[1].clone(),
            view.visible[1].clone(),
        ),
    ];
    let out = nets.btr.forward(composed[0].clone(), composed[1].clone());
    let fine = [out.left, out.right];
    let fine_image = render_with(fine.clone(), &light)?;
    let albedo_render = render_with(unwrapped.clone(), &light)?;
    Ok(Outputs {
        light,
        albedo_image,
        coefficients: [coeffs.left, coeffs.right],
        coarse,
        unwrapped,
        composed,
        fine,
        fine_image,
        coarse_image,
        albedo_render,
        consistency_albedos,
    })
}
