//! Cross-sections: the digits' rounded profiles (knuckles, pads, nails) and the palm's lobes.

use std::f64::consts::{FRAC_PI_2, PI};

use glam::DVec2;

use super::skeleton::Chain;

/// Smoothstep on `[0, 1]` (clamped).
pub(super) fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// A Gaussian bump of unit height.
pub(super) fn bell(x: f64) -> f64 {
    (-x * x).exp()
}

/// Angle wrapped into `(-pi, pi]`.
pub(super) fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI { w - 2.0 * PI } else { w }
}

/// Piecewise-linear interpolation through `(x, y)` keys sorted by `x` (clamped at both ends).
fn interpolate(keys: &[(f64, f64)], x: f64) -> f64 {
    let (first, last) = (keys[0], keys[keys.len() - 1]);
    if x <= first.0 {
        return first.1;
    }
    keys.windows(2)
        .find(|w| x <= w[1].0)
        .map(|w| {
            let u = (x - w[0].0) / (w[1].0 - w[0].0).max(1e-12);
            w[0].1 + (w[1].1 - w[0].1) * u
        })
        .unwrap_or(last.1)
}

/// Shape constants of one kind of digit.
#[derive(Debug, Clone, Copy)]
pub(super) struct DigitStyle {
    /// Radius factor at the base joint, the two distal joints and the tip.
    pub taper: [f64; 4],
    /// Semi-axis factors: back-to-pad (`e1`) and side-to-side (`e2`).
    pub ellipse: [f64; 2],
    /// Dorsal knuckle bump height at the two distal joints (fraction of the radius).
    pub knuckles: [f64; 2],
    /// Palmar pad bulge at mid-segment (fraction of the radius).
    pub pad: f64,
}

/// The four fingers.
pub(super) const FINGER_STYLE: DigitStyle = DigitStyle {
    taper: [1.0, 0.9, 0.83, 0.8],
    ellipse: [0.93, 1.04],
    knuckles: [0.10, 0.08],
    pad: 0.06,
};

/// The thumb (its base radius factor describes the thenar end of the metacarpal).
pub(super) const THUMB_STYLE: DigitStyle = DigitStyle {
    taper: [1.35, 1.08, 1.0, 0.92],
    ellipse: [0.88, 1.1],
    knuckles: [0.10, 0.08],
    pad: 0.05,
};

impl DigitStyle {
    /// Radius of `chain` at arc length `s` (before the dorsal/palmar features).
    pub fn radius(&self, chain: &Chain, s: f64) -> f64 {
        let keys: [(f64, f64); 4] = std::array::from_fn(|k| (chain.s[k], self.taper[k]));
        chain.radius * interpolate(&keys, s)
    }

    /// Offset of the surface from the chain axis at arc length `s` and angle `phi` (0: nail
    /// side), as `(e2, e1)` components of the ring frame.
    pub fn section(&self, chain: &Chain, s: f64, phi: f64) -> DVec2 {
        let r = self.radius(chain, s);
        let (sin, cos) = phi.sin_cos();
        let mut radial = 0.0;
        for k in 0..2 {
            let bump = bell((s - chain.s[k + 1]) / 0.0045);
            radial += self.knuckles[k] * chain.radius * bump * cos.max(0.0).powi(2);
        }
        for k in 0..3 {
            let u = ((s - chain.s[k]) / (chain.s[k + 1] - chain.s[k])).clamp(0.0, 1.0);
            radial += self.pad * chain.radius * (PI * u).sin() * (-cos).max(0.0).powi(2);
        }
        let nail = nail_weight(chain, r, s);
        let plate = 1.0 - smoothstep((wrap_angle(phi).abs() - 0.6) / 0.35);
        radial += 0.07 * r * nail * plate;
        let (ra, rb) = (self.ellipse[0] * r, self.ellipse[1] * r);
        let mut p = DVec2::new(rb * sin, ra * cos) + DVec2::new(sin, cos) * radial;
        // The nail flattens the top of the distal segment.
        let level = ra * 0.9_f64.cos();
        p.y -= 0.35 * nail * (p.y - level).max(0.0);
        p
    }
}

/// How much of the nail covers arc length `s` (0 off the distal segment, 1 on the plate).
fn nail_weight(chain: &Chain, radius: f64, s: f64) -> f64 {
    let dip = chain.s[2];
    let len = chain.s[3] - dip;
    let start = smoothstep((s - (dip + 0.3 * len)) / (0.15 * len));
    let end = 1.0 - smoothstep((s - (chain.s[3] - 0.45 * radius)) / (0.35 * radius));
    start * end
}

/// One palm lobe's cross-section at a station: a box with rounded outer edges, in its ring
/// frame (`x` along `e2`, towards the pinky; `y` along `e1`, towards the back of the hand).
#[derive(Debug, Clone, Copy)]
pub(super) struct LobeBox {
    /// Height of the back above the lobe's axis, at the middle of the palm.
    pub top: f64,
    /// Depth of the palm side below the lobe's axis, at the middle of the palm.
    pub bottom: f64,
    /// Extent towards the thumb (`-x`).
    pub radial: f64,
    /// Extent towards the pinky (`+x`).
    pub ulnar: f64,
    /// Rounding radius of the palm's outer edges.
    pub corner: f64,
    /// Whether the radial / ulnar side is the palm's outer edge (index / pinky lobe).
    pub outer: [bool; 2],
    /// The lobe axis's offset from the middle of the palm, along `x`.
    pub offset: f64,
    /// The back falls away by `arch * d^2` at distance `d` from the middle of the palm.
    pub arch: f64,
    /// The palm side deepens by `cup * d^2` (the palm's hollow between its thick edges).
    pub cup: f64,
}

impl LobeBox {
    fn top_at(&self, x: f64) -> f64 {
        self.top - self.arch * (self.offset + x).powi(2)
    }

    fn bottom_at(&self, x: f64) -> f64 {
        self.bottom + self.cup * (self.offset + x).powi(2)
    }

    /// The back-side outline, from the radial end to the ulnar end.
    pub(crate) fn dorsal_path(&self) -> Vec<DVec2> {
        let c = self.corner;
        let (x0, x1) = (-self.radial, self.ulnar);
        let a = if self.outer[0] { x0 + c } else { x0 };
        let b = if self.outer[1] { x1 - c } else { x1 };
        let mut p = Vec::new();
        if self.outer[0] {
            let y = self.top_at(a);
            p.push(DVec2::new(x0, 0.5 * (y - self.bottom_at(x0))));
            p.push(DVec2::new(x0, y - c));
            arc(&mut p, DVec2::new(a, y - c), c, PI, FRAC_PI_2);
        }
        p.extend((0..=8).map(|i| {
            let x = a + (b - a) * f64::from(i) / 8.0;
            DVec2::new(x, self.top_at(x))
        }));
        if self.outer[1] {
            let y = self.top_at(b);
            arc(&mut p, DVec2::new(b, y - c), c, FRAC_PI_2, 0.0);
            p.push(DVec2::new(x1, 0.5 * (y - self.bottom_at(x1))));
        }
        p
    }

    /// The palm-side outline, from the ulnar end to the radial end.
    pub(crate) fn palmar_path(&self) -> Vec<DVec2> {
        let c = self.corner;
        let (x0, x1) = (-self.radial, self.ulnar);
        let a = if self.outer[0] { x0 + c } else { x0 };
        let b = if self.outer[1] { x1 - c } else { x1 };
        let mut p = Vec::new();
        if self.outer[1] {
            let y = -self.bottom_at(b);
            p.push(DVec2::new(x1, 0.5 * (self.top_at(x1) + y)));
            p.push(DVec2::new(x1, y + c));
            arc(&mut p, DVec2::new(b, y + c), c, 0.0, -FRAC_PI_2);
        }
        p.extend((0..=8).map(|i| {
            let x = b + (a - b) * f64::from(i) / 8.0;
            DVec2::new(x, -self.bottom_at(x))
        }));
        if self.outer[0] {
            let y = -self.bottom_at(a);
            arc(&mut p, DVec2::new(a, y + c), c, -FRAC_PI_2, -PI);
            p.push(DVec2::new(x0, 0.5 * (self.top_at(x0) + y)));
        }
        p
    }
}

/// Appends a circular arc (its start excluded: it is the previous point).
fn arc(p: &mut Vec<DVec2>, centre: DVec2, r: f64, a0: f64, a1: f64) {
    const STEPS: usize = 8;
    for i in 1..=STEPS {
        let a = a0 + (a1 - a0) * i as f64 / STEPS as f64;
        p.push(centre + DVec2::new(a.cos(), a.sin()) * r);
    }
}

/// The point at fraction `lambda` of a polyline's length.
pub(super) fn sample_path(path: &[DVec2], lambda: f64) -> DVec2 {
    let total: f64 = path.windows(2).map(|w| w[0].distance(w[1])).sum();
    let mut left = lambda.clamp(0.0, 1.0) * total;
    for w in path.windows(2) {
        let len = w[0].distance(w[1]);
        if left <= len && len > 0.0 {
            return w[0].lerp(w[1], left / len);
        }
        left -= len;
    }
    path[path.len() - 1]
}
