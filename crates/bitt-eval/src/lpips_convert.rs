//! The `lpips` package's and torchvision's torch weights turned into the LPIPS weights file.

use bitt_stdx::FileErrorExt;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use bitt_pickle::{ArrayData, Value};
use burn::tensor::Device;

use crate::EvalError;
use crate::lpips::{self, LpipsVgg};

/// The float tensors of a torch state dict: (name, shape, values as `f32`).
pub(crate) type StateDict = Vec<(String, Vec<usize>, Vec<f32>)>;

/// The float tensors of a torch checkpoint's state dict (values as `f32`), the reader
/// [`convert`] takes.
///
/// # Errors
/// A file that is not a torch checkpoint, or one that holds something else than a dict.
pub fn torch_state_dict(path: &Path) -> Result<StateDict, EvalError> {
    let v = bitt_pickle::load_torch(path).map_err(|e| EvalError::Invalid(e.to_string()))?;
    let Value::Dict(items) = v else {
        return Err(EvalError::format(
            path,
            format!(
                "the checkpoint holds a {}, expected a state dict",
                v.type_name()
            ),
        ));
    };
    let mut out = Vec::new();
    for (k, t) in items {
        let (Value::Str(name), Value::Array(a)) = (k, t) else {
            continue;
        };
        if matches!(a.data, ArrayData::F32(_) | ArrayData::F64(_)) {
            let shape = a.shape.clone();
            out.push((name, shape, a.into_f32()));
        }
    }
    Ok(out)
}

/// Where torch caches torchvision's VGG16 weights,
/// `~/.cache/torch/hub/checkpoints/vgg16-397923af.pth` (relative without `HOME`).
pub(crate) fn torch_cache_vgg16() -> PathBuf {
    std::env::var_os("HOME")
        .map(PathBuf::from)
        .unwrap_or_default()
        .join(".cache/torch/hub/checkpoints/vgg16-397923af.pth")
}

/// Our tensor name for a name of the `lpips` package's state dict or of torchvision's VGG16;
/// `None` for tensors LPIPS does not use.
pub(crate) fn our_name(name: &str) -> Option<String> {
    // lpips: lin{l}.model.1.weight, lins.{l}.model.1.weight, net.slice{s}.{idx}.{weight,bias}
    if let Some(rest) = name.strip_prefix("lins.") {
        let l = rest.strip_suffix(".model.1.weight")?;
        return Some(format!("lin{l}.weight"));
    }
    if let Some(rest) = name.strip_prefix("lin") {
        let l = rest.strip_suffix(".model.1.weight")?;
        return Some(format!("lin{l}.weight"));
    }
    if let Some(rest) = name.strip_prefix("net.slice") {
        let (_, tail) = rest.split_once('.')?;
        return Some(format!("features.{tail}"));
    }
    // torchvision: features.{idx}.{weight,bias} (the classifier is not used).
    name.starts_with("features.").then(|| name.to_string())
}

/// What [`convert`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Converted {
    /// The weights file.
    pub path: PathBuf,
    /// How many tensors it holds.
    pub tensors: usize,
}

/// Writes the LPIPS weights file from the `lpips` package's `lin` weights (`vgg.pth`, or a
/// whole `lpips.LPIPS(net='vgg').state_dict()`) and, when `lin` holds no VGG16 backbone,
/// torchvision's `vgg16-397923af.pth` (`vgg`, default [`torch_cache_vgg16`]). `read` reads a
/// torch checkpoint's state dict. `out` defaults to [`lpips::default_weights_path`]. The file
/// is read back on `device` as LPIPS will read it.
pub fn convert(
    lin: &Path,
    vgg: Option<&Path>,
    out: Option<&Path>,
    mut read: impl FnMut(&Path) -> Result<StateDict, EvalError>,
    device: &Device,
) -> Result<Converted, EvalError> {
    type Tensors = HashMap<String, (Vec<usize>, Vec<f32>)>;
    let mut add = |tensors: &mut Tensors, path: &Path| -> Result<(), EvalError> {
        for (name, shape, data) in read(path)? {
            if let Some(ours) = our_name(&name) {
                tensors.entry(ours).or_insert((shape, data));
            }
        }
        Ok(())
    };
    let mut tensors = Tensors::new();
    add(&mut tensors, lin)?;
    let needs_vgg = lpips::weight_names()
        .iter()
        .any(|(n, _)| n.starts_with("features.") && !tensors.contains_key(n));
    if needs_vgg {
        let vgg = match vgg {
            Some(p) => p.to_path_buf(),
            None => {
                let p = torch_cache_vgg16();
                if !p.is_file() {
                    return Err(EvalError::Invalid(format!(
                        "{} holds no VGG16 backbone and {} does not exist; pass --vgg \
                         vgg16-397923af.pth (from https://download.pytorch.org/models/\
                         vgg16-397923af.pth)",
                        lin.display(),
                        p.display()
                    )));
                }
                p
            }
        };
        add(&mut tensors, &vgg)?;
    }
    let mut ordered = Vec::new();
    for (name, shape) in lpips::weight_names() {
        let Some((s, data)) = tensors.remove(&name) else {
            return Err(EvalError::Invalid(format!(
                "tensor {name} ({shape:?}) was found in none of the inputs ({}{})",
                lin.display(),
                vgg.map_or(String::new(), |p| format!(", {}", p.display()))
            )));
        };
        if s != shape {
            return Err(EvalError::Invalid(format!(
                "tensor {name} has shape {s:?} in the inputs, expected {shape:?}"
            )));
        }
        ordered.push((name, shape, data));
    }
    let path = match out {
        Some(p) => p.to_path_buf(),
        None => lpips::default_weights_path().ok_or_else(|| {
            EvalError::Invalid(
                "no --out and no HOME to put ~/.cache/bitt/lpips_vgg.safetensors in".into(),
            )
        })?,
    };
    lpips::save_weights(&path, &ordered)?;
    // Read it back as LPIPS will.
    LpipsVgg::load(&path, device)
        .map_err(|e| EvalError::Invalid(format!("checking {}: {e}", path.display())))?;
    Ok(Converted {
        path,
        tensors: ordered.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lpips_names_map_from_both_packages() {
        for (torch, ours) in [
            ("lin3.model.1.weight", Some("lin3.weight")),
            ("lins.0.model.1.weight", Some("lin0.weight")),
            ("net.slice4.19.bias", Some("features.19.bias")),
            ("features.28.weight", Some("features.28.weight")),
            ("classifier.0.weight", None),
            ("scaling_layer.shift", None),
        ] {
            assert_eq!(our_name(torch).as_deref(), ours, "{torch}");
        }
    }

    /// The `lpips` package's lin weights and torchvision's VGG16 names, zero values.
    fn fake(path: &Path) -> Result<StateDict, EvalError> {
        let lin = path.ends_with("vgg.pth");
        let mut out = StateDict::new();
        for (name, shape) in lpips::weight_names() {
            let torch = match name.strip_suffix(".weight") {
                Some(l) if l.starts_with("lin") => format!("{l}.model.1.weight"),
                _ => name.clone(),
            };
            if torch.starts_with("lin") == lin {
                out.push((torch, shape.clone(), vec![0.0; shape.iter().product()]));
            }
        }
        out.push(("classifier.0.weight".into(), vec![2], vec![0.0; 2]));
        Ok(out)
    }

    #[test]
    fn converts_both_checkpoints_and_names_what_is_missing() {
        let dir = std::env::temp_dir().join(format!("bitt-lpips-convert-{}", std::process::id()));
        let out = dir.join("w.safetensors");
        let device = Device::flex();
        let (lin, vgg) = (Path::new("vgg.pth"), Path::new("vgg16.pth"));
        let done = convert(lin, Some(vgg), Some(&out), fake, &device).unwrap();
        assert_eq!(done.path, out);
        assert_eq!(done.tensors, lpips::weight_names().len());
        assert!(LpipsVgg::load(&out, &device).is_ok());
        fn wrong_shape(p: &Path) -> Result<StateDict, EvalError> {
            fake(p).map(|mut d| {
                d[0].1 = vec![1, 7, 1, 1];
                d
            })
        }
        type Read = fn(&Path) -> Result<StateDict, EvalError>;
        let cases: [(&Path, Read, [&str; 2]); 2] = [
            // Without the backbone: the missing tensor and both inputs are named.
            (lin, fake, ["features.0.weight", "vgg.pth, vgg.pth"]),
            // A wrong shape is named.
            (vgg, wrong_shape, ["features.0.weight", "[1, 7, 1, 1]"]),
        ];
        for (second, read, names) in cases {
            let e = convert(lin, Some(second), Some(&out), read, &device)
                .unwrap_err()
                .to_string();
            assert!(names.iter().all(|n| e.contains(n)), "{e}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
