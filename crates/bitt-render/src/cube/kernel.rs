//! The rasterizer as one CubeCL kernel, a port of the CPU core (`raster.rs`, `clip.rs`) that
//! makes the same decisions with the same arithmetic: `f64` for clipping, screen positions,
//! barycentrics and depth, exact `i64` integer edge functions on positions snapped to 1/65536
//! pixel, the top-left fill rule, and the far-plane discard.
//!
//! One unit per face; the kernel runs three times over the same buffers ([`Pass`]), because
//! WGSL has no 64-bit atomics to pack depth and face id into one atomic minimum:
//! 1. [`Pass::Depth`]: atomic minimum of each fragment's depth key (the `f32` depth's bits
//!    mapped to an order-preserving `i32`, see [`depth_key`]);
//! 2. [`Pass::Face`]: among the fragments whose key equals the pixel's minimum, atomic
//!    minimum of the face id: ties go to the lower face index, as in the CPU core;
//! 3. [`Pass::Write`]: the winning fragment writes its barycentrics and depth.
//!
//! The CPU core's edge functions are `i128`; here they are `i64` products of 24-bit limbs
//! ([`edge_sign`]), exact for snapped coordinates up to the core's 2^30-pixel guard band.

use cubecl::prelude::*;

/// Which of the three passes a launch runs (see the module docs).
#[derive(CubeType, Clone, Copy, Debug, Hash, PartialEq, Eq)]
pub(crate) enum Pass {
    /// Atomic minimum of the depth keys.
    Depth,
    /// Atomic minimum of the face ids among the nearest fragments.
    Face,
    /// The winning fragments write barycentrics and depth.
    Write,
}

/// `x` is neither NaN nor infinite.
#[cube]
#[allow(clippy::manual_range_contains)] // kernel code: `RangeInclusive` has no CubeCL form
fn finite(x: f64) -> bool {
    x >= -1.7976931348623157e308f64 && x <= 1.7976931348623157e308f64
}

/// Rust's `f64::round` (halves away from zero); WGSL's `round` goes to even.
#[cube]
fn round_away(v: f64) -> f64 {
    let t = v.trunc();
    let d = v - t;
    let mut r = t;
    if d >= 0.5f64 {
        r = t + 1.0f64;
    }
    if d <= -0.5f64 {
        r = t - 1.0f64;
    }
    r
}

/// Screen coordinate (pixels) of clip coordinate `x` at `w` on an axis of `size` pixels,
/// clamped to the guard band, as `ScreenVertex::new`.
#[cube]
fn screen(x: f64, w: f64, size: f64) -> f64 {
    let guard = 1073741824.0f64;
    let mut s = (x / w + 1.0f64) * 0.5f64 * size;
    if s < -guard {
        s = -guard;
    }
    if s > guard {
        s = guard;
    }
    s
}

/// The snapped fixed-point coordinate of a screen coordinate.
#[cube]
fn snap(s: f64) -> i64 {
    i64::cast_from(round_away(s * 65536.0f64))
}

/// Sign (-1, 0, 1) of `dx ey - dy ex`, exact for magnitudes below 2^48: each factor is split
/// into a signed high and an unsigned low 24-bit limb, the three limb sums are carried, and
/// the top limb decides.
#[cube]
fn edge_sign(dx: i64, dy: i64, ex: i64, ey: i64) -> i32 {
    let mask = 16777215i64;
    let (dx1, dx0) = (dx >> 24i64, dx & mask);
    let (dy1, dy0) = (dy >> 24i64, dy & mask);
    let (ex1, ex0) = (ex >> 24i64, ex & mask);
    let (ey1, ey0) = (ey >> 24i64, ey & mask);
    let c0 = dx0 * ey0 - dy0 * ex0;
    let c1 = dx1 * ey0 + dx0 * ey1 - dy1 * ex0 - dy0 * ex1 + (c0 >> 24i64);
    let c2 = dx1 * ey1 - dy1 * ex1 + (c1 >> 24i64);
    let low = (c1 & mask) != 0i64 || (c0 & mask) != 0i64;
    let mut sign = 0i32;
    if c2 > 0i64 {
        sign = 1i32;
    } else if c2 < 0i64 {
        sign = -1i32;
    } else if low {
        sign = 1i32;
    }
    sign
}

/// `dx ey - dy ex` as `f64` (the sliver fallback of the barycentrics), from the same limbs.
#[cube]
fn edge_value(dx: i64, dy: i64, ex: i64, ey: i64) -> f64 {
    let mask = 16777215i64;
    let (dx1, dx0) = (dx >> 24i64, dx & mask);
    let (dy1, dy0) = (dy >> 24i64, dy & mask);
    let (ex1, ex0) = (ex >> 24i64, ex & mask);
    let (ey1, ey0) = (ey >> 24i64, ey & mask);
    let c0 = dx0 * ey0 - dy0 * ex0;
    let c1 = dx1 * ey0 + dx0 * ey1 - dy1 * ex0 - dy0 * ex1 + (c0 >> 24i64);
    let c2 = dx1 * ey1 - dy1 * ex1 + (c1 >> 24i64);
    f64::cast_from(c2) * 281474976710656.0f64
        + f64::cast_from(c1 & mask) * 16777216.0f64
        + f64::cast_from(c0 & mask)
}

/// Smallest `i` with `i * 65536 + 32768 >= v`.
#[cube]
fn first_centre(v: i64) -> i64 {
    let d = v - 32768i64;
    let mut i = d >> 16i64;
    if (d & 65535i64) != 0i64 {
        i += 1i64;
    }
    i
}

/// Largest `i` with `i * 65536 + 32768 <= v`.
#[cube]
fn last_centre(v: i64) -> i64 {
    (v - 32768i64) >> 16i64
}

/// The order-preserving `i32` key of an `f32` depth (both zeros map to 0, as `<` sees them).
#[cube]
fn depth_key(depth: f32) -> i32 {
    let bits = i32::reinterpret(depth);
    let mut key = bits;
    if bits < 0i32 {
        key = bits ^ 2147483647i32;
    }
    if (bits & 2147483647i32) == 0i32 {
        key = 0i32;
    }
    key
}

/// Signed distance of polygon vertex `i` to the clip plane: `w - 1e-6` or `z + w`.
#[cube]
fn plane_dist(pos: &Array<f64>, i: usize, #[comptime] w_plane: bool) -> f64 {
    let mut d = pos[i * 4 + 2] + pos[i * 4 + 3];
    if w_plane {
        d = pos[i * 4 + 3] - 0.000001f64;
    }
    d
}

/// One Sutherland–Hodgman step (`clip.rs`'s `clip_plane`): the polygon of `len` vertices in
/// `pos` (4 per vertex) and `wts` (3 per vertex) clipped into `out_pos` / `out_wts`; returns
/// the new vertex count.
#[cube]
fn clip_plane(
    pos: &Array<f64>,
    wts: &Array<f64>,
    len: usize,
    out_pos: &mut Array<f64>,
    out_wts: &mut Array<f64>,
    #[comptime] w_plane: bool,
) -> usize {
    let mut n = 0usize;
    for i in 0..len {
        let mut j = i + 1;
        if j == len {
            j = 0;
        }
        let da = plane_dist(pos, i, w_plane);
        let db = plane_dist(pos, j, w_plane);
        let in_a = da >= 0.0f64;
        let in_b = db >= 0.0f64;
        if in_a {
            for c in 0..4usize {
                out_pos[n * 4 + c] = pos[i * 4 + c];
            }
            for c in 0..3usize {
                out_wts[n * 3 + c] = wts[i * 3 + c];
            }
            n += 1;
        }
        if in_a != in_b {
            let t = da / (da - db);
            for c in 0..4usize {
                let a = pos[i * 4 + c];
                out_pos[n * 4 + c] = a + t * (pos[j * 4 + c] - a);
            }
            for c in 0..3usize {
                let a = wts[i * 3 + c];
                out_wts[n * 3 + c] = a + t * (wts[j * 3 + c] - a);
            }
            n += 1;
        }
    }
    n
}

/// The rasterizer: unit `f` handles face `f` (see the module docs for the passes).
///
/// # Shapes
/// clip `[V * 4]` (x, y, z, w per vertex), faces `[F * 3]`, keys and winners `[H * W]`
/// (initialised to `i32::MAX`), bary `[H * W * 3]`, depth `[H * W]`.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn rasterize_kernel(
    clip: &[f32],
    faces: &[i32],
    keys: &[Atomic<i32>],
    winners: &[Atomic<i32>],
    bary: &mut [f32],
    depth: &mut [f32],
    width: u32,
    height: u32,
    #[comptime] pass: Pass,
) {
    let f = ABSOLUTE_POS;
    if f >= faces.len() / 3 {
        terminate!();
    }
    let face_id = i32::cast_from(f);
    let mut pos = Array::<f64>::new(32usize);
    let mut wts = Array::<f64>::new(24usize);
    let mut tmp_pos = Array::<f64>::new(32usize);
    let mut tmp_wts = Array::<f64>::new(24usize);
    let mut all_inside = true;
    for k in 0..3usize {
        let vi = usize::cast_from(faces[f * 3 + k]);
        for c in 0..4usize {
            pos[k * 4 + c] = f64::cast_from(clip[vi * 4 + c]);
        }
        for c in 0..3usize {
            wts[k * 3 + c] = 0.0f64;
        }
        wts[k * 3 + k] = 1.0f64;
        let w = pos[k * 4 + 3];
        if !(w - 0.000001f64 >= 0.0f64 && pos[k * 4 + 2] + w >= 0.0f64) {
            all_inside = false;
        }
    }
    let mut len = 3usize;
    if !all_inside {
        len = clip_plane(&pos, &wts, len, &mut tmp_pos, &mut tmp_wts, true);
        if len >= 3 {
            len = clip_plane(&tmp_pos, &tmp_wts, len, &mut pos, &mut wts, false);
        } else {
            len = 0;
        }
        if len < 3 {
            len = 0;
        }
    }
    let (wf, hf) = (f64::cast_from(width), f64::cast_from(height));
    let mut k = 1usize;
    while k + 1 < len {
        // The fan triangle (0, k, k + 1), oriented positively: (0, j1, j2).
        let mut j1 = k;
        let mut j2 = k + 1;
        let sx0 = screen(pos[0], pos[3], wf);
        let sy0 = screen(pos[1], pos[3], hf);
        let fx0 = snap(sx0);
        let fy0 = snap(sy0);
        let area = edge_sign(
            snap(screen(pos[j1 * 4], pos[j1 * 4 + 3], wf)) - fx0,
            snap(screen(pos[j1 * 4 + 1], pos[j1 * 4 + 3], hf)) - fy0,
            snap(screen(pos[j2 * 4], pos[j2 * 4 + 3], wf)) - fx0,
            snap(screen(pos[j2 * 4 + 1], pos[j2 * 4 + 3], hf)) - fy0,
        );
        if area < 0i32 {
            j1 = k + 1;
            j2 = k;
        }
        if area != 0i32 {
            raster_triangle(
                &pos, &wts, j1, j2, face_id, keys, winners, bary, depth, width, height, pass,
            );
        }
        k += 1;
    }
}

/// Rasterizes the positively oriented triangle (0, `j1`, `j2`) of the clipped polygon.
#[cube]
#[allow(clippy::too_many_arguments)]
fn raster_triangle(
    pos: &Array<f64>,
    wts: &Array<f64>,
    j1: usize,
    j2: usize,
    face_id: i32,
    keys: &[Atomic<i32>],
    winners: &[Atomic<i32>],
    bary: &mut [f32],
    depth: &mut [f32],
    width: u32,
    height: u32,
    #[comptime] pass: Pass,
) {
    let (wf, hf) = (f64::cast_from(width), f64::cast_from(height));
    // Per vertex (0, j1, j2 -> slots 0, 1, 2): unsnapped and snapped screen positions.
    let mut idx = Array::<usize>::new(3usize);
    idx[0] = 0;
    idx[1] = j1;
    idx[2] = j2;
    let mut sx = Array::<f64>::new(3usize);
    let mut sy = Array::<f64>::new(3usize);
    let mut fx = Array::<i64>::new(3usize);
    let mut fy = Array::<i64>::new(3usize);
    for s in 0..3usize {
        let i = idx[s];
        sx[s] = screen(pos[i * 4], pos[i * 4 + 3], wf);
        sy[s] = screen(pos[i * 4 + 1], pos[i * 4 + 3], hf);
        fx[s] = snap(sx[s]);
        fy[s] = snap(sy[s]);
    }
    let min_x = min(fx[0], min(fx[1], fx[2]));
    let max_x = max(fx[0], max(fx[1], fx[2]));
    let min_y = min(fy[0], min(fy[1], fy[2]));
    let max_y = max(fy[0], max(fy[1], fy[2]));
    let col0 = max(first_centre(min_x), 0i64);
    let col1 = min(last_centre(max_x), i64::cast_from(width) - 1i64);
    let row0 = max(first_centre(min_y), 0i64);
    let row1 = min(last_centre(max_y), i64::cast_from(height) - 1i64);
    if col0 <= col1 && row0 <= row1 {
        // Edge k runs from vertex (k + 1) % 3 to (k + 2) % 3.
        let mut top_left = Array::<bool>::new(3usize);
        for e in 0..3usize {
            let a = (e + 1) % 3;
            let b = (e + 2) % 3;
            let dx = fx[b] - fx[a];
            let dy = fy[b] - fy[a];
            top_left[e] = dx > 0i64 || (dx == 0i64 && dy < 0i64);
        }
        for row in u32::cast_from(row0)..u32::cast_from(row1) + 1 {
            let py = i64::cast_from(row) * 65536i64 + 32768i64;
            let pyf = f64::cast_from(row) + 0.5f64;
            for col in u32::cast_from(col0)..u32::cast_from(col1) + 1 {
                let px = i64::cast_from(col) * 65536i64 + 32768i64;
                let pxf = f64::cast_from(col) + 0.5f64;
                let mut inside = true;
                let mut s = Array::<f64>::new(3usize);
                for e in 0..3usize {
                    let a = (e + 1) % 3;
                    let b = (e + 2) % 3;
                    let sign = edge_sign(fx[b] - fx[a], fy[b] - fy[a], px - fx[a], py - fy[a]);
                    if !(sign > 0i32 || (sign == 0i32 && top_left[e])) {
                        inside = false;
                    }
                    s[e] = (sx[b] - sx[a]) * (pyf - sy[a]) - (sy[b] - sy[a]) * (pxf - sx[a]);
                }
                if inside {
                    let mut total = s[0] + s[1] + s[2];
                    if !(total > 0.0f64 && finite(total)) {
                        for e in 0..3usize {
                            let a = (e + 1) % 3;
                            let b = (e + 2) % 3;
                            s[e] = edge_value(fx[b] - fx[a], fy[b] - fy[a], px - fx[a], py - fy[a]);
                        }
                        total = s[0] + s[1] + s[2];
                    }
                    // Perspective correction (`raster.rs`'s `perspective`).
                    let mut q = Array::<f64>::new(3usize);
                    for v in 0..3usize {
                        q[v] = s[v] / total / pos[idx[v] * 4 + 3];
                    }
                    let sum = q[0] + q[1] + q[2];
                    for v in 0..3usize {
                        q[v] /= sum;
                    }
                    let mut b = Array::<f64>::new(3usize);
                    let mut ok = true;
                    for i in 0..3usize {
                        b[i] = q[0] * wts[idx[0] * 3 + i]
                            + q[1] * wts[idx[1] * 3 + i]
                            + q[2] * wts[idx[2] * 3 + i];
                        if !finite(b[i]) {
                            ok = false;
                        }
                    }
                    let z = q[0] * pos[idx[0] * 4 + 2]
                        + q[1] * pos[idx[1] * 4 + 2]
                        + q[2] * pos[idx[2] * 4 + 2];
                    let w = q[0] * pos[idx[0] * 4 + 3]
                        + q[1] * pos[idx[1] * 4 + 3]
                        + q[2] * pos[idx[2] * 4 + 3];
                    let d = z / w;
                    if ok && finite(d) && d <= 1.0f64 {
                        let pixel = usize::cast_from(row * width + col);
                        let d32 = f32::cast_from(d);
                        let key = depth_key(d32);
                        match pass {
                            Pass::Depth => {
                                keys[pixel].fetch_min(key);
                            }
                            Pass::Face => {
                                if keys[pixel].load() == key {
                                    winners[pixel].fetch_min(face_id);
                                }
                            }
                            Pass::Write => {
                                if keys[pixel].load() == key && winners[pixel].load() == face_id {
                                    for i in 0..3usize {
                                        bary[pixel * 3 + i] = f32::cast_from(b[i]);
                                    }
                                    depth[pixel] = d32;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}
