//! Per-person skin parameters.

use super::noise::{SplitMix64, derive};

/// The skin of one person: every knob of the procedural texture that differs between people.
///
/// All values are plain numbers so an identity can be edited, serialised and compared;
/// [`SkinIdentity::sample`] draws a plausible one from a seed. Strengths and densities are
/// multipliers around 1 (0 switches a layer off); the ranges below are those `sample` draws.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SkinIdentity {
    /// Seed of every random placement (freckles, hairs, veins, crease jitter, blotches).
    pub seed: u64,
    /// Melanin-like skin tone of the back of the hand: 0 very light, 1 very dark (`[0, 1]`).
    pub tone: f64,
    /// Undertone: -1 red/pink, +1 yellow/olive (`[-1, 1]`).
    pub undertone: f64,
    /// Overall blood redness (`[0.2, 1]`).
    pub redness: f64,
    /// Fraction of the melanin missing on the palm side (palms are lighter, very much so on
    /// dark skin; `[0.38, 0.68]`).
    pub palm_lightness: f64,
    /// Extra redness of the palm side (palms are pinker than the back; `[0.5, 1.2]`).
    pub palm_redness: f64,
    /// Darkness of the palm creases and finger flexion creases (`[0.5, 1.5]`).
    pub crease_strength: f64,
    /// Strength of the knuckle wrinkles and the darker, redder knuckles (`[0.4, 1.5]`).
    pub knuckle_strength: f64,
    /// How visible the dorsal veins are (`[0, 1.3]`; light skin shows them more).
    pub vein_visibility: f64,
    /// Density of fine hairs on the back of the hand and the proximal phalanges (`[0, 1.5]`).
    pub hair_density: f64,
    /// Darkness of those hairs (`[0.3, 1]`).
    pub hair_darkness: f64,
    /// Nail bed tint: -1 pale/white, +1 pink (`[-1, 1]`).
    pub nail_tint: f64,
    /// Density of freckles (`[0, 1.5]`; drawn lower for darker skin).
    pub freckle_density: f64,
    /// Density of moles (`[0, 1.2]`).
    pub mole_density: f64,
    /// Amplitude of the low-frequency blotchiness (`[0.4, 1.4]`).
    pub blotchiness: f64,
    /// Amplitude of the extra noise that makes the left and the right hand differ (`[0.5, 1.5]`).
    pub asymmetry: f64,
    /// Seed of that left/right asymmetry noise.
    pub asymmetry_seed: u64,
}

impl SkinIdentity {
    /// A random identity; deterministic in `seed`. Skin tones are spread uniformly from very
    /// light to very dark, and the other parameters are drawn independently (freckles and
    /// vein visibility lean towards light skin, as in real populations).
    pub fn sample(seed: u64) -> Self {
        let mut rng = SplitMix64::new(derive(seed, 0x1D));
        let tone = rng.range(0.02, 0.98);
        let light = 1.0 - tone;
        SkinIdentity {
            seed: derive(seed, 0x5EED),
            tone,
            undertone: rng.range(-1.0, 1.0),
            redness: rng.range(0.2, 1.0),
            palm_lightness: rng.range(0.38, 0.68),
            palm_redness: rng.range(0.5, 1.2),
            crease_strength: rng.range(0.5, 1.5),
            knuckle_strength: rng.range(0.4, 1.5),
            vein_visibility: rng.range(0.0, 1.3) * (0.4 + 0.6 * light),
            hair_density: rng.range(0.0, 1.5),
            hair_darkness: rng.range(0.3, 1.0),
            nail_tint: rng.range(-1.0, 1.0),
            freckle_density: rng.range(0.0, 1.5) * light * light,
            mole_density: rng.range(0.0, 1.2),
            blotchiness: rng.range(0.4, 1.4),
            asymmetry: rng.range(0.5, 1.5),
            asymmetry_seed: derive(seed, 0xA5),
        }
    }

    /// This identity with another skin tone (handy for side-by-side comparisons).
    pub fn with_tone(mut self, tone: f64) -> Self {
        self.tone = tone.clamp(0.0, 1.0);
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampling_is_deterministic_and_in_range() {
        assert_eq!(SkinIdentity::sample(42), SkinIdentity::sample(42));
        assert_ne!(SkinIdentity::sample(42), SkinIdentity::sample(43));
        let tones: Vec<f64> = (0..200).map(|s| SkinIdentity::sample(s).tone).collect();
        assert!(tones.iter().all(|t| (0.0..=1.0).contains(t)));
        let light = tones.iter().filter(|&&t| t < 0.3).count();
        let dark = tones.iter().filter(|&&t| t > 0.7).count();
        assert!(
            light > 40 && dark > 40,
            "tones not spread: {light} light, {dark} dark"
        );
        let json = serde_json::to_string(&SkinIdentity::sample(5)).unwrap();
        let back: SkinIdentity = serde_json::from_str(&json).unwrap();
        let orig = SkinIdentity::sample(5);
        assert_eq!(
            (back.seed, back.asymmetry_seed),
            (orig.seed, orig.asymmetry_seed)
        );
        assert!((back.tone - orig.tone).abs() < 1e-12);
    }
}
