//! Deterministic randomness: a SplitMix64 generator, lattice hashing, 3D gradient noise and
//! fractal (fBm) sums of it, with octaves finer than the texel size faded out.

use std::cell::RefCell;

use bitt_mesh::glam::DVec3;

/// SplitMix64 (Steele, Lea and Flood 2014): a tiny, fast, statistically solid generator.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator starting from `seed`.
    pub fn new(seed: u64) -> Self {
        SplitMix64 { state: seed }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)`.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// Approximately standard normal (sum of four uniforms, rescaled; tails clipped at ~3.5).
    pub fn normal(&mut self) -> f64 {
        let s: f64 = (0..4).map(|_| self.next_f64()).sum();
        (s - 2.0) * 3.0_f64.sqrt()
    }
}

/// SplitMix64's output function: a bijective 64-bit mixer.
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash of a seed and an integer lattice point.
pub(crate) fn hash3(seed: u64, x: i64, y: i64, z: i64) -> u64 {
    let mut h = mix64(seed ^ 0x51_7CC1_B727_220A);
    for c in [x, y, z] {
        h = mix64(h ^ (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    }
    h
}

/// A seed derived from `seed` and a small label, so that layers get independent streams.
pub fn derive(seed: u64, label: u64) -> u64 {
    mix64(seed.wrapping_add(mix64(label.wrapping_add(0x2545_F491_4F6C_DD1D))))
}

/// Uniform `[0, 1)` from 53 bits of `h`.
pub fn unit(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// log2 of the slots of the per-thread cache of lattice gradients.
const GRADIENT_CACHE_BITS: u32 = 12;

/// Unit gradient of a lattice point (a uniformly random direction): [`gradient_of`], from a
/// small per-thread direct-mapped cache keyed by the hash (neighbouring texels share most
/// lattice corners, and the cosine and sine dominate the cost of noise). The cached value
/// is the computed one, so results are unchanged bit for bit.
fn gradient(h: u64) -> DVec3 {
    thread_local! {
        static CACHE: RefCell<Vec<(u64, DVec3)>> = const { RefCell::new(Vec::new()) };
    }
    CACHE.with(|cache| {
        let mut cache = cache.borrow_mut();
        if cache.is_empty() {
            // Every slot starts as the (valid) entry of hash 0.
            cache.resize(1 << GRADIENT_CACHE_BITS, (0, gradient_of(0)));
        }
        let slot = &mut cache[(h >> (64 - GRADIENT_CACHE_BITS)) as usize];
        if slot.0 != h {
            *slot = (h, gradient_of(h));
        }
        slot.1
    })
}

/// The unit gradient of hash `h`, computed.
fn gradient_of(h: u64) -> DVec3 {
    let z = 2.0 * unit(h) - 1.0;
    let a = std::f64::consts::TAU * unit(mix64(h));
    let r = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(r * a.cos(), r * a.sin(), z)
}

/// Quintic fade curve `6t^5 - 15t^4 + 10t^3`.
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// 3D gradient (Perlin-style) noise with unit lattice spacing, roughly in `[-1, 1]`.
pub(crate) fn gradient_noise(seed: u64, p: DVec3) -> f64 {
    gradient_noise_with(seed, p, gradient)
}

/// [`gradient_noise`] with the lattice gradients from `gradient`.
#[inline(always)]
fn gradient_noise_with(seed: u64, p: DVec3, gradient: impl Fn(u64) -> DVec3) -> f64 {
    let base = p.floor();
    let f = p - base;
    let (ix, iy, iz) = (base.x as i64, base.y as i64, base.z as i64);
    let (u, v, w) = (fade(f.x), fade(f.y), fade(f.z));
    let corner = |dx: i64, dy: i64, dz: i64| {
        let g = gradient(hash3(seed, ix + dx, iy + dy, iz + dz));
        g.dot(f - DVec3::new(dx as f64, dy as f64, dz as f64))
    };
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(corner(0, 0, 0), corner(1, 0, 0), u);
    let x10 = lerp(corner(0, 1, 0), corner(1, 1, 0), u);
    let x01 = lerp(corner(0, 0, 1), corner(1, 0, 1), u);
    let x11 = lerp(corner(0, 1, 1), corner(1, 1, 1), u);
    // Gradient noise in 3D peaks near +-1/sqrt(3)*... ; 1.6 brings it close to [-1, 1].
    1.6 * lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

/// Fractal Brownian motion: `octaves` layers of gradient noise, each at twice the frequency
/// and `gain` times the amplitude of the previous one, normalised so the sum stays roughly in
/// `[-1, 1]`. `wavelength` is the period of the first octave in metres; octaves whose
/// wavelength falls below about two texels (`texel` metres) fade out instead of aliasing.
pub(crate) fn fbm(
    seed: u64,
    p: DVec3,
    wavelength: f64,
    octaves: u32,
    gain: f64,
    texel: f64,
) -> f64 {
    let mut sum = 0.0;
    let mut norm = 0.0;
    let mut amp = 1.0;
    let mut lambda = wavelength;
    for o in 0..octaves {
        let keep = band_limit(lambda, texel);
        if keep <= 0.0 {
            break;
        }
        let s = derive(seed, u64::from(o));
        sum += amp * keep * gradient_noise(s, p / lambda);
        norm += amp;
        amp *= gain;
        lambda *= 0.5;
    }
    if norm > 0.0 { sum / norm } else { 0.0 }
}

/// How much of a feature with period `lambda` survives sampling every `texel`: 1 well above
/// the Nyquist limit, fading to 0 at about two texels.
pub(crate) fn band_limit(lambda: f64, texel: f64) -> f64 {
    smoothstep(2.0, 4.0, lambda / texel.max(1e-9))
}

/// Hermite smoothstep from `edge0` to `edge1` (clamped; works for either order of the edges).
pub fn smoothstep(edge0: f64, edge1: f64, x: f64) -> f64 {
    let t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The darkening profile of a thin line of half-width `width` at distance `d`, band-limited to
/// the texel size: a line thinner than a texel is spread over about one texel with its total
/// "ink" preserved, so it fades instead of aliasing into dotted fragments.
pub(crate) fn line_profile(d: f64, width: f64, texel: f64) -> f64 {
    let w = (width * width + 0.25 * texel * texel).sqrt();
    (width / w) * (-(d / w) * (d / w)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cached_gradients_are_the_computed_ones() {
        let mut rng = SplitMix64::new(17);
        // Random hashes, repeated (hits) and colliding in the cache (misses after eviction).
        let hashes: Vec<u64> = (0..5000).map(|_| rng.next_u64()).collect();
        for _ in 0..3 {
            for &h in hashes.iter().chain(&[0, 1, u64::MAX]) {
                let (a, b) = (gradient(h), gradient_of(h));
                assert_eq!(
                    a.to_array().map(f64::to_bits),
                    b.to_array().map(f64::to_bits)
                );
            }
        }
        // Noise through the cache equals noise from computed gradients.
        for seed in [3, 99] {
            for _ in 0..20_000 {
                let p = DVec3::new(
                    rng.range(-9.0, 9.0),
                    rng.range(-9.0, 9.0),
                    rng.range(-9.0, 9.0),
                );
                let (a, b) = (
                    gradient_noise(seed, p),
                    gradient_noise_with(seed, p, gradient_of),
                );
                assert_eq!(a.to_bits(), b.to_bits());
            }
        }
    }

    #[test]
    fn splitmix_is_deterministic_and_uniform() {
        let mut a = SplitMix64::new(7);
        let mut b = SplitMix64::new(7);
        let xs: Vec<f64> = (0..10_000).map(|_| a.next_f64()).collect();
        let ys: Vec<f64> = (0..10_000).map(|_| b.next_f64()).collect();
        assert_eq!(xs, ys);
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((mean - 0.5).abs() < 0.01, "mean {mean}");
        assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        // The reference sequence of SplitMix64 from seed 0.
        let mut z = SplitMix64::new(0);
        assert_eq!(z.next_u64(), 0xE220_A839_7B1D_CDAF);
    }

    #[test]
    fn noise_is_bounded_smooth_and_zero_mean() {
        let mut rng = SplitMix64::new(3);
        let mut sum = 0.0;
        let n = 20_000;
        for _ in 0..n {
            let p = DVec3::new(
                rng.range(-50.0, 50.0),
                rng.range(-50.0, 50.0),
                rng.range(-5.0, 5.0),
            );
            let v = gradient_noise(11, p);
            assert!(v.abs() <= 1.6, "{v}");
            let dv = gradient_noise(11, p + DVec3::splat(1e-4)) - v;
            assert!(dv.abs() < 1e-2, "not continuous: {dv}");
            sum += v;
        }
        assert!((sum / n as f64).abs() < 0.02);
        // Lattice points are zeros of gradient noise.
        assert_eq!(gradient_noise(5, DVec3::new(3.0, -2.0, 7.0)), 0.0);
    }

    #[test]
    fn fbm_fades_octaves_below_the_texel() {
        let p = DVec3::new(0.0123, 0.0456, -0.0789);
        let coarse = fbm(1, p, 0.02, 6, 0.5, 0.02);
        assert_eq!(coarse, 0.0, "first octave at one texel must vanish");
        let fine = fbm(1, p, 0.02, 6, 0.5, 1e-5);
        assert!(fine.is_finite() && fine.abs() <= 1.6);
    }

    #[test]
    fn thin_lines_keep_their_ink() {
        let texel = 1e-3;
        let ink = |w: f64| {
            (-8000..=8000)
                .map(|i| line_profile(f64::from(i) * 1e-6, w, texel) * 1e-6)
                .sum::<f64>()
        };
        let sharp = ink(2e-3) / 2e-3;
        let thin = ink(1e-4) / 1e-4;
        assert!((sharp / thin - 1.0).abs() < 0.15, "{sharp} vs {thin}");
    }
}
