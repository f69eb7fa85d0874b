//! Reads a TFLite model (a FlatBuffers file, schema `tensorflow/lite/schema/schema.fbs`) into
//! a [`Graph`]: the operations MediaPipe Hands' two models use, their options, shapes and
//! weights. The fp16 weights' DEQUANTIZE steps are folded into float constants and the int32
//! shape tensors (PAD, RESIZE, MEAN) into attributes. Anything else is an error naming the
//! operation, so a model this crate cannot run is refused when it is read, not mid-run.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use half::f16;

use crate::DetectError;
use crate::flatbuffer::{FbResult, Table};
use crate::graph::{Activation, Graph, Op, Padding};

// BuiltinOperator codes (schema.fbs).
const ADD: i32 = 0;
const CONCATENATION: i32 = 2;
const CONV_2D: i32 = 3;
const DEPTHWISE_CONV_2D: i32 = 4;
const DEQUANTIZE: i32 = 6;
const FULLY_CONNECTED: i32 = 9;
const LOGISTIC: i32 = 14;
const MAX_POOL_2D: i32 = 17;
const RESHAPE: i32 = 22;
const RESIZE_BILINEAR: i32 = 23;
const PAD: i32 = 34;
const MEAN: i32 = 40;
const PRELU: i32 = 54;

// TensorType codes.
const FLOAT32: i8 = 0;
const FLOAT16: i8 = 1;
const INT32: i8 = 2;

/// A tensor as the file declares it.
struct TensorInfo {
    shape: Vec<usize>,
    dtype: i8,
    data: Vec<u8>,
    name: String,
}

/// Reads `bytes` (a `.tflite` file; `path` names it in errors) into a [`Graph`].
///
/// # Errors
/// A malformed file, an operation or option this crate does not implement, or shapes that
/// do not fit together.
pub(crate) fn read_tflite(bytes: &[u8], path: &Path) -> Result<Graph, DetectError> {
    parse(bytes, path).map_err(|e| match e {
        Parse::Fb(detail) => DetectError::model(path, detail),
        Parse::Detect(e) => e,
    })
}

enum Parse {
    Fb(String),
    Detect(DetectError),
}

impl From<String> for Parse {
    fn from(s: String) -> Self {
        Parse::Fb(s)
    }
}

impl From<DetectError> for Parse {
    fn from(e: DetectError) -> Self {
        Parse::Detect(e)
    }
}

fn activation(code: i8, what: &str) -> FbResult<Activation> {
    match code {
        0 => Ok(Activation::None),
        1 => Ok(Activation::Relu),
        3 => Ok(Activation::Relu6),
        c => Err(format!("{what}: fused activation {c} is not supported")),
    }
}

fn padding(code: i8, what: &str) -> FbResult<Padding> {
    match code {
        0 => Ok(Padding::Same),
        1 => Ok(Padding::Valid),
        c => Err(format!("{what}: padding {c} is unknown")),
    }
}

fn positive(v: i32, what: &str) -> FbResult<usize> {
    usize::try_from(v)
        .ok()
        .filter(|&v| v > 0)
        .ok_or_else(|| format!("{what} is {v}, expected a positive number"))
}

fn parse(bytes: &[u8], path: &Path) -> Result<Graph, Parse> {
    let model = Table::root(bytes)?;
    if bytes.get(4..8) != Some(b"TFL3") {
        return Err(Parse::Fb("not a TFLite model (no TFL3 identifier)".into()));
    }
    let codes: Vec<i32> = model
        .tables(1)?
        .iter()
        .map(|c| -> FbResult<i32> { Ok(c.i32(3, 0)?.max(c.i8(0, 0)? as i32)) })
        .collect::<FbResult<_>>()?;
    let buffers = model.tables(4)?;
    let subgraphs = model.tables(2)?;
    let [graph] = subgraphs.as_slice() else {
        return Err(Parse::Fb(format!(
            "{} subgraphs, expected exactly one",
            subgraphs.len()
        )));
    };

    let mut tensors = Vec::new();
    for (i, t) in graph.tables(0)?.iter().enumerate() {
        let shape = t
            .i32s(0)?
            .into_iter()
            .map(|d| usize::try_from(d).map_err(|_| format!("tensor {i} has a dimension {d}")))
            .collect::<FbResult<Vec<_>>>()?;
        let buffer = t.u32(2, 0)? as usize;
        let data = match buffers.get(buffer) {
            Some(b) if b.u64(1, 0)? > 0 => {
                return Err(Parse::Fb(format!(
                    "tensor {i}'s data lies outside the flatbuffer (offset buffers are not supported)"
                )));
            }
            Some(b) => b.bytes(0)?.to_vec(),
            None if buffer == 0 => Vec::new(),
            None => {
                return Err(Parse::Fb(format!(
                    "tensor {i} names buffer {buffer}, which does not exist"
                )));
            }
        };
        tensors.push(TensorInfo {
            shape,
            dtype: t.i8(1, 0)?,
            data,
            name: t.string(3)?,
        });
    }
    let tensor = |i: i32, what: &str| -> FbResult<usize> {
        usize::try_from(i)
            .ok()
            .filter(|&i| i < tensors.len())
            .ok_or_else(|| format!("{what} names tensor {i}, which does not exist"))
    };

    let inputs = graph.i32s(1)?;
    let [input] = inputs.as_slice() else {
        return Err(Parse::Fb(format!("{} inputs, expected one", inputs.len())));
    };
    let input = tensor(*input, "the input")?;
    if tensors[input].dtype != FLOAT32 {
        return Err(Parse::Fb("the input is not float32".into()));
    }
    let mut outputs = BTreeMap::new();
    for o in graph.i32s(2)? {
        let o = tensor(o, "an output")?;
        outputs.insert(tensors[o].name.clone(), o);
    }

    let mut constants: BTreeMap<usize, Vec<f32>> = BTreeMap::new();
    let mut ints: HashMap<usize, Vec<i32>> = HashMap::new();
    for (i, t) in tensors.iter().enumerate() {
        if t.data.is_empty() {
            continue;
        }
        let n: usize = t.shape.iter().product();
        let (size, values): (usize, Option<Vec<f32>>) = match t.dtype {
            FLOAT32 => (
                4,
                Some(
                    t.data
                        .chunks_exact(4)
                        .map(|c| f32::from_le_bytes(c.try_into().expect("4")))
                        .collect(),
                ),
            ),
            FLOAT16 => (
                2,
                Some(
                    t.data
                        .chunks_exact(2)
                        .map(|c| f16::from_le_bytes([c[0], c[1]]).to_f32())
                        .collect(),
                ),
            ),
            INT32 => {
                ints.insert(
                    i,
                    t.data
                        .chunks_exact(4)
                        .map(|c| i32::from_le_bytes(c.try_into().expect("4")))
                        .collect(),
                );
                (4, None)
            }
            d => {
                return Err(Parse::Fb(format!(
                    "tensor {i} has the unsupported type {d}"
                )));
            }
        };
        if t.data.len() != n * size {
            return Err(Parse::Fb(format!(
                "tensor {i} has {} bytes of data, its shape {:?} needs {}",
                t.data.len(),
                t.shape,
                n * size
            )));
        }
        if let Some(v) = values {
            constants.insert(i, v);
        }
    }

    let mut ops = Vec::new();
    for (k, op) in graph.tables(3)?.iter().enumerate() {
        let index = op.u32(0, 0)? as usize;
        let code = *codes
            .get(index)
            .ok_or_else(|| format!("operation {k} has opcode index {index}, out of range"))?;
        let ins: Vec<i32> = op.i32s(1)?;
        let outs: Vec<i32> = op.i32s(2)?;
        let what = format!("operation {k} (builtin {code})");
        let arg = |j: usize| -> FbResult<usize> {
            let i = *ins
                .get(j)
                .ok_or_else(|| format!("{what}: missing input {j}"))?;
            tensor(i, &what)
        };
        let opt_arg = |j: usize| -> FbResult<Option<usize>> {
            match ins.get(j) {
                Some(&i) if i >= 0 => tensor(i, &what).map(Some),
                _ => Ok(None),
            }
        };
        let [output] = outs.as_slice() else {
            return Err(Parse::Fb(format!(
                "{what}: {} outputs, expected one",
                outs.len()
            )));
        };
        let output = tensor(*output, &what)?;
        let options = op.table(4)?;
        let opt = || options.ok_or_else(|| format!("{what}: missing options"));
        let int_arg = |j: usize| -> FbResult<Vec<i32>> {
            let t = arg(j)?;
            ints.get(&t).cloned().ok_or_else(|| {
                format!("{what}: input {j} (tensor {t}) is not a constant int32 tensor")
            })
        };
        let node = match code {
            DEQUANTIZE => {
                let from = arg(0)?;
                let values = constants.get(&from).cloned().ok_or_else(|| {
                    format!("{what}: DEQUANTIZE of a tensor that is not a constant")
                })?;
                constants.insert(output, values);
                continue;
            }
            CONV_2D => {
                let o = opt()?;
                Op::Conv2d {
                    input: arg(0)?,
                    weight: arg(1)?,
                    bias: opt_arg(2)?,
                    output,
                    padding: padding(o.i8(0, 0)?, &what)?,
                    stride: [
                        positive(o.i32(2, 1)?, "stride_h")?,
                        positive(o.i32(1, 1)?, "stride_w")?,
                    ],
                    activation: activation(o.i8(3, 0)?, &what)?,
                    dilation: [
                        positive(o.i32(5, 1)?, "dilation_h")?,
                        positive(o.i32(4, 1)?, "dilation_w")?,
                    ],
                }
            }
            DEPTHWISE_CONV_2D => {
                let o = opt()?;
                Op::DepthwiseConv2d {
                    input: arg(0)?,
                    weight: arg(1)?,
                    bias: opt_arg(2)?,
                    output,
                    padding: padding(o.i8(0, 0)?, &what)?,
                    stride: [
                        positive(o.i32(2, 1)?, "stride_h")?,
                        positive(o.i32(1, 1)?, "stride_w")?,
                    ],
                    activation: activation(o.i8(4, 0)?, &what)?,
                    dilation: [
                        positive(o.i32(6, 1)?, "dilation_h")?,
                        positive(o.i32(5, 1)?, "dilation_w")?,
                    ],
                }
            }
            ADD => Op::Add {
                a: arg(0)?,
                b: arg(1)?,
                output,
                activation: activation(options.map_or(Ok(0), |o| o.i8(0, 0))?, &what)?,
            },
            PRELU => Op::Prelu {
                input: arg(0)?,
                alpha: arg(1)?,
                output,
            },
            MAX_POOL_2D => {
                let o = opt()?;
                if o.i8(5, 0)? != 0 {
                    return Err(Parse::Fb(format!(
                        "{what}: a fused activation on pooling is not supported"
                    )));
                }
                Op::MaxPool2d {
                    input: arg(0)?,
                    output,
                    padding: padding(o.i8(0, 0)?, &what)?,
                    stride: [
                        positive(o.i32(2, 1)?, "stride_h")?,
                        positive(o.i32(1, 1)?, "stride_w")?,
                    ],
                    kernel: [
                        positive(o.i32(4, 1)?, "filter_height")?,
                        positive(o.i32(3, 1)?, "filter_width")?,
                    ],
                }
            }
            PAD => {
                let p = int_arg(1)?;
                let pads = p
                    .chunks_exact(2)
                    .map(|c| -> FbResult<[usize; 2]> {
                        Ok([
                            usize::try_from(c[0])
                                .map_err(|_| format!("{what}: negative padding"))?,
                            usize::try_from(c[1])
                                .map_err(|_| format!("{what}: negative padding"))?,
                        ])
                    })
                    .collect::<FbResult<Vec<_>>>()?;
                Op::Pad {
                    input: arg(0)?,
                    output,
                    pads,
                }
            }
            RESIZE_BILINEAR => {
                let size = int_arg(1)?;
                let [h, w] = size.as_slice() else {
                    return Err(Parse::Fb(format!("{what}: size has {} values", size.len())));
                };
                let o = opt()?;
                Op::ResizeBilinear {
                    input: arg(0)?,
                    output,
                    size: [positive(*h, "height")?, positive(*w, "width")?],
                    align_corners: o.bool(2)?,
                    half_pixel_centers: o.bool(3)?,
                }
            }
            RESHAPE => Op::Reshape {
                input: arg(0)?,
                output,
            },
            CONCATENATION => {
                let o = opt()?;
                if o.i8(1, 0)? != 0 {
                    return Err(Parse::Fb(format!(
                        "{what}: a fused activation on concatenation is not supported"
                    )));
                }
                let inputs = (0..ins.len()).map(&arg).collect::<FbResult<Vec<_>>>()?;
                let rank = tensors[output].shape.len() as i32;
                let axis = o.i32(0, 0)?;
                let axis = if axis < 0 { axis + rank } else { axis };
                Op::Concatenation {
                    inputs,
                    output,
                    axis: usize::try_from(axis).map_err(|_| format!("{what}: bad axis"))?,
                }
            }
            MEAN => {
                let rank = tensors[arg(0)?].shape.len() as i32;
                let axes = int_arg(1)?
                    .into_iter()
                    .map(|a| {
                        let a = if a < 0 { a + rank } else { a };
                        usize::try_from(a).map_err(|_| format!("{what}: bad axis"))
                    })
                    .collect::<FbResult<Vec<_>>>()?;
                Op::Mean {
                    input: arg(0)?,
                    output,
                    axes,
                }
            }
            FULLY_CONNECTED => {
                let o = opt()?;
                if o.i8(1, 0)? != 0 {
                    return Err(Parse::Fb(format!(
                        "{what}: only the default weights format is supported"
                    )));
                }
                Op::FullyConnected {
                    input: arg(0)?,
                    weight: arg(1)?,
                    bias: opt_arg(2)?,
                    output,
                    activation: activation(o.i8(0, 0)?, &what)?,
                }
            }
            LOGISTIC => Op::Logistic {
                input: arg(0)?,
                output,
            },
            other => {
                return Err(Parse::Fb(format!(
                    "operation {k} is builtin operator {other}, which this crate does not implement"
                )));
            }
        };
        ops.push(node);
    }

    // Keep only the constants the operations read, and the shapes of every tensor in use.
    let mut used = std::collections::BTreeSet::new();
    used.insert(input);
    for op in &ops {
        let (ins, out) = op.tensors();
        used.extend(ins);
        used.insert(out);
    }
    constants.retain(|id, _| used.contains(id));
    let shapes = used
        .iter()
        .map(|&i| (i, tensors[i].shape.clone()))
        .collect();
    let graph = Graph {
        input,
        outputs,
        shapes,
        ops,
        constants,
    };
    graph.validate(path)?;
    Ok(graph)
}

/// Where the two models lie in the mediapipe 0.10.21 wheel.
pub(crate) const WHEEL_MODELS: [(&str, &str); 2] = [
    (
        crate::graph::PALM,
        "mediapipe/modules/palm_detection/palm_detection_full.tflite",
    ),
    (
        crate::graph::LANDMARK,
        "mediapipe/modules/hand_landmark/hand_landmark_full.tflite",
    ),
];

/// The notice stored with the converted weights.
pub(crate) const NOTICE: &str = "MediaPipe Hands palm_detection_full and hand_landmark_full (mediapipe 0.10.21 wheel), Copyright Google LLC, Apache License 2.0 (crates/bitt-detect/assets/LICENSE-mediapipe.txt); converted to fp16 graphs by bitt-detect.";

/// Reads both models from an unpacked mediapipe 0.10.21 wheel (`wheel_dir`) and encodes them
/// as the weights file ([`crate::graph::to_safetensors`]); `out` names it in errors.
///
/// # Errors
/// A model file that is missing, malformed, or uses an operation this crate does not run.
pub fn convert_mediapipe(wheel_dir: &Path, out: &Path) -> Result<Vec<u8>, DetectError> {
    let mut graphs = Vec::new();
    for (name, rel) in WHEEL_MODELS {
        let path = wheel_dir.join(rel);
        let bytes = bitt_stdx::st::read_file(&path)?;
        graphs.push((name, read_tflite(&bytes, &path)?));
    }
    let refs: Vec<(&str, &Graph)> = graphs.iter().map(|(n, g)| (*n, g)).collect();
    crate::graph::to_safetensors(&refs, NOTICE, out)
}
