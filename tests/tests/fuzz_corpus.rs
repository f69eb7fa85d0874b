//! Replays the committed fuzz corpora (`fuzz/corpus/<target>/`, minimised with
//! `cargo fuzz cmin`) through the entry points the fuzz targets (`fuzz/fuzz_targets/`) call:
//! no input may panic, errors must name the file, and the seeds (`seed_*`, valid files built
//! in code by `bitt_tests::fuzz_seeds`, written by `cargo xtask fuzz-seeds`) must still read. Needs neither the network nor
//! `../shared`.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;

use bitt_tests::fuzz_checks as checks;
use bitt_tests::fuzz_seeds::{corpus_dir, seeds};

/// Feeds every file of a corpus to `read` (which returns whether it read the file, and
/// panics on nothing); checks that every seed reads and returns how many files there are.
fn replay(target: &str, read: impl Fn(&[u8]) -> bool) -> usize {
    let dir = corpus_dir(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let mut seeds = 0;
    for path in &files {
        let bytes = std::fs::read(path).unwrap();
        let ok = catch_unwind(AssertUnwindSafe(|| read(&bytes)))
            .unwrap_or_else(|_| panic!("{target}: {} panicked", path.display()));
        let name = path.file_name().unwrap().to_string_lossy();
        if name.starts_with("seed_") {
            assert!(ok, "{target}: seed {} no longer reads", path.display());
            seeds += 1;
        }
    }
    assert!(seeds >= 1, "{target}: no seed in {}", dir.display());
    files.len()
}

#[test]
fn from_bytes_corpus_replays() {
    replay("from_bytes", checks::from_bytes);
}

#[test]
fn torch_corpus_replays() {
    replay("torch", checks::torch);
}

#[test]
fn mano_safetensors_corpus_replays() {
    replay("mano_safetensors", checks::mano_safetensors);
}

#[test]
fn annotation_corpus_replays() {
    replay("annotation", checks::annotation);
}

#[test]
fn camera_values_corpus_replays() {
    replay("camera_values", checks::camera_values);
}

#[test]
fn light_corpus_replays() {
    replay("light", checks::light);
}

#[test]
fn interhand_corpus_replays() {
    replay("interhand", checks::interhand);
}

#[test]
fn keypoints_corpus_replays() {
    replay("keypoints", checks::keypoints);
}

/// The seeds are valid inputs of their readers (so the fuzzers start from real structure).
#[test]
fn fuzz_seeds_read() {
    for (target, name, bytes) in seeds() {
        let ok = match target {
            "from_bytes" => checks::from_bytes(&bytes),
            "torch" => checks::torch(&bytes),
            "mano_safetensors" => checks::mano_safetensors(&bytes),
            "annotation" => checks::annotation(&bytes),
            "interhand" => checks::interhand(&bytes),
            "keypoints" => checks::keypoints(&bytes),
            "camera_values" => checks::camera_values(&bytes),
            "light" => checks::light(&bytes),
            other => panic!("unknown target {other}"),
        };
        assert!(ok, "{target}: seed {name} does not read");
    }
}
