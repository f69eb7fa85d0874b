//! Generalized cylinders: rows of vertex rings (optionally closed by a pole at either end) and
//! the triangles between them.
//!
//! Convention: a ring's slots run counter-clockwise about the tube's direction of travel (from
//! the back side `e1` towards `e2 = direction x e1`), and rows follow that direction. The
//! triangles below are then counter-clockwise seen from outside.

use glam::DVec3;

/// Which part of the hand a tube is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(super) enum Piece {
    /// The palm, closed at the wrist.
    Palm,
    /// Finger `f` (0 index .. 3 pinky).
    Finger(usize),
    /// The thumb.
    Thumb,
}

/// One row of a tube.
#[derive(Debug, Clone)]
pub(super) enum Row {
    /// A single vertex closing the tube.
    Pole {
        /// Mesh vertex.
        vertex: u32,
        /// Its position.
        pos: DVec3,
    },
    /// A ring of slots. A slot is `None` where the tube has an opening (no vertex there), but
    /// its position is still known (the UV unwrap measures arc lengths through it).
    Ring {
        /// Mesh vertex of each slot.
        slots: Vec<Option<u32>>,
        /// Position of each slot.
        pos: Vec<DVec3>,
    },
}

impl Row {
    /// Positions of the row (one for a pole).
    pub fn positions(&self) -> &[DVec3] {
        match self {
            Row::Pole { pos, .. } => std::slice::from_ref(pos),
            Row::Ring { pos, .. } => pos,
        }
    }

    /// Mesh vertex of slot `k` (any slot of a pole).
    fn vertex(&self, k: usize) -> u32 {
        match self {
            Row::Pole { vertex, .. } => *vertex,
            Row::Ring { slots, .. } => slots[k].expect("tube face touches a slot with no vertex"),
        }
    }
}

/// A rectangle of quads left out of a tube: bands starting at rows `rows[0]..rows[1]`, edges
/// from slot `edges[0]..edges[1]`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Opening {
    /// First and one-past-last band.
    pub rows: [usize; 2],
    /// First and one-past-last ring edge.
    pub edges: [usize; 2],
}

/// A lofted tube.
#[derive(Debug, Clone)]
pub(super) struct Tube {
    /// What the tube is.
    pub piece: Piece,
    /// Rows in the direction of travel.
    pub rows: Vec<Row>,
    /// The palm-side half of every ring: its first slot and how many ring edges it spans; the
    /// back half is the rest.
    pub palmar: (usize, usize),
    /// Quads left out for another tube to attach.
    pub opening: Option<Opening>,
}

/// A triangle of a tube, with the `(row, slot)` of each corner and the half it belongs to
/// (0: palm side, 1: back side).
#[derive(Debug, Clone, Copy)]
pub(super) struct TubeFace {
    /// Mesh vertices, counter-clockwise from outside.
    pub verts: [u32; 3],
    /// `(row, slot)` of each corner (slot 0 for a pole).
    pub corners: [(usize, usize); 3],
    /// 0: palm-side half, 1: back-side half.
    pub half: usize,
}

impl Tube {
    /// Number of slots per ring.
    pub(crate) fn ring_len(&self) -> usize {
        self.rows
            .iter()
            .find_map(|r| match r {
                Row::Ring { pos, .. } => Some(pos.len()),
                Row::Pole { .. } => None,
            })
            .unwrap_or(0)
    }

    /// 0 if ring edge `k -> k + 1` lies in the palm-side half, else 1.
    pub(crate) fn half_of_edge(&self, k: usize) -> usize {
        let n = self.ring_len();
        let (first, len) = self.palmar;
        usize::from((k + n - first) % n >= len)
    }

    /// The slots of half `h` in ring order (both seam slots included).
    pub(crate) fn half_slots(&self, h: usize) -> Vec<usize> {
        let n = self.ring_len();
        let (first, len) = self.palmar;
        let (start, count) = if h == 0 {
            (first, len)
        } else {
            (first + len, n - len)
        };
        (0..=count).map(|i| (start + i) % n).collect()
    }

    fn in_opening(&self, row: usize, edge: usize) -> bool {
        self.opening.is_some_and(|o| {
            (o.rows[0]..o.rows[1]).contains(&row) && (o.edges[0]..o.edges[1]).contains(&edge)
        })
    }

    /// All triangles of the tube.
    pub fn faces(&self) -> Vec<TubeFace> {
        let n = self.ring_len();
        let mut out = Vec::new();
        for (r, pair) in self.rows.windows(2).enumerate() {
            for k in 0..n {
                if self.in_opening(r, k) {
                    continue;
                }
                let k1 = (k + 1) % n;
                let half = self.half_of_edge(k);
                let mut push = |c: [(usize, usize); 3]| {
                    let verts = c.map(|(row, slot)| self.rows[row].vertex(slot));
                    out.push(TubeFace {
                        verts,
                        corners: c,
                        half,
                    });
                };
                match pair {
                    [Row::Ring { .. }, Row::Ring { .. }] => {
                        push([(r, k), (r, k1), (r + 1, k)]);
                        push([(r, k1), (r + 1, k1), (r + 1, k)]);
                    }
                    [Row::Pole { .. }, Row::Ring { .. }] => push([(r, 0), (r + 1, k1), (r + 1, k)]),
                    [Row::Ring { .. }, Row::Pole { .. }] => push([(r, k), (r, k1), (r + 1, 0)]),
                    _ => {}
                }
            }
        }
        out
    }
}
