//! Interacting two-hand poses of the kinds InterHand2.6M has, built from [`HandParams`].
//!
//! # Frames
//!
//! Poses are designed in a *person frame*: `x` towards the person's left, `y` up, `z` forward
//! (away from the chest), metres, right-handed; the hands sit around the origin in front of
//! the chest. A camera in front of the person (on `+z`, looking back) sees the person's left
//! hand on the right of the image, as in a photo.
//!
//! Each hand is placed by three directions: where its fingers point (`f`, the metacarpal
//! direction), where its palm faces (`p`), and where its wrist joint is. The hand models are
//! in MANO's frame (right hand: fingers `-x`, palm `-y`, thumb `+z`; the left hand is the
//! x-mirror: fingers `+x`, palm `-y`, thumb `+z`), so the root rotation maps the model's
//! finger axis to `f` and its palm normal to `p`; the thumb then lands on `f x p` for the
//! right hand and on `p x f` for the left.
//!
//! Finger articulation is axis-angle about each joint's own flexion axis (the direction of
//! the model's relaxed mean pose at that joint) plus an abduction about `segment x flexion` at
//! the base joints, designed in right-hand terms and mirrored (`(x, y, z) -> (x, -y, -z)`)
//! for the left hand, so that one curl value means the same motion on both hands.
//!
//! # Contact
//!
//! Each family gives a *push axis*. After both hands are posed, the right hand slides along
//! that axis to the first position where the two hands' capsule skeletons (bones with their
//! radii, the palm as a fan of capsules) overlap by at most [`CONTACT_TOLERANCE`]: the hands
//! touch but do not interpenetrate grossly.

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::lbs::{HandParams, HandPose};
use bitt_mesh::model::{NUM_BETAS, NUM_POSE};
use bitt_mesh::{HandModel, HandPair, Side};
use bitt_texture::procedural::noise::SplitMix64;

use crate::SynthError;

/// Largest overlap (metres) of two capsules of different hands that still counts as contact
/// (skin gives a little; the capsules are slightly slimmer than the surface too).
pub(crate) const CONTACT_TOLERANCE: f64 = 0.002;

/// The interacting-pose families.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseFamily {
    /// Hands clasped, fingers interlocked and wrapped around the other hand's back.
    Clasp,
    /// Palms facing in a V, straight fingers interlaced.
    Interlaced,
    /// Right palm resting on the back of the left hand, both palms down.
    PalmOnBack,
    /// Right hand palm up, left hand palm down lying across it.
    PalmOverPalm,
    /// Side by side: right palm up, left palm down, edges touching.
    SideBySide,
    /// Right hand a finger gun, the left hand cupping it from below.
    FingerGun,
    /// Right thumb and index pinching the left index fingertip.
    Pinch,
    /// Right fist pressed into the open left palm.
    FistInPalm,
    /// Palms pressed together, fingers up.
    Prayer,
}

impl PoseFamily {
    /// Every family, in a fixed order.
    pub const ALL: [PoseFamily; 9] = [
        PoseFamily::Clasp,
        PoseFamily::Interlaced,
        PoseFamily::PalmOnBack,
        PoseFamily::PalmOverPalm,
        PoseFamily::SideBySide,
        PoseFamily::FingerGun,
        PoseFamily::Pinch,
        PoseFamily::FistInPalm,
        PoseFamily::Prayer,
    ];

    /// Relative frequency in generated scenes: open, side-showing poses more often than
    /// fists, which hide most of a hand (tuned towards the paper's Table 3).
    pub fn weight(self) -> f64 {
        match self {
            PoseFamily::Interlaced
            | PoseFamily::PalmOnBack
            | PoseFamily::SideBySide
            | PoseFamily::Pinch => 1.5,
            PoseFamily::FistInPalm => 0.6,
            PoseFamily::Clasp | PoseFamily::PalmOverPalm | PoseFamily::FingerGun => 0.9,
            PoseFamily::Prayer => 1.0,
        }
    }
}

/// Finger articulation of one hand, in right-hand terms. Digits: thumb, index, middle, ring,
/// pinky.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Digits {
    /// Flexion (radians) of each digit's three joints, base first (positive curls towards
    /// the palm).
    pub curl: [[f64; 3]; 5],
    /// Abduction at each digit's base joint (radians).
    pub spread: [f64; 5],
}

impl Digits {
    /// Every digit with the same three flexions, no spread.
    fn uniform(curl: [f64; 3]) -> Self {
        Digits {
            curl: [curl; 5],
            spread: [0.0; 5],
        }
    }

    /// With the four fingers (not the thumb) set to `curl`.
    fn fingers(mut self, curl: [f64; 3]) -> Self {
        for d in 1..5 {
            self.curl[d] = curl;
        }
        self
    }

    /// With the thumb set to `curl`.
    fn thumb(mut self, curl: [f64; 3]) -> Self {
        self.curl[0] = curl;
        self
    }

    /// With the four fingers fanned out by `amount` (index towards the thumb, pinky away).
    fn fanned(mut self, amount: f64) -> Self {
        for (d, k) in [(1, 1.0), (2, 0.0), (3, -0.8), (4, -1.6)] {
            self.spread[d] = k * amount;
        }
        self
    }

    /// Adds independent random jitter (`amount` radians, about one standard deviation) to
    /// every flexion and spread; flexions stay at or above a slight hyperextension.
    fn jittered(mut self, rng: &mut SplitMix64, amount: f64) -> Self {
        for d in 0..5 {
            for k in 0..3 {
                self.curl[d][k] = (self.curl[d][k] + amount * rng.normal()).max(-0.15);
            }
            self.spread[d] += 0.5 * amount * rng.normal();
        }
        self
    }
}

/// Skeleton joint ids of each digit (thumb, index, middle, ring, pinky), base first.
const DIGIT_JOINTS: [[usize; 3]; 5] = [[13, 14, 15], [1, 2, 3], [4, 5, 6], [10, 11, 12], [7, 8, 9]];
/// Index into `HandModel::fingertips` of each digit (thumb, index, middle, ring, pinky).
const DIGIT_TIP: [usize; 5] = [0, 1, 2, 3, 4];

/// Per-joint flexion and abduction axes of the right hand, read from a hand model.
#[derive(Debug, Clone)]
pub struct Rig {
    /// Flexion axis of skeleton joint `j` (index `j - 1`), unit, right-hand frame.
    flex: [DVec3; 15],
    /// Abduction axis of joint `j` (index `j - 1`), unit, right-hand frame.
    abduct: [DVec3; 15],
}

impl Rig {
    /// Reads the axes from the right hand model: flexion along its relaxed mean pose, abduction
    /// along `segment x flexion`.
    ///
    /// # Errors
    /// When the model is not a right hand or its mean pose has a joint with no flexion.
    pub fn new(right: &HandModel) -> Result<Self, SynthError> {
        if right.side != Side::Right {
            return Err(SynthError::Generate(
                "the pose rig needs the right hand model".into(),
            ));
        }
        if right.pose_pca_mean.len() != NUM_POSE {
            return Err(SynthError::Generate(format!(
                "{}: the mean pose has {} values, expected {NUM_POSE}",
                right.source,
                right.pose_pca_mean.len()
            )));
        }
        let joints = right.regress_joints(&right.v_template);
        let mut flex = [DVec3::ZERO; 15];
        let mut abduct = [DVec3::ZERO; 15];
        for (d, ids) in DIGIT_JOINTS.iter().enumerate() {
            let tip = right
                .v_template
                .get(right.fingertips[DIGIT_TIP[d]] as usize)
                .copied()
                .ok_or_else(|| SynthError::Generate("fingertip vertex out of range".into()))?;
            for (k, &j) in ids.iter().enumerate() {
                let m = &right.pose_pca_mean[3 * (j - 1)..3 * j];
                let axis = DVec3::new(m[0], m[1], m[2]);
                if axis.length() < 1e-6 {
                    return Err(SynthError::Generate(format!(
                        "{}: joint {j} has no flexion in the mean pose; cannot find its axis",
                        right.source
                    )));
                }
                let child = if k < 2 { joints[ids[k + 1]] } else { tip };
                let seg = (child - joints[j]).normalize_or(DVec3::NEG_X);
                flex[j - 1] = axis.normalize();
                abduct[j - 1] = seg.cross(flex[j - 1]).normalize_or(DVec3::Y);
            }
        }
        Ok(Rig { flex, abduct })
    }

    /// The 45 axis-angle values of `digits` for `side` (mirrored for the left hand).
    pub fn axis_angles(&self, digits: &Digits, side: Side) -> Vec<f64> {
        let mut out = vec![0.0; NUM_POSE];
        for (d, ids) in DIGIT_JOINTS.iter().enumerate() {
            for (k, &j) in ids.iter().enumerate() {
                let mut aa = self.flex[j - 1] * digits.curl[d][k];
                if k == 0 {
                    aa += self.abduct[j - 1] * digits.spread[d];
                }
                if side == Side::Left {
                    aa = DVec3::new(aa.x, -aa.y, -aa.z);
                }
                out[3 * (j - 1)..3 * j].copy_from_slice(&aa.to_array());
            }
        }
        out
    }
}

/// The root rotation that points the hand's fingers along `f` with its palm facing `p`
/// (`p` is made orthogonal to `f`).
pub fn root_rotation(side: Side, f: DVec3, p: DVec3) -> DMat3 {
    let f = f.normalize_or(DVec3::Z);
    let p = (p - f * p.dot(f)).normalize_or(f.any_orthonormal_vector());
    match side {
        // Model x -> -f, y -> -p, z -> f x p.
        Side::Right => DMat3::from_cols(-f, -p, f.cross(p)),
        // Model x -> f, y -> -p, z -> p x f.
        Side::Left => DMat3::from_cols(f, -p, p.cross(f)),
    }
}

/// One designed hand: directions, wrist and fingers.
#[derive(Debug, Clone, Copy)]
struct HandDesign {
    f: DVec3,
    p: DVec3,
    wrist: DVec3,
    digits: Digits,
}

/// A designed two-hand arrangement before contact resolution.
#[derive(Debug, Clone, Copy)]
struct Design {
    left: HandDesign,
    right: HandDesign,
    /// Direction the right hand moves to separate from the left.
    push: DVec3,
    /// For the pinch: move the right hand so its pinch point meets the left index tip.
    pinch: bool,
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z).normalize()
}

/// Uniform in `[lo, hi)`.
fn u(rng: &mut SplitMix64, lo: f64, hi: f64) -> f64 {
    rng.range(lo, hi)
}

/// Rotation about `axis` by `angle`.
fn rot(axis: DVec3, angle: f64) -> DMat3 {
    DMat3::from_axis_angle(axis.normalize(), angle)
}

/// The designed arrangement of `family`, with per-scene variation drawn from `rng`.
fn design(family: PoseFamily, rng: &mut SplitMix64) -> Design {
    let relaxed = Digits::uniform([0.15, 0.25, 0.15]).thumb([0.1, 0.15, 0.1]);
    let fist = Digits::uniform([1.15, 1.35, 0.75]).thumb([0.45, 0.6, 0.45]);
    match family {
        PoseFamily::Clasp => {
            let f = v(0.0, u(rng, 0.4, 0.8), 0.8);
            let wrap = [u(rng, 1.1, 1.4), u(rng, 1.0, 1.3), 0.5];
            let d = Digits::uniform(wrap).thumb([0.1, 0.2, 0.2]).fanned(0.12);
            let lateral = f.cross(DVec3::X) * 0.008;
            Design {
                right: HandDesign {
                    f,
                    p: DVec3::X,
                    wrist: DVec3::new(-0.02, 0.0, 0.0) + lateral,
                    digits: d,
                },
                left: HandDesign {
                    f,
                    p: DVec3::NEG_X,
                    wrist: DVec3::new(0.02, 0.0, 0.0) - lateral,
                    digits: d,
                },
                push: DVec3::NEG_X,
                pinch: false,
            }
        }
        PoseFamily::Interlaced => {
            let open = u(rng, 0.35, 0.6);
            let f = v(0.0, 1.0, u(rng, 0.2, 0.6));
            let d = Digits::uniform([0.35, 0.25, 0.1])
                .thumb([0.0, 0.1, 0.1])
                .fanned(0.2);
            let lateral = f.cross(DVec3::X) * 0.009;
            Design {
                right: HandDesign {
                    f: rot(f.cross(DVec3::X), -open * 0.5) * f,
                    p: rot(f.cross(DVec3::X), -open * 0.5) * DVec3::X,
                    wrist: DVec3::new(-0.045, 0.0, 0.0) + lateral,
                    digits: d,
                },
                left: HandDesign {
                    f: rot(f.cross(DVec3::X), open * 0.5) * f,
                    p: rot(f.cross(DVec3::X), open * 0.5) * DVec3::NEG_X,
                    wrist: DVec3::new(0.045, 0.0, 0.0) - lateral,
                    digits: d,
                },
                push: DVec3::NEG_X,
                pinch: false,
            }
        }
        PoseFamily::PalmOnBack => {
            let drape = u(rng, 0.15, 0.45);
            Design {
                left: HandDesign {
                    f: v(u(rng, -0.1, 0.3), 0.0, 1.0),
                    p: DVec3::NEG_Y,
                    wrist: DVec3::new(0.02, 0.0, -0.04),
                    digits: relaxed,
                },
                right: HandDesign {
                    f: v(u(rng, -0.6, -0.1), -0.1, 1.0),
                    p: v(0.0, -1.0, u(rng, -0.1, 0.2)),
                    wrist: DVec3::new(-0.02, 0.0, -0.02),
                    digits: Digits::uniform([drape, drape + 0.1, 0.15]).thumb([0.1, 0.2, 0.1]),
                },
                push: DVec3::Y,
                pinch: false,
            }
        }
        PoseFamily::PalmOverPalm => {
            let cup = u(rng, 0.2, 0.6);
            Design {
                right: HandDesign {
                    f: v(u(rng, 0.2, 0.7), 0.0, 1.0),
                    p: DVec3::Y,
                    wrist: DVec3::new(-0.03, 0.0, -0.03),
                    digits: Digits::uniform([cup * 0.6, cup * 0.7, 0.2]).thumb([0.0, 0.1, 0.1]),
                },
                left: HandDesign {
                    f: v(u(rng, -0.8, -0.2), 0.0, 1.0),
                    p: DVec3::NEG_Y,
                    wrist: DVec3::new(0.04, 0.0, -0.02),
                    digits: Digits::uniform([cup, cup + 0.2, 0.3]).thumb([0.1, 0.2, 0.2]),
                },
                push: DVec3::NEG_Y,
                pinch: false,
            }
        }
        PoseFamily::SideBySide => {
            let tilt = u(rng, -0.3, 0.3);
            Design {
                right: HandDesign {
                    f: v(u(rng, -0.3, 0.1), 0.0, 1.0),
                    p: v(tilt, 1.0, 0.0),
                    wrist: DVec3::new(-0.04, 0.0, 0.0),
                    digits: relaxed.fanned(0.1),
                },
                left: HandDesign {
                    f: v(u(rng, -0.1, 0.3), 0.0, 1.0),
                    p: v(tilt, -1.0, 0.0),
                    wrist: DVec3::new(0.04, 0.0, 0.0),
                    digits: relaxed,
                },
                push: DVec3::NEG_X,
                pinch: false,
            }
        }
        PoseFamily::FingerGun => Design {
            right: HandDesign {
                f: v(0.0, u(rng, -0.1, 0.3), 1.0),
                p: DVec3::X,
                wrist: DVec3::new(0.0, 0.0, 0.0),
                digits: fist
                    .thumb([0.0, 0.0, 0.05])
                    .fanned(0.0)
                    .with_index([0.05, 0.05, 0.05]),
            },
            left: HandDesign {
                f: v(-1.0, 0.0, u(rng, 0.3, 0.9)),
                p: v(0.0, 1.0, u(rng, -0.2, 0.2)),
                wrist: DVec3::new(0.06, -0.05, -0.03),
                digits: Digits::uniform([0.7, 0.8, 0.4]).thumb([0.2, 0.3, 0.2]),
            },
            push: DVec3::Y,
            pinch: false,
        },
        PoseFamily::Pinch => Design {
            left: HandDesign {
                f: v(u(rng, -0.3, 0.2), 1.0, u(rng, -0.2, 0.4)),
                p: v(u(rng, -0.5, 0.2), 0.0, 1.0),
                wrist: DVec3::new(0.05, -0.05, 0.0),
                digits: relaxed.fanned(0.12),
            },
            right: HandDesign {
                f: v(0.8, u(rng, 0.2, 0.6), -0.4),
                p: v(0.0, 0.2, -1.0),
                wrist: DVec3::new(-0.08, 0.0, 0.1),
                digits: fist
                    .fingers([1.2, 1.3, 0.8])
                    .thumb([0.45, 0.35, 0.3])
                    .with_index([0.75, 0.9, 0.45]),
            },
            push: v(-1.0, 0.0, 1.0),
            pinch: true,
        },
        PoseFamily::FistInPalm => Design {
            left: HandDesign {
                f: v(0.0, 1.0, u(rng, 0.0, 0.5)),
                p: DVec3::NEG_X,
                wrist: DVec3::new(0.03, 0.0, 0.0),
                digits: Digits::uniform([0.3, 0.3, 0.15]).thumb([0.1, 0.2, 0.1]),
            },
            right: HandDesign {
                f: DVec3::X,
                p: v(0.0, -1.0, u(rng, -0.5, 0.5)),
                wrist: DVec3::new(-0.06, 0.0, 0.0),
                digits: fist,
            },
            push: DVec3::NEG_X,
            pinch: false,
        },
        PoseFamily::Prayer => {
            let f = v(0.0, 1.0, u(rng, -0.1, 0.5));
            let d = Digits::uniform([0.05, 0.08, 0.05]).thumb([0.0, 0.1, 0.1]);
            Design {
                right: HandDesign {
                    f,
                    p: DVec3::X,
                    wrist: DVec3::new(-0.02, 0.0, 0.0),
                    digits: d,
                },
                left: HandDesign {
                    f,
                    p: DVec3::NEG_X,
                    wrist: DVec3::new(0.02, 0.0, 0.0),
                    digits: d,
                },
                push: DVec3::NEG_X,
                pinch: false,
            }
        }
    }
}

impl Digits {
    /// With the index finger set to `curl`.
    fn with_index(mut self, curl: [f64; 3]) -> Self {
        self.curl[1] = curl;
        self
    }
}

/// Hand parameters placing `model`'s wrist joint at `wrist` (the root rotates about the rest
/// wrist, so the posed wrist is `rest wrist + trans`).
fn params(
    model: &HandModel,
    rig: &Rig,
    betas: &[f64],
    h: &HandDesign,
    frame: DMat3,
    centre: DVec3,
) -> HandParams {
    let rest_wrist = model.regress_joints(&model.shaped_vertices(betas))[0];
    HandParams {
        root_rotation: frame * root_rotation(model.side, h.f, h.p),
        pose: HandPose::AxisAngle(rig.axis_angles(&h.digits, model.side)),
        betas: betas.to_vec(),
        trans: frame * h.wrist + centre - rest_wrist,
    }
}

/// A capsule: segment `a`-`b` with radius `r`.
#[derive(Debug, Clone, Copy)]
struct Capsule {
    a: DVec3,
    b: DVec3,
    r: f64,
}

/// Closest distance between segments `p0-p1` and `q0-q1`.
fn segment_distance(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> f64 {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.dot(d1);
    let e = d2.dot(d2);
    let f = d2.dot(r);
    let (s, t);
    if a <= 1e-12 && e <= 1e-12 {
        return r.length();
    }
    if a <= 1e-12 {
        s = 0.0;
        t = (f / e).clamp(0.0, 1.0);
    } else {
        let c = d1.dot(r);
        if e <= 1e-12 {
            t = 0.0;
            s = (-c / a).clamp(0.0, 1.0);
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s0 = if denom > 1e-12 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                t0 = 0.0;
                s0 = (-c / a).clamp(0.0, 1.0);
            } else if t0 > 1.0 {
                t0 = 1.0;
                s0 = ((b - c) / a).clamp(0.0, 1.0);
            }
            s = s0;
            t = t0;
        }
    }
    ((p0 + d1 * s) - (q0 + d2 * t)).length()
}

/// The capsule skeleton of a posed hand from its 21 output joints (wrist, thumb CMC..tip,
/// index MCP..tip, middle, ring, pinky): phalanges, and the palm as capsules from the wrist
/// region to each knuckle plus one across the knuckles.
fn capsules(joints: &[DVec3], scale: f64) -> Vec<Capsule> {
    let mut out = Vec::with_capacity(24);
    let finger_r = [0.0105, 0.0085, 0.0085, 0.008, 0.007];
    for (d, radius) in finger_r.iter().enumerate() {
        let base = 1 + 4 * d;
        for (k, taper) in [1.0, 0.9, 0.8].iter().enumerate() {
            out.push(Capsule {
                a: joints[base + k],
                b: joints[base + k + 1],
                r: radius * taper * scale,
            });
        }
    }
    let wrist = joints[0];
    let palm_r = 0.012 * scale;
    for d in 1..5 {
        let knuckle = joints[1 + 4 * d];
        // Start a little into the palm so the wrist end does not bulge.
        out.push(Capsule {
            a: wrist + (knuckle - wrist) * 0.15,
            b: knuckle,
            r: palm_r,
        });
    }
    out.push(Capsule {
        a: joints[5],
        b: joints[17],
        r: palm_r,
    });
    // The thenar eminence: wrist region to the thumb MCP.
    out.push(Capsule {
        a: wrist + (joints[9] - wrist) * 0.2,
        b: joints[2],
        r: palm_r,
    });
    out
}

/// Largest overlap of any capsule of `a` with any capsule of `b` (negative: the gap).
fn overlap(a: &[Capsule], b: &[Capsule]) -> f64 {
    let mut worst = f64::NEG_INFINITY;
    for x in a {
        for y in b {
            let d = segment_distance(x.a, x.b, y.a, y.b);
            worst = worst.max(x.r + y.r - d);
        }
    }
    worst
}

/// A generated two-hand pose.
#[derive(Debug, Clone)]
pub struct TwoHandPose {
    /// The family it was drawn from.
    pub family: PoseFamily,
    /// Left hand (person frame).
    pub left: HandParams,
    /// Right hand (person frame).
    pub right: HandParams,
}

/// Draws a two-hand pose of `family` for hands of shape `betas`, jittered from `rng`, with
/// the arrangement turned by a random rotation (up to about 25 degrees about each axis) and
/// its hands touching without gross interpenetration.
///
/// # Errors
/// When posing fails (it does not for valid models and finite betas).
pub fn two_hand_pose(
    models: &HandPair,
    rig: &Rig,
    betas: &[f64],
    family: PoseFamily,
    rng: &mut SplitMix64,
) -> Result<TwoHandPose, SynthError> {
    if betas.len() != NUM_BETAS {
        return Err(SynthError::Generate(format!(
            "{} betas, expected {NUM_BETAS}",
            betas.len()
        )));
    }
    let mut d = design(family, rng);
    d.left.digits = d.left.digits.jittered(rng, 0.06);
    d.right.digits = d.right.digits.jittered(rng, 0.06);
    let spin = 0.45;
    let frame = DMat3::from_rotation_y(u(rng, -spin, spin))
        * DMat3::from_rotation_x(u(rng, -spin, spin))
        * DMat3::from_rotation_z(u(rng, -spin, spin));
    let left = params(&models.left, rig, betas, &d.left, frame, DVec3::ZERO);
    let mut right = params(&models.right, rig, betas, &d.right, frame, DVec3::ZERO);
    let posed_left = models.left.forward(&left)?;
    let left_caps = capsules(&posed_left.joints, 0.9);
    let posed_right = models.right.forward(&right)?;
    let mut right_joints = posed_right.joints;
    if d.pinch {
        // Pinch point: between the thumb tip (4) and the index tip (8), a little towards the
        // thumb; the left index tip (8) goes there.
        let pinch = right_joints[4] * 0.5 + right_joints[8] * 0.5;
        let shift = posed_left.joints[8] - pinch;
        right.trans += shift;
        for j in &mut right_joints {
            *j += shift;
        }
    }
    // Slide the right hand along the push axis to first contact (from 3 cm inside to 15 cm
    // out), 1 mm steps.
    let push = frame * d.push.normalize();
    let mut best = None;
    let steps = if d.pinch { 0..=150 } else { -30..=150 };
    for step in steps {
        let s = step as f64 * 0.001;
        let moved: Vec<DVec3> = right_joints.iter().map(|j| *j + push * s).collect();
        let o = overlap(&left_caps, &capsules(&moved, 0.9));
        let tolerance = if d.pinch { 0.006 } else { CONTACT_TOLERANCE };
        if o <= tolerance {
            best = Some(s);
            break;
        }
    }
    right.trans += push * best.unwrap_or(0.15);
    // Centre the pair on the origin (mean of both hands' joints).
    let posed_right = models.right.forward(&right)?;
    let centre = (posed_left.joints.iter().sum::<DVec3>()
        + posed_right.joints.iter().sum::<DVec3>())
        / (posed_left.joints.len() + posed_right.joints.len()) as f64;
    let mut left = left;
    left.trans -= centre;
    right.trans -= centre;
    Ok(TwoHandPose {
        family,
        left,
        right,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::procedural_pair;

    #[test]
    fn root_rotation_points_fingers_and_palm() {
        let models = procedural_pair();
        for side in Side::BOTH {
            let f = v(0.2, 1.0, 0.3);
            let p = v(1.0, 0.0, 0.1);
            let r = root_rotation(side, f, p);
            assert!((r.determinant() - 1.0).abs() < 1e-9);
            // The model's finger axis and palm normal land on f and p.
            let model_f = if side == Side::Right {
                DVec3::NEG_X
            } else {
                DVec3::X
            };
            assert!((r * model_f - f).length() < 1e-9);
            let pp = (p - f * p.dot(f)).normalize();
            assert!((r * DVec3::NEG_Y - pp).length() < 1e-9);
            let _ = models.get(side);
        }
    }

    #[test]
    fn curl_bends_fingers_towards_the_palm_on_both_hands() {
        let models = procedural_pair();
        let rig = Rig::new(&models.right).unwrap();
        for side in Side::BOTH {
            let model = models.get(side);
            let flat = HandParams::flat();
            let curled = HandParams {
                pose: HandPose::AxisAngle(rig.axis_angles(&Digits::uniform([1.2, 1.2, 0.6]), side)),
                ..HandParams::flat()
            };
            let a = model.forward(&flat).unwrap().joints;
            let b = model.forward(&curled).unwrap().joints;
            // Index tip (8) moves towards the palm side (-y in the model frame).
            assert!(b[8].y < a[8].y - 0.03, "{side}: {} vs {}", b[8].y, a[8].y);
        }
    }

    #[test]
    fn every_family_poses_touching_hands() {
        let models = procedural_pair();
        let rig = Rig::new(&models.right).unwrap();
        let betas = vec![0.0; NUM_BETAS];
        for (i, family) in PoseFamily::ALL.into_iter().enumerate() {
            let mut rng = SplitMix64::new(i as u64);
            let pose = two_hand_pose(&models, &rig, &betas, family, &mut rng).unwrap();
            let l = models.left.forward(&pose.left).unwrap().joints;
            let r = models.right.forward(&pose.right).unwrap().joints;
            let o = overlap(&capsules(&l, 0.9), &capsules(&r, 0.9));
            assert!(o <= 0.0061, "{family:?}: overlap {o}");
            assert!(o > -0.03, "{family:?}: the hands are {o} m apart");
        }
    }
}
