//! Helpers shared by this crate's unit tests beyond the workspace's kit (`bitt-testkit`).

use std::sync::Mutex;

use crate::pca::{FitProgress, FitStage};

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
