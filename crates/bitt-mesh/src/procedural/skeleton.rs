//! The rest-pose skeleton of the procedural right hand, in a wrist-centred frame.
//!
//! Axes follow MANO's right hand: `-x` points from the wrist towards the fingertips, `+y` out of
//! the back of the hand, `+z` towards the thumb. The wrist joint is the origin here; the builder
//! moves everything to [`super::ProceduralHandConfig::wrist_position`] at the very end.

use glam::DVec3;

use super::ProceduralHandConfig;

/// Skeleton joints of the four fingers in anatomical order (index, middle, ring, pinky):
/// MCP, PIP and DIP ids in MANO's joint order.
pub(super) const FINGER_JOINTS: [[usize; 3]; 4] = [[1, 2, 3], [4, 5, 6], [10, 11, 12], [7, 8, 9]];
/// Skeleton joints of the thumb: CMC, MCP and IP.
pub(super) const THUMB_JOINTS: [usize; 3] = [13, 14, 15];
/// Index of the thumb among [`Skeleton::chains`].
pub(super) const THUMB: usize = 4;

/// Where each finger's MCP sits along the palm, as a fraction of the palm length.
const MCP_DEPTH: [f64; 4] = [0.955, 1.0, 0.945, 0.86];
/// Height of each MCP above the palm plane, as a fraction of the palm thickness (the dorsal arch).
const MCP_HEIGHT: [f64; 4] = [0.0, 0.06, -0.02, -0.13];
/// Splay of each finger (multiples of the configured spread; positive turns towards the thumb).
const SPLAY: [f64; 4] = [1.0, 0.0, -1.0, -2.2];
/// Distance between neighbouring finger axes at the knuckles, as a fraction of the palm width.
const FINGER_PITCH: f64 = 0.239;
/// Lateral centre of the knuckle row (negative: towards the pinky), as a fraction of the palm
/// width.
const KNUCKLE_CENTRE: f64 = -0.075;
/// How far the nail side of the thumb is turned from the back of the hand towards the radial side.
const THUMB_PRONATION: f64 = 1.0;
/// How much the thumb's second and third segments turn back towards the fingers (radians).
const THUMB_CURVE: [f64; 3] = [0.0, 0.15, 0.27];
/// How far each thumb segment dips below the palm plane (radians).
const THUMB_DIP: [f64; 3] = [0.22, 0.14, 0.10];

/// One digit's rest-pose kinematic chain: a polyline from its base joint to its fingertip.
#[derive(Debug, Clone)]
pub(super) struct Chain {
    /// Base joint (MCP, or CMC for the thumb), the two distal joints, and the fingertip.
    pub points: [DVec3; 4],
    /// Skeleton joint ids of the three joints.
    pub joint_ids: [usize; 3],
    /// Arc length of each point along the chain (`s[0] = 0`).
    pub s: [f64; 4],
    /// Angle turning the nail side from `+y` towards the radial side, about the chain.
    pub pronation: f64,
    /// Radius of the digit at its proximal phalanx.
    pub radius: f64,
}

impl Chain {
    fn new(points: [DVec3; 4], joint_ids: [usize; 3], pronation: f64, radius: f64) -> Self {
        let mut s = [0.0; 4];
        for k in 1..4 {
            s[k] = s[k - 1] + points[k].distance(points[k - 1]);
        }
        Chain {
            points,
            joint_ids,
            s,
            pronation,
            radius,
        }
    }

    /// Total length from the base joint to the fingertip.
    pub fn length(&self) -> f64 {
        self.s[3]
    }

    /// Unit direction of segment `k` (0: proximal, 2: distal).
    pub(crate) fn segment_dir(&self, k: usize) -> DVec3 {
        (self.points[k + 1] - self.points[k]).normalize()
    }

    /// The segment holding arc length `s` (clamped to the chain).
    fn segment_at(&self, s: f64) -> usize {
        (0..2).find(|&k| s < self.s[k + 1]).unwrap_or(2)
    }

    /// Point at arc length `s`, extended straight beyond both ends.
    pub fn point(&self, s: f64) -> DVec3 {
        let k = self.segment_at(s);
        self.points[k] + self.segment_dir(k) * (s - self.s[k])
    }

    /// Unit tangent at `s`, blended over a short band around each joint so ring planes turn
    /// smoothly.
    pub fn tangent(&self, s: f64) -> DVec3 {
        const BAND: f64 = 0.006;
        let mut t = self.segment_dir(self.segment_at(s));
        for k in 1..3 {
            let x = (s - self.s[k]) / BAND;
            if x.abs() < 1.0 {
                let w = 0.5 + 0.5 * x;
                t = self.segment_dir(k - 1) * (1.0 - w) + self.segment_dir(k) * w;
            }
        }
        t.normalize()
    }

    /// Orthonormal ring frame at `s`: the tangent, `e1` towards the nail (back) side, and
    /// `e2 = tangent x e1` (towards the pinky side for the fingers).
    pub fn frame(&self, s: f64) -> (DVec3, DVec3, DVec3) {
        nail_frame(self.tangent(s), self.pronation)
    }

    /// Rest-pose flexion axis of joint `k`: a positive rotation about it curls the digit towards
    /// the palm (the pad side).
    pub(crate) fn flexion_axis(&self, k: usize) -> DVec3 {
        let (t, e1, _) = nail_frame(self.segment_dir(k), self.pronation);
        e1.cross(t)
    }
}

/// The frame of a digit pointing along `t` whose nail side is `+y` turned by `pronation` towards
/// the radial side.
pub(super) fn nail_frame(t: DVec3, pronation: f64) -> (DVec3, DVec3, DVec3) {
    let radial = DVec3::Y.cross(t).normalize_or(DVec3::Z);
    let raw = DVec3::Y * pronation.cos() + radial * pronation.sin();
    let e1 = (raw - t * raw.dot(t)).normalize();
    (t, e1, t.cross(e1))
}

/// The whole rest skeleton: four fingers and the thumb (the wrist is the origin).
#[derive(Debug, Clone)]
pub(super) struct Skeleton {
    /// Index, middle, ring, pinky, thumb (see [`THUMB`]).
    pub chains: [Chain; 5],
    /// Lateral centre of the knuckle row.
    pub knuckle_centre_z: f64,
    /// Thickness of the palm at the knuckles.
    pub palm_thickness: f64,
}

impl Skeleton {
    /// Lays out the skeleton from a (sanitized) configuration.
    pub fn new(cfg: &ProceduralHandConfig) -> Self {
        let fingers: [Chain; 4] = std::array::from_fn(|f| finger_chain(cfg, f));
        let [index, middle, ring, pinky] = fingers;
        Skeleton {
            chains: [index, middle, ring, pinky, thumb_chain(cfg)],
            knuckle_centre_z: KNUCKLE_CENTRE * cfg.palm_width,
            palm_thickness: cfg.palm_thickness,
        }
    }

    /// The 16 rest joints in MANO order (wrist-centred).
    pub fn joints(&self) -> [DVec3; 16] {
        let mut joints = [DVec3::ZERO; 16];
        for chain in &self.chains {
            for (id, p) in chain.joint_ids.iter().zip(&chain.points) {
                joints[*id] = *p;
            }
        }
        joints
    }
}

/// Finger `f` (0 index .. 3 pinky): straight along its splayed direction from its MCP.
fn finger_chain(cfg: &ProceduralHandConfig, f: usize) -> Chain {
    let z = KNUCKLE_CENTRE * cfg.palm_width + (1.5 - f as f64) * FINGER_PITCH * cfg.palm_width;
    let mcp = DVec3::new(
        -MCP_DEPTH[f] * cfg.palm_length,
        MCP_HEIGHT[f] * cfg.palm_thickness,
        z,
    );
    let angle = SPLAY[f] * cfg.finger_spread;
    let dir = DVec3::new(-angle.cos(), 0.0, angle.sin());
    let [l0, l1, l2] = cfg.finger_lengths[f];
    let points = [
        mcp,
        mcp + dir * l0,
        mcp + dir * (l0 + l1),
        mcp + dir * (l0 + l1 + l2),
    ];
    Chain::new(points, FINGER_JOINTS[f], 0.0, cfg.finger_radii[f])
}

/// The thumb: from its CMC near the radial-palmar corner of the wrist, abducted away from the
/// index and dipping below the palm plane, each segment curving slightly back towards the
/// fingers.
fn thumb_chain(cfg: &ProceduralHandConfig) -> Chain {
    let cmc = DVec3::new(
        -0.2 * cfg.palm_length,
        -0.45 * cfg.palm_thickness,
        0.42 * cfg.wrist_width,
    );
    let mut points = [cmc; 4];
    for k in 0..3 {
        let yaw = cfg.thumb_abduction - THUMB_CURVE[k];
        let dip = THUMB_DIP[k];
        let dir = DVec3::new(-yaw.cos() * dip.cos(), -dip.sin(), yaw.sin() * dip.cos());
        points[k + 1] = points[k] + dir * cfg.thumb_lengths[k];
    }
    Chain::new(points, THUMB_JOINTS, THUMB_PRONATION, cfg.thumb_radius)
}
