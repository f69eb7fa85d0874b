//! Ambient occlusion of posed meshes by shadow rays: per vertex, the cosine-weighted fraction
//! of its hemisphere from which light reaches it past every mesh of the scene (the hand
//! itself and the other hand). A crease between fingers or a palm pressed against the other
//! hand's back gets a low value; an open knuckle 1.
//!
//! Rays are cast against all triangles through a bounding-volume hierarchy (median split,
//! any-hit traversal), so a scene of two hands (a few thousand triangles) takes a few tens of
//! milliseconds on one core. Everything is on the host and deterministic: the same vertices
//! give the same values bit for bit.

use glam::DVec3;

use crate::error::MeshError;

/// How the shadow rays are cast.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OcclusionSettings {
    /// Rays per vertex over its hemisphere (cosine-weighted).
    pub rays: usize,
    /// How far an occluder may be and still shadow, in the vertices' unit (metres for hands):
    /// beyond it the light is taken to come around it (the rooms and rigs hands are
    /// photographed in light them from everywhere).
    pub reach: f64,
    /// How far along its normal a ray starts, so that it does not hit its own surface.
    pub offset: f64,
}

impl Default for OcclusionSettings {
    /// 64 rays, 4 cm reach (about two finger widths), 0.2 mm offset.
    fn default() -> Self {
        Self {
            rays: 64,
            reach: 0.04,
            offset: 2e-4,
        }
    }
}

/// One mesh of a scene: posed vertices and their triangles.
#[derive(Debug, Clone, Copy)]
pub struct OccluderMesh<'a> {
    /// Vertex positions.
    pub vertices: &'a [DVec3],
    /// Triangles into `vertices`.
    pub faces: &'a [[u32; 3]],
}

/// Per mesh, per vertex, the fraction in `[0, 1]` of the cosine-weighted hemisphere above the
/// vertex (about its area-weighted normal) whose ray meets no triangle of any mesh within
/// `settings.reach`. A vertex without a normal (a degenerate neighbourhood) gets 1.
///
/// # Errors
/// No rays, a reach or offset that is not finite and positive, a face index out of range,
/// or a non-finite vertex.
pub fn ambient_occlusion(
    meshes: &[OccluderMesh<'_>],
    settings: &OcclusionSettings,
) -> Result<Vec<Vec<f32>>, MeshError> {
    if settings.rays == 0 {
        return Err(MeshError::InvalidParams(
            "ambient occlusion needs at least one ray".into(),
        ));
    }
    for (what, v) in [("reach", settings.reach), ("offset", settings.offset)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(MeshError::InvalidParams(format!(
                "the occlusion {what} must be finite and positive, not {v}"
            )));
        }
    }
    let mut triangles = Vec::new();
    for (m, mesh) in meshes.iter().enumerate() {
        if let Some(i) = mesh.vertices.iter().position(|v| !v.is_finite()) {
            return Err(MeshError::InvalidParams(format!(
                "mesh {m}: vertex {i} is {:?}",
                mesh.vertices[i]
            )));
        }
        for (f, face) in mesh.faces.iter().enumerate() {
            if let Some(&i) = face.iter().find(|&&i| i as usize >= mesh.vertices.len()) {
                return Err(MeshError::InvalidParams(format!(
                    "mesh {m}: face {f} names vertex {i}; the mesh has {}",
                    mesh.vertices.len()
                )));
            }
            triangles.push(face.map(|i| mesh.vertices[i as usize]));
        }
    }
    let bvh = Bvh::new(triangles);
    let directions = hemisphere_directions(settings.rays);
    Ok(meshes
        .iter()
        .map(|mesh| {
            let normals = crate::model::vertex_normals(mesh.vertices, mesh.faces);
            mesh.vertices
                .iter()
                .zip(&normals)
                .enumerate()
                .map(|(k, (&p, &n))| {
                    if n == DVec3::ZERO {
                        return 1.0;
                    }
                    let (t, b) = n.any_orthonormal_pair();
                    // Each vertex turns the pattern by its own angle, so neighbours' misses
                    // do not line up into bands.
                    let (s, c) = (k as f64 * 2.399_963_229_728_653).sin_cos();
                    let origin = p + n * settings.offset;
                    let open = directions
                        .iter()
                        .filter(|d| {
                            let (x, y) = (c * d.x - s * d.y, s * d.x + c * d.y);
                            let dir = t * x + b * y + n * d.z;
                            !bvh.hits(origin, dir, settings.reach)
                        })
                        .count();
                    open as f32 / directions.len() as f32
                })
                .collect()
        })
        .collect())
}

/// `count` cosine-weighted directions on the hemisphere about `+z` (a spiral with the golden
/// angle: evenly spread, the same every call).
fn hemisphere_directions(count: usize) -> Vec<DVec3> {
    (0..count)
        .map(|k| {
            let u = (k as f64 + 0.5) / count as f64;
            let phi = k as f64 * 2.399_963_229_728_653;
            let r = u.sqrt();
            DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u).sqrt())
        })
        .collect()
}

/// A bounding-volume hierarchy over triangles for any-hit ray queries.
struct Bvh {
    triangles: Vec<[DVec3; 3]>,
    nodes: Vec<Node>,
}

/// A node: its box, and either two children or a run of `triangles`.
struct Node {
    min: DVec3,
    max: DVec3,
    /// Leaf: `start..end` in `triangles`; inner: children `start` and `end`.
    start: usize,
    end: usize,
    leaf: bool,
}

const LEAF_SIZE: usize = 4;

impl Bvh {
    fn new(mut triangles: Vec<[DVec3; 3]>) -> Self {
        let mut nodes = Vec::with_capacity(2 * triangles.len() / LEAF_SIZE + 1);
        if !triangles.is_empty() {
            let n = triangles.len();
            Self::build(&mut triangles, 0, n, &mut nodes);
        }
        Self { triangles, nodes }
    }

    /// Builds the node of `triangles[start..end]` and returns its index.
    fn build(
        triangles: &mut [[DVec3; 3]],
        start: usize,
        end: usize,
        nodes: &mut Vec<Node>,
    ) -> usize {
        let (mut min, mut max) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for t in &triangles[start..end] {
            for p in t {
                min = min.min(*p);
                max = max.max(*p);
            }
        }
        let index = nodes.len();
        nodes.push(Node {
            min,
            max,
            start,
            end,
            leaf: true,
        });
        if end - start <= LEAF_SIZE {
            return index;
        }
        let extent = max - min;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let centre = |t: &[DVec3; 3]| (t[0][axis] + t[1][axis] + t[2][axis]) / 3.0;
        let mid = (start + end) / 2;
        triangles[start..end]
            .select_nth_unstable_by(mid - start, |a, b| centre(a).total_cmp(&centre(b)));
        let left = Self::build(triangles, start, mid, nodes);
        let right = Self::build(triangles, mid, end, nodes);
        nodes[index] = Node {
            min,
            max,
            start: left,
            end: right,
            leaf: false,
        };
        index
    }

    /// Whether the ray `origin + s dir` (`dir` of unit length) meets a triangle at some
    /// `0 < s <= reach`.
    fn hits(&self, origin: DVec3, dir: DVec3, reach: f64) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let inv = DVec3::ONE / dir;
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i];
            if !slab(node.min, node.max, origin, inv, reach) {
                continue;
            }
            if node.leaf {
                if self.triangles[node.start..node.end]
                    .iter()
                    .any(|t| intersect(t, origin, dir, reach))
                {
                    return true;
                }
            } else {
                stack.push(node.start);
                stack.push(node.end);
            }
        }
        false
    }
}

/// Whether the ray meets the box within `[0, reach]` (slab test; `inv` is `1 / dir`).
fn slab(min: DVec3, max: DVec3, origin: DVec3, inv: DVec3, reach: f64) -> bool {
    let a = (min - origin) * inv;
    let b = (max - origin) * inv;
    let near = a.min(b);
    let far = a.max(b);
    // NaN (0 * inf on a face of the box) compares false, so `max_element`-like folds would
    // drop it; fold by hand, keeping the finite values.
    let enter = [near.x, near.y, near.z]
        .into_iter()
        .filter(|v| !v.is_nan())
        .fold(0.0f64, f64::max);
    let exit = [far.x, far.y, far.z]
        .into_iter()
        .filter(|v| !v.is_nan())
        .fold(reach, f64::min);
    enter <= exit
}

/// Möller-Trumbore: whether the ray meets the triangle at some `0 < s <= reach`.
fn intersect(t: &[DVec3; 3], origin: DVec3, dir: DVec3, reach: f64) -> bool {
    let e1 = t[1] - t[0];
    let e2 = t[2] - t[0];
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-18 {
        return false;
    }
    let inv = 1.0 / det;
    let s = origin - t[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let d = e2.dot(q) * inv;
    d > 0.0 && d <= reach
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square `[-h, h]^2` at height `z`, facing `+z` (two triangles).
    fn square(h: f64, z: f64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let v = vec![
            DVec3::new(-h, -h, z),
            DVec3::new(h, -h, z),
            DVec3::new(h, h, z),
            DVec3::new(-h, h, z),
        ];
        (v, vec![[0, 1, 2], [0, 2, 3]])
    }

    /// The BVH's any-hit answer against testing every triangle.
    #[test]
    fn the_hierarchy_answers_as_every_triangle_would() {
        let mut triangles = Vec::new();
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..300 {
            let c = DVec3::new(rnd(), rnd(), rnd());
            triangles.push([0, 1, 2].map(|_| c + 0.4 * DVec3::new(rnd(), rnd(), rnd())));
        }
        let bvh = Bvh::new(triangles.clone());
        let mut hits = 0;
        for _ in 0..2000 {
            let o = DVec3::new(rnd(), rnd(), rnd());
            let d = DVec3::new(rnd(), rnd(), rnd()).normalize();
            let reach = 0.3 + rnd();
            let brute = triangles.iter().any(|t| intersect(t, o, d, reach));
            assert_eq!(bvh.hits(o, d, reach), brute);
            hits += usize::from(brute);
        }
        assert!(
            hits > 200 && hits < 1800,
            "{hits} hits: the test should see both"
        );
        // Axis-aligned rays (zero components, infinite inverses) too.
        for d in [DVec3::X, DVec3::NEG_Y, DVec3::Z] {
            let o = DVec3::new(rnd(), rnd(), rnd());
            let brute = triangles.iter().any(|t| intersect(t, o, d, 2.0));
            assert_eq!(bvh.hits(o, d, 2.0), brute);
        }
    }

    /// An open square sees its whole hemisphere; under a lid of its size at height `g` it sees
    /// the fraction that cosine-weighted rays escape sideways: at the centre of a square of
    /// half-side `h` under a lid at `g`, each ray escapes if `tan(theta) > h / g` (up to the
    /// square's corners), so with `h = g` about `cos^2(45 deg) = 1/2` of the weight, and with
    /// `h = 10 g` almost none. A lid beyond the reach shadows nothing.
    #[test]
    fn a_lid_shadows_what_lies_under_it() {
        let (floor, faces) = square(1.0, 0.0);
        let settings = OcclusionSettings {
            rays: 4096,
            reach: 5.0,
            offset: 1e-6,
        };
        let open = ambient_occlusion(
            &[OccluderMesh {
                vertices: &floor,
                faces: &faces,
            }],
            &settings,
        )
        .unwrap();
        assert!(open[0].iter().all(|&a| a == 1.0), "{:?}", open[0]);

        // A centre vertex: a fan of four triangles around (0, 0, 0).
        let mut fan = floor.clone();
        fan.push(DVec3::ZERO);
        let fan_faces = vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        for (g, lo, hi) in [(1.0, 0.30, 0.52), (0.1, 0.0, 0.02)] {
            // The lid faces down; which way it faces does not matter to the rays.
            let (lid, lid_faces) = square(1.0, g);
            let scene = [
                OccluderMesh {
                    vertices: &fan,
                    faces: &fan_faces,
                },
                OccluderMesh {
                    vertices: &lid,
                    faces: &lid_faces,
                },
            ];
            let ao = ambient_occlusion(&scene, &settings).unwrap();
            let centre = ao[0][4];
            assert!((lo..=hi).contains(&centre), "lid at {g}: {centre}");
            let far = ambient_occlusion(
                &scene,
                &OcclusionSettings {
                    reach: g * 0.5,
                    ..settings
                },
            )
            .unwrap();
            assert_eq!(far[0][4], 1.0, "a lid beyond the reach");
        }
    }

    #[test]
    fn bad_settings_and_meshes_are_named() {
        let (v, f) = square(1.0, 0.0);
        let mesh = [OccluderMesh {
            vertices: &v,
            faces: &f,
        }];
        let err = |s: OcclusionSettings, m: &[OccluderMesh<'_>]| {
            ambient_occlusion(m, &s).unwrap_err().to_string()
        };
        let d = OcclusionSettings::default();
        assert!(err(OcclusionSettings { rays: 0, ..d }, &mesh).contains("ray"));
        assert!(
            err(
                OcclusionSettings {
                    reach: f64::NAN,
                    ..d
                },
                &mesh
            )
            .contains("reach")
        );
        assert!(err(OcclusionSettings { offset: -1.0, ..d }, &mesh).contains("offset"));
        let bad_face = [[0, 1, 9]];
        let e = err(
            d,
            &[OccluderMesh {
                vertices: &v,
                faces: &bad_face,
            }],
        );
        assert!(e.contains("face 0") && e.contains("vertex 9"), "{e}");
        let mut nan = v.clone();
        nan[2].x = f64::NAN;
        let e = err(
            d,
            &[OccluderMesh {
                vertices: &nan,
                faces: &f,
            }],
        );
        assert!(e.contains("vertex 2"), "{e}");
    }
}
