//! Rigging: skinning weights, the joint regressor, shape and pose blend shapes, the mean pose.
//!
//! Everything here is computed for the right hand in the wrist-centred frame; the left hand is
//! derived by mirroring (see the parent module).

use std::f64::consts::{FRAC_PI_2, PI};

use glam::{DMat3, DVec3};

use super::section::{bell, smoothstep, wrap_angle};
use super::skeleton::{Skeleton, THUMB};
use super::surface::{Anchor, Surface};
use super::tube::{Piece, Row, Tube};
use crate::model::{NUM_BETAS, NUM_JOINTS, NUM_POSE, NUM_POSE_FEATURES};

/// Linear ramp from 0 at `centre - half` to 1 at `centre + half`.
fn ramp(s: f64, centre: f64, half: f64) -> f64 {
    ((s - centre + half) / (2.0 * half)).clamp(0.0, 1.0)
}

/// Skinning weights of one chain position: `(joint, weight)` for the wrist and the chain's
/// three joints. Each joint's influence ramps in linearly over a band around it; the band
/// half-width grows with the digit's radius so that even a right-angle bend does not fold the
/// skin on the inside of the joint.
fn chain_weights(
    skel: &Skeleton,
    thumb_base: (f64, f64),
    chain_id: usize,
    s: f64,
) -> [(usize, f64); 4] {
    let chain = &skel.chains[chain_id];
    let r = chain.radius;
    let rho = if chain_id == THUMB {
        let (lo, hi) = thumb_base;
        [
            ramp(s, 0.5 * (lo + hi), 0.5 * (hi - lo).max(1e-4)),
            ramp(s, chain.s[1], 0.85 * r),
            ramp(s, chain.s[2], 0.75 * r),
        ]
    } else {
        let (l1, l2) = (chain.s[2] - chain.s[1], chain.s[3] - chain.s[2]);
        [
            ramp(s, 0.0, (1.5 * r).max(0.62 * skel.palm_thickness)),
            ramp(s, chain.s[1], (1.0 * r).min(0.42 * l1)),
            ramp(s, chain.s[2], (0.7 * r).min(0.3 * l1).min(0.4 * l2)),
        ]
    };
    let [a, b, c] = chain.joint_ids;
    [
        (0, 1.0 - rho[0]),
        (a, rho[0] - rho[1]),
        (b, rho[1] - rho[2]),
        (c, rho[2]),
    ]
}

/// Share of the thumb's CMC in the skinning weights of the rim of the palm's thumb opening.
const THENAR_EDGE: f64 = 0.6;
/// Distance from the opening over which the palm stops following the thumb's CMC.
const THENAR_REACH: f64 = 0.035;
/// Distance from the wrist over which the thenar's following of the CMC fades in.
const THENAR_WRIST: f64 = 0.02;

/// Skinning weights, `[V, NUM_JOINTS]` row-major: the mean of the vertex's anchors' chain
/// weights.
///
/// The palm around the thumb opening (the thenar eminence) also follows the thumb's CMC a
/// little, fading out with the distance from the opening and towards the wrist, and the
/// thumb's loft blends from the weights of the opening's rim to those of its first round ring:
/// bending the CMC then spreads over the loft and the palm around it.
pub(super) fn skinning_weights(skel: &Skeleton, surface: &Surface) -> Vec<f64> {
    let cmc = skel.chains[THUMB].joint_ids[0];
    let thumb = surface
        .tubes
        .iter()
        .find(|t| t.piece == Piece::Thumb)
        .expect("thumb tube");
    let rim = thumb.rows[0].positions();
    let mut w = vec![0.0; surface.positions.len() * NUM_JOINTS];
    for (v, (p, anchors)) in surface.positions.iter().zip(&surface.anchors).enumerate() {
        let row = &mut w[v * NUM_JOINTS..(v + 1) * NUM_JOINTS];
        let share = 1.0 / anchors.len() as f64;
        for a in anchors {
            for (j, x) in anchor_weights(skel, surface, a) {
                row[j] += share * x;
            }
        }
        if anchors.iter().all(|a| a.chain != THUMB) {
            let d = rim
                .iter()
                .map(|q| q.distance(*p))
                .fold(f64::INFINITY, f64::min);
            let follow = THENAR_EDGE
                * (1.0 - smoothstep(d / THENAR_REACH))
                * smoothstep(-p.x / THENAR_WRIST);
            row.iter_mut().for_each(|x| *x *= 1.0 - follow);
            row[cmc] += follow;
        }
    }
    blend_thumb_loft(&mut w, surface, thumb);
    w
}

/// Distance beyond the web over which a finger stops sharing its neighbours' weights.
const WEB_FADE: f64 = 0.012;

/// Weights of one anchor: its chain's, blended towards the neighbouring finger's near the
/// side facing it (half-and-half at the web itself), so that two fingers bending about
/// different knuckles stretch the web between them smoothly instead of shearing it.
fn anchor_weights(skel: &Skeleton, surface: &Surface, a: &Anchor) -> Vec<(usize, f64)> {
    let own = chain_weights(skel, surface.thumb_base, a.chain, a.s);
    let mut row: Vec<(usize, f64)> = own.to_vec();
    if a.chain == THUMB {
        return row;
    }
    let fade = 1.0 - smoothstep((a.s - surface.web_s[a.chain]) / WEB_FADE);
    for (side, neighbour) in [
        (FRAC_PI_2, a.chain + 1),
        (3.0 * FRAC_PI_2, a.chain.wrapping_sub(1)),
    ] {
        if neighbour >= 4 {
            continue;
        }
        let off = wrap_angle(a.phi - side).abs();
        let eta = 0.5 * (1.0 - smoothstep(off / (PI / 3.0))) * fade;
        if eta > 0.0 {
            row.iter_mut().for_each(|(_, x)| *x *= 1.0 - eta);
            row.extend(
                chain_weights(skel, surface.thumb_base, neighbour, a.s).map(|(j, x)| (j, eta * x)),
            );
        }
    }
    row
}

/// Gives each vertex of the thumb's loft (the rows before its first round ring) a blend of the
/// weights of the rim vertex it rises from and of the first round ring.
fn blend_thumb_loft(w: &mut [f64], surface: &Surface, thumb: &Tube) {
    let (s_rim, s_free) = surface.thumb_base;
    let slots = |row: &Row| -> Vec<u32> {
        match row {
            Row::Ring { slots, .. } => slots.iter().flatten().copied().collect(),
            Row::Pole { vertex, .. } => vec![*vertex],
        }
    };
    let rim = slots(&thumb.rows[0]);
    let loft: Vec<Vec<u32>> = thumb.rows[1..]
        .iter()
        .map(slots)
        .take_while(|r| surface.anchors[r[0] as usize][0].s < s_free - 1e-12)
        .collect();
    let Some(free) = thumb.rows.get(loft.len() + 1).map(slots) else {
        return;
    };
    let target: Vec<f64> = w[free[0] as usize * NUM_JOINTS..][..NUM_JOINTS].to_vec();
    for row in &loft {
        let t = ((surface.anchors[row[0] as usize][0].s - s_rim) / (s_free - s_rim).max(1e-6))
            .clamp(0.0, 1.0);
        for (v, r) in row.iter().zip(&rim) {
            for j in 0..NUM_JOINTS {
                let from = w[*r as usize * NUM_JOINTS + j];
                w[*v as usize * NUM_JOINTS + j] = from + (target[j] - from) * t;
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Joint regressor

/// Non-negative weights summing to one with `sum w_i p_i = target`, as close as possible (in a
/// chi-square sense) to `base`. Points whose weight would turn negative are dropped and the
/// system is solved again.
fn convex_weights(points: &[DVec3], base: &[f64], target: DVec3) -> Vec<f64> {
    let mut b: Vec<f64> = base.to_vec();
    let mut w = b.clone();
    for _ in 0..32 {
        let total: f64 = b.iter().sum();
        let mean = points.iter().zip(&b).map(|(p, x)| *p * *x).sum::<DVec3>() / total;
        let mut cov = DMat3::ZERO;
        for (p, x) in points.iter().zip(&b) {
            let d = *p - mean;
            cov += DMat3::from_cols(d * d.x, d * d.y, d * d.z) * (*x / total);
        }
        let lambda = if cov.determinant().abs() > 1e-30 {
            cov.inverse() * (target - mean)
        } else {
            DVec3::ZERO
        };
        w = points
            .iter()
            .zip(&b)
            .map(|(p, x)| x / total * (1.0 + (*p - mean).dot(lambda)))
            .collect();
        if w.iter().all(|x| *x >= 0.0) {
            return w;
        }
        for (bi, wi) in b.iter_mut().zip(&w) {
            if *wi < 0.0 {
                *bi = 0.0;
            }
        }
    }
    let total: f64 = w.iter().map(|x| x.max(0.0)).sum();
    w.iter().map(|x| x.max(0.0) / total).collect()
}

/// Distinct ring vertices of `rows` (poles included), each with the given row weight.
fn row_vertices(tube: &Tube, rows: &[(usize, f64)], keep: impl Fn(u32) -> bool) -> Vec<(u32, f64)> {
    let mut out: Vec<(u32, f64)> = Vec::new();
    for &(r, weight) in rows {
        let verts: Vec<u32> = match &tube.rows[r] {
            Row::Pole { vertex, .. } => vec![*vertex],
            Row::Ring { slots, .. } => slots
                .iter()
                .flatten()
                .copied()
                .filter(|v| keep(*v))
                .collect(),
        };
        let share = weight / verts.len().max(1) as f64;
        for v in verts {
            match out.iter_mut().find(|(u, _)| *u == v) {
                Some(entry) => entry.1 += share,
                None => out.push((v, share)),
            }
        }
    }
    out
}

/// The rows `r - 1, r, r + 1` around row `r` with tent weights, clamped to the tube.
fn tent(tube: &Tube, r: usize) -> Vec<(usize, f64)> {
    let last = tube.rows.len() - 1;
    let r = r.clamp(1, last - 1);
    vec![(r - 1, 0.25), (r, 0.5), (r + 1, 0.25)]
}

/// The row of `tube` whose anchors on `chain` lie closest to arc length `s`.
fn nearest_row(surface: &Surface, tube: &Tube, chain: usize, s: f64) -> usize {
    let distance = |row: &Row| -> f64 {
        let verts: Vec<u32> = match row {
            Row::Pole { vertex, .. } => vec![*vertex],
            Row::Ring { slots, .. } => slots.iter().flatten().copied().collect(),
        };
        verts
            .iter()
            .flat_map(|v| surface.anchors[*v as usize].iter())
            .filter(|a| a.chain == chain)
            .map(|a| (a.s - s).abs())
            .fold(f64::INFINITY, f64::min)
    };
    (0..tube.rows.len())
        .min_by(|&a, &b| distance(&tube.rows[a]).total_cmp(&distance(&tube.rows[b])))
        .unwrap_or(0)
}

/// Joint regressor, `[NUM_JOINTS, V]` row-major: each joint a convex combination of the
/// vertices on the few rings around it that reproduces its rest position exactly.
pub(super) fn joint_regressor(skel: &Skeleton, surface: &Surface) -> Vec<f64> {
    let v_count = surface.positions.len();
    let joints = skel.joints();
    let tube = |piece: Piece| {
        surface
            .tubes
            .iter()
            .find(|t| t.piece == piece)
            .expect("tube present")
    };
    let on_chain =
        |chain: usize| move |v: u32| surface.anchors[v as usize].iter().any(|a| a.chain == chain);
    let mut candidates: Vec<Vec<(u32, f64)>> = vec![Vec::new(); NUM_JOINTS];

    let palm = tube(Piece::Palm);
    candidates[0] = row_vertices(palm, &tent(palm, surface.palm_cap_rows), |_| true);
    for (f, chain) in skel.chains.iter().enumerate().take(4) {
        let r = nearest_row(surface, palm, f, 0.0);
        candidates[chain.joint_ids[0]] = row_vertices(palm, &tent(palm, r), on_chain(f));
        let finger = tube(Piece::Finger(f));
        for k in 1..3 {
            let r = nearest_row(surface, finger, f, chain.s[k]);
            candidates[chain.joint_ids[k]] = row_vertices(finger, &tent(finger, r), |_| true);
        }
    }
    let chain = &skel.chains[THUMB];
    let thumb = tube(Piece::Thumb);
    let cmc_row = nearest_row(
        surface,
        palm,
        0,
        (chain.points[0] - skel.chains[0].points[0]).dot(skel.chains[0].segment_dir(0)),
    );
    let mut cmc = row_vertices(palm, &tent(palm, cmc_row), on_chain(0));
    cmc.extend(row_vertices(thumb, &[(1, 0.5), (2, 0.5)], |_| true));
    candidates[chain.joint_ids[0]] = cmc;
    for k in 1..3 {
        let r = nearest_row(surface, thumb, THUMB, chain.s[k]);
        candidates[chain.joint_ids[k]] = row_vertices(thumb, &tent(thumb, r), |_| true);
    }

    let mut regressor = vec![0.0; NUM_JOINTS * v_count];
    for (j, cands) in candidates.iter().enumerate() {
        let points: Vec<DVec3> = cands
            .iter()
            .map(|(v, _)| surface.positions[*v as usize])
            .collect();
        let base: Vec<f64> = cands.iter().map(|c| c.1).collect();
        for ((v, _), w) in cands.iter().zip(convex_weights(&points, &base, joints[j])) {
            regressor[j * v_count + *v as usize] += w;
        }
    }
    regressor
}

// ---------------------------------------------------------------------------------------------
// Blend shapes

/// Per unit beta: overall scale, finger length, palm width, digit thickness, palm thickness,
/// thumb length, digit taper, palm length, finger splay, radial-vs-ulnar finger length.
const SHAPE_AMPLITUDE: [f64; NUM_BETAS] =
    [0.03, 0.035, 0.04, 0.05, 0.05, 0.04, 0.2, 0.04, 0.06, 0.03];
/// Relative splay of each finger for the splay blend shape (index .. pinky, thumb).
const SPLAY_SHAPE: [f64; 5] = [1.0, 0.0, -1.0, -2.0, 1.0];
/// Relative length change of each finger for the radial-vs-ulnar blend shape.
const BALANCE_SHAPE: [f64; 4] = [1.0, 0.4, -0.4, -1.0];

/// How much of a digit (rather than of the palm) an anchor is: 0 on the palm, 1 from the
/// finger's knuckle band (or the end of the thumb's loft) on.
fn digit_share(skel: &Skeleton, thumb_base: (f64, f64), a: &Anchor) -> f64 {
    if a.chain == THUMB {
        let (lo, hi) = thumb_base;
        smoothstep((a.s - lo) / (hi - lo).max(1e-6))
    } else {
        1.0 - chain_weights(skel, thumb_base, a.chain, a.s)[0].1
    }
}

/// Unit displacements of one vertex for every beta.
fn shape_displacements(
    skel: &Skeleton,
    thumb_base: (f64, f64),
    p: DVec3,
    anchors: &[Anchor],
) -> [DVec3; NUM_BETAS] {
    let mut d = [DVec3::ZERO; NUM_BETAS];
    let share = 1.0 / anchors.len() as f64;
    let zc = skel.knuckle_centre_z;
    d[0] = p;
    for a in anchors {
        let chain = &skel.chains[a.chain];
        let g = digit_share(skel, thumb_base, a);
        let root = chain.points[0];
        let radial = p - a.centre;
        d[2] += DVec3::Z * ((1.0 - g) * (p.z - zc) + g * (root.z - zc)) * share;
        d[3] += radial * g * share;
        d[4] += DVec3::Y * ((1.0 - g) * radial.y) * share;
        d[7] += DVec3::X * ((1.0 - g) * p.x + g * root.x) * share;
        let along = a.s.max(0.0);
        if a.chain == THUMB {
            d[5] += (chain.point(along) - root) * g * share;
        } else {
            d[1] += chain.segment_dir(0) * along * share;
            d[9] += chain.segment_dir(0) * along * BALANCE_SHAPE[a.chain] * share;
        }
        let taper = (a.s / chain.length()).clamp(0.0, 1.0) - 0.5;
        d[6] += radial * g * taper * share;
        d[8] += DVec3::Y.cross(p - root) * g * SPLAY_SHAPE[a.chain] * share;
    }
    d
}

/// Shape blend shapes, `[V, 3, NUM_BETAS]` row-major.
pub(super) fn shape_dirs(skel: &Skeleton, surface: &Surface) -> Vec<f64> {
    let mut out = vec![0.0; surface.positions.len() * 3 * NUM_BETAS];
    for (v, (p, anchors)) in surface.positions.iter().zip(&surface.anchors).enumerate() {
        let d = shape_displacements(skel, surface.thumb_base, *p, anchors);
        for (b, (dir, amp)) in d.iter().zip(SHAPE_AMPLITUDE).enumerate() {
            for c in 0..3 {
                out[(v * 3 + c) * NUM_BETAS + b] = dir[c] * amp;
            }
        }
    }
    out
}

/// Knuckle bulge (metres, for a right-angle bend of a digit of radius 9.5 mm) at each joint of
/// a finger and of the thumb.
const BULGE: [[f64; 3]; 2] = [[0.0022, 0.0014, 0.0010], [0.0, 0.0012, 0.0009]];
/// Length (along the digit) of the bulge at each joint.
const BULGE_WIDTH: [f64; 3] = [0.006, 0.0045, 0.0045];

/// Pose blend shapes, `[V, 3, NUM_POSE_FEATURES]` row-major: the back of each knuckle bulges
/// out by `BULGE * (1 - cos angle)` as the joint bends. `1 - cos angle` is minus half the sum of
/// the diagonal of `R - I`, so only the three diagonal features of each joint are used (which
/// keeps the mirror image exact: those features are the same for both hands).
pub(super) fn pose_dirs(skel: &Skeleton, surface: &Surface) -> Vec<f64> {
    let mut out = vec![0.0; surface.positions.len() * 3 * NUM_POSE_FEATURES];
    for (v, (p, anchors)) in surface.positions.iter().zip(&surface.anchors).enumerate() {
        let share = 1.0 / anchors.len() as f64;
        for a in anchors {
            let chain = &skel.chains[a.chain];
            let normal = (*p - a.centre).normalize_or_zero();
            let back = a.phi.cos().max(0.0).powi(2);
            let bulge = BULGE[usize::from(a.chain == THUMB)];
            let joints = chain
                .joint_ids
                .iter()
                .zip(&chain.s)
                .zip(bulge)
                .zip(BULGE_WIDTH);
            for (((joint, s_joint), amp), width) in joints {
                let height =
                    amp * chain.radius / 0.0095 * back * bell((a.s - s_joint) / width) * share;
                let feature = (joint - 1) * 9;
                for c in 0..3 {
                    for diag in [0, 4, 8] {
                        out[(v * 3 + c) * NUM_POSE_FEATURES + feature + diag] -=
                            0.5 * height * normal[c];
                    }
                }
            }
        }
    }
    out
}

/// Relaxed flexion (radians) of a finger's MCP, PIP and DIP.
const RELAXED: [f64; 3] = [0.25, 0.4, 0.2];
/// How much more each finger (index .. pinky) curls when relaxed.
const RELAXED_SCALE: [f64; 4] = [0.85, 1.0, 1.12, 1.25];
/// Relaxed flexion (radians) of the thumb's CMC, MCP and IP.
const RELAXED_THUMB: [f64; 3] = [0.15, 0.25, 0.2];

/// The mean pose: every joint slightly flexed about its own flexion axis, `[NUM_POSE]`.
pub(super) fn pose_mean(skel: &Skeleton) -> Vec<f64> {
    let mut mean = vec![0.0; NUM_POSE];
    for (c, chain) in skel.chains.iter().enumerate() {
        for k in 0..3 {
            let angle = if c == THUMB {
                RELAXED_THUMB[k]
            } else {
                RELAXED[k] * RELAXED_SCALE[c]
            };
            let aa = chain.flexion_axis(k) * angle;
            let j = chain.joint_ids[k] - 1;
            mean[3 * j..3 * j + 3].copy_from_slice(&aa.to_array());
        }
    }
    mean
}
