//! Cameras around the hands and studio lights.
//!
//! A camera is placed on a direction (azimuth about the person's up axis, 0 = in front;
//! elevation, positive from above) at a distance, looks at the hands' centre with a small
//! roll, and its intrinsics are chosen so the hands' projected bounding box fills a given
//! fraction of the (square) image and sits in its middle, as InterHand2.6M crops do.

use bitt_mesh::PinholeCamera;
use bitt_mesh::glam::{DMat3, DVec3};
use bitt_render::scene::LightValues;
use bitt_texture::procedural::noise::SplitMix64;

use crate::SynthError;

/// Where a camera stands, relative to the hands' centre (person frame: `x` left, `y` up,
/// `z` forward).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPlacement {
    /// Azimuth about `+y` (radians; 0 = in front of the person, on `+z`).
    pub azimuth: f64,
    /// Elevation (radians; positive = from above).
    pub elevation: f64,
    /// Distance to the hands' centre (metres).
    pub distance: f64,
    /// Roll about the viewing axis (radians).
    pub roll: f64,
    /// Fraction of the image side the hands' bounding box fills.
    pub fill: f64,
}

/// A camera looking at `target` from `placement`, framed on `points` (world), `size` pixels
/// square.
///
/// # Errors
/// When every point is behind the camera or the framing is degenerate.
pub fn framed_camera(
    placement: &CameraPlacement,
    target: DVec3,
    points: &[DVec3],
    size: u32,
) -> Result<PinholeCamera, SynthError> {
    let (ce, se) = (placement.elevation.cos(), placement.elevation.sin());
    let (ca, sa) = (placement.azimuth.cos(), placement.azimuth.sin());
    let dir = DVec3::new(sa * ce, se, ca * ce);
    let centre = target + dir * placement.distance;
    let z = (target - centre).normalize();
    let up = DVec3::Y;
    let y0 = -(up - z * up.dot(z)).normalize_or(DVec3::X);
    let x0 = y0.cross(z);
    // Roll the image axes about z.
    let (cr, sr) = (placement.roll.cos(), placement.roll.sin());
    let x = x0 * cr + y0 * sr;
    let y = z.cross(x);
    let rotation = DMat3::from_cols(x, y, z).transpose();
    let translation = -(rotation * centre);
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in points {
        let c = rotation * *p + translation;
        if c.z <= 1e-3 {
            return Err(SynthError::Generate(format!(
                "a hand point is behind the camera (distance {:.3} m is too short)",
                placement.distance
            )));
        }
        let n = [c.x / c.z, c.y / c.z];
        for k in 0..2 {
            lo[k] = lo[k].min(n[k]);
            hi[k] = hi[k].max(n[k]);
        }
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if !(extent > 1e-6 && extent.is_finite()) {
        return Err(SynthError::Generate(
            "cannot frame an empty set of points".into(),
        ));
    }
    let s = f64::from(size);
    let focal = placement.fill * s / extent;
    let cx = s / 2.0 - focal * (lo[0] + hi[0]) / 2.0;
    let cy = s / 2.0 - focal * (lo[1] + hi[1]) / 2.0;
    let intrinsics = DMat3::from_cols(
        DVec3::new(focal, 0.0, 0.0),
        DVec3::new(0.0, focal, 0.0),
        DVec3::new(cx, cy, 1.0),
    );
    Ok(PinholeCamera::new(
        intrinsics,
        rotation,
        translation,
        size,
        size,
    )?)
}

/// A training-camera candidate: mostly from the front half, from a little below to well above, as
/// most InterHand2.6M cameras see the hands.
pub(crate) fn train_placement(rng: &mut SplitMix64) -> CameraPlacement {
    CameraPlacement {
        azimuth: rng.range(-1.75, 1.75),
        elevation: rng.range(-0.5, 1.0),
        distance: rng.range(0.45, 0.75),
        roll: rng.range(-0.25, 0.25),
        fill: rng.range(0.72, 0.88),
    }
}

/// `n` novel cameras spread around the hands (evenly spaced azimuths from a random start,
/// jittered; elevations from below to above).
pub(crate) fn novel_placements(n: usize, rng: &mut SplitMix64) -> Vec<CameraPlacement> {
    let start = rng.range(0.0, std::f64::consts::TAU);
    (0..n)
        .map(|k| CameraPlacement {
            azimuth: start
                + std::f64::consts::TAU * k as f64 / n.max(1) as f64
                + rng.range(-0.25, 0.25),
            elevation: rng.range(-0.6, 1.0),
            distance: rng.range(0.45, 0.75),
            roll: rng.range(-0.25, 0.25),
            fill: rng.range(0.62, 0.8),
        })
        .collect()
}

/// A studio light of a scene, in the person (world) frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StudioLight {
    /// Ambient colour.
    pub ambient: [f32; 3],
    /// Diffuse colour.
    pub diffuse: [f32; 3],
    /// Specular colour (no effect with the neutral material; kept for the 12 numbers).
    pub specular: [f32; 3],
    /// Location in the person frame (metres).
    pub location: [f64; 3],
}

impl StudioLight {
    /// Draws a light: warm, neutral or cool white (with a faint tint now and then), ambient
    /// 0.3-0.5, diffuse 0.45-0.75, placed 0.4-0.9 m from the hands on the training camera's
    /// side, usually above.
    pub fn sample(rng: &mut SplitMix64, train: &PinholeCamera, target: DVec3) -> Self {
        let temps: [[f32; 3]; 6] = [
            [1.0, 0.93, 0.82],
            [1.0, 0.97, 0.92],
            [1.0, 1.0, 1.0],
            [0.9, 0.95, 1.0],
            [1.0, 0.9, 0.95],
            [0.93, 1.0, 0.93],
        ];
        let pick = |rng: &mut SplitMix64| temps[(rng.next_u64() % temps.len() as u64) as usize];
        let (ta, td) = (pick(rng), pick(rng));
        let a = rng.range(0.3, 0.5) as f32;
        let d = rng.range(0.45, 0.75) as f32;
        // Direction in the training camera's frame: towards the camera (-z), spread sideways,
        // mostly from above (camera y is down).
        let dir_cam = DVec3::new(rng.range(-1.3, 1.3), rng.range(-1.5, 0.5), -1.0).normalize();
        let dir = train.rotation.transpose() * dir_cam;
        let location = target + dir * rng.range(0.4, 0.9);
        StudioLight {
            ambient: ta.map(|c| c * a),
            diffuse: td.map(|c| c * d),
            specular: [0.2; 3],
            location: location.to_array(),
        }
    }

    /// The light as the renderer takes it for `camera`: location in that camera's frame.
    pub(crate) fn in_camera(&self, camera: &PinholeCamera) -> LightValues {
        let p = camera.world_to_camera(DVec3::from_array(self.location));
        LightValues {
            ambient: self.ambient,
            diffuse: self.diffuse,
            specular: self.specular,
            location: [p.x as f32, p.y as f32, p.z as f32],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_fills_the_image_and_centres_the_points() {
        let points: Vec<DVec3> = (0..50)
            .map(|i| {
                let t = i as f64 * 0.37;
                DVec3::new(t.sin() * 0.08, t.cos() * 0.05, (t * 1.7).sin() * 0.04)
            })
            .collect();
        for az in [0.0, 1.0, 2.5, -2.0] {
            let placement = CameraPlacement {
                azimuth: az,
                elevation: 0.4,
                distance: 0.6,
                roll: 0.1,
                fill: 0.7,
            };
            let cam = framed_camera(&placement, DVec3::ZERO, &points, 128).unwrap();
            let px: Vec<_> = points.iter().filter_map(|p| cam.project(*p)).collect();
            assert_eq!(px.len(), points.len());
            let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
            for p in &px {
                lo = [lo[0].min(p.x), lo[1].min(p.y)];
                hi = [hi[0].max(p.x), hi[1].max(p.y)];
            }
            let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
            assert!((extent - 0.7 * 128.0).abs() < 1e-6, "{extent}");
            assert!(((lo[0] + hi[0]) / 2.0 - 64.0).abs() < 1e-6);
            assert!(((lo[1] + hi[1]) / 2.0 - 64.0).abs() < 1e-6);
            // The camera stands where it was asked to.
            assert!((cam.center().length() - 0.6).abs() < 1e-9);
        }
    }
}
