//! Runs a [`Graph`] on any burn device: the weights are laid out for burn once, when the
//! network is built, then [`Network::forward`] interprets the operations in order.
//!
//! Image tensors (rank 4 in the graph, NHWC) live on the device as burn's `[N, C, H, W]`;
//! every other tensor as a matrix `[rows, last axis]`. A reshape or concatenation that crosses
//! between the two goes through the NHWC order, so the result is TFLite's bit for bit layout.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::tensor::activation::sigmoid;
use burn::tensor::module::{conv2d, max_pool2d};
use burn::tensor::ops::{ConvOptions, MaxPoolOptions, PadMode};
use burn::tensor::{Device, Tensor, TensorData};

use crate::DetectError;
use crate::graph::{Activation, Graph, Op, Padding};

/// A value during execution.
#[derive(Debug, Clone)]
enum Value {
    /// An NHWC image tensor stored as `[N, C, H, W]`.
    Image(Tensor<4>),
    /// Any other tensor as `[N, rows, last axis]` (rows: the product of the axes between).
    Matrix(Tensor<3>),
}

impl Value {
    /// All values of the batch in TFLite's row-major order (NHWC for images), flat.
    fn flat_in_tflite_order(self) -> Tensor<1> {
        match self {
            Value::Image(x) => {
                let [n, c, h, w] = x.dims();
                x.permute([0, 2, 3, 1]).reshape([n * h * w * c])
            }
            Value::Matrix(x) => {
                let [n, r, c] = x.dims();
                x.reshape([n * r * c])
            }
        }
    }
}

/// The weights of one operation, laid out for burn.
#[derive(Debug, Clone)]
enum Weights {
    None,
    /// Convolution weight `[O, I/groups, kh, kw]`, bias `[O]`, groups.
    Conv(Tensor<4>, Option<Tensor<1>>, usize),
    /// Fully connected: `Wᵀ` `[in, out]`, bias `[1, out]`.
    Dense(Tensor<2>, Option<Tensor<2>>),
    /// PReLU slope `[1, C, 1, 1]`.
    Slope(Tensor<4>),
    /// A constant operand of an addition, as the value it is.
    Operand(Value),
}

/// A network ready to run on one device.
#[derive(Debug, Clone)]
pub struct Network {
    graph: Graph,
    weights: Vec<Weights>,
    device: Device,
    origin: PathBuf,
}

fn host_tensor<const D: usize>(values: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// `values` in the row-major `[d0, d1, d2, d3]` layout permuted by `perm` (output axis `i`
/// is input axis `perm[i]`).
fn permute_host(values: &[f32], dims: [usize; 4], perm: [usize; 4]) -> (Vec<f32>, [usize; 4]) {
    let out_dims = perm.map(|p| dims[p]);
    let strides = [dims[1] * dims[2] * dims[3], dims[2] * dims[3], dims[3], 1];
    let mut out = Vec::with_capacity(values.len());
    for a in 0..out_dims[0] {
        for b in 0..out_dims[1] {
            for c in 0..out_dims[2] {
                for d in 0..out_dims[3] {
                    let idx = [a, b, c, d];
                    let mut src = 0;
                    for (k, &p) in perm.iter().enumerate() {
                        src += idx[k] * strides[p];
                    }
                    out.push(values[src]);
                }
            }
        }
    }
    (out, out_dims)
}

fn dims4(shape: &[usize]) -> Option<[usize; 4]> {
    <[usize; 4]>::try_from(shape).ok()
}

/// TFLite's SAME padding of one axis: `(before, after)`.
fn same_padding(size: usize, kernel: usize, stride: usize, dilation: usize) -> (usize, usize) {
    let effective = (kernel - 1) * dilation + 1;
    let out = size.div_ceil(stride);
    let total = ((out - 1) * stride + effective).saturating_sub(size);
    (total / 2, total - total / 2)
}

fn activate<const D: usize>(x: Tensor<D>, act: Activation) -> Tensor<D> {
    match act {
        Activation::None => x,
        Activation::Relu => x.clamp_min(0.0),
        Activation::Relu6 => x.clamp(0.0, 6.0),
    }
}

impl Network {
    /// Lays `graph`'s weights out on `device`; `origin` names the weights in errors.
    ///
    /// # Errors
    /// Weights whose shapes do not fit their operations.
    pub fn new(graph: Graph, device: &Device, origin: &Path) -> Result<Self, DetectError> {
        graph.validate(origin)?;
        let err =
            |k: usize, what: &str| DetectError::model(origin, format!("operation {k}: {what}"));
        let mut weights = Vec::with_capacity(graph.ops.len());
        for (k, op) in graph.ops.iter().enumerate() {
            let w = match op {
                Op::Conv2d { weight, bias, .. } | Op::DepthwiseConv2d { weight, bias, .. } => {
                    let shape = dims4(graph.shape(*weight, origin)?)
                        .ok_or_else(|| err(k, "the weight is not of rank 4"))?;
                    let values = graph.constant(*weight, origin)?;
                    let depthwise = matches!(op, Op::DepthwiseConv2d { .. });
                    let (out, groups) = if depthwise {
                        // [1, kh, kw, C·m] -> [C·m, 1, kh, kw]
                        let in_channels = graph
                            .shape(op.tensors().0[0], origin)?
                            .last()
                            .copied()
                            .unwrap_or(0);
                        if in_channels == 0 || shape[3] % in_channels != 0 {
                            return Err(err(k, "depthwise channels do not divide"));
                        }
                        (permute_host(values, shape, [3, 0, 1, 2]), in_channels)
                    } else {
                        // [O, kh, kw, I] -> [O, I, kh, kw]
                        (permute_host(values, shape, [0, 3, 1, 2]), 1)
                    };
                    let (v, d) = out;
                    let bias = match bias {
                        Some(b) => {
                            let b = graph.constant(*b, origin)?.to_vec();
                            if b.len() != d[0] {
                                return Err(err(k, "the bias does not fit the weight"));
                            }
                            Some(host_tensor(b, [d[0]], device))
                        }
                        None => None,
                    };
                    Weights::Conv(host_tensor(v, d, device), bias, groups)
                }
                Op::FullyConnected { weight, bias, .. } => {
                    let shape = graph.shape(*weight, origin)?;
                    let [out, inp] = <[usize; 2]>::try_from(shape)
                        .map_err(|_| err(k, "the weight is not of rank 2"))?;
                    let w = host_tensor(
                        graph.constant(*weight, origin)?.to_vec(),
                        [out, inp],
                        device,
                    )
                    .transpose();
                    let bias = match bias {
                        Some(b) => {
                            let b = graph.constant(*b, origin)?.to_vec();
                            if b.len() != out {
                                return Err(err(k, "the bias does not fit the weight"));
                            }
                            Some(host_tensor(b, [1, out], device))
                        }
                        None => None,
                    };
                    Weights::Dense(w, bias)
                }
                Op::Prelu { alpha, .. } => {
                    let a = graph.constant(*alpha, origin)?.to_vec();
                    let c = a.len();
                    Weights::Slope(host_tensor(a, [1, c, 1, 1], device))
                }
                Op::Add { a, b, .. } => {
                    let constant = [*a, *b]
                        .into_iter()
                        .find(|t| graph.constants.contains_key(t));
                    match constant {
                        Some(t) => {
                            let shape = graph.shape(t, origin)?.to_vec();
                            let values = graph.constant(t, origin)?.to_vec();
                            Weights::Operand(constant_value(values, &shape, device))
                        }
                        None => Weights::None,
                    }
                }
                _ => Weights::None,
            };
            weights.push(w);
        }
        Ok(Network {
            graph,
            weights,
            device: device.clone(),
            origin: origin.to_path_buf(),
        })
    }

    /// The graph this network runs.
    pub fn graph(&self) -> &Graph {
        &self.graph
    }

    /// The device it runs on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The input's `[H, W]`.
    pub(crate) fn input_size(&self) -> [usize; 2] {
        let s = self.graph.input_shape();
        [
            s.get(1).copied().unwrap_or(0),
            s.get(2).copied().unwrap_or(0),
        ]
    }

    /// Runs the network on a batch of images and returns every output, by TFLite name, as a
    /// `[batch, values]` matrix (TFLite's row-major layout of each sample's output).
    ///
    /// # Shapes
    /// - `input`: `[N, 3, H, W]` (NCHW; the graph's NHWC input transposed), values as the
    ///   model expects them (MediaPipe: `[0, 1]`)
    /// - output: `name -> [N, values per sample]`
    ///
    /// # Errors
    /// An input of the wrong size, or shapes that do not fit an operation.
    pub fn forward(&self, input: Tensor<4>) -> Result<HashMap<String, Tensor<2>>, DetectError> {
        let [n, c, h, w] = input.dims();
        let want = self.graph.input_shape();
        if want.len() != 4 || [c, h, w] != [want[3], want[1], want[2]] {
            return Err(DetectError::model(
                &self.origin,
                format!("input is [{n}, {c}, {h}, {w}] (NCHW), the network takes {want:?} (NHWC)"),
            ));
        }
        let mut values: HashMap<usize, Value> = HashMap::new();
        values.insert(self.graph.input, Value::Image(input));
        let mut remaining_uses: HashMap<usize, usize> = HashMap::new();
        for op in &self.graph.ops {
            for i in op.tensors().0 {
                *remaining_uses.entry(i).or_default() += 1;
            }
        }
        for out in self.graph.outputs.values() {
            *remaining_uses.entry(*out).or_default() += 1;
        }
        for (k, op) in self.graph.ops.iter().enumerate() {
            let (inputs, output) = op.tensors();
            let y = self.run(k, op, &values, n)?;
            values.insert(output, y);
            // Free what no later operation reads.
            for i in inputs {
                if let Some(u) = remaining_uses.get_mut(&i) {
                    *u -= 1;
                    if *u == 0 {
                        values.remove(&i);
                    }
                }
            }
        }
        let mut outs = HashMap::new();
        for (name, id) in &self.graph.outputs {
            let v = values.remove(id).ok_or_else(|| {
                DetectError::model(&self.origin, format!("output {name} was not computed"))
            })?;
            let m = match v {
                Value::Image(t) => {
                    let [n, c, h, w] = t.dims();
                    t.permute([0, 2, 3, 1]).reshape([n, h * w * c])
                }
                Value::Matrix(t) => {
                    let [n, rows, cols] = t.dims();
                    t.reshape([n, rows * cols])
                }
            };
            outs.insert(name.clone(), m);
        }
        Ok(outs)
    }

    fn get(
        &self,
        values: &HashMap<usize, Value>,
        id: usize,
        k: usize,
    ) -> Result<Value, DetectError> {
        values.get(&id).cloned().ok_or_else(|| {
            DetectError::model(
                &self.origin,
                format!("operation {k}: tensor {id} is not available"),
            )
        })
    }

    fn image(
        &self,
        values: &HashMap<usize, Value>,
        id: usize,
        k: usize,
    ) -> Result<Tensor<4>, DetectError> {
        match self.get(values, id, k)? {
            Value::Image(t) => Ok(t),
            Value::Matrix(_) => Err(DetectError::model(
                &self.origin,
                format!("operation {k}: tensor {id} is not an image tensor"),
            )),
        }
    }

    /// The logical shape of tensor `id` with the batch `n` in place of the graph's first axis.
    fn shape_of(&self, id: usize, n: usize) -> Result<Vec<usize>, DetectError> {
        let mut s = self.graph.shape(id, &self.origin)?.to_vec();
        if let Some(first) = s.first_mut() {
            *first = n;
        }
        Ok(s)
    }

    fn run(
        &self,
        k: usize,
        op: &Op,
        values: &HashMap<usize, Value>,
        n: usize,
    ) -> Result<Value, DetectError> {
        let err = |what: String| DetectError::model(&self.origin, format!("operation {k}: {what}"));
        Ok(match op {
            Op::Conv2d {
                input,
                stride,
                dilation,
                padding,
                activation,
                ..
            }
            | Op::DepthwiseConv2d {
                input,
                stride,
                dilation,
                padding,
                activation,
                ..
            } => {
                let Weights::Conv(weight, bias, groups) = &self.weights[k] else {
                    return Err(err("weights missing".into()));
                };
                let x = self.image(values, *input, k)?;
                let [_, _, kh, kw] = weight.dims();
                let [_, _, h, w] = x.dims();
                let x = self.pad_same(x, *padding, [h, w], [kh, kw], *stride, *dilation, 0.0);
                let options = ConvOptions::new(*stride, [0, 0], *dilation, *groups);
                Value::Image(activate(
                    conv2d(x, weight.clone(), bias.clone(), options),
                    *activation,
                ))
            }
            Op::Add {
                a, b, activation, ..
            } => {
                let operand = |id: usize| -> Result<Value, DetectError> {
                    match (&self.weights[k], self.graph.constants.contains_key(&id)) {
                        (Weights::Operand(v), true) => Ok(v.clone()),
                        _ => self.get(values, id, k),
                    }
                };
                match (operand(*a)?, operand(*b)?) {
                    (Value::Image(x), Value::Image(y)) => {
                        Value::Image(activate(x + y, *activation))
                    }
                    (Value::Matrix(x), Value::Matrix(y)) => {
                        Value::Matrix(activate(x + y, *activation))
                    }
                    _ => return Err(err("adding an image tensor to a matrix".into())),
                }
            }
            Op::Prelu { input, .. } => {
                let Weights::Slope(alpha) = &self.weights[k] else {
                    return Err(err("slope missing".into()));
                };
                let x = self.image(values, *input, k)?;
                let neg = x.clone().clamp_max(0.0) * alpha.clone();
                Value::Image(x.clamp_min(0.0) + neg)
            }
            Op::MaxPool2d {
                input,
                kernel,
                stride,
                padding,
                ..
            } => {
                let x = self.image(values, *input, k)?;
                let [_, _, h, w] = x.dims();
                let x = self.pad_same(x, *padding, [h, w], *kernel, *stride, [1, 1], f32::MIN);
                Value::Image(max_pool2d(
                    x,
                    MaxPoolOptions::new(*kernel).with_stride(*stride),
                ))
            }
            Op::Pad { input, pads, .. } => match self.get(values, *input, k)? {
                Value::Image(x) => {
                    let [[_, _], [t, b], [l, r], [c0, c1]] =
                        <[[usize; 2]; 4]>::try_from(pads.as_slice())
                            .map_err(|_| err("padding of an image tensor needs 4 axes".into()))?;
                    let x = x.pad([(c0, c1), (t, b), (l, r)], PadMode::Constant(0.0));
                    Value::Image(x)
                }
                Value::Matrix(_) => return Err(err("padding a matrix is not supported".into())),
            },
            Op::ResizeBilinear {
                input,
                size,
                align_corners,
                half_pixel_centers,
                ..
            } => {
                let x = self.image(values, *input, k)?;
                let [n, c, h, w] = x.dims();
                let ry = resize_matrix(h, size[0], *align_corners, *half_pixel_centers);
                let rx = resize_matrix(w, size[1], *align_corners, *half_pixel_centers);
                let ry = host_tensor(ry, [size[0], h], &self.device);
                let rxt = host_tensor(rx, [size[1], w], &self.device).transpose();
                // [N·C·H, W] x [W, W'] then [H', H] x [N·C, H, W'] per plane.
                let y = x
                    .reshape([n * c * h, w])
                    .matmul(rxt)
                    .reshape([n * c, h, size[1]]);
                let y = ry.unsqueeze::<3>().matmul(y);
                Value::Image(y.reshape([n, c, size[0], size[1]]))
            }
            Op::Reshape { input, output } => {
                let target = self.shape_of(*output, n)?;
                let flat = self.get(values, *input, k)?.flat_in_tflite_order();
                let total: usize = target.iter().product();
                if flat.dims()[0] != total {
                    return Err(err(format!(
                        "cannot reshape {} values to {target:?}",
                        flat.dims()[0]
                    )));
                }
                from_flat(flat, &target)
            }
            Op::Concatenation {
                inputs,
                output,
                axis,
            } => {
                let rank = self.graph.shape(*output, &self.origin)?.len();
                let parts = inputs
                    .iter()
                    .map(|&i| self.get(values, i, k))
                    .collect::<Result<Vec<_>, _>>()?;
                if rank == 4 {
                    let dim = [0, 2, 3, 1][*axis];
                    let t = parts
                        .into_iter()
                        .map(|p| match p {
                            Value::Image(t) => Ok(t),
                            Value::Matrix(_) => Err(err("mixed concatenation".into())),
                        })
                        .collect::<Result<Vec<_>, _>>()?;
                    Value::Image(Tensor::cat(t, dim))
                } else {
                    let t = parts
                        .into_iter()
                        .map(|p| match p {
                            Value::Matrix(t) => Ok(t),
                            Value::Image(_) => Err(err("mixed concatenation".into())),
                        })
                        .collect::<Result<Vec<_>, _>>()?;
                    // Rows are the axes between the batch and the last one: concatenating along
                    // the one just before the last is along the rows when the axes before it
                    // (batch excluded) are all 1.
                    let shape = self.graph.shape(*output, &self.origin)?;
                    let ones_before = shape[1..(*axis).max(1)].iter().all(|&d| d == 1);
                    if *axis + 1 == rank && rank >= 2 {
                        Value::Matrix(Tensor::cat(t, 2))
                    } else if *axis + 2 == rank && *axis >= 1 && ones_before {
                        Value::Matrix(Tensor::cat(t, 1))
                    } else {
                        return Err(err(format!(
                            "concatenation along axis {axis} of rank {rank}"
                        )));
                    }
                }
            }
            Op::Mean {
                input,
                output,
                axes,
            } => {
                let x = self.image(values, *input, k)?;
                let mut sorted = axes.clone();
                sorted.sort_unstable();
                if sorted != [1, 2] {
                    return Err(err(format!(
                        "mean over axes {axes:?} (only [1, 2] is supported)"
                    )));
                }
                let [n, c, _, _] = x.dims();
                let y = x.mean_dim(3).mean_dim(2);
                if self.graph.shape(*output, &self.origin)?.len() == 4 {
                    Value::Image(y)
                } else {
                    Value::Matrix(y.reshape([n, 1, c]))
                }
            }
            Op::FullyConnected {
                input, activation, ..
            } => {
                let Weights::Dense(w, bias) = &self.weights[k] else {
                    return Err(err("weights missing".into()));
                };
                let [inp, out] = w.dims();
                let flat = self.get(values, *input, k)?.flat_in_tflite_order();
                let total = flat.dims()[0];
                if total % (n * inp) != 0 {
                    return Err(err(format!("{total} values do not make rows of {inp}")));
                }
                let rows = total / (n * inp);
                let y = flat.reshape([n * rows, inp]).matmul(w.clone());
                let y = match bias {
                    Some(b) => y + b.clone(),
                    None => y,
                };
                Value::Matrix(activate(y, *activation).reshape([n, rows, out]))
            }
            Op::Logistic { input, .. } => match self.get(values, *input, k)? {
                Value::Image(x) => Value::Image(sigmoid(x)),
                Value::Matrix(x) => Value::Matrix(sigmoid(x)),
            },
        })
    }

    /// `x` padded for TFLite's SAME rule with `fill` (nothing for VALID).
    #[allow(clippy::too_many_arguments)]
    fn pad_same(
        &self,
        x: Tensor<4>,
        padding: Padding,
        size: [usize; 2],
        kernel: [usize; 2],
        stride: [usize; 2],
        dilation: [usize; 2],
        fill: f32,
    ) -> Tensor<4> {
        if padding == Padding::Valid {
            return x;
        }
        let (t, b) = same_padding(size[0], kernel[0], stride[0], dilation[0]);
        let (l, r) = same_padding(size[1], kernel[1], stride[1], dilation[1]);
        if t + b + l + r == 0 {
            return x;
        }
        x.pad([(t, b), (l, r)], PadMode::Constant(fill))
    }
}

/// A constant as the value it is on the device.
fn constant_value(values: Vec<f32>, shape: &[usize], device: &Device) -> Value {
    match dims4(shape) {
        Some(d) => {
            let (v, dims) = permute_host(&values, d, [0, 3, 1, 2]);
            Value::Image(host_tensor(v, dims, device))
        }
        None => {
            let cols = shape.last().copied().unwrap_or(1).max(1);
            let n = if shape.len() >= 2 { shape[0].max(1) } else { 1 };
            let rows = values.len() / cols / n;
            Value::Matrix(host_tensor(values, [n, rows, cols], device))
        }
    }
}

/// A flat NHWC-ordered tensor as the value of logical shape `target`.
fn from_flat(flat: Tensor<1>, target: &[usize]) -> Value {
    match dims4(target) {
        Some([n, h, w, c]) => Value::Image(flat.reshape([n, h, w, c]).permute([0, 3, 1, 2])),
        None => {
            let cols = target.last().copied().unwrap_or(1).max(1);
            let n = if target.len() >= 2 {
                target[0].max(1)
            } else {
                1
            };
            let rows = target.iter().product::<usize>() / cols / n;
            Value::Matrix(flat.reshape([n, rows, cols]))
        }
    }
}

/// The `[out, in]` matrix of TFLite's bilinear resize along one axis.
fn resize_matrix(input: usize, output: usize, align_corners: bool, half_pixel: bool) -> Vec<f32> {
    let scale = if align_corners && output > 1 {
        (input as f64 - 1.0) / (output as f64 - 1.0)
    } else {
        input as f64 / output as f64
    };
    let mut m = vec![0f32; output * input];
    for o in 0..output {
        let src = if half_pixel {
            ((o as f64 + 0.5) * scale - 0.5).max(0.0)
        } else {
            o as f64 * scale
        };
        let lo = (src.floor() as usize).min(input - 1);
        let hi = (lo + 1).min(input - 1);
        let frac = (src - lo as f64) as f32;
        m[o * input + lo] += 1.0 - frac;
        m[o * input + hi] += frac;
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_padding_is_tflites() {
        // 192 -> 96 with a 5x5 kernel, stride 2: total 3, one before and two after.
        assert_eq!(same_padding(192, 5, 2, 1), (1, 2));
        assert_eq!(same_padding(192, 3, 1, 1), (1, 1));
        assert_eq!(same_padding(24, 2, 2, 1), (0, 0));
        assert_eq!(same_padding(7, 3, 2, 1), (1, 1));
    }

    #[test]
    fn resize_rows_sum_to_one_and_match_half_pixel_centres() {
        let m = resize_matrix(12, 24, false, true);
        for o in 0..24 {
            let s: f32 = m[o * 12..(o + 1) * 12].iter().sum();
            assert!((s - 1.0).abs() < 1e-6);
        }
        // Output pixel 1 (centre 1.5 -> source 0.25): 0.75 of pixel 0, 0.25 of pixel 1.
        assert!((m[12] - 0.75).abs() < 1e-6 && (m[13] - 0.25).abs() < 1e-6);
        // The first output pixel clamps to pixel 0.
        assert!((m[0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn permute_host_moves_axes() {
        // [1, 2, 1, 3] -> [0, 3, 1, 2] gives [1, 3, 2, 1]
        let v: Vec<f32> = (0..6).map(|i| i as f32).collect();
        let (p, d) = permute_host(&v, [1, 2, 1, 3], [0, 3, 1, 2]);
        assert_eq!(d, [1, 3, 2, 1]);
        assert_eq!(p, vec![0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
    }
}
