//! Ground-truth skin textures: the procedural skin of an identity, plus one-sided details.
//!
//! Both hands get [`generate_texture`] of the same [`SkinIdentity`] (mirror-symmetric except
//! for the generator's own asymmetry noise and unmirrored moles). On top of that every scene
//! puts a few details on **one** hand only, so that symmetry helps but is not the whole truth:
//! a mole on the back of the hand or a finger, a healed scar (a thin, lighter, pinker line),
//! and a tan line (a paler band left by a ring on the ring finger or a watch at the wrist).
//! They are painted in texture space at the texels' rest-pose 3D points (right-hand frame; texel
//! `i` is the same spot on both hands), so they are round and straight on the hand, not in UV.
//!
//! Before the details, both hands get the same **personal appearance** ([`AppearancePatch`]):
//! smooth, centimetre-sized patches of darker or lighter skin (uneven tan, dry or sun-exposed
//! areas) and of redness (cold fingertips, chapped knuckles) at random places. Real people have
//! them and a texture PCA of other people cannot know where (HTML's reconstructions are
//! smooth averages, paper Fig. 1); they are what the image, and through symmetry the other
//! hand, must supply, so they make the coarse (PCA) texture imperfect in the way HTML is.

use bitt_mesh::glam::DVec3;
use bitt_mesh::{HandPair, Side};
use bitt_texture::procedural::noise::{SplitMix64, smoothstep};
use bitt_texture::{SkinIdentity, TextureLayout, generate_texture};

use crate::SynthError;

/// Gutter ring (texels) around the UV charts of the textures, as `bitt render` uses.
pub const TEXTURE_GUTTER: usize = 2;

/// Per-hand texture layouts of the procedural hand pair at `texture_size` (each hand's own UV
/// faces, with the [`TEXTURE_GUTTER`]); the texel order is identical on both hands.
///
/// # Errors
/// A size outside 64..=2048, a model without a UV layout, or layouts whose texels differ.
pub fn texture_layouts(
    models: &HandPair,
    texture_size: usize,
) -> Result<[TextureLayout; 2], SynthError> {
    if !(64..=2048).contains(&texture_size) {
        return Err(SynthError::Config(format!(
            "texture_size must be between 64 and 2048 (got {texture_size})"
        )));
    }
    let layout = |side: Side| -> Result<TextureLayout, SynthError> {
        let model = models.get(side);
        let uv = model.uv.as_ref().ok_or_else(|| {
            SynthError::Generate(format!(
                "the {side} hand model ({}) has no UV layout",
                model.source
            ))
        })?;
        Ok(TextureLayout::from_uv(
            uv,
            texture_size,
            texture_size,
            TEXTURE_GUTTER,
        )?)
    };
    let layouts = [layout(Side::Left)?, layout(Side::Right)?];
    if layouts[0].texels != layouts[1].texels {
        return Err(SynthError::Generate(format!(
            "the left and right UV layouts have different texels ({} vs {}); one texel order \
             must serve both hands",
            layouts[0].num_texels(),
            layouts[1].num_texels()
        )));
    }
    Ok(layouts)
}

/// What a one-sided detail is.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DetailKind {
    /// A dark round mole of `radius` metres.
    Mole {
        /// Radius (metres).
        radius: f64,
    },
    /// A healed scar: a line of `length` metres along `direction`, `width` wide.
    Scar {
        /// Direction of the line (rest right-hand frame, unit).
        direction: [f64; 3],
        /// Length (metres).
        length: f64,
        /// Width (metres).
        width: f64,
    },
    /// A paler band left by a ring on the ring finger's proximal phalanx.
    RingTan {
        /// Width of the band (metres).
        width: f64,
    },
    /// A paler band left by a watch around the wrist.
    WatchTan {
        /// Width of the band (metres).
        width: f64,
    },
}

/// A detail painted on one hand only.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SkinDetail {
    /// The hand that has it.
    pub side: Side,
    /// Its centre on the rest right hand (metres, MANO frame; the left hand's spot is the
    /// same texel).
    pub centre: [f64; 3],
    /// What it is.
    pub kind: DetailKind,
    /// Strength in `(0, 1]`.
    pub strength: f64,
}

/// What a personal appearance patch changes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PatchKind {
    /// Brightness: the colour is scaled by `1 + amount` at the centre (negative: darker).
    Tone {
        /// Relative change of brightness at the centre.
        amount: f64,
    },
    /// Redness: red up, green and blue down by `amount` (relative) at the centre.
    Redness {
        /// Strength at the centre (`> 0`).
        amount: f64,
    },
}

/// A smooth patch of personal appearance, the same on both hands (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AppearancePatch {
    /// Centre on the rest right hand (metres, MANO frame).
    pub centre: [f64; 3],
    /// Gaussian radius (metres): the effect falls to `exp(-1/2)` at this distance.
    pub radius: f64,
    /// What it changes.
    pub kind: PatchKind,
}

/// Tone patches per identity.
const TONE_PATCHES: usize = 10;
/// Redness patches per identity.
const REDNESS_PATCHES: usize = 8;

/// Draws an identity's personal appearance: [`TONE_PATCHES`] tone patches (radius 8-20 mm,
/// brightness ±8-20 %) and [`REDNESS_PATCHES`] redness patches (radius 6-14 mm, strength
/// 8-25 %), centred at random texels (`points`: rest right-hand texel points, roughly uniform
/// over the surface).
pub(crate) fn draw_appearance(points: &[DVec3], rng: &mut SplitMix64) -> Vec<AppearancePatch> {
    let pick = |rng: &mut SplitMix64| points[(rng.next_u64() % points.len() as u64) as usize];
    let mut out = Vec::with_capacity(TONE_PATCHES + REDNESS_PATCHES);
    for _ in 0..TONE_PATCHES {
        let centre = pick(rng).to_array();
        let radius = rng.range(0.008, 0.020);
        let magnitude = rng.range(0.08, 0.20);
        let amount = if rng.next_f64() < 0.5 {
            -magnitude
        } else {
            magnitude
        };
        out.push(AppearancePatch {
            centre,
            radius,
            kind: PatchKind::Tone { amount },
        });
    }
    for _ in 0..REDNESS_PATCHES {
        let centre = pick(rng).to_array();
        let radius = rng.range(0.006, 0.014);
        out.push(AppearancePatch {
            centre,
            radius,
            kind: PatchKind::Redness {
                amount: rng.range(0.08, 0.25),
            },
        });
    }
    out
}

/// Paints the personal appearance onto a compact texture `[3, T]` (`points`: the rest
/// right-hand point of each texel). Brightness and redness factors of overlapping patches
/// multiply.
fn paint_appearance(texture: &mut [f32], points: &[DVec3], patches: &[AppearancePatch]) {
    let t = points.len();
    for (i, p) in points.iter().enumerate() {
        let mut factor = [1.0f64; 3];
        for patch in patches {
            let d2 = (*p - DVec3::from_array(patch.centre)).length_squared();
            let r2 = patch.radius * patch.radius;
            if d2 > 9.0 * r2 {
                continue;
            }
            let w = (-0.5 * d2 / r2).exp();
            match patch.kind {
                PatchKind::Tone { amount } => {
                    for f in &mut factor {
                        *f *= 1.0 + amount * w;
                    }
                }
                PatchKind::Redness { amount } => {
                    let a = amount * w;
                    factor[0] *= 1.0 + 0.35 * a;
                    factor[1] *= 1.0 - a;
                    factor[2] *= 1.0 - 0.8 * a;
                }
            }
        }
        for (ch, f) in factor.iter().enumerate() {
            let v = &mut texture[ch * t + i];
            *v = (*v * *f as f32).clamp(0.0, 1.0);
        }
    }
}

/// Rest-pose landmarks of the right hand used to place details.
struct Landmarks {
    wrist: DVec3,
    /// MCP of index, middle, ring, pinky.
    mcp: [DVec3; 4],
    ring_pip: DVec3,
}

impl Landmarks {
    fn new(models: &HandPair) -> Self {
        let j = models.right.regress_joints(&models.right.v_template);
        Landmarks {
            wrist: j[0],
            mcp: [j[1], j[4], j[10], j[7]],
            ring_pip: j[11],
        }
    }
}

/// Draws the one-sided details of a scene: one mole, one scar and one tan line, each on a
/// random hand, placed among `points` (rest right-hand texel points).
pub(crate) fn draw_details(
    models: &HandPair,
    points: &[DVec3],
    rng: &mut SplitMix64,
) -> Result<Vec<SkinDetail>, SynthError> {
    let lm = Landmarks::new(models);
    let knuckles = lm.mcp.iter().sum::<DVec3>() / 4.0;
    // The back of the hand: between the wrist and the knuckles, on the +y side.
    let back: Vec<DVec3> = points
        .iter()
        .copied()
        .filter(|p| {
            let along = (p.x - lm.wrist.x) / (knuckles.x - lm.wrist.x);
            (0.2..0.85).contains(&along) && p.y > knuckles.y + 0.006
        })
        .collect();
    if back.is_empty() {
        return Err(SynthError::Generate(
            "no texel on the back of the hand to place a detail on".into(),
        ));
    }
    let side = |rng: &mut SplitMix64| {
        if rng.next_f64() < 0.5 {
            Side::Left
        } else {
            Side::Right
        }
    };
    let pick = |rng: &mut SplitMix64| back[(rng.next_u64() % back.len() as u64) as usize];
    let mut out = Vec::new();
    let mole_at = pick(rng);
    out.push(SkinDetail {
        side: side(rng),
        centre: mole_at.to_array(),
        kind: DetailKind::Mole {
            radius: rng.range(0.0012, 0.0024),
        },
        strength: rng.range(0.75, 1.0),
    });
    let scar_at = pick(rng);
    let angle = rng.range(0.0, std::f64::consts::PI);
    out.push(SkinDetail {
        side: side(rng),
        centre: scar_at.to_array(),
        kind: DetailKind::Scar {
            direction: [angle.cos(), 0.0, angle.sin()],
            length: rng.range(0.012, 0.028),
            width: rng.range(0.0009, 0.0016),
        },
        strength: rng.range(0.7, 1.0),
    });
    let tan = if rng.next_f64() < 0.5 {
        SkinDetail {
            side: side(rng),
            centre: (lm.mcp[2] * 0.55 + lm.ring_pip * 0.45).to_array(),
            kind: DetailKind::RingTan {
                width: rng.range(0.004, 0.007),
            },
            strength: rng.range(0.7, 1.0),
        }
    } else {
        SkinDetail {
            side: side(rng),
            centre: (lm.wrist + (knuckles - lm.wrist) * 0.08).to_array(),
            kind: DetailKind::WatchTan {
                width: rng.range(0.012, 0.02),
            },
            strength: rng.range(0.6, 0.9),
        }
    };
    out.push(tan);
    Ok(out)
}

/// Paints `details` of hand `side` onto its compact texture `[3, T]` (`points`: the rest
/// right-hand point of each texel).
fn paint(
    texture: &mut [f32],
    points: &[DVec3],
    details: &[SkinDetail],
    side: Side,
    models: &HandPair,
) {
    let lm = Landmarks::new(models);
    let t = points.len();
    let ring_axis = (lm.ring_pip - lm.mcp[2]).normalize_or(DVec3::NEG_X);
    let hand_axis = ((lm.mcp.iter().sum::<DVec3>() / 4.0) - lm.wrist).normalize_or(DVec3::NEG_X);
    for d in details.iter().filter(|d| d.side == side) {
        let c = DVec3::from_array(d.centre);
        for (i, p) in points.iter().enumerate() {
            let (weight, target): (f64, [f64; 3]) = match d.kind {
                DetailKind::Mole { radius } => {
                    let r = (*p - c).length();
                    if r > 2.0 * radius {
                        continue;
                    }
                    (
                        1.0 - smoothstep(0.7 * radius, 1.15 * radius, r),
                        [0.32, 0.2, 0.14],
                    )
                }
                DetailKind::Scar {
                    direction,
                    length,
                    width,
                } => {
                    let dir = DVec3::from_array(direction);
                    let q = *p - c;
                    let along = q.dot(dir);
                    if along.abs() > 0.5 * length + width {
                        continue;
                    }
                    let across = (q - dir * along).length();
                    // Narrower towards the ends, a slight waviness along the line.
                    let end = 1.0 - smoothstep(0.35 * length, 0.5 * length, along.abs());
                    let wobble = 1.0 + 0.25 * (along / width * 0.9).sin();
                    let w = width * 0.5 * wobble * (0.4 + 0.6 * end);
                    let k = (1.0 - smoothstep(0.6 * w, 1.3 * w, across)) * end;
                    if k <= 0.0 {
                        continue;
                    }
                    (k * 0.75, [f64::NAN; 3])
                }
                DetailKind::RingTan { width } => {
                    let q = *p - c;
                    let along = q.dot(ring_axis);
                    let radial = (q - ring_axis * along).length();
                    if radial > 0.016 {
                        continue;
                    }
                    (
                        1.0 - smoothstep(0.35 * width, 0.6 * width, along.abs()),
                        [f64::INFINITY; 3],
                    )
                }
                DetailKind::WatchTan { width } => {
                    let along = (*p - c).dot(hand_axis);
                    (
                        1.0 - smoothstep(0.3 * width, 0.55 * width, along.abs()),
                        [f64::INFINITY; 3],
                    )
                }
            };
            let k = (weight * d.strength).clamp(0.0, 1.0) as f32;
            if k <= 0.0 {
                continue;
            }
            let rgb = [texture[i], texture[t + i], texture[2 * t + i]];
            let out: [f32; 3] = if target[0].is_nan() {
                // Scar: lighter, pinker, a little glossy-flat.
                let grey = (rgb[0] + rgb[1] + rgb[2]) / 3.0;
                [
                    rgb[0] + 0.6 * (1.0 - rgb[0]) * 0.35 + 0.02 * (grey - rgb[0]),
                    rgb[1] + 0.6 * (1.0 - rgb[1]) * 0.2,
                    rgb[2] + 0.6 * (1.0 - rgb[2]) * 0.22,
                ]
            } else if target[0].is_infinite() {
                // Tan line: paler and a little less saturated.
                let grey = (rgb[0] + rgb[1] + rgb[2]) / 3.0;
                std::array::from_fn(|ch| {
                    let paler = rgb[ch] + 0.22 * (1.0 - rgb[ch]);
                    paler + 0.15 * (grey - rgb[ch])
                })
            } else {
                // Mole: towards a dark brown, keeping a little of the skin underneath.
                std::array::from_fn(|ch| rgb[ch] * 0.25 + target[ch] as f32 * 0.75 * rgb[ch].sqrt())
            };
            for ch in 0..3 {
                let v = rgb[ch] + k * (out[ch] - rgb[ch]);
                texture[ch * t + i] = v.clamp(0.0, 1.0);
            }
        }
    }
}

/// The rest right-hand 3D point of each texel of `layout_right` (the right hand's layout).
pub fn texel_points(
    models: &HandPair,
    layout_right: &TextureLayout,
) -> Result<Vec<DVec3>, SynthError> {
    layout_right
        .texel_points(&models.right.faces, &models.right.v_template)
        .ok_or_else(|| {
            SynthError::Generate("the texture layout has no per-texel faces for this hand".into())
        })
}

/// The ground-truth textures `[left, right]` (compact `[3, T]` each) of an identity with its
/// personal appearance (both hands) and one-sided details.
pub(crate) fn identity_textures(
    models: &HandPair,
    layouts: &[TextureLayout; 2],
    points: &[DVec3],
    skin: &SkinIdentity,
    appearance: &[AppearancePatch],
    details: &[SkinDetail],
) -> Result<[Vec<f32>; 2], SynthError> {
    let mut out: [Vec<f32>; 2] = Default::default();
    for (k, side) in Side::BOTH.into_iter().enumerate() {
        let mut tex = generate_texture(&layouts[k], models.get(side), skin, side)?;
        paint_appearance(&mut tex, points, appearance);
        paint(&mut tex, points, details, side, models);
        out[k] = tex;
    }
    Ok(out)
}
