//! Helpers shared by this crate's unit tests.

use std::sync::Mutex;

use burn::tensor::{Device, Tensor};

use crate::pca::{FitProgress, FitStage};

/// The CPU devices every numeric test runs on.
#[allow(deprecated)] // burn-ndarray is deprecated but still a supported backend here
pub(crate) fn devices() -> Vec<(&'static str, Device)> {
    vec![("flex", Device::flex()), ("ndarray", Device::ndarray())]
}

/// A tensor's values as `f32`.
pub(crate) fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    crate::pca::read(t).expect("tensor readback")
}

/// Element-wise `|a - b| <= tol * max(1, |b|)`.
pub(crate) fn assert_close(a: &[f32], b: &[f32], tol: f32) {
    assert_eq!(a.len(), b.len(), "lengths differ");
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol * y.abs().max(1.0),
            "value {i}: {x} vs {y} (tol {tol})\n{a:?}\n{b:?}"
        );
    }
}

/// A deterministic generator (SplitMix64) for test data.
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Self {
        Rng(seed)
    }

    /// Uniform in `[lo, hi)`.
    pub(crate) fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 40) as f32 / (1u64 << 24) as f32)
    }
}

/// A fresh empty folder for one test's files.
pub(crate) fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("bitt-texture-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("create temp dir");
    d
}

/// Runs `f` on a rayon pool of `threads` threads.
pub(crate) fn on_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("rayon pool")
        .install(f)
}

/// Records every progress report.
#[derive(Default)]
pub(crate) struct Recorder(pub(crate) Mutex<Vec<(FitStage, usize, usize)>>);

impl FitProgress for Recorder {
    fn report(&self, stage: FitStage, done: usize, total: usize) {
        self.0.lock().unwrap().push((stage, done, total));
    }
}

impl Recorder {
    /// Checks the reports: the stages in `order`, each from 0 to its total, monotone.
    pub(crate) fn check(&self, order: &[FitStage]) -> Vec<usize> {
        let calls = self.0.lock().unwrap().clone();
        let mut stages: Vec<FitStage> = calls.iter().map(|c| c.0).collect();
        stages.dedup();
        assert_eq!(stages, order, "{calls:?}");
        let mut totals = Vec::new();
        for &stage in order {
            let mine: Vec<_> = calls.iter().filter(|c| c.0 == stage).collect();
            let total = mine[0].2;
            assert!(total >= 1, "{stage:?}");
            assert_eq!(mine[0].1, 0, "{stage:?} starts at 0");
            assert!(mine.iter().all(|c| c.2 == total), "{stage:?}: {mine:?}");
            assert!(
                mine.windows(2).all(|w| w[0].1 <= w[1].1),
                "{stage:?} not monotone: {mine:?}"
            );
            assert_eq!(mine.last().unwrap().1, total, "{stage:?} ends at total");
            totals.push(total);
        }
        totals
    }
}
