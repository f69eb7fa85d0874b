//! A small seeded generator (SplitMix64) for test inputs: the same bits everywhere.

use burn::tensor::{Device, Tensor, TensorData};

/// SplitMix64 (Steele, Lea and Flood 2014).
///
/// The library crates' own generator, `bitt_texture::procedural::noise::SplitMix64`, is the
/// same algorithm; this copy exists because the kit sits below `bitt-texture` (whose tests
/// use it).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator starting from `seed`.
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`, 53 bits.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform in `[lo, hi)` computed in `f32` from 24 bits (exact steps of `2^-24`).
    pub fn uniform_f32(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next_u64() >> 40) as f32 / (1u64 << 24) as f32)
    }

    /// Uniform integer in `0..n`.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// `n` values uniform in `[-1, 1)` from `seed` (a different stream for each seed).
pub fn values(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = Rng::new(seed.wrapping_mul(0x2545_F491_4F6C_DD1D));
    (0..n).map(|_| rng.uniform_f32(-1.0, 1.0)).collect()
}

/// A tensor of [`values`] in `[-1, 1)`: the same numbers on every device.
pub fn random<const D: usize>(shape: [usize; D], seed: u64, device: &Device) -> Tensor<D> {
    let n = shape.iter().product();
    Tensor::from_data(TensorData::new(values(n, seed), shape), device)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64's published first outputs from seed 0, and the ranges.
    #[test]
    fn splitmix64_stream_and_ranges() {
        let mut r = Rng::new(0);
        assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        let v = values(1000, 3);
        assert!(v.iter().all(|x| (-1.0..1.0).contains(x)));
        assert_eq!(v, values(1000, 3));
        assert_ne!(v, values(1000, 4));
        assert!((0..100).all(|_| r.below(7) < 7));
    }
}
