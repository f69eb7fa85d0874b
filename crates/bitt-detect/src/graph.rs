//! The networks as this crate stores and runs them: a list of operations over numbered
//! tensors, with the constant weights alongside. Built from a TFLite model by
//! [`crate::tflite`] (the DEQUANTIZE steps of its fp16 weights folded away, shape constants
//! turned into attributes) and saved, both networks in one safetensors file: each graph as JSON
//! in the metadata, its weights as fp16 tensors (`{graph}.t{id}`).
//!
//! Layouts are TFLite's: activations NHWC, convolution weights `[O, kh, kw, I]`, depthwise
//! weights `[1, kh, kw, C·m]`, fully connected weights `[out, in]`. The executor
//! ([`crate::exec`]) maps them onto burn's NCHW.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use bitt_stdx::st;
use half::f16;
use safetensors::Dtype;
use serde::{Deserialize, Serialize};

use crate::DetectError;

/// An activation fused into an operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// None.
    None,
    /// `max(x, 0)`.
    Relu,
    /// `min(max(x, 0), 6)`.
    Relu6,
}

/// TFLite's two padding rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Padding {
    /// Output size `ceil(in / stride)`, the padding split with the extra pixel after.
    Same,
    /// No padding.
    Valid,
}

/// One operation; every tensor is named by its id in [`Graph::shapes`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum Op {
    /// 2-D convolution (weights `[O, kh, kw, I]`).
    Conv2d {
        /// Input, output, weight, bias.
        input: usize,
        /// Output tensor.
        output: usize,
        /// Weight constant.
        weight: usize,
        /// Bias constant.
        bias: Option<usize>,
        /// `[h, w]`.
        stride: [usize; 2],
        /// `[h, w]`.
        dilation: [usize; 2],
        /// Padding rule.
        padding: Padding,
        /// Fused activation.
        activation: Activation,
    },
    /// Depthwise convolution (weights `[1, kh, kw, C·multiplier]`).
    DepthwiseConv2d {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
        /// Weight constant.
        weight: usize,
        /// Bias constant.
        bias: Option<usize>,
        /// `[h, w]`.
        stride: [usize; 2],
        /// `[h, w]`.
        dilation: [usize; 2],
        /// Padding rule.
        padding: Padding,
        /// Fused activation.
        activation: Activation,
    },
    /// `a + b` with broadcasting.
    Add {
        /// First operand.
        a: usize,
        /// Second operand.
        b: usize,
        /// Output tensor.
        output: usize,
        /// Fused activation.
        activation: Activation,
    },
    /// `max(x, 0) + alpha · min(x, 0)`, alpha per channel.
    Prelu {
        /// Input tensor.
        input: usize,
        /// Alpha constant (its last axis is the channel).
        alpha: usize,
        /// Output tensor.
        output: usize,
    },
    /// Max pooling.
    MaxPool2d {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
        /// `[h, w]`.
        kernel: [usize; 2],
        /// `[h, w]`.
        stride: [usize; 2],
        /// Padding rule.
        padding: Padding,
    },
    /// Zero padding, `[before, after]` per axis.
    Pad {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
        /// Per axis of the input.
        pads: Vec<[usize; 2]>,
    },
    /// Bilinear resize of an NHWC tensor to `size`.
    ResizeBilinear {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
        /// `[h, w]`.
        size: [usize; 2],
        /// TFLite's `align_corners`.
        align_corners: bool,
        /// TFLite's `half_pixel_centers`.
        half_pixel_centers: bool,
    },
    /// Reshape (row-major, of the NHWC layout).
    Reshape {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
    },
    /// Concatenation along `axis`.
    Concatenation {
        /// Input tensors.
        inputs: Vec<usize>,
        /// Output tensor.
        output: usize,
        /// Axis (non-negative).
        axis: usize,
    },
    /// Mean over `axes`.
    Mean {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
        /// Axes (non-negative).
        axes: Vec<usize>,
    },
    /// `x · Wᵀ + b` (weights `[out, in]`); the input is flattened to `[rows, in]`.
    FullyConnected {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
        /// Weight constant.
        weight: usize,
        /// Bias constant.
        bias: Option<usize>,
        /// Fused activation.
        activation: Activation,
    },
    /// `1 / (1 + e^-x)`.
    Logistic {
        /// Input tensor.
        input: usize,
        /// Output tensor.
        output: usize,
    },
}

/// A network: its operations in execution order, every tensor's shape, its weights.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Graph {
    /// The input tensor (NHWC, float).
    pub input: usize,
    /// The outputs by their TFLite names (`Identity`, `Identity_1`, ...).
    pub outputs: BTreeMap<String, usize>,
    /// Every tensor's shape (TFLite's, NHWC for images).
    pub shapes: BTreeMap<usize, Vec<usize>>,
    /// The operations in the order they run.
    pub ops: Vec<Op>,
    /// Constant tensors (weights, biases, PReLU slopes), kept out of the JSON.
    #[serde(skip)]
    pub constants: BTreeMap<usize, Vec<f32>>,
}

impl Graph {
    /// The input's shape `[1, H, W, 3]`.
    pub fn input_shape(&self) -> &[usize] {
        self.shapes.get(&self.input).map_or(&[], Vec::as_slice)
    }

    /// A constant's values, or a model error.
    pub(crate) fn constant(&self, id: usize, origin: &Path) -> Result<&[f32], DetectError> {
        self.constants
            .get(&id)
            .map(Vec::as_slice)
            .ok_or_else(|| DetectError::model(origin, format!("tensor {id} is not a constant")))
    }

    /// A tensor's shape, or a model error.
    pub(crate) fn shape(&self, id: usize, origin: &Path) -> Result<&[usize], DetectError> {
        self.shapes
            .get(&id)
            .map(Vec::as_slice)
            .ok_or_else(|| DetectError::model(origin, format!("tensor {id} has no shape")))
    }

    /// Checks that every operation's tensors exist, that constants have the right sizes and
    /// that every non-constant input is produced before it is used.
    pub(crate) fn validate(&self, origin: &Path) -> Result<(), DetectError> {
        let mut known: std::collections::HashSet<usize> = self.constants.keys().copied().collect();
        known.insert(self.input);
        for (id, values) in &self.constants {
            let n: usize = self.shape(*id, origin)?.iter().product();
            if n != values.len() {
                return Err(DetectError::model(
                    origin,
                    format!("constant {id} has {} values, its shape {n}", values.len()),
                ));
            }
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Err(DetectError::model(
                    origin,
                    format!("constant {id} has a non-finite value at {i}"),
                ));
            }
        }
        for (k, op) in self.ops.iter().enumerate() {
            let (inputs, output) = op.tensors();
            for i in inputs {
                if !known.contains(&i) {
                    return Err(DetectError::model(
                        origin,
                        format!("operation {k} reads tensor {i} before anything writes it"),
                    ));
                }
                self.shape(i, origin)?;
            }
            self.shape(output, origin)?;
            known.insert(output);
        }
        for (name, id) in &self.outputs {
            if !known.contains(id) {
                return Err(DetectError::model(
                    origin,
                    format!("output {name} (tensor {id}) is never computed"),
                ));
            }
        }
        Ok(())
    }
}

impl Op {
    /// The tensors the operation reads (constants included) and the one it writes.
    pub fn tensors(&self) -> (Vec<usize>, usize) {
        match self {
            Op::Conv2d {
                input,
                output,
                weight,
                bias,
                ..
            }
            | Op::DepthwiseConv2d {
                input,
                output,
                weight,
                bias,
                ..
            }
            | Op::FullyConnected {
                input,
                output,
                weight,
                bias,
                ..
            } => {
                let mut v = vec![*input, *weight];
                v.extend(bias);
                (v, *output)
            }
            Op::Add { a, b, output, .. } => (vec![*a, *b], *output),
            Op::Prelu {
                input,
                alpha,
                output,
            } => (vec![*input, *alpha], *output),
            Op::Concatenation { inputs, output, .. } => (inputs.clone(), *output),
            Op::MaxPool2d { input, output, .. }
            | Op::Pad { input, output, .. }
            | Op::ResizeBilinear { input, output, .. }
            | Op::Reshape { input, output }
            | Op::Mean { input, output, .. }
            | Op::Logistic { input, output } => (vec![*input], *output),
        }
    }
}

/// The `format` metadata of the weights file.
pub const FORMAT: &str = "bitt-detect weights";

/// The networks' names in the weights file.
pub const PALM: &str = "palm_detection";
/// See [`PALM`].
pub(crate) const LANDMARK: &str = "hand_landmark";

/// Encodes graphs as one safetensors file: each graph's JSON under its name in the
/// metadata, its constants as fp16 tensors `{name}.t{id}`, plus `notice` (where the weights
/// come from and their license).
///
/// # Errors
/// A graph that does not serialize.
pub fn to_safetensors(
    graphs: &[(&str, &Graph)],
    notice: &str,
    path: &Path,
) -> Result<Vec<u8>, DetectError> {
    let mut entries = Vec::new();
    let mut meta = HashMap::new();
    meta.insert("format".to_string(), FORMAT.to_string());
    meta.insert("notice".to_string(), notice.to_string());
    for (name, graph) in graphs {
        let json = serde_json::to_string(graph)
            .map_err(|e| DetectError::model(path, format!("cannot encode {name}: {e}")))?;
        meta.insert((*name).to_string(), json);
        for (id, values) in &graph.constants {
            let bytes: Vec<u8> = values
                .iter()
                .flat_map(|v| f16::from_f32(*v).to_le_bytes())
                .collect();
            let shape = graph.shapes.get(id).cloned().unwrap_or_default();
            entries.push((format!("{name}.t{id}"), Dtype::F16, shape, bytes));
        }
    }
    Ok(st::serialize(path, &entries, meta)?)
}

/// Decodes one graph of a file written by [`to_safetensors`]; `path` names it in errors.
///
/// # Errors
/// A missing or malformed graph, a missing or wrongly shaped constant, or a graph that
/// fails [`Graph::validate`].
pub fn from_safetensors(bytes: &[u8], name: &str, path: &Path) -> Result<Graph, DetectError> {
    let reader = st::Reader::new(bytes, path, FORMAT)?;
    let json = reader
        .metadata()
        .get(name)
        .ok_or_else(|| DetectError::model(path, format!("no network `{name}` in the file")))?;
    let mut graph: Graph = serde_json::from_str(json)
        .map_err(|e| DetectError::model(path, format!("network `{name}`: {e}")))?;
    let prefix = format!("{name}.t");
    for tensor in reader.names() {
        let Some(id) = tensor.strip_prefix(&prefix) else {
            continue;
        };
        let id: usize = id
            .parse()
            .map_err(|_| DetectError::model(path, format!("bad tensor name `{tensor}`")))?;
        let n: usize = graph.shape(id, path)?.iter().product();
        let raw = reader.bytes(tensor)?;
        if raw.len() != 2 * n {
            return Err(DetectError::model(
                path,
                format!(
                    "tensor `{tensor}` has {} bytes, expected {n} fp16 values",
                    raw.len()
                ),
            ));
        }
        let values = raw
            .chunks_exact(2)
            .map(|c| f16::from_le_bytes([c[0], c[1]]));
        graph
            .constants
            .insert(id, values.map(f16::to_f32).collect());
    }
    graph.validate(path)?;
    Ok(graph)
}
