//! The closed hand surface: a palm tube capped at the wrist whose far end splits into four
//! finger tubes, and a thumb tube lofted out of an opening in the palm's radial-palmar corner.
//!
//! The palm is lofted through rings made of four *lobes*, one per finger. Each lobe is a rounded
//! box near the wrist and the knuckles that turns into its finger's round cross-section at the
//! finger web. Neighbouring lobes share the vertices where they meet, so the palm's last ring is
//! exactly the four finger rings fused side by side; the gap left between two fingers is closed
//! by a *crotch* vertex in the web, shared by both fingers' first rings.

use std::f64::consts::{PI, TAU};

use glam::{DQuat, DVec2, DVec3};

use super::ProceduralHandConfig;
use super::section::{
    FINGER_STYLE, LobeBox, THUMB_STYLE, bell, sample_path, smoothstep, wrap_angle,
};
use super::skeleton::{Chain, Skeleton, THUMB};
use super::tube::{Opening, Piece, Row, Tube};

/// Where a vertex sits relative to a digit's chain (palm lobes count as their finger's chain).
#[derive(Debug, Clone, Copy)]
pub(super) struct Anchor {
    /// 0..4: index, middle, ring, pinky; 4: thumb.
    pub chain: usize,
    /// Arc length along the chain from its base joint (negative inside the palm).
    pub s: f64,
    /// The axis point of the vertex's ring.
    pub centre: DVec3,
    /// Angle about the axis (0: back side, pi: palm side).
    pub phi: f64,
}

/// The generated surface, before UVs and rigging.
#[derive(Debug, Clone)]
pub(super) struct Surface {
    /// Rest positions (wrist at the origin).
    pub positions: Vec<DVec3>,
    /// One or two anchors per vertex (two where neighbouring lobes or fingers meet).
    pub anchors: Vec<Vec<Anchor>>,
    /// Palm, index, middle, ring, pinky, thumb.
    pub tubes: Vec<Tube>,
    /// Tip vertex of each digit: thumb, index, middle, ring, pinky.
    pub fingertips: [u32; 5],
    /// Number of wrist-cap rows before the palm's first station in the palm tube.
    pub palm_cap_rows: usize,
    /// Arc lengths along the thumb chain where its loft leaves the palm opening and where it
    /// becomes a round tube.
    pub thumb_base: (f64, f64),
    /// Arc length of each finger's web ring along its chain.
    pub web_s: [f64; 4],
}

impl Surface {
    /// Builds the whole surface for a sanitized configuration.
    pub fn build(skel: &Skeleton, cfg: &ProceduralHandConfig) -> Self {
        let mut b = Builder {
            positions: Vec::new(),
            anchors: Vec::new(),
        };
        let palm = PalmShape::new(skel, cfg);
        let built = palm.build(&mut b);
        let mut tubes = vec![built.tube.clone()];
        let crotches: [u32; 3] = std::array::from_fn(|f| crotch_vertex(&mut b, &palm, f));
        let mut tips = [0; 5];
        for f in 0..4 {
            let tube = build_finger(&mut b, &palm, &built, &crotches, f);
            tips[f + 1] = pole_vertex(&tube);
            tubes.push(tube);
        }
        let (thumb, thumb_base) = build_thumb(&mut b, skel, cfg, &built.hole_loop);
        tips[0] = pole_vertex(&thumb);
        tubes.push(thumb);
        Surface {
            positions: b.positions,
            anchors: b.anchors,
            tubes,
            fingertips: tips,
            palm_cap_rows: built.cap_rows,
            thumb_base,
            web_s: palm.lobes.map(|l| l.web_s),
        }
    }
}

fn pole_vertex(tube: &Tube) -> u32 {
    match tube.rows.last() {
        Some(Row::Pole { vertex, .. }) => *vertex,
        _ => unreachable!("digit tubes end in a pole"),
    }
}

/// Accumulates vertices.
struct Builder {
    positions: Vec<DVec3>,
    anchors: Vec<Vec<Anchor>>,
}

impl Builder {
    fn add(&mut self, pos: DVec3, anchors: Vec<Anchor>) -> u32 {
        self.positions.push(pos);
        self.anchors.push(anchors);
        u32::try_from(self.positions.len() - 1).expect("vertex count fits in u32")
    }

    /// Adds a full ring of fresh vertices.
    fn ring(&mut self, pos: Vec<DVec3>, anchors: impl Fn(usize) -> Anchor) -> Row {
        let slots = pos
            .iter()
            .enumerate()
            .map(|(m, p)| Some(self.add(*p, vec![anchors(m)])))
            .collect();
        Row::Ring { slots, pos }
    }
}

/// Number of ring segments of every finger (a multiple of 4).
fn quarter(cfg: &ProceduralHandConfig) -> usize {
    cfg.radial_segments / 4
}

/// Rows of a digit's tip cap: `count` shrinking rings then the pole at the fingertip.
fn cap_rows(
    b: &mut Builder,
    chain: &Chain,
    chain_id: usize,
    (n, phase): (usize, f64),
    s_cap: f64,
) -> Vec<Row> {
    let style = if chain_id == THUMB {
        THUMB_STYLE
    } else {
        FINGER_STYLE
    };
    let count = (n / 4).max(3);
    let depth = chain.length() - s_cap;
    let (_, e1, e2) = chain.frame(s_cap);
    let mut rows = Vec::new();
    for j in 1..=count {
        let theta = 0.5 * PI * j as f64 / (count + 1) as f64;
        let s = s_cap + depth * theta.sin();
        let centre = chain.point(s_cap) + chain.tangent(s_cap) * depth * theta.sin();
        let pos = ring_angles(n, phase)
            .map(|phi| {
                let o = style.section(chain, s, phi) * theta.cos();
                centre + e2 * o.x + e1 * o.y
            })
            .collect();
        rows.push(b.ring(pos, |m| Anchor {
            chain: chain_id,
            s,
            centre,
            phi: ring_angle(n, phase, m),
        }));
    }
    let tip = chain.points[3];
    let anchor = Anchor {
        chain: chain_id,
        s: chain.length(),
        centre: tip,
        phi: 0.0,
    };
    rows.push(Row::Pole {
        vertex: b.add(tip, vec![anchor]),
        pos: tip,
    });
    rows
}

fn ring_angle(n: usize, phase: f64, m: usize) -> f64 {
    phase + TAU * m as f64 / n as f64
}

fn ring_angles(n: usize, phase: f64) -> impl Iterator<Item = f64> {
    (0..n).map(move |m| ring_angle(n, phase, m))
}

/// Ring of a digit at arc length `s`, one slot per angle.
fn digit_ring(chain: &Chain, thumb: bool, s: f64, angles: &[f64]) -> Vec<DVec3> {
    let style = if thumb { THUMB_STYLE } else { FINGER_STYLE };
    let (_, e1, e2) = chain.frame(s);
    let centre = chain.point(s);
    angles
        .iter()
        .map(|&phi| {
            let o = style.section(chain, s, phi);
            centre + e2 * o.x + e1 * o.y
        })
        .collect()
}

/// Evenly spaced arc lengths from `a` to `b` (both included), about `step` apart.
fn stations(a: f64, b: f64, step: f64) -> Vec<f64> {
    let count = ((b - a) / step).ceil().max(1.0) as usize;
    (0..=count)
        .map(|j| a + (b - a) * j as f64 / count as f64)
        .collect()
}

/// Where the fingertip cap starts along a digit.
fn cap_start(chain: &Chain, thumb: bool) -> f64 {
    let style = if thumb { THUMB_STYLE } else { FINGER_STYLE };
    let tip_radius = style.radius(chain, chain.length()) * style.ellipse[0];
    chain.length() - 0.95 * tip_radius
}

// ---------------------------------------------------------------------------------------------
// Palm

/// One finger's lobe of the palm: a path from the wrist to the finger's web ring.
#[derive(Debug, Clone, Copy)]
struct Lobe {
    wrist: DVec3,
    web: DVec3,
    mcp: DVec3,
    dir: DVec3,
    /// Arc length of the web ring along the finger chain.
    web_s: f64,
    /// Arc length of the wrist end along the finger chain (negative).
    wrist_s: f64,
}

impl Lobe {
    /// Cubic Hermite from the wrist (leaving along `-x`) to the web (arriving along the finger).
    fn point(&self, t: f64) -> DVec3 {
        let (t2, t3) = (t * t, t * t * t);
        let len = self.web.distance(self.wrist);
        self.wrist * (2.0 * t3 - 3.0 * t2 + 1.0)
            + DVec3::NEG_X * len * (t3 - 2.0 * t2 + t)
            + self.web * (-2.0 * t3 + 3.0 * t2)
            + self.dir * len * (t3 - t2)
    }

    fn tangent(&self, t: f64) -> DVec3 {
        let t2 = t * t;
        let len = self.web.distance(self.wrist);
        (self.wrist * (6.0 * t2 - 6.0 * t)
            + DVec3::NEG_X * len * (3.0 * t2 - 4.0 * t + 1.0)
            + self.web * (-6.0 * t2 + 6.0 * t)
            + self.dir * len * (3.0 * t2 - 2.0 * t))
            .normalize()
    }
}

/// Which lobe slots make up each palm ring slot: one `(finger, finger-ring slot)`, or two where
/// neighbouring lobes meet.
type Role = Vec<(usize, usize)>;

/// The palm's ring layout for finger rings of `4q` slots, starting at the pinky's outer side
/// and running across the palm side to the index's outer side, then back across the back.
fn palm_roles(q: usize) -> Vec<Role> {
    let n = 4 * q;
    let mut roles: Vec<Role> = vec![vec![(3, q)]];
    roles.extend((q + 1..3 * q - 1).map(|m| vec![(3, m)]));
    for f in [3, 2, 1] {
        roles.push(vec![(f, 3 * q - 1), (f - 1, q + 1)]);
        if f > 1 {
            roles.extend((q + 2..3 * q - 1).map(|m| vec![(f - 1, m)]));
        }
    }
    roles.extend((q + 2..=3 * q).map(|m| vec![(0, m)]));
    let dorsal = |f: usize, first: usize, last: usize| -> Vec<Role> {
        (first..n).chain(0..=last).map(|m| vec![(f, m)]).collect()
    };
    roles.extend(dorsal(0, 3 * q + 1, q - 2));
    for f in 0..3 {
        roles.push(vec![(f, q - 1), (f + 1, 3 * q + 1)]);
        let last = if f + 1 == 3 { q - 1 } else { q - 2 };
        roles.extend(dorsal(f + 1, 3 * q + 2, last));
    }
    roles
}

/// The palm's geometry.
struct PalmShape<'a> {
    cfg: &'a ProceduralHandConfig,
    skel: &'a Skeleton,
    lobes: [Lobe; 4],
    q: usize,
}

/// What the fingers and the thumb need from the palm.
struct PalmBuilt {
    tube: Tube,
    /// Vertex of every palm role on the last station (the finger webs).
    last_ring: Vec<u32>,
    /// `(finger, slot)` -> palm role, for the last ring.
    role_of: Vec<Vec<Option<usize>>>,
    /// The thumb opening's boundary, in the order the thumb tube's first ring uses it.
    hole_loop: Vec<HoleVertex>,
    cap_rows: usize,
}

impl<'a> PalmShape<'a> {
    fn new(skel: &'a Skeleton, cfg: &'a ProceduralHandConfig) -> Self {
        let pitch = 0.225 * cfg.wrist_width;
        let lobes = std::array::from_fn(|f| {
            let chain = &skel.chains[f];
            let web_s = 0.32 * (chain.s[1] - chain.s[0]);
            let wrist = DVec3::new(0.0, 0.0, (1.5 - f as f64) * pitch);
            let dir = chain.segment_dir(0);
            let mcp = chain.points[0];
            Lobe {
                wrist,
                web: chain.point(web_s),
                mcp,
                dir,
                web_s,
                wrist_s: (wrist - mcp).dot(dir),
            }
        });
        PalmShape {
            cfg,
            skel,
            lobes,
            q: quarter(cfg),
        }
    }

    fn n(&self) -> usize {
        4 * self.q
    }

    /// Centre, back direction `e1`, side direction `e2` and finger arc length of lobe `f` at `t`.
    fn lobe_frame(&self, f: usize, t: f64) -> (DVec3, DVec3, DVec3, f64) {
        let lobe = &self.lobes[f];
        let centre = lobe.point(t);
        let tangent = lobe.tangent(t);
        let e1 = (DVec3::Y - tangent * tangent.y).normalize();
        (
            centre,
            e1,
            tangent.cross(e1),
            (centre - lobe.mcp).dot(lobe.dir),
        )
    }

    /// The rounded box of lobe `f` at `t` (arc length `s` along its finger).
    fn lobe_box(&self, f: usize, t: f64, s: f64) -> LobeBox {
        let cfg = self.cfg;
        let lobe = &self.lobes[f];
        let tau = ((s - lobe.wrist_s) / -lobe.wrist_s).clamp(0.0, 1.0);
        let ease = 1.0 - (1.0 - tau).powi(2);
        let lerp = |a: f64, b: f64| a + (b - a) * ease;
        let thickness = lerp(cfg.wrist_thickness, cfg.palm_thickness);
        let top = lerp(0.47 * cfg.wrist_thickness, 0.45 * cfg.palm_thickness);
        let mut bottom = lerp(0.53 * cfg.wrist_thickness, 0.55 * cfg.palm_thickness);
        bottom += 0.06 * cfg.palm_thickness * bell((tau - 0.88) / 0.14);
        if f == 3 {
            bottom += 0.08 * cfg.palm_thickness * bell((tau - 0.4) / 0.3);
        }
        let centre_z = |g: usize| self.lobes[g].point(t).z;
        let half_gap = |g: usize| 0.5 * (centre_z(g) - centre_z(f)).abs();
        let radial = if f == 0 {
            lerp(0.165 * cfg.wrist_width, 0.14 * cfg.palm_width)
        } else {
            half_gap(f - 1)
        };
        let ulnar = if f == 3 {
            lerp(0.165 * cfg.wrist_width, 0.135 * cfg.palm_width)
        } else {
            half_gap(f + 1)
        };
        let outer_width = if f == 0 { radial } else { ulnar };
        let corner = lerp(0.85, 0.55) * top.min(bottom).min(outer_width);
        // The back arches across the hand and the palm side is hollow between its edges.
        let middle = 0.5 * (centre_z(1) + centre_z(2));
        let reach = (0.75 * (centre_z(0) - centre_z(3))).powi(2).max(1e-6);
        LobeBox {
            top,
            bottom,
            radial,
            ulnar,
            corner,
            outer: [f == 0, f == 3],
            offset: middle - centre_z(f),
            arch: 0.14 * thickness / reach,
            cup: 0.08 * thickness / reach,
        }
    }

    /// Position and anchor of lobe `f`'s finger-ring slot `m` at station `t`.
    fn lobe_point(&self, f: usize, m: usize, t: f64) -> (DVec3, Anchor) {
        let (q, n) = (self.q, self.n());
        let (centre, e1, e2, s) = self.lobe_frame(f, t);
        let phi = TAU * m as f64 / n as f64;
        let bx = self.lobe_box(f, t, s);
        let dorsal = m > 3 * q || m <= q || (m == 3 * q && f == 0);
        let mut flat = if dorsal {
            let (start, end) = (3 * q + usize::from(f != 0), n + q - usize::from(f != 3));
            let u = if m <= q { m + n } else { m };
            let lambda = (u as f64 - start as f64) / (end - start) as f64;
            sample_path(&bx.dorsal_path(), lambda)
        } else {
            let (start, end) = (q + usize::from(f != 3), 3 * q - usize::from(f != 0));
            sample_path(&bx.palmar_path(), (m - start) as f64 / (end - start) as f64)
        };
        if dorsal {
            let chain = &self.skel.chains[f];
            flat.y += 0.28 * chain.radius * bell(s / 0.007) * bell(flat.x / 0.0055);
        }
        let round = FINGER_STYLE.section(&self.skel.chains[f], s.max(0.0), phi);
        let beta = smoothstep(s / self.lobes[f].web_s);
        let o = flat * (1.0 - beta) + round * beta;
        (
            centre + e2 * o.x + e1 * o.y,
            Anchor {
                chain: f,
                s,
                centre,
                phi,
            },
        )
    }

    /// Position (mean of its lobes) and anchors of a palm role at station `t`.
    fn role_point(&self, role: &Role, t: f64) -> (DVec3, Vec<Anchor>) {
        let pts: Vec<(DVec3, Anchor)> = role
            .iter()
            .map(|&(f, m)| self.lobe_point(f, m, t))
            .collect();
        let pos = pts.iter().map(|p| p.0).sum::<DVec3>() / pts.len() as f64;
        (pos, pts.into_iter().map(|p| p.1).collect())
    }

    /// Builds the palm tube: wrist cap, stations, the thumb opening.
    fn build(&self, b: &mut Builder) -> PalmBuilt {
        let roles = palm_roles(self.q);
        let lobe = &self.lobes[1];
        let count =
            ((lobe.web.distance(lobe.wrist) / self.cfg.ring_spacing).ceil() as usize).max(6);
        let ts: Vec<f64> = (0..=count).map(|i| i as f64 / count as f64).collect();
        let grid: Vec<Vec<(DVec3, Vec<Anchor>)>> = ts
            .iter()
            .map(|&t| roles.iter().map(|r| self.role_point(r, t)).collect())
            .collect();
        let side = roles
            .iter()
            .position(|r| r == &vec![(0, 3 * self.q)])
            .expect("index side role");
        let hole = self.choose_opening(&ts, &grid, side);

        let mut rows = self.wrist_cap(b, &grid[0]);
        let cap_rows = rows.len();
        let mut ids: Vec<Vec<Option<u32>>> = Vec::new();
        for (i, ring) in grid.iter().enumerate() {
            let slots: Vec<Option<u32>> = ring
                .iter()
                .enumerate()
                .map(|(k, (p, a))| {
                    let inside = i > hole.0[0] && i < hole.0[1] && k > hole.1[0] && k < hole.1[1];
                    (!inside).then(|| b.add(*p, a.clone()))
                })
                .collect();
            ids.push(slots.clone());
            rows.push(Row::Ring {
                slots,
                pos: ring.iter().map(|(p, _)| *p).collect(),
            });
        }
        let opening = Opening {
            rows: [cap_rows + hole.0[0], cap_rows + hole.0[1]],
            edges: [hole.1[0], hole.1[1]],
        };
        let hole_loop = opening_loop(hole, &ids, &grid);
        let last_ring = ids[count]
            .iter()
            .map(|v| v.expect("last ring is complete"))
            .collect();
        let mut role_of = vec![vec![None; self.n()]; 4];
        for (k, role) in roles.iter().enumerate() {
            for &(f, m) in role {
                role_of[f][m] = Some(k);
            }
        }
        let tube = Tube {
            piece: Piece::Palm,
            rows,
            palmar: (0, side),
            opening: Some(opening),
        };
        PalmBuilt {
            tube,
            last_ring,
            role_of,
            hole_loop,
            cap_rows,
        }
    }

    /// The thumb opening: stations `[i0, i1]` and ring slots `[k0, k1]` of its boundary.
    fn choose_opening(
        &self,
        ts: &[f64],
        grid: &[Vec<(DVec3, Vec<Anchor>)>],
        side: usize,
    ) -> ([usize; 2], [usize; 2]) {
        let cmc = self.skel.chains[THUMB].points[0];
        let scale = self.cfg.palm_length / 0.09;
        let last = ts.len() - 1;
        let station = |x: f64| {
            ts.iter()
                .position(|&t| self.lobes[0].point(t).x <= x)
                .unwrap_or(last)
        };
        let i0 = station(cmc.x + 0.014 * scale).max(1);
        let i1 = station(cmc.x - 0.034 * scale).clamp(i0 + 2, last.saturating_sub(3).max(i0 + 2));
        let mid = &grid[(i0 + i1) / 2];
        let perimeter: f64 = (0..mid.len())
            .map(|k| mid[k].0.distance(mid[(k + 1) % mid.len()].0))
            .sum();
        let pitch = perimeter / mid.len() as f64;
        let below = ((0.016 * scale / pitch).round() as usize).max(2);
        let above = ((0.007 * scale / pitch).round() as usize).max(1);
        ([i0, i1], [side.saturating_sub(below).max(1), side + above])
    }

    /// The wrist cap: a pole then shrinking copies of the first station, domed outwards (`+x`).
    fn wrist_cap(&self, b: &mut Builder, first: &[(DVec3, Vec<Anchor>)]) -> Vec<Row> {
        let count = (self.n() / 8).max(2);
        let centre = first.iter().map(|p| p.0).sum::<DVec3>() / first.len() as f64;
        let depth = self.cfg.wrist_cap_depth * self.cfg.wrist_thickness;
        let pole_anchor = Anchor {
            chain: 1,
            s: self.lobes[1].wrist_s,
            centre,
            phi: 0.0,
        };
        let pole = centre + DVec3::X * depth;
        let mut rows = vec![Row::Pole {
            vertex: b.add(pole, vec![pole_anchor]),
            pos: pole,
        }];
        for j in (1..=count).rev() {
            let theta = 0.5 * PI * j as f64 / (count + 1) as f64;
            let mut slots = Vec::new();
            let mut pos = Vec::new();
            for (p, anchors) in first {
                let x = centre + (*p - centre) * theta.cos() + DVec3::X * depth * theta.sin();
                slots.push(Some(b.add(x, anchors.clone())));
                pos.push(x);
            }
            rows.push(Row::Ring { slots, pos });
        }
        rows
    }
}

/// The boundary of the opening (stations `i0..=i1`, slots `k0..=k1`), counter-clockwise seen
/// from outside: along station `i0` towards `k1`, up to `i1`, back to `k0`, and down. Each
/// boundary vertex comes with the palm's outward normal there.
fn opening_loop(
    (st, sl): ([usize; 2], [usize; 2]),
    ids: &[Vec<Option<u32>>],
    grid: &[Vec<(DVec3, Vec<Anchor>)>],
) -> Vec<HoleVertex> {
    let [i0, i1] = st;
    let [k0, k1] = sl;
    let mut cells: Vec<(usize, usize)> = (k0..=k1).map(|k| (i0, k)).collect();
    cells.extend((i0 + 1..=i1).map(|i| (i, k1)));
    cells.extend((k0..k1).rev().map(|k| (i1, k)));
    cells.extend((i0 + 1..i1).rev().map(|i| (i, k0)));
    let at = |i: usize, k: usize| grid[i][k % grid[i].len()].0;
    cells
        .into_iter()
        .map(|(i, k)| {
            let around = at(i, k + 1) - at(i, k + grid[i].len() - 1);
            let along = at(i + 1, k) - at(i - 1, k);
            HoleVertex {
                vertex: ids[i][k].expect("opening boundary vertex"),
                pos: grid[i][k].0,
                normal: around.cross(along).normalize(),
            }
        })
        .collect()
}

/// A vertex on the boundary of the palm's thumb opening.
#[derive(Debug, Clone, Copy)]
struct HoleVertex {
    vertex: u32,
    pos: DVec3,
    /// The palm's outward normal there.
    normal: DVec3,
}

// ---------------------------------------------------------------------------------------------
// Fingers

/// Finger `f`: its web ring from the palm (plus the crotch vertices), rings to the tip, the cap.
fn build_finger(
    b: &mut Builder,
    palm: &PalmShape<'_>,
    built: &PalmBuilt,
    crotches: &[u32; 3],
    f: usize,
) -> Tube {
    let (q, n) = (palm.q, palm.n());
    let chain = &palm.skel.chains[f];
    let mut slots = Vec::with_capacity(n);
    let mut pos = Vec::with_capacity(n);
    for m in 0..n {
        let vertex = match built.role_of[f][m] {
            Some(k) => built.last_ring[k],
            None if m == q => crotches[f],
            None => crotches[f - 1],
        };
        slots.push(Some(vertex));
        pos.push(b.positions[vertex as usize]);
    }
    let mut rows = vec![Row::Ring { slots, pos }];
    let s_cap = cap_start(chain, false);
    // However fine the rings, keep the first one clear of the web: the two fingers sharing a
    // web bend about different knuckles, which shears it.
    let first = palm.lobes[f].web_s + palm.cfg.ring_spacing.max(0.6 * chain.radius);
    for s in stations(first, s_cap, palm.cfg.ring_spacing) {
        let centre = chain.point(s);
        let ring = digit_ring(chain, false, s, &ring_angles(n, 0.0).collect::<Vec<_>>());
        rows.push(b.ring(ring, |m| Anchor {
            chain: f,
            s,
            centre,
            phi: ring_angle(n, 0.0, m),
        }));
    }
    rows.extend(cap_rows(b, chain, f, (n, 0.0), s_cap));
    Tube {
        piece: Piece::Finger(f),
        rows,
        palmar: (q, 2 * q),
        opening: None,
    }
}

/// The crotch vertex in the web between finger `f` and finger `f + 1`: the midpoint of their
/// facing side slots on the web ring.
fn crotch_vertex(b: &mut Builder, palm: &PalmShape<'_>, f: usize) -> u32 {
    let q = palm.q;
    let (pa, aa) = palm.lobe_point(f, q, 1.0);
    let (pb, ab) = palm.lobe_point(f + 1, 3 * q, 1.0);
    b.add((pa + pb) * 0.5, vec![aa, ab])
}

// ---------------------------------------------------------------------------------------------
// Thumb

/// A cubic Hermite curve and its derivative.
fn hermite(p0: DVec3, m0: DVec3, p1: DVec3, m1: DVec3, t: f64) -> (DVec3, DVec3) {
    let (t2, t3) = (t * t, t * t * t);
    let point = p0 * (2.0 * t3 - 3.0 * t2 + 1.0)
        + m0 * (t3 - 2.0 * t2 + t)
        + p1 * (-2.0 * t3 + 3.0 * t2)
        + m1 * (t3 - t2);
    let slope = p0 * (6.0 * t2 - 6.0 * t)
        + m0 * (3.0 * t2 - 4.0 * t + 1.0)
        + p1 * (-6.0 * t2 + 6.0 * t)
        + m1 * (3.0 * t2 - 2.0 * t);
    (point, slope)
}

/// Outward normal of a closed loop (Newell's method; counter-clockwise loops face the viewer).
fn loop_normal(points: &[DVec3]) -> DVec3 {
    let n = points.len();
    (0..n)
        .map(|i| points[i].cross(points[(i + 1) % n]))
        .sum::<DVec3>()
        .normalize()
}

/// The thumb: lofted out of the palm opening to its first round ring near the MCP (which makes
/// the thenar eminence and the first web space), then rings to the tip and the cap. Also
/// returns the arc lengths (along the thumb chain) of the opening and of the first round ring.
///
/// Each opening vertex rises to its ring slot along a Hermite curve that leaves the palm
/// tangentially (heading into the opening) and arrives along the thumb, so the loft swells out
/// of the palm without a crease. To pair each opening vertex with a ring slot without twisting,
/// angles are compared in frames carried without twist along a path that leaves the opening
/// along its normal and arrives along the thumb; the first round rings take the opening's
/// angular spacing and relax to even spacing over a few rings.
fn build_thumb(
    b: &mut Builder,
    skel: &Skeleton,
    cfg: &ProceduralHandConfig,
    hole: &[HoleVertex],
) -> (Tube, (f64, f64)) {
    let chain = &skel.chains[THUMB];
    let n = hole.len();
    let outline: Vec<DVec3> = hole.iter().map(|h| h.pos).collect();
    let hole_centre = outline.iter().sum::<DVec3>() / n as f64;
    let normal = loop_normal(&outline);
    let s_free = 0.8 * (chain.s[1] - chain.s[0]);
    let free_centre = chain.point(s_free);
    let (tangent, e1, e2) = chain.frame(s_free);

    // Carry a frame from the opening's plane to the first round ring without twist.
    let reach = hole_centre.distance(free_centre);
    let path = |t: f64| hermite(hole_centre, normal * reach, free_centre, tangent * reach, t);
    let a0 = (e1 - normal * e1.dot(normal)).normalize();
    let mut carried = a0;
    let mut previous = normal;
    for i in 1..=32 {
        let t = path(f64::from(i) / 32.0).1.normalize();
        carried = DQuat::from_rotation_arc(previous, t) * carried;
        previous = t;
    }
    let gamma = carried.dot(e2).atan2(carried.dot(e1));
    let b0 = normal.cross(a0);
    let even = |m: usize, phase: f64| ring_angle(n, phase, m);
    let opening: Vec<f64> = outline
        .iter()
        .map(|p| {
            let d = *p - hole_centre;
            d.dot(b0).atan2(d.dot(a0)) + gamma
        })
        .collect();
    let phase = {
        let sum = opening.iter().enumerate().fold(DVec2::ZERO, |acc, (m, a)| {
            let d = a - even(m, 0.0);
            acc + DVec2::new(d.cos(), d.sin())
        });
        sum.y.atan2(sum.x)
    };
    // The opening's angles, each unwrapped next to its evenly spaced slot.
    let matched: Vec<f64> = opening
        .iter()
        .enumerate()
        .map(|(m, a)| even(m, phase) + wrap_angle(a - even(m, phase)))
        .collect();
    let angles = |relax: f64| -> Vec<f64> {
        matched
            .iter()
            .enumerate()
            .map(|(m, a)| a + (even(m, phase) - a) * smoothstep(relax))
            .collect()
    };

    let free = digit_ring(chain, true, s_free, &angles(0.0));
    let s_hole = (hole_centre - chain.points[0]).dot(chain.segment_dir(0));
    let loft_rows = ((reach / cfg.ring_spacing).round() as usize).max(2);
    let slots = hole.iter().map(|h| Some(h.vertex)).collect();
    let mut rows = vec![Row::Ring {
        slots,
        pos: outline,
    }];
    for i in 1..loft_rows {
        let t = i as f64 / loft_rows as f64;
        let axis = hole_centre.lerp(free_centre, t);
        let pos = hole
            .iter()
            .zip(&free)
            .map(|(h, r)| {
                // Leave the palm tangentially (heading into the opening), arrive along the thumb.
                let inward = hole_centre - h.pos;
                let start = (inward - h.normal * inward.dot(h.normal)).normalize_or_zero();
                let chord = h.pos.distance(*r);
                hermite(h.pos, start * chord, *r, tangent * chord, t).0
            })
            .collect();
        let s = s_hole + (s_free - s_hole) * t;
        rows.push(b.ring(pos, |m| Anchor {
            chain: THUMB,
            s,
            centre: axis,
            phi: matched[m],
        }));
    }
    let s_cap = cap_start(chain, true);
    let span = stations(s_free, s_cap, cfg.ring_spacing);
    let settle = 3.0_f64.min(span.len() as f64 - 1.0).max(1.0);
    for (j, &s) in span.iter().enumerate() {
        let phi = angles(j as f64 / settle);
        let centre = chain.point(s);
        let ring = digit_ring(chain, true, s, &phi);
        rows.push(b.ring(ring, |m| Anchor {
            chain: THUMB,
            s,
            centre,
            phi: phi[m],
        }));
    }
    rows.extend(cap_rows(b, chain, THUMB, (n, phase), s_cap));
    let step = TAU / n as f64;
    let first = ((0.5 * PI - phase) / step).round().rem_euclid(n as f64) as usize;
    let tube = Tube {
        piece: Piece::Thumb,
        rows,
        palmar: (first, n / 2),
        opening: None,
    };
    (tube, (s_hole, s_free))
}
