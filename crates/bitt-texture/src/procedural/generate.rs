//! The per-texel skin shader: layers of colour computed from a texel's rest-pose point, its
//! normal and the skeleton.

use bitt_mesh::glam::{DVec2, DVec3};
use bitt_mesh::{HandModel, Side};

use super::anatomy::{
    Crease, DigitCoord, HandSkeleton, THUMB, TexelGeometry, Vein, dorsal_veins, palm_creases,
    wrap_angle,
};
use super::identity::SkinIdentity;
use super::noise::{
    band_limit, derive, fbm, gradient_noise, hash3, line_profile, mix64, smoothstep, unit,
};
use crate::TextureError;
use crate::layout::TextureLayout;

/// Skin colours along the tone axis (sRGB, 0-255), from very light (tone 0) to very dark
/// (tone 1), evenly spaced; interpolated in linear light.
const TONE_PALETTE: [[f64; 3]; 6] = [
    [246.0, 218.0, 202.0],
    [233.0, 190.0, 164.0],
    [210.0, 158.0, 121.0],
    [172.0, 119.0, 84.0],
    [122.0, 80.0, 54.0],
    [76.0, 49.0, 35.0],
];
/// Nail bed colours (sRGB): pale and pink.
const NAIL_PALE: [f64; 3] = [236.0, 214.0, 204.0];
const NAIL_PINK: [f64; 3] = [232.0, 168.0, 164.0];
/// The lunula and the free edge of the nail (sRGB).
const NAIL_WHITE: [f64; 3] = [244.0, 236.0, 228.0];
/// Hair colours (sRGB): dark brown-black and light brown.
const HAIR_DARK: [f64; 3] = [38.0, 28.0, 22.0];
const HAIR_LIGHT: [f64; 3] = [120.0, 88.0, 60.0];
/// A mole (sRGB).
const MOLE: [f64; 3] = [78.0, 48.0, 34.0];

/// sRGB (0-255) to linear light.
fn srgb_to_linear(c: [f64; 3]) -> DVec3 {
    let f = |v: f64| {
        let v = v / 255.0;
        if v <= 0.04045 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    DVec3::new(f(c[0]), f(c[1]), f(c[2]))
}

/// Linear light to sRGB in `[0, 1]`.
fn linear_to_srgb(c: DVec3) -> [f32; 3] {
    let f = |v: f64| {
        let v = v.clamp(0.0, 1.0);
        let s = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        s.clamp(0.0, 1.0) as f32
    };
    [f(c.x), f(c.y), f(c.z)]
}

/// Generates the texture of one hand of one person: compact `[3, T]` (channel-major) sRGB
/// colours in `[0, 1]`, one per texel of `layout`.
///
/// `hand` must be the model of `side` whose UV layout `layout` was rasterized from (or the
/// other side of the same mirrored pair: the left and right procedural hands share their UV
/// coordinates). Each texel is shaded from its rest-pose point, its interpolated normal and
/// the regressed skeleton, in the right hand's frame (the left hand is mapped by `x -> -x`),
/// so the two hands of a person match texel for texel except for the identity's asymmetry
/// noise, which is seeded per side. Deterministic.
///
/// # Errors
/// [`TextureError::Invalid`] when `hand.side` is not `side`, when the layout has no per-texel
/// faces, or when the layout's triangles do not belong to the hand.
pub fn generate_texture(
    layout: &TextureLayout,
    hand: &HandModel,
    identity: &SkinIdentity,
    side: Side,
) -> Result<Vec<f32>, TextureError> {
    if hand.side != side {
        return Err(TextureError::Invalid(format!(
            "asked for the {side} hand's texture but the model is the {} hand",
            hand.side
        )));
    }
    let geometry = TexelGeometry::new(layout, hand)?;
    let skeleton = HandSkeleton::new(hand)?;
    let shader = Shader::new(&skeleton, identity, side, geometry.texel_size);
    let t = geometry.points.len();
    let mut out = vec![0.0f32; 3 * t];
    for (i, (p, n)) in geometry.points.iter().zip(&geometry.normals).enumerate() {
        let c = shader.shade(*p, *n);
        for (ch, v) in c.iter().enumerate() {
            out[ch * t + i] = *v;
        }
    }
    Ok(out)
}

/// Which texels of `layout` lie on the palm side of `hand` (the shader's own palm/back split:
/// each texel's rest-pose normal against the local nail-side direction, see
/// [`generate_texture`]'s layers). Works for any hand model with a UV layout, MANO
/// included.
///
/// # Errors
/// A layout without per-texel faces, or one that does not fit `hand`.
pub fn palm_side_texels(
    layout: &TextureLayout,
    hand: &HandModel,
) -> Result<Vec<bool>, TextureError> {
    let geometry = TexelGeometry::new(layout, hand)?;
    let skeleton = HandSkeleton::new(hand)?;
    Ok(geometry
        .points
        .iter()
        .zip(&geometry.normals)
        .map(|(p, n)| dorsal_weight(&skeleton, *n, &skeleton.digits[THUMB].locate(*p)) < 0.5)
        .collect())
}

/// 1 on the back of the hand, 0 on the palm side, from the normal against the local
/// nail-side direction (`+y`, turned towards the thumb's own nail side along the thumb).
fn dorsal_weight(skel: &HandSkeleton, n: DVec3, thumb: &DigitCoord) -> f64 {
    let d = &skel.digits[THUMB];
    let along = smoothstep(
        0.15 * d.segment_length(0),
        0.6 * d.segment_length(0),
        thumb.s,
    );
    let near = smoothstep(2.6 * d.radius, 1.7 * d.radius, thumb.dist);
    let w = along * near;
    let seg = if thumb.s < d.s[1] {
        0
    } else if thumb.s < d.s[2] {
        1
    } else {
        2
    };
    let e1 = (DVec3::Y * (1.0 - w) + d.nail_direction(seg) * w).normalize_or(DVec3::Y);
    smoothstep(-0.28, 0.28, n.dot(e1))
}

/// Everything the per-texel shader needs, prepared once per hand.
pub(super) struct Shader<'a> {
    skel: &'a HandSkeleton,
    id: &'a SkinIdentity,
    /// Seed shared by both hands of the person.
    seed: u64,
    /// Seed of this hand's asymmetry.
    side_seed: u64,
    texel: f64,
    creases: Vec<Crease>,
    veins: Vec<Vein>,
    palette: [DVec3; 6],
    nail_pale: DVec3,
    nail_pink: DVec3,
    nail_white: DVec3,
    hair: DVec3,
    mole: DVec3,
}

/// Per-texel accumulators of the layers that act through the tone and redness.
struct Skin {
    /// Melanin-like tone (palette coordinate).
    tone: f64,
    /// Blood redness.
    red: f64,
    /// Multiplicative darkening from creases and wrinkles (0 none).
    fold: f64,
}

impl<'a> Shader<'a> {
    pub(super) fn new(
        skel: &'a HandSkeleton,
        id: &'a SkinIdentity,
        side: Side,
        texel: f64,
    ) -> Self {
        let seed = id.seed;
        let side_seed = derive(id.asymmetry_seed, if side == Side::Left { 1 } else { 2 });
        let hair_mix = 0.35 + 0.65 * id.tone.max(id.hair_darkness);
        Shader {
            skel,
            id,
            seed,
            side_seed,
            texel,
            creases: palm_creases(&skel.palm, seed, side_seed),
            veins: dorsal_veins(&skel.palm, seed),
            palette: TONE_PALETTE.map(srgb_to_linear),
            nail_pale: srgb_to_linear(NAIL_PALE),
            nail_pink: srgb_to_linear(NAIL_PINK),
            nail_white: srgb_to_linear(NAIL_WHITE),
            hair: srgb_to_linear(HAIR_LIGHT).lerp(srgb_to_linear(HAIR_DARK), hair_mix),
            mole: srgb_to_linear(MOLE),
        }
    }

    /// Linear skin colour at a palette coordinate (clamped to the palette).
    fn tone_colour(&self, tone: f64) -> DVec3 {
        let x = tone.clamp(0.0, 1.0) * (self.palette.len() - 1) as f64;
        let i = (x.floor() as usize).min(self.palette.len() - 2);
        self.palette[i].lerp(self.palette[i + 1], x - i as f64)
    }

    /// The colour of the point `p` with outward normal `n` (right-hand frame).
    fn shade(&self, p: DVec3, n: DVec3) -> [f32; 3] {
        let id = self.id;
        let skel = self.skel;
        let coords: [DigitCoord; 5] = std::array::from_fn(|k| skel.digits[k].locate(p));
        // The nearest digit axis, and the digit whose skin this is (past its web).
        let nearest = (0..5)
            .min_by(|&a, &b| coords[a].dist.total_cmp(&coords[b].dist))
            .expect("five digits");
        let owner = (0..5)
            .filter(|&k| {
                coords[k].s > skel.web_s(k) && coords[k].dist < 1.7 * skel.digits[k].radius
            })
            .min_by(|&a, &b| coords[a].dist.total_cmp(&coords[b].dist));
        let dorsal = self.dorsal_weight(n, &coords[THUMB]);
        let palm_uv = skel.palm.coords(p);
        let palm_units = skel.palm.units(palm_uv);

        // Base tone: the palm side carries less melanin; low-frequency blotches on top.
        let palm_tone = id.tone * (1.0 - id.palm_lightness);
        // The back of the hand also carries a little sun tan, most visible on light skin.
        let back_tone = id.tone + 0.05 * (1.0 - id.tone);
        let mut skin = Skin {
            tone: palm_tone + (back_tone - palm_tone) * dorsal,
            red: 0.0,
            fold: 0.0,
        };
        let blotch = fbm(derive(self.seed, 1), p, 0.035, 4, 0.5, self.texel);
        let asym = fbm(derive(self.side_seed, 1), p, 0.03, 3, 0.5, self.texel);
        skin.tone +=
            (0.05 * id.blotchiness * blotch + 0.06 * id.asymmetry * asym) * (0.4 + id.tone);
        let mottle = fbm(derive(self.seed, 2), p, 0.012, 4, 0.55, self.texel);
        let asym_red = fbm(derive(self.side_seed, 2), p, 0.02, 3, 0.5, self.texel);
        skin.red = id.redness * (0.35 + 0.2 * mottle)
            + (1.0 - dorsal) * id.palm_redness * (0.45 + 0.35 * mottle)
            + 0.2 * id.asymmetry * asym_red;
        // Palm eminences (thenar, hypothenar) and the finger pads are redder.
        let eminence =
            smoothstep(1.0, 2.0, palm_units.y.abs()) * smoothstep(0.9, 0.6, palm_units.x);
        skin.red += (1.0 - dorsal) * 0.35 * eminence * (0.6 + 0.4 * mottle);

        if let Some(k) = owner {
            self.digit_skin(k, &coords[k], dorsal, &mut skin);
        }
        self.knuckles(nearest, &coords[nearest], dorsal, &mut skin, p);
        if owner.is_none() || owner == Some(THUMB) && coords[THUMB].s < skel.digits[THUMB].s[1] {
            self.palm_lines(palm_uv, p, dorsal, owner.is_none(), &mut skin);
        }
        self.spots(p, dorsal, &mut skin);

        // Tone, undertone and blood into a linear colour.
        let mut c = self.tone_colour(skin.tone);
        let u = id.undertone;
        c *= if u >= 0.0 {
            DVec3::new(1.0, 1.0 + 0.03 * u, 1.0 - 0.12 * u)
        } else {
            DVec3::new(
                1.0 + 0.02 * u.abs(),
                1.0 - 0.05 * u.abs(),
                1.0 - 0.01 * u.abs(),
            )
        };
        let red = skin.red.max(0.0);
        c *=
            DVec3::new(1.0 + 0.03 * red, 1.0 - 0.15 * red, 1.0 - 0.11 * red).max(DVec3::splat(0.2));
        // Palm skin (thick, scattering stratum corneum) is a little paler.
        // and pinker (less yellow) than the back.
        c *= DVec3::ONE.lerp(DVec3::new(1.06, 1.045, 1.07 + 0.13 * id.tone), 1.0 - dorsal);
        // Fine grain.
        let grain = fbm(derive(self.seed, 3), p, 0.0025, 2, 0.5, self.texel);
        c *= 1.0 + 0.035 * grain;
        c *= (1.0 - skin.fold).max(0.0);

        if owner.is_none() {
            c = self.veins(c, palm_uv, p, dorsal, palm_units.x);
        }
        c = self.hairs(c, p, n, &coords, owner, dorsal, palm_units.x);
        c = self.moles(c, p);
        if coords[nearest].dist < 1.6 * skel.digits[nearest].radius {
            c = self.nail(c, nearest, &coords[nearest], p);
        }
        linear_to_srgb(c)
    }

    /// [`Shader::dorsal_weight`] at a point.
    #[cfg(test)]
    pub(super) fn dorsal_at(&self, p: DVec3, n: DVec3) -> f64 {
        self.dorsal_weight(n, &self.skel.digits[THUMB].locate(p))
    }

    /// [`dorsal_weight`] with this hand's skeleton.
    fn dorsal_weight(&self, n: DVec3, thumb: &DigitCoord) -> f64 {
        dorsal_weight(self.skel, n, thumb)
    }

    /// Fingertips redder, pads pinker, flexion creases on the palm side of the digits.
    fn digit_skin(&self, k: usize, c: &DigitCoord, dorsal: f64, skin: &mut Skin) {
        let d = &self.skel.digits[k];
        let id = self.id;
        let len2 = d.segment_length(2);
        skin.red += 0.45 * smoothstep(d.s[2] + 0.2 * len2, d.s[3], c.s);
        // Pads: the middle of each phalanx on the palm side.
        let palmar = 1.0 - dorsal;
        for seg in 0..3 {
            let mid = 0.5 * (d.s[seg] + d.s[seg + 1]);
            let half = 0.5 * d.segment_length(seg);
            let x = (c.s - mid) / half.max(1e-6);
            skin.red += 0.25 * palmar * (-x * x * 2.0).exp();
        }
        // Flexion creases: (position, offset of a second line, strength).
        let r = d.radius;
        let creases: &[(f64, f64, f64)] = if k == THUMB {
            &[(d.s[1] - 0.1 * r, 0.0013, 0.9), (d.s[2], 0.0011, 1.0)]
        } else {
            &[
                (0.34 * d.segment_length(0), 0.0014, 0.75),
                (d.s[1] - 0.05 * r, 0.0012, 1.0),
                (d.s[2] - 0.05 * r, 0.0, 0.85),
            ]
        };
        let phi = wrap_angle(c.phi);
        let mask = smoothstep(1.25, 1.85, phi.abs()) * id.crease_strength;
        if mask <= 0.0 {
            return;
        }
        let bend = 0.22 * r * (1.0 + phi.cos()); // the lines bow slightly towards the tip at the sides
        let wobble = 0.0004
            * gradient_noise(
                derive(self.seed, 10 + k as u64),
                DVec3::new(phi * 2.0, c.s * 300.0, 0.0),
            );
        let mut line = 0.0_f64;
        for &(s0, second, strength) in creases {
            let x = c.s - s0 - bend + wobble;
            let mut v = line_profile(x, 0.00028, self.texel);
            if second > 0.0 {
                v = v.max(0.8 * line_profile(x - second, 0.00024, self.texel));
            }
            line = line.max(v * strength);
        }
        skin.fold += 0.32 * mask * line;
        skin.tone += 0.12 * mask * line;
    }

    /// Darker, redder knuckles with wrinkles on the back of each joint.
    fn knuckles(&self, k: usize, c: &DigitCoord, dorsal: f64, skin: &mut Skin, p: DVec3) {
        let d = &self.skel.digits[k];
        let r = d.radius;
        if c.dist > 1.6 * r || dorsal <= 0.0 {
            return;
        }
        let id = self.id;
        let phi = wrap_angle(c.phi);
        // (arc length, patch size along, wrinkle spacing, strength) of MCP/PIP/DIP (thumb: MCP, IP).
        let joints: [(f64, f64, f64, f64); 3] = if k == THUMB {
            [
                (d.s[1], 0.7 * r, 0.0019, 0.6),
                (d.s[2], 0.55 * r, 0.0015, 0.8),
                (f64::NAN, 0.0, 0.0, 0.0),
            ]
        } else {
            [
                (d.s[0], 0.75 * r, 0.0021, 0.45),
                (d.s[1], 0.6 * r, 0.0017, 1.0),
                (d.s[2], 0.5 * r, 0.0014, 0.7),
            ]
        };
        let warp = 0.0004 * gradient_noise(derive(self.seed, 20 + k as u64), p / 0.003);
        for (s0, size, spacing, strength) in joints {
            if !s0.is_finite() {
                continue;
            }
            let x = (c.s - s0) / size;
            if x.abs() > 3.0 {
                continue;
            }
            let across = phi / 1.2;
            let xp = 1.3 * x;
            let patch = (-xp * xp - across.powi(4)).exp() * dorsal * strength * id.knuckle_strength;
            skin.tone += 0.055 * patch * (0.35 + id.tone);
            skin.red += 0.35 * patch;
            // Wrinkles: transverse lines, bowed towards the wrist at the sides.
            let q = c.s - s0 + 0.3 * r * across * across + warp;
            let xw = (c.s - s0) / (1.25 * size);
            let env =
                (-xw * xw - (phi / 0.8).powi(2)).exp() * dorsal * strength * id.knuckle_strength;
            let lines = periodic_lines(q, spacing, 0.00022, self.texel);
            skin.fold += 0.28 * env * lines;
            skin.tone += 0.05 * env * lines;
        }
    }

    /// The palm's major creases, minor crease texture and the wrist bracelets.
    fn palm_lines(&self, m: DVec2, p: DVec3, dorsal: f64, on_palm: bool, skin: &mut Skin) {
        let palmar = smoothstep(0.6, 0.2, dorsal);
        if palmar <= 0.0 {
            return;
        }
        let id = self.id;
        let mut line = 0.0_f64;
        for (i, crease) in self.creases.iter().enumerate() {
            let Some((d, t)) = crease.curve.nearest(m, 0.003) else {
                continue;
            };
            let taper = smoothstep(0.0, 0.1, t) * smoothstep(1.0, 0.88, t);
            let vary = 0.8 + 0.2 * gradient_noise(derive(self.seed, 40 + i as u64), p / 0.006);
            let width = crease.width * (0.8 + 0.4 * taper);
            line = line.max(line_profile(d, width, self.texel) * crease.depth * taper * vary);
        }
        // Minor creases: the ridges of a noise field.
        let minor = if on_palm {
            // Ridges of a noise field stretched across the palm: short, mostly transverse lines,
            // only in patches.
            let palm = &self.skel.palm;
            let d = p - palm.origin;
            let q = palm.along * d.dot(palm.along)
                + palm.across * (0.3 * d.dot(palm.across))
                + DVec3::Y * d.y;
            let n = fbm(derive(self.seed, 4), q, 0.006, 2, 0.5, self.texel);
            let patches = smoothstep(
                -0.1,
                0.5,
                fbm(derive(self.seed, 14), p, 0.02, 2, 0.5, self.texel),
            );
            0.18 * smoothstep(0.93, 0.99, 1.0 - n.abs()) * patches * band_limit(0.003, self.texel)
        } else {
            0.0
        };
        let v = (line + minor) * palmar * id.crease_strength;
        skin.fold += 0.35 * v;
        skin.tone += 0.15 * v;
        skin.red += 0.2 * v;
    }

    /// Freckles: small light-brown spots, mostly on the back.
    fn spots(&self, p: DVec3, dorsal: f64, skin: &mut Skin) {
        let id = self.id;
        let density = id.freckle_density * (0.12 + 0.88 * dorsal);
        if density <= 0.0 {
            return;
        }
        let spot = scatter(derive(self.seed, 5), p, 0.0028, density * 0.3, |h, d2| {
            let r = 0.0003 + 0.0005 * unit(mix64(h ^ 1));
            disc(d2, r, self.texel) * (0.5 + 0.5 * unit(mix64(h ^ 2)))
        });
        skin.tone += 0.22 * spot.min(1.0) * (1.1 - id.tone);
    }

    /// Moles: rarer, darker, larger spots; a few shared by both hands, a few per hand.
    fn moles(&self, c: DVec3, p: DVec3) -> DVec3 {
        let id = self.id;
        if id.mole_density <= 0.0 {
            return c;
        }
        let mole = |h: u64, d2: f64| {
            let r = 0.0005 + 0.0008 * unit(mix64(h ^ 1));
            disc(d2, r, self.texel) * (0.6 + 0.4 * unit(mix64(h ^ 2)))
        };
        let shared = scatter(derive(self.seed, 6), p, 0.012, 0.05 * id.mole_density, mole);
        let own = scatter(
            derive(self.side_seed, 6),
            p,
            0.012,
            0.04 * id.mole_density,
            mole,
        );
        let m = shared.max(own).min(1.0);
        let dark = self.mole * (0.6 + 0.6 * (1.0 - id.tone));
        c.lerp(dark.min(c), m)
    }

    /// Dorsal veins: soft blue-green lines on the back of the hand.
    fn veins(&self, c: DVec3, m: DVec2, p: DVec3, dorsal: f64, u_units: f64) -> DVec3 {
        let id = self.id;
        let vis = id.vein_visibility * (1.0 - 0.75 * id.tone);
        let mask = smoothstep(0.45, 0.85, dorsal) * smoothstep(0.95, 0.75, u_units);
        if vis <= 0.0 || mask <= 0.0 {
            return c;
        }
        // Shared network, nudged differently on each hand.
        let warp = DVec2::new(
            gradient_noise(derive(self.side_seed, 7), p / 0.012),
            gradient_noise(derive(self.side_seed, 8), p / 0.012),
        ) * 0.0008
            * id.asymmetry
            + DVec2::new(
                gradient_noise(derive(self.seed, 7), p / 0.004),
                gradient_noise(derive(self.seed, 8), p / 0.004),
            ) * 0.0004;
        let q = m + warp;
        let mut v = 0.0_f64;
        for vein in &self.veins {
            let Some((d, t)) = vein.curve.nearest(q, 0.007) else {
                continue;
            };
            let hw = vein.width_at(t);
            let ends = smoothstep(0.0, 0.05, t) * smoothstep(1.0, 0.9, t);
            let x = d / hw;
            v = v.max((-x * x).exp() * ends);
        }
        let a = (0.5 * vis * mask * v).min(0.6);
        c * DVec3::ONE.lerp(DVec3::new(0.72, 0.84, 1.02), a)
    }

    /// Fine dark hairs on the back of the hand and the proximal phalanges.
    #[allow(clippy::too_many_arguments)]
    fn hairs(
        &self,
        c: DVec3,
        p: DVec3,
        n: DVec3,
        coords: &[DigitCoord; 5],
        owner: Option<usize>,
        dorsal: f64,
        u_units: f64,
    ) -> DVec3 {
        let id = self.id;
        let back = smoothstep(0.55, 0.9, dorsal);
        if id.hair_density <= 0.0 || back <= 0.0 {
            return c;
        }
        let palm = &self.skel.palm;
        let (region, dir) = match owner {
            None => (
                smoothstep(-0.15, 0.1, u_units) * (1.0 - 0.4 * smoothstep(0.4, 0.95, u_units)),
                (palm.along - 0.35 * palm.across).normalize(),
            ),
            Some(k) => {
                let d = &self.skel.digits[k];
                let x = (coords[k].s - d.s[0]) / (d.s[1] - d.s[0]).max(1e-6);
                let density = if k == THUMB {
                    0.5 * smoothstep(0.9, 1.1, x) * smoothstep(2.0, 1.6, x)
                } else {
                    0.85 * smoothstep(1.0, 0.75, x)
                        + 0.18 * smoothstep(1.05, 1.2, x) * smoothstep(1.8, 1.5, x)
                };
                (density, coords[k].tangent)
            }
        };
        let density = id.hair_density * region * back;
        if density <= 0.0 {
            return c;
        }
        // Hair direction in the tangent plane.
        let dir = (dir - n * dir.dot(n)).normalize_or(dir);
        let side = n.cross(dir);
        let cell = 0.0028;
        let ink = scatter_with(
            derive(self.seed, 9),
            p,
            cell,
            (0.85 * density).min(1.0),
            |h, d| {
                if d.dot(n).abs() > 0.5 * cell {
                    return 0.0;
                }
                let len = 0.0014 + 0.0016 * unit(mix64(h ^ 3));
                let tilt = 0.35 * (2.0 * unit(mix64(h ^ 4)) - 1.0);
                let a = (dir + side * tilt).normalize();
                let along = d.dot(a);
                if along.abs() > 0.5 * len {
                    return 0.0;
                }
                let across = d.dot(n.cross(a));
                let taper = 1.0 - (2.0 * along / len).powi(4);
                line_profile(across, 0.000045, self.texel) * taper
            },
        );
        let a = (0.9 * ink * id.hair_darkness).min(0.85);
        c.lerp(self.hair.min(c), a)
    }

    /// Nails on the back of the distal phalanges: pink bed, lighter lunula and free edge, a
    /// thin cuticle line around the base.
    fn nail(&self, c: DVec3, k: usize, dc: &DigitCoord, p: DVec3) -> DVec3 {
        let d = &self.skel.digits[k];
        let len2 = d.segment_length(2);
        let r = d.radius;
        let phi = wrap_angle(dc.phi);
        let half = 0.78;
        let base = d.s[2] + 0.36 * len2 + 0.3 * r * (phi / half).powi(2);
        let tip = d.s[3] - 0.28 * r;
        if dc.s < base - 0.002 || phi.abs() > half + 0.2 {
            return c;
        }
        // The free edge is rounded like the base, less strongly.
        let tip = tip - 0.22 * r * (phi / half).powi(4);
        let soft = 0.00025_f64.max(0.5 * self.texel);
        let across = smoothstep(half, half - soft / r, phi.abs());
        let mask = smoothstep(base - 0.5 * soft, base + 0.5 * soft, dc.s)
            * smoothstep(tip + soft, tip - 0.3 * soft, dc.s)
            * across;
        let id = self.id;
        let cuticle = line_profile(dc.s - base + 0.0002, 0.00025, self.texel)
            * smoothstep(half + 0.1, half - 0.1, phi.abs());
        let mut out = c * (1.0 - 0.25 * cuticle);
        if mask <= 0.0 {
            return out;
        }
        let nail_len = (tip - base).max(1e-4);
        let tint = 0.5 + 0.5 * id.nail_tint;
        let palm_skin = self.tone_colour(id.tone * (1.0 - id.palm_lightness));
        let mut bed = self.nail_pale.lerp(self.nail_pink, tint);
        bed = bed.lerp(palm_skin * DVec3::new(1.0, 0.9, 0.92), 0.2 + 0.45 * id.tone);
        bed *= 1.0
            + 0.04
                * gradient_noise(
                    derive(self.seed, 30 + k as u64),
                    DVec3::new(phi * r / 0.0006, 0.0, 0.0),
                );
        let lunula_size = if k == THUMB {
            0.24
        } else if k == 0 {
            0.17
        } else {
            0.12
        };
        let e = ((dc.s - base) / (lunula_size * nail_len)).powi(2) + (phi / (0.6 * half)).powi(2);
        let lunula = smoothstep(1.0, 0.75, e) * 0.55;
        let free = smoothstep(tip - 0.1 * nail_len, tip - 0.04 * nail_len, dc.s) * 0.75;
        let nail = bed.lerp(self.nail_white, lunula.max(free));
        // A slight sheen variation along the nail.
        let shine = 1.0 + 0.03 * fbm(derive(self.seed, 31), p, 0.004, 2, 0.5, self.texel);
        out = out.lerp(nail * shine, mask);
        out
    }
}

/// Periodic parallel lines across `q` (spacing `spacing`, half-width `width`), fading to their
/// mean darkness when the spacing approaches the texel size.
fn periodic_lines(q: f64, spacing: f64, width: f64, texel: f64) -> f64 {
    let d = q - spacing * (q / spacing).round();
    let line = line_profile(d, width, texel);
    let mean = (width * std::f64::consts::PI.sqrt() / spacing).min(1.0);
    let keep = band_limit(spacing, texel);
    keep * line + (1.0 - keep) * mean
}

/// A soft disc of radius `r` at squared distance `d2`, its "ink" preserved when smaller than a
/// texel.
fn disc(d2: f64, r: f64, texel: f64) -> f64 {
    let re2 = r * r + 0.25 * texel * texel;
    (r * r / re2) * (-d2 / re2).exp()
}

/// Sums `f(hash, squared distance)` over points scattered in a cubic grid of `cell` (at most
/// one per cell, present with probability `p`) around `x`.
fn scatter(seed: u64, x: DVec3, cell: f64, p: f64, f: impl Fn(u64, f64) -> f64) -> f64 {
    scatter_with(seed, x, cell, p, |h, d| f(h, d.length_squared()))
}

/// Like [`scatter`], handing `f` the offset from the scattered point to `x`.
fn scatter_with(seed: u64, x: DVec3, cell: f64, p: f64, f: impl Fn(u64, DVec3) -> f64) -> f64 {
    if p <= 0.0 {
        return 0.0;
    }
    let g = x / cell;
    let base = g.floor();
    let mut sum = 0.0;
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (ix, iy, iz) = (base.x as i64 + dx, base.y as i64 + dy, base.z as i64 + dz);
                let h = hash3(seed, ix, iy, iz);
                if unit(h) >= p {
                    continue;
                }
                let jitter = DVec3::new(
                    unit(mix64(h ^ 11)),
                    unit(mix64(h ^ 12)),
                    unit(mix64(h ^ 13)),
                );
                let centre = (DVec3::new(ix as f64, iy as f64, iz as f64) + jitter) * cell;
                let d = x - centre;
                if d.length_squared() > 2.25 * cell * cell {
                    continue;
                }
                sum += f(h, d);
            }
        }
    }
    sum
}
