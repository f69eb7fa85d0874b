//! Checkpoints: network parameters, Adam moments and the run's progress in one safetensors
//! file, written atomically, checksummed, restored exactly.
//!
//! Format `bitt-checkpoint-2`: tensors `param.i`, `adam_m.i`, `adam_v.i` (F32), `history`
//! (F64 `[iterations, LossTerms::COUNT + 1]`: the loss terms and the total, bit-exact) and `progress` (F64
//! `[lr_scale, seconds]`); metadata `iteration`, `parameters`, `adam_steps`, `events`,
//! `tensors` (how many), and the `checksums` and `metadata_checksum` that [`bitt_stdx::st`]
//! writes into every file (and verifies). Every count, checksum and shape is verified on
//! load, and what is wrong is named. Files of the earlier format `bitt-checkpoint-1`
//! (progress as JSON text, no checksums) are still read.

use std::collections::HashMap;
use std::path::Path;

use bitt_stdx::st;
use safetensors::Dtype;

use crate::TrainError;
use crate::losses::LossTerms;
use bitt_stdx::FileErrorExt;

/// The `format` metadata of a checkpoint file.
pub(crate) const CHECKPOINT_FORMAT: &str = "bitt-checkpoint-2";

/// The format before checksums (read, never written).
const CHECKPOINT_FORMAT_1: &str = "bitt-checkpoint-1";

/// Values per `history` row: the six loss terms, then the total.
const HISTORY_COLUMNS: usize = LossTerms::COUNT + 1;

/// One flattened tensor: shape and values.
pub(crate) type HostTensor = (Vec<usize>, Vec<f32>);

/// Everything needed to continue a run exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// Iterations completed.
    pub iteration: usize,
    /// Factor on the scheduled learning rate (halved at every non-finite loss).
    pub lr_scale: f64,
    /// Loss terms of every completed iteration.
    pub history: Vec<LossTerms>,
    /// Non-finite events: (iteration, what happened).
    pub events: Vec<(usize, String)>,
    /// Network parameters in visiting order.
    pub parameters: Vec<HostTensor>,
    /// Adam steps per parameter (empty before the first step).
    pub adam_steps: Vec<u64>,
    /// Adam first moments (flattened; `None` before the first gradient).
    pub adam_m: Vec<Option<Vec<f32>>>,
    /// Adam second moments.
    pub adam_v: Vec<Option<Vec<f32>>>,
    /// Seconds of training so far.
    pub seconds: f64,
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn f64_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

impl Checkpoint {
    /// Writes the checkpoint to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<(), TrainError> {
        let mut entries: Vec<st::Entry> = Vec::new();
        for (i, (shape, values)) in self.parameters.iter().enumerate() {
            entries.push((
                format!("param.{i}"),
                Dtype::F32,
                shape.clone(),
                f32_bytes(values),
            ));
        }
        for (name, list) in [("adam_m", &self.adam_m), ("adam_v", &self.adam_v)] {
            for (i, m) in list.iter().enumerate() {
                if let Some(m) = m {
                    entries.push((
                        format!("{name}.{i}"),
                        Dtype::F32,
                        vec![m.len()],
                        f32_bytes(m),
                    ));
                }
            }
        }
        let history: Vec<f64> = self.history.iter().flat_map(|h| h.values()).collect();
        entries.push((
            "history".into(),
            Dtype::F64,
            vec![self.history.len(), HISTORY_COLUMNS],
            f64_bytes(&history),
        ));
        entries.push((
            "progress".into(),
            Dtype::F64,
            vec![2],
            f64_bytes(&[self.lr_scale, self.seconds]),
        ));
        let json = |v: serde_json::Result<String>| {
            v.map_err(|e| TrainError::format(path, format!("cannot encode metadata: {e}")))
        };
        let metadata = HashMap::from([
            ("format".to_string(), CHECKPOINT_FORMAT.to_string()),
            ("iteration".to_string(), self.iteration.to_string()),
            ("parameters".to_string(), self.parameters.len().to_string()),
            ("tensors".to_string(), entries.len().to_string()),
            (
                "adam_steps".to_string(),
                json(serde_json::to_string(&self.adam_steps))?,
            ),
            (
                "events".to_string(),
                json(serde_json::to_string(&self.events))?,
            ),
        ]);
        // `st` adds the checksums of every tensor and of the metadata.
        Ok(st::write(path, &entries, metadata)?)
    }

    /// Reads a checkpoint written by [`Checkpoint::save`], verifying its checksums and counts.
    pub fn load(path: &Path) -> Result<Self, TrainError> {
        let bytes = std::fs::read(path).map_err(|e| TrainError::io(path, e))?;
        Self::from_bytes(&bytes, path)
    }

    /// [`Checkpoint::load`] of a file's bytes; `path` names it in errors.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, TrainError> {
        let bad = |m: String| TrainError::format(path, m);
        let r = st::Reader::open(bytes, path)?;
        let meta = r.metadata();
        let get = |k: &str| {
            meta.get(k)
                .cloned()
                .ok_or_else(|| bad(format!("metadata `{k}` is missing")))
        };
        let format = get("format")?;
        let legacy = match format.as_str() {
            CHECKPOINT_FORMAT => false,
            CHECKPOINT_FORMAT_1 => true,
            _ => {
                return Err(bad(format!(
                    "format is {format:?}, expected {CHECKPOINT_FORMAT:?}"
                )));
            }
        };
        fn parse<T: serde::de::DeserializeOwned>(
            text: &str,
            key: &str,
            path: &Path,
        ) -> Result<T, TrainError> {
            serde_json::from_str(text)
                .map_err(|e| TrainError::format(path, format!("metadata `{key}`: {e}")))
        }
        if !legacy {
            // `st::Reader::open` verified the checksums; a checkpoint must have them.
            if !r.checksummed() {
                return Err(bad("the file has no checksums".into()));
            }
            let tensors: usize = parse(&get("tensors")?, "tensors", path)?;
            let names = r.names();
            if names.len() != tensors {
                return Err(bad(format!(
                    "the file holds {} tensors; its metadata says {tensors}",
                    names.len()
                )));
            }
        }
        let iteration: usize = parse(&get("iteration")?, "iteration", path)?;
        let count: usize = parse(&get("parameters")?, "parameters", path)?;
        let adam_steps: Vec<u64> = parse(&get("adam_steps")?, "adam_steps", path)?;
        let events: Vec<(usize, String)> = parse(&get("events")?, "events", path)?;
        let f64s = |name: &str, rank: usize| -> Result<Vec<f64>, TrainError> {
            Ok(r.values::<f64>(name, &vec![None; rank])?.1)
        };
        let (lr_scale, seconds, history) = if legacy {
            let lr_scale: f64 = parse(&get("lr_scale")?, "lr_scale", path)?;
            let seconds: f64 = parse(&get("seconds")?, "seconds", path)?;
            let history: Vec<LossTerms> = parse(&get("history")?, "history", path)?;
            (lr_scale, seconds, history)
        } else {
            let progress = f64s("progress", 1)?;
            let [lr_scale, seconds] = progress[..] else {
                return Err(bad(format!(
                    "progress holds {} values, not 2",
                    progress.len()
                )));
            };
            let rows = f64s("history", 2)?;
            let history: Vec<LossTerms> = rows
                .chunks_exact(HISTORY_COLUMNS)
                .filter_map(|r| r.try_into().ok().map(LossTerms::from_row))
                .collect();
            if rows.len() != history.len() * HISTORY_COLUMNS {
                return Err(bad(format!(
                    "history holds {} values, not rows of {HISTORY_COLUMNS}",
                    rows.len()
                )));
            }
            (lr_scale, seconds, history)
        };
        let read = |name: &str| -> Result<Option<HostTensor>, TrainError> {
            if !r.has(name) {
                return Ok(None);
            }
            Ok(Some(r.finite_f32s(name, None)?))
        };
        if !(adam_steps.is_empty() || adam_steps.len() == count) {
            return Err(bad(format!(
                "{} Adam step counts for {count} parameters",
                adam_steps.len()
            )));
        }
        let mut parameters = Vec::with_capacity(count);
        let (mut adam_m, mut adam_v) = (Vec::new(), Vec::new());
        for i in 0..count {
            let p =
                read(&format!("param.{i}"))?.ok_or_else(|| bad(format!("param.{i} is missing")))?;
            let m = read(&format!("adam_m.{i}"))?.map(|t| t.1);
            let v = read(&format!("adam_v.{i}"))?.map(|t| t.1);
            let stepped = adam_steps.get(i).is_some_and(|&s| s > 0);
            for (name, moment) in [("adam_m", &m), ("adam_v", &v)] {
                match moment {
                    Some(_) if !stepped => {
                        return Err(bad(format!(
                            "{name}.{i} is present, but parameter {i} has taken no Adam step"
                        )));
                    }
                    Some(x) if x.len() != p.1.len() => {
                        return Err(bad(format!(
                            "{name}.{i} holds {} values; parameter {i} has {}",
                            x.len(),
                            p.1.len()
                        )));
                    }
                    None if stepped => {
                        return Err(bad(format!(
                            "{name}.{i} is missing, but parameter {i} has taken Adam steps"
                        )));
                    }
                    _ => {}
                }
            }
            parameters.push(p);
            adam_m.push(m);
            adam_v.push(v);
        }
        let progress_ok =
            lr_scale > 0.0 && lr_scale <= 1.0 && seconds.is_finite() && seconds >= 0.0;
        if !progress_ok || history.len() != iteration {
            return Err(bad(format!(
                "inconsistent progress: iteration {iteration}, {} losses, lr scale {lr_scale}, \
                 {seconds} s",
                history.len()
            )));
        }
        Ok(Checkpoint {
            iteration,
            lr_scale,
            history,
            events,
            parameters,
            adam_steps,
            adam_m,
            adam_v,
            seconds,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> Checkpoint {
        // Sized by `LossTerms::COUNT`, so a new loss term needs no edit here.
        let plain: Vec<f64> = (1..=LossTerms::COUNT).map(|k| k as f64 / 10.0).collect();
        let terms = LossTerms::from_values(&plain, 1.0);
        // Values whose shortest decimal text does not always parse back to the same bits.
        let odd: Vec<f64> = [
            0.1 + 0.2,
            1.0 / 3.0,
            2.2250738585072014e-308,
            7e-9,
            0.0,
            5.0,
        ]
        .into_iter()
        .cycle()
        .take(LossTerms::COUNT)
        .collect();
        let odd = LossTerms::from_values(&odd, 9.000000000000002);
        Checkpoint {
            iteration: 2,
            lr_scale: 0.5,
            history: vec![terms, odd],
            events: vec![(1, "loss was NaN".into())],
            parameters: vec![(vec![2, 2], vec![1.0, 2.0, 3.0, 4.0]), (vec![1], vec![5.0])],
            adam_steps: vec![2, 0],
            adam_m: vec![Some(vec![0.1; 4]), None],
            adam_v: vec![Some(vec![0.2; 4]), None],
            seconds: 3.5,
        }
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("bitt-ckpt-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join("checkpoint.safetensors")
    }

    #[test]
    fn round_trip_is_bit_exact_and_garbage_is_named() {
        let path = scratch("round");
        let c = example();
        c.save(&path).unwrap();
        let back = Checkpoint::load(&path).unwrap();
        assert_eq!(back, c);
        for (a, b) in back.history.iter().zip(&c.history) {
            assert_eq!(a.values().map(f64::to_bits), b.values().map(f64::to_bits));
        }
        std::fs::write(&path, b"not a checkpoint").unwrap();
        let e = Checkpoint::load(&path).unwrap_err().to_string();
        assert!(e.contains("checkpoint.safetensors"), "{e}");
        std::fs::remove_dir_all(path.parent().unwrap()).ok();
    }

    /// Every byte of every tensor is covered: a flipped byte anywhere in the data is named.
    #[test]
    fn a_flipped_byte_in_any_tensor_is_named() {
        let path = scratch("flip");
        example().save(&path).unwrap();
        let good = std::fs::read(&path).unwrap();
        let header = u64::from_le_bytes(good[..8].try_into().unwrap()) as usize + 8;
        // Any byte of the header flipped, or the file cut anywhere: an error, never a panic,
        // and never a checkpoint that differs from the one written.
        for at in 0..header {
            let mut bad = good.clone();
            bad[at] ^= 0x01;
            if let Ok(c) = Checkpoint::from_bytes(&bad, &path) {
                assert_eq!(c, example(), "header byte {at} changed the checkpoint");
            }
        }
        for len in 0..good.len() {
            assert!(
                Checkpoint::from_bytes(&good[..len], &path).is_err(),
                "cut at {len}"
            );
        }
        for at in header..good.len() {
            let mut bad = good.clone();
            bad[at] ^= 0x10;
            let e = Checkpoint::from_bytes(&bad, &path).unwrap_err().to_string();
            assert!(
                e.contains("checkpoint.safetensors") && e.contains("corrupt"),
                "byte {at}: {e}"
            );
        }
        std::fs::remove_dir_all(path.parent().unwrap()).ok();
    }

    /// Altered metadata (an Adam step count, the iteration) and inconsistent counts are named.
    #[test]
    fn altered_metadata_and_wrong_counts_are_named() {
        let path = scratch("meta");
        let c = example();
        c.save(&path).unwrap();
        let good = std::fs::read(&path).unwrap();
        let find = |hay: &[u8], needle: &[u8]| hay.windows(needle.len()).position(|w| w == needle);
        let at = find(&good, br#""adam_steps":"[2,0]""#).expect("header layout changed");
        let mut altered = good.clone();
        altered[at + 15] = b'3';
        let e = Checkpoint::from_bytes(&altered, &path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("metadata is corrupt"), "{e}");
        // Counts are checked even when the checksums agree (a file written by a buggy writer).
        for (field, broken, expect) in [
            (
                "adam_steps",
                Checkpoint {
                    adam_steps: vec![2],
                    ..c.clone()
                },
                "Adam step counts",
            ),
            (
                "history",
                Checkpoint {
                    iteration: 3,
                    ..c.clone()
                },
                "inconsistent progress",
            ),
            (
                "adam_m",
                Checkpoint {
                    adam_m: vec![Some(vec![0.1; 3]), None],
                    ..c.clone()
                },
                "adam_m.0 holds 3 values",
            ),
            (
                "adam_v",
                Checkpoint {
                    adam_v: vec![Some(vec![0.2; 4]), Some(vec![0.0])],
                    ..c.clone()
                },
                "adam_v.1 is present",
            ),
            (
                "lr_scale",
                Checkpoint {
                    lr_scale: 8.0,
                    ..c.clone()
                },
                "lr scale 8",
            ),
        ] {
            broken.save(&path).unwrap();
            let e = Checkpoint::load(&path).unwrap_err().to_string();
            assert!(
                e.contains(expect) && e.contains("checkpoint.safetensors"),
                "{field}: {e}"
            );
        }
        std::fs::remove_dir_all(path.parent().unwrap()).ok();
    }

    /// Checkpoints of the first format (no checksums, progress as JSON text) still resume.
    #[test]
    fn first_format_files_still_load() {
        let path = scratch("v1");
        let c = Checkpoint {
            history: vec![LossTerms::from_values(&[0.5; LossTerms::COUNT], 3.0); 2],
            ..example()
        };
        let bytes = |v: &[f32]| f32_bytes(v);
        let tensors = [
            ("param.0", vec![2, 2], bytes(&c.parameters[0].1)),
            ("param.1", vec![1], bytes(&c.parameters[1].1)),
            ("adam_m.0", vec![4], bytes(&[0.1; 4])),
            ("adam_v.0", vec![4], bytes(&[0.2; 4])),
        ];
        let views: Vec<_> = tensors
            .iter()
            .map(|(n, s, b)| {
                let v = safetensors::tensor::TensorView::new(Dtype::F32, s.clone(), b).unwrap();
                (n.to_string(), v)
            })
            .collect();
        let meta = HashMap::from([
            ("format".to_string(), CHECKPOINT_FORMAT_1.to_string()),
            ("iteration".to_string(), "2".to_string()),
            ("lr_scale".to_string(), "0.5".to_string()),
            ("seconds".to_string(), "3.5".to_string()),
            ("parameters".to_string(), "2".to_string()),
            ("adam_steps".to_string(), "[2,0]".to_string()),
            (
                "history".to_string(),
                serde_json::to_string(&c.history).unwrap(),
            ),
            (
                "events".to_string(),
                serde_json::to_string(&c.events).unwrap(),
            ),
        ]);
        std::fs::write(&path, safetensors::serialize(views, Some(meta)).unwrap()).unwrap();
        assert_eq!(Checkpoint::load(&path).unwrap(), c);
        std::fs::remove_dir_all(path.parent().unwrap()).ok();
    }
}
