//! Where things are on the hand: texel points and normals in a canonical (right-hand) frame,
//! the digits' local coordinates, the palm's 2D coordinates, and the curves drawn on them
//! (palm creases, the dorsal veins).
//!
//! Everything is computed from the rest-pose template and the regressed skeleton, so the same
//! code serves any hand in MANO's frame (fingers along `-x`, back of the hand `+y`, thumb
//! `+z` for the right hand). The left hand is mapped into the right hand's frame by `x -> -x`.

use std::f64::consts::PI;

use bitt_mesh::glam::{DVec2, DVec3};
use bitt_mesh::{HandModel, Side};

use super::noise::{SplitMix64, derive};
use crate::TextureError;
use crate::layout::TextureLayout;

/// Skeleton joints of the index, middle, ring and pinky fingers (MCP, PIP, DIP) and of the
/// thumb (CMC, MCP, IP), in MANO's joint order.
const DIGIT_JOINTS: [[usize; 3]; 5] = [[1, 2, 3], [4, 5, 6], [10, 11, 12], [7, 8, 9], [13, 14, 15]];
/// Index into `HandModel::fingertips` (thumb, index, middle, ring, pinky) of each digit above.
const DIGIT_TIPS: [usize; 5] = [1, 2, 3, 4, 0];
/// Index of the thumb among the digits.
pub(super) const THUMB: usize = 4;
/// How far the thumb's nail side is turned from the back of the hand towards the radial side
/// (radians), as the procedural hand builds it.
const THUMB_PRONATION: f64 = 1.0;

/// Texel positions and normals of one hand, in the right hand's frame.
#[derive(Debug, Clone)]
pub(super) struct TexelGeometry {
    /// Rest-pose point of each texel.
    pub points: Vec<DVec3>,
    /// Unit outward surface normal of each texel (interpolated vertex normals).
    pub normals: Vec<DVec3>,
    /// Approximate size of one texel on the surface, in metres.
    pub texel_size: f64,
}

/// Maps a point or direction of `side` into the right hand's frame.
fn canonical(side: Side, p: DVec3) -> DVec3 {
    match side {
        Side::Right => p,
        Side::Left => DVec3::new(-p.x, p.y, p.z),
    }
}

impl TexelGeometry {
    /// Points and normals of every texel of `layout` on `hand`'s rest pose.
    ///
    /// The layout's barycentrics refer to the corners of its own UV triangles; when the hand's
    /// UV triangles list the same corners in another order (the left hand's triangles are the
    /// right hand's with two corners swapped), the mesh corners are matched through the UV
    /// indices, so one layout serves both hands.
    pub fn new(layout: &TextureLayout, hand: &HandModel) -> Result<Self, TextureError> {
        let texel_faces = layout.texel_faces().ok_or_else(|| {
            TextureError::Invalid(
                "procedural textures need a layout rasterized from a UV layout (per-texel faces)"
                    .into(),
            )
        })?;
        let nv = hand.v_template.len();
        let faces = aligned_faces(layout, hand)?;
        if let Some(f) = texel_faces.iter().find(|(f, _)| *f as usize >= faces.len()) {
            return Err(TextureError::Invalid(format!(
                "layout texel on face {} but the hand has {} faces",
                f.0,
                faces.len()
            )));
        }
        if faces.iter().flatten().any(|&v| v as usize >= nv) {
            return Err(TextureError::Invalid(
                "hand face indexes past its vertices".into(),
            ));
        }
        let vertex_normals = vertex_normals(&hand.v_template, &hand.faces);
        let side = hand.side;
        let mut points = Vec::with_capacity(texel_faces.len());
        let mut normals = Vec::with_capacity(texel_faces.len());
        for (f, w) in texel_faces {
            let corners = faces[*f as usize];
            let mut p = DVec3::ZERO;
            let mut n = DVec3::ZERO;
            for (c, wk) in corners.iter().zip(w) {
                p += hand.v_template[*c as usize] * f64::from(*wk);
                n += vertex_normals[*c as usize] * f64::from(*wk);
            }
            points.push(canonical(side, p));
            normals.push(canonical(side, n.normalize_or(DVec3::Y)));
        }
        let texel_size = texel_size(layout, hand);
        Ok(TexelGeometry {
            points,
            normals,
            texel_size,
        })
    }
}

/// The hand's mesh triangles with their corners in the order of the layout's UV triangles.
fn aligned_faces(layout: &TextureLayout, hand: &HandModel) -> Result<Vec<[u32; 3]>, TextureError> {
    let (Some(luv), Some(huv)) = (&layout.uv, &hand.uv) else {
        return Ok(hand.faces.clone());
    };
    if luv.faces.len() != hand.faces.len() || huv.faces.len() != hand.faces.len() {
        return Err(TextureError::Invalid(format!(
            "layout has {} UV triangles but the hand has {} faces",
            luv.faces.len(),
            hand.faces.len()
        )));
    }
    let mut out = Vec::with_capacity(hand.faces.len());
    for ((lf, hf), mf) in luv.faces.iter().zip(&huv.faces).zip(&hand.faces) {
        let mut corners = [0u32; 3];
        for (dst, l) in corners.iter_mut().zip(lf) {
            let k = hf.iter().position(|h| h == l).ok_or_else(|| {
                TextureError::Invalid(
                    "the layout's UV triangles do not match the hand's UV layout".into(),
                )
            })?;
            *dst = mf[k];
        }
        out.push(corners);
    }
    Ok(out)
}

/// Area-weighted vertex normals (`+Y` where undefined).
fn vertex_normals(vertices: &[DVec3], faces: &[[u32; 3]]) -> Vec<DVec3> {
    bitt_mesh::model::vertex_normals(vertices, faces)
        .into_iter()
        .map(|n| if n == DVec3::ZERO { DVec3::Y } else { n })
        .collect()
}

/// Mean edge of a texel on the surface: `sqrt(surface area / UV area) / resolution`.
fn texel_size(layout: &TextureLayout, hand: &HandModel) -> f64 {
    let res = (layout.width.max(layout.height).max(1)) as f64;
    let Some(uv) = layout.uv.as_ref().or(hand.uv.as_ref()) else {
        return 0.2 / res;
    };
    let (mut a3, mut a2) = (0.0, 0.0);
    for (f, u) in hand.faces.iter().zip(&uv.faces) {
        let p = f.map(|i| hand.v_template[i as usize]);
        let q = u.map(|i| uv.uvs[i as usize]);
        a3 += 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        a2 += 0.5 * (q[1] - q[0]).perp_dot(q[2] - q[0]).abs();
    }
    if a2 > 0.0 && a3 > 0.0 {
        (a3 / a2).sqrt() / res
    } else {
        0.2 / res
    }
}

/// The nail-side frame of a digit pointing along `t`: `(t, e1, e2)`, `e1` the back (nail) side
/// turned by `pronation` from `+y` towards the radial side.
fn nail_frame(t: DVec3, pronation: f64) -> (DVec3, DVec3, DVec3) {
    let radial = DVec3::Y.cross(t).normalize_or(DVec3::Z);
    let raw = DVec3::Y * pronation.cos() + radial * pronation.sin();
    let e1 = (raw - t * raw.dot(t)).normalize_or(DVec3::Y);
    (t, e1, t.cross(e1))
}

/// One digit's rest-pose chain: base joint, two joints, fingertip.
#[derive(Debug, Clone)]
pub(super) struct Digit {
    /// Base joint (MCP, CMC for the thumb), the next two joints, the fingertip.
    pub points: [DVec3; 4],
    /// Arc length of each point from the base joint.
    pub s: [f64; 4],
    /// Radius of the digit (median over the middle segment's vertices).
    pub radius: f64,
    /// Nail-side rotation about the digit.
    pub pronation: f64,
}

/// A point's coordinates relative to a digit.
#[derive(Debug, Clone, Copy)]
pub(super) struct DigitCoord {
    /// Arc length along the chain (negative before the base joint, past the tip beyond it).
    pub s: f64,
    /// Distance from the chain's axis.
    pub dist: f64,
    /// Angle about the axis: 0 on the nail (back) side, `+-pi` on the pad side.
    pub phi: f64,
    /// Unit direction of the nearest segment.
    pub tangent: DVec3,
}

impl Digit {
    fn new(points: [DVec3; 4], pronation: f64) -> Self {
        let mut s = [0.0; 4];
        for k in 1..4 {
            s[k] = s[k - 1] + points[k].distance(points[k - 1]);
        }
        Digit {
            points,
            s,
            radius: 0.0,
            pronation,
        }
    }

    /// Length of segment `k` (0 proximal, 2 distal).
    pub(crate) fn segment_length(&self, k: usize) -> f64 {
        self.s[k + 1] - self.s[k]
    }

    /// Coordinates of `p`: projected on the nearest segment (the first extended backwards,
    /// the last forwards).
    pub(crate) fn locate(&self, p: DVec3) -> DigitCoord {
        let mut best = (f64::INFINITY, 0.0, DVec3::ZERO, 0usize);
        for k in 0..3 {
            let a = self.points[k];
            let d = self.points[k + 1] - a;
            let len = d.length().max(1e-9);
            let t = d / len;
            let mut x = (p - a).dot(t);
            if k > 0 {
                x = x.max(0.0);
            }
            if k < 2 {
                x = x.min(len);
            }
            let q = a + t * x;
            let dist = p.distance(q);
            if dist < best.0 {
                best = (dist, self.s[k] + x, q, k);
            }
        }
        let (dist, s, q, k) = best;
        let t = (self.points[k + 1] - self.points[k]).normalize_or(DVec3::NEG_X);
        let (_, e1, e2) = nail_frame(t, self.pronation);
        let d = p - q;
        DigitCoord {
            s,
            dist,
            phi: d.dot(e2).atan2(d.dot(e1)),
            tangent: t,
        }
    }

    /// The nail-side direction at segment `k`.
    pub(crate) fn nail_direction(&self, k: usize) -> DVec3 {
        let t = (self.points[k + 1] - self.points[k]).normalize_or(DVec3::NEG_X);
        nail_frame(t, self.pronation).1
    }
}

/// A 2D frame on the palm: `u` from the wrist towards the middle knuckle, `w` across the palm
/// towards the thumb. Curves on the palm and the back of the hand are drawn in it.
#[derive(Debug, Clone)]
pub(super) struct PalmFrame {
    /// The wrist joint.
    pub origin: DVec3,
    /// Unit direction from the wrist towards the fingers (horizontal).
    pub along: DVec3,
    /// Unit direction across the palm towards the thumb.
    pub across: DVec3,
    /// Wrist-to-middle-knuckle distance along `along`.
    pub length: f64,
    /// Spacing of the finger axes at the knuckles.
    pub pitch: f64,
    /// `w` of the middle of the knuckle row.
    pub centre: f64,
}

impl PalmFrame {
    /// Metric palm coordinates `(u, w)` of a point.
    pub(crate) fn coords(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.along), d.dot(self.across))
    }

    /// Metric coordinates of a point given in palm units: `u` in palm lengths, `w` in finger
    /// pitches from the centre of the knuckle row (index at about `+1.5`, pinky `-1.5`).
    pub fn metres(&self, unit: DVec2) -> DVec2 {
        DVec2::new(unit.x * self.length, self.centre + unit.y * self.pitch)
    }

    /// Palm units of metric coordinates (inverse of [`PalmFrame::metres`]).
    pub fn units(&self, m: DVec2) -> DVec2 {
        DVec2::new(m.x / self.length, (m.y - self.centre) / self.pitch)
    }
}

/// The hand's skeleton in the right hand's frame.
#[derive(Debug, Clone)]
pub(super) struct HandSkeleton {
    /// Index, middle, ring, pinky, thumb.
    pub digits: [Digit; 5],
    /// The palm frame.
    pub palm: PalmFrame,
}

impl HandSkeleton {
    /// Regresses the joints of `hand`'s template and measures the digits.
    pub fn new(hand: &HandModel) -> Result<Self, TextureError> {
        if hand.v_template.is_empty() {
            return Err(TextureError::Invalid("hand has no vertices".into()));
        }
        let side = hand.side;
        let joints: Vec<DVec3> = hand
            .regress_joints(&hand.v_template)
            .into_iter()
            .map(|p| canonical(side, p))
            .collect();
        let vertices: Vec<DVec3> = hand
            .v_template
            .iter()
            .map(|p| canonical(side, *p))
            .collect();
        let tip = |k: usize| -> Result<DVec3, TextureError> {
            let v = hand.fingertips[DIGIT_TIPS[k]] as usize;
            vertices.get(v).copied().ok_or_else(|| {
                TextureError::Invalid(format!("fingertip vertex {v} is past the vertices"))
            })
        };
        let mut digits: Vec<Digit> = Vec::with_capacity(5);
        for (k, ids) in DIGIT_JOINTS.iter().enumerate() {
            let points = [joints[ids[0]], joints[ids[1]], joints[ids[2]], tip(k)?];
            let pronation = if k == THUMB { THUMB_PRONATION } else { 0.0 };
            digits.push(Digit::new(points, pronation));
        }
        // Radius: median axis distance of the vertices around each middle segment.
        let mut per_digit: Vec<Vec<f64>> = vec![Vec::new(); 5];
        for p in &vertices {
            let coords: Vec<DigitCoord> = digits.iter().map(|d| d.locate(*p)).collect();
            let (k, c) = coords
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.dist.total_cmp(&b.1.dist))
                .expect("five digits");
            let d = &digits[k];
            let mid = 0.5 * (d.s[1] + d.s[2]);
            if (c.s - mid).abs() < 0.3 * d.segment_length(1) {
                per_digit[k].push(c.dist);
            }
        }
        for (d, dists) in digits.iter_mut().zip(&mut per_digit) {
            dists.sort_by(f64::total_cmp);
            d.radius = dists
                .get(dists.len() / 2)
                .copied()
                .unwrap_or(0.009)
                .max(1e-3);
        }
        let digits: [Digit; 5] = digits.try_into().expect("five digits");
        let wrist = joints[0];
        let mut along = digits[1].points[0] - wrist;
        along.y = 0.0;
        let along = along.normalize_or(DVec3::NEG_X);
        let across = DVec3::Y.cross(along).normalize_or(DVec3::Z);
        let w = |p: DVec3| (p - wrist).dot(across);
        let (wi, wp) = (w(digits[0].points[0]), w(digits[3].points[0]));
        let palm = PalmFrame {
            origin: wrist,
            along,
            across,
            length: (digits[1].points[0] - wrist).dot(along).max(1e-3),
            pitch: ((wi - wp) / 3.0).abs().max(1e-3),
            centre: 0.5 * (wi + wp),
        };
        Ok(HandSkeleton { digits, palm })
    }

    /// Where the skin of digit `k` leaves the palm (the finger web), as an arc length.
    pub fn web_s(&self, k: usize) -> f64 {
        let factor = if k == THUMB { 0.55 } else { 0.32 };
        factor * self.digits[k].segment_length(0)
    }
}

/// A smooth open curve on the palm frame (metric coordinates), sampled densely.
#[derive(Debug, Clone)]
pub(super) struct Curve {
    points: Vec<DVec2>,
    /// Cumulative arc length at each point, normalised to end at 1.
    t: Vec<f64>,
    lo: DVec2,
    hi: DVec2,
}

impl Curve {
    /// A Catmull-Rom spline through `control` (at least two points), `per_span` samples per
    /// span.
    pub fn through(control: &[DVec2], per_span: usize) -> Self {
        let n = control.len();
        let at = |i: isize| control[i.clamp(0, n as isize - 1) as usize];
        let mut points = Vec::new();
        for i in 0..n.saturating_sub(1) {
            let (p0, p1, p2, p3) = (
                at(i as isize - 1),
                at(i as isize),
                at(i as isize + 1),
                at(i as isize + 2),
            );
            for j in 0..per_span {
                let t = j as f64 / per_span as f64;
                let (t2, t3) = (t * t, t * t * t);
                points.push(
                    0.5 * ((2.0 * p1)
                        + (p2 - p0) * t
                        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
                        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * t3),
                );
            }
        }
        points.push(control[n - 1]);
        Self::polyline(points)
    }

    /// A curve through the given points, joined by straight segments.
    pub fn polyline(points: Vec<DVec2>) -> Self {
        let mut t = vec![0.0];
        for w in points.windows(2) {
            t.push(t[t.len() - 1] + w[0].distance(w[1]));
        }
        let total = t[t.len() - 1].max(1e-12);
        t.iter_mut().for_each(|x| *x /= total);
        let lo = points
            .iter()
            .fold(DVec2::splat(f64::INFINITY), |a, b| a.min(*b));
        let hi = points
            .iter()
            .fold(DVec2::splat(f64::NEG_INFINITY), |a, b| a.max(*b));
        Curve { points, t, lo, hi }
    }

    /// Distance from `q` to the curve and the normalised arc length of the nearest point, or
    /// `None` when `q` is farther than `reach` from the curve's bounding box.
    pub fn nearest(&self, q: DVec2, reach: f64) -> Option<(f64, f64)> {
        if q.x < self.lo.x - reach
            || q.y < self.lo.y - reach
            || q.x > self.hi.x + reach
            || q.y > self.hi.y + reach
        {
            return None;
        }
        let mut best = (f64::INFINITY, 0.0);
        for (i, w) in self.points.windows(2).enumerate() {
            let d = w[1] - w[0];
            let l2 = d.length_squared();
            let x = if l2 > 0.0 {
                ((q - w[0]).dot(d) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let dist = q.distance(w[0] + d * x);
            if dist < best.0 {
                best = (dist, self.t[i] + (self.t[i + 1] - self.t[i]) * x);
            }
        }
        Some(best)
    }
}

/// A palm crease: its curve, darkness and half-width.
#[derive(Debug, Clone)]
pub(super) struct Crease {
    pub curve: Curve,
    pub depth: f64,
    pub width: f64,
}

/// The palm creases of one hand of one person: the three major lines (heart, head, life), two
/// wrist bracelets and, for some people, a faint vertical (fate) line.
///
/// Control points are in palm units (see [`PalmFrame::metres`]), jittered per person by
/// `seed` and a little more per hand by `side_seed`.
pub(super) fn palm_creases(palm: &PalmFrame, seed: u64, side_seed: u64) -> Vec<Crease> {
    let mut rng = SplitMix64::new(derive(seed, 0xC2EA5E));
    let mut side_rng = SplitMix64::new(derive(side_seed, 0xC2EA5E));
    let mut jitter = |pts: &[[f64; 2]], du: f64, dw: f64, rng: &mut SplitMix64| -> Vec<DVec2> {
        // One shared offset per curve plus a smaller one per control point.
        let (su, sw) = (rng.normal() * du, rng.normal() * dw);
        pts.iter()
            .map(|p| {
                let u = p[0] + su + 0.25 * du * rng.normal() + 0.2 * du * side_rng.normal();
                let w = p[1] + sw + 0.25 * dw * rng.normal() + 0.2 * dw * side_rng.normal();
                palm.metres(DVec2::new(u, w))
            })
            .collect()
    };
    let heart = jitter(
        &[
            [0.73, -2.35],
            [0.76, -1.3],
            [0.8, -0.2],
            [0.86, 0.55],
            [0.93, 0.95],
        ],
        0.02,
        0.12,
        &mut rng,
    );
    let head = jitter(
        &[
            [0.69, 2.3],
            [0.67, 1.3],
            [0.62, 0.2],
            [0.56, -0.8],
            [0.5, -1.5],
        ],
        0.025,
        0.15,
        &mut rng,
    );
    let life = jitter(
        &[
            [0.68, 2.25],
            [0.6, 1.55],
            [0.47, 1.05],
            [0.3, 0.8],
            [0.14, 0.78],
            [0.03, 0.85],
        ],
        0.02,
        0.12,
        &mut rng,
    );
    let bracelet = |u: f64, rng: &mut SplitMix64| {
        let pts: Vec<DVec2> = (0..7)
            .map(|i| {
                let w = -1.9 + 3.8 * f64::from(i) / 6.0;
                palm.metres(DVec2::new(
                    u + 0.006 * rng.normal() - 0.012 * (w / 1.9).powi(2),
                    w,
                ))
            })
            .collect();
        Curve::through(&pts, 8)
    };
    let mut creases = vec![
        Crease {
            curve: Curve::through(&heart, 10),
            depth: rng.range(0.8, 1.1),
            width: 0.00045,
        },
        Crease {
            curve: Curve::through(&head, 10),
            depth: rng.range(0.7, 1.0),
            width: 0.0004,
        },
        Crease {
            curve: Curve::through(&life, 10),
            depth: rng.range(0.75, 1.05),
            width: 0.00045,
        },
        Crease {
            curve: bracelet(0.035, &mut rng),
            depth: 0.45,
            width: 0.0003,
        },
        Crease {
            curve: bracelet(0.07, &mut rng),
            depth: 0.35,
            width: 0.00028,
        },
    ];
    if rng.next_f64() < 0.5 {
        let fate = jitter(
            &[[0.12, 0.1], [0.35, 0.05], [0.58, -0.05]],
            0.03,
            0.2,
            &mut rng,
        );
        creases.push(Crease {
            curve: Curve::through(&fate, 10),
            depth: 0.35,
            width: 0.0003,
        });
    }
    creases
}

/// A vein: its curve (metric palm coordinates) and its half-width at both ends.
#[derive(Debug, Clone)]
pub(super) struct Vein {
    pub curve: Curve,
    pub width: [f64; 2],
}

impl Vein {
    /// Half-width at normalised arc length `t`.
    pub(crate) fn width_at(&self, t: f64) -> f64 {
        self.width[0] + (self.width[1] - self.width[0]) * t
    }
}

/// The dorsal venous network of one person: three to five veins from the wrist towards the
/// gaps between the knuckles, joined by an arch across the back of the hand, with a few side
/// branches. Each vein is a smooth spline through a few jittered control points, laid out in
/// palm units and converted to metres.
pub(super) fn dorsal_veins(palm: &PalmFrame, seed: u64) -> Vec<Vein> {
    let mut rng = SplitMix64::new(derive(seed, 0x7E1A5));
    let to_curve = |pts: &[DVec2]| {
        let metric: Vec<DVec2> = pts.iter().map(|p| palm.metres(*p)).collect();
        Curve::through(&metric, 12)
    };
    // A gently bending path from `a` to `b` (palm units) with `n` interior control points.
    let path = |rng: &mut SplitMix64, a: DVec2, b: DVec2, n: usize, bend: f64| -> Vec<DVec2> {
        let side = rng.normal() * bend;
        let mut pts = vec![a];
        for i in 1..=n {
            let t = i as f64 / (n + 1) as f64;
            let bow = side * (std::f64::consts::PI * t).sin();
            pts.push(
                a.lerp(b, t) + DVec2::new(0.02 * rng.normal(), bow + 0.12 * bend * rng.normal()),
            );
        }
        pts.push(b);
        pts
    };
    let count = 3 + (rng.next_u64() % 3) as usize;
    let mut veins = Vec::new();
    let mut mains: Vec<Vec<DVec2>> = Vec::new();
    for i in 0..count {
        let f = (i as f64 + 0.5) / count as f64;
        let from = DVec2::new(-0.1, -1.8 + 3.6 * f + 0.25 * rng.normal());
        let gap = -1.5 + 3.0 * f + 0.3 * rng.normal();
        let to = DVec2::new(rng.range(0.72, 0.86), gap.clamp(-1.6, 1.8));
        let pts = path(&mut rng, from, to, 3, 0.35);
        veins.push(Vein {
            curve: to_curve(&pts),
            width: [rng.range(0.0021, 0.0029), rng.range(0.0012, 0.0017)],
        });
        mains.push(pts);
    }
    let on = |pts: &[DVec2], t: f64| {
        let c = Curve::through(pts, 12);
        let k = ((c.points.len() - 1) as f64 * t) as usize;
        c.points[k]
    };
    // The arch: a curved connection between neighbouring veins.
    for pair in mains.windows(2) {
        if rng.next_f64() < 0.8 {
            let a = on(&pair[0], rng.range(0.4, 0.7));
            let b = on(&pair[1], rng.range(0.4, 0.7));
            let mid = (a + b) * 0.5 + DVec2::new(rng.range(0.04, 0.1), 0.15 * rng.normal());
            veins.push(Vein {
                curve: to_curve(&[a, mid, b]),
                width: [rng.range(0.0013, 0.0018), rng.range(0.0013, 0.0018)],
            });
        }
    }
    // Side branches.
    let branches = 2 + (rng.next_u64() % 4) as usize;
    for _ in 0..branches {
        let main = &mains[(rng.next_u64() % mains.len() as u64) as usize];
        let from = on(main, rng.range(0.2, 0.75));
        let dir = if rng.next_f64() < 0.5 { -1.0 } else { 1.0 };
        let to = from + DVec2::new(rng.range(0.12, 0.25), dir * rng.range(0.4, 0.9));
        let pts = path(&mut rng, from, to, 1, 0.2);
        veins.push(Vein {
            curve: to_curve(&pts),
            width: [rng.range(0.001, 0.0014), 0.0005],
        });
    }
    veins
}

/// `a` wrapped into `(-pi, pi]`.
pub(super) fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI { w - 2.0 * PI } else { w }
}
