//! Checkpoints: network parameters, Adam moments and the run's progress in one safetensors
//! file, written atomically, restored exactly.

use std::collections::HashMap;
use std::path::Path;

use safetensors::{Dtype, SafeTensors};

use crate::BittError;
use crate::losses::LossTerms;

/// The `format` metadata of a checkpoint file.
pub const CHECKPOINT_FORMAT: &str = "bitt-checkpoint-1";

/// One flattened tensor: shape and values.
pub type HostTensor = (Vec<usize>, Vec<f32>);

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
    /// Adam steps per parameter.
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

impl Checkpoint {
    /// Writes the checkpoint to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<(), BittError> {
        let mut entries: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
        for (i, (shape, values)) in self.parameters.iter().enumerate() {
            entries.push((format!("param.{i}"), shape.clone(), f32_bytes(values)));
        }
        for (name, list) in [("adam_m", &self.adam_m), ("adam_v", &self.adam_v)] {
            for (i, m) in list.iter().enumerate() {
                if let Some(m) = m {
                    entries.push((format!("{name}.{i}"), vec![m.len()], f32_bytes(m)));
                }
            }
        }
        let mut views = Vec::with_capacity(entries.len());
        for (name, shape, bytes) in &entries {
            let view = safetensors::tensor::TensorView::new(Dtype::F32, shape.clone(), bytes)
                .map_err(|e| BittError::corrupt(path, format!("cannot encode {name}: {e}")))?;
            views.push((name.clone(), view));
        }
        let json = |v: serde_json::Result<String>| {
            v.map_err(|e| BittError::corrupt(path, format!("cannot encode metadata: {e}")))
        };
        let metadata = HashMap::from([
            ("format".to_string(), CHECKPOINT_FORMAT.to_string()),
            ("iteration".to_string(), self.iteration.to_string()),
            (
                "lr_scale".to_string(),
                json(serde_json::to_string(&self.lr_scale))?,
            ),
            (
                "seconds".to_string(),
                json(serde_json::to_string(&self.seconds))?,
            ),
            ("parameters".to_string(), self.parameters.len().to_string()),
            (
                "adam_steps".to_string(),
                json(serde_json::to_string(&self.adam_steps))?,
            ),
            (
                "history".to_string(),
                json(serde_json::to_string(&self.history))?,
            ),
            (
                "events".to_string(),
                json(serde_json::to_string(&self.events))?,
            ),
        ]);
        let bytes = safetensors::serialize(views, Some(metadata))
            .map_err(|e| BittError::corrupt(path, format!("cannot encode: {e}")))?;
        bitt_mesh::export::write_atomically(path, &bytes)?;
        Ok(())
    }

    /// Reads a checkpoint written by [`Checkpoint::save`].
    pub fn load(path: &Path) -> Result<Self, BittError> {
        let bytes = std::fs::read(path).map_err(|e| BittError::io(path, e))?;
        let bad = |m: String| BittError::corrupt(path, m);
        let st = SafeTensors::deserialize(&bytes)
            .map_err(|e| bad(format!("not a safetensors file: {e}")))?;
        let (_, meta) = SafeTensors::read_metadata(&bytes)
            .map_err(|e| bad(format!("bad safetensors header: {e}")))?;
        let meta = meta.metadata().clone().unwrap_or_default();
        let get = |k: &str| {
            meta.get(k)
                .cloned()
                .ok_or_else(|| bad(format!("metadata `{k}` is missing")))
        };
        let format = get("format")?;
        if format != CHECKPOINT_FORMAT {
            return Err(bad(format!(
                "format is {format:?}, expected {CHECKPOINT_FORMAT:?}"
            )));
        }
        fn parse<T: serde::de::DeserializeOwned>(
            text: &str,
            key: &str,
            path: &Path,
        ) -> Result<T, BittError> {
            serde_json::from_str(text)
                .map_err(|e| BittError::corrupt(path, format!("metadata `{key}`: {e}")))
        }
        let iteration: usize = parse(&get("iteration")?, "iteration", path)?;
        let lr_scale: f64 = parse(&get("lr_scale")?, "lr_scale", path)?;
        let seconds: f64 = parse(&get("seconds")?, "seconds", path)?;
        let count: usize = parse(&get("parameters")?, "parameters", path)?;
        let adam_steps: Vec<u64> = parse(&get("adam_steps")?, "adam_steps", path)?;
        let history: Vec<LossTerms> = parse(&get("history")?, "history", path)?;
        let events: Vec<(usize, String)> = parse(&get("events")?, "events", path)?;
        let read = |name: &str| -> Result<Option<HostTensor>, BittError> {
            let t = match st.tensor(name) {
                Ok(t) => t,
                Err(_) => return Ok(None),
            };
            if t.dtype() != Dtype::F32 {
                return Err(bad(format!("{name} is {:?}, expected F32", t.dtype())));
            }
            let values: Vec<f32> = t
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            if values.iter().any(|v| !v.is_finite()) {
                return Err(bad(format!("{name} holds non-finite values")));
            }
            Ok(Some((t.shape().to_vec(), values)))
        };
        let mut parameters = Vec::with_capacity(count);
        let (mut adam_m, mut adam_v) = (Vec::new(), Vec::new());
        for i in 0..count {
            parameters.push(
                read(&format!("param.{i}"))?.ok_or_else(|| bad(format!("param.{i} is missing")))?,
            );
            adam_m.push(read(&format!("adam_m.{i}"))?.map(|t| t.1));
            adam_v.push(read(&format!("adam_v.{i}"))?.map(|t| t.1));
        }
        if adam_steps.len() > count {
            return Err(bad(format!(
                "{} Adam step counts for {count} parameters",
                adam_steps.len()
            )));
        }
        if !(lr_scale.is_finite() && lr_scale > 0.0) || history.len() != iteration {
            return Err(bad(format!(
                "inconsistent progress: iteration {iteration}, {} losses, lr scale {lr_scale}",
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

    #[test]
    fn round_trip_and_corruption_is_named() {
        let dir = std::env::temp_dir().join(format!("bitt-ckpt-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("checkpoint.safetensors");
        let terms = LossTerms::from_values(&[0.1, 0.2, 0.3, 0.4, 0.5, 0.6], 1.0);
        let c = Checkpoint {
            iteration: 2,
            lr_scale: 0.5,
            history: vec![terms, terms],
            events: vec![(1, "loss was NaN".into())],
            parameters: vec![(vec![2, 2], vec![1.0, 2.0, 3.0, 4.0]), (vec![1], vec![5.0])],
            adam_steps: vec![2, 0],
            adam_m: vec![Some(vec![0.1; 4]), None],
            adam_v: vec![Some(vec![0.2; 4]), None],
            seconds: 3.5,
        };
        c.save(&path).unwrap();
        assert_eq!(Checkpoint::load(&path).unwrap(), c);
        std::fs::write(&path, b"not a checkpoint").unwrap();
        let e = Checkpoint::load(&path).unwrap_err().to_string();
        assert!(e.contains("checkpoint.safetensors"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
