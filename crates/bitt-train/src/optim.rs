//! Adam, as PyTorch's `torch.optim.Adam` (no weight decay, no amsgrad), over every float
//! parameter of a module, with a state that can be saved and restored exactly (resumable
//! runs).
//!
//! Parameters are addressed by their visiting order, which is fixed by the module's
//! structure, so a state saved by one process restores in another.

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Device, Gradients, Tensor, TensorData};

use crate::config::{Bounds, OptimConfig};

/// The largest Adam step a keypoint fit or a refinement may start from: one radian of
/// rotation (or one translation or shape unit) per iteration. The defaults are 0.02 (fit)
/// and 0.01 (refinement); 1e30 used to surface as a non-finite loss naming neither.
pub(crate) const MAX_LEARNING_RATE: f64 = 1.0;

/// The learning rates a keypoint fit or a refinement may ask for: `(0, MAX_LEARNING_RATE]`.
pub const STEP_BOUNDS: Bounds = Bounds::new(0.0, true, MAX_LEARNING_RATE, false).because(
    "an Adam step of more than a radian, or a translation or shape unit, per iteration only \
     diverges",
);

/// Per-parameter Adam moments, flattened, on the training device without autodiff.
#[derive(Debug, Clone, Default)]
pub struct AdamState {
    /// Steps taken by each parameter (PyTorch's per-parameter `step`).
    pub steps: Vec<u64>,
    /// First moments (`None` before a parameter's first gradient).
    pub m: Vec<Option<Tensor<1>>>,
    /// Second moments.
    pub v: Vec<Option<Tensor<1>>>,
}

/// The Adam optimiser.
#[derive(Debug, Clone)]
pub struct Adam {
    /// Hyper-parameters (the learning rate is given per step).
    pub config: OptimConfig,
    /// Moments.
    pub state: AdamState,
}

impl Adam {
    /// A fresh optimiser.
    pub fn new(config: OptimConfig) -> Self {
        Adam {
            config,
            state: AdamState::default(),
        }
    }

    /// One update of every parameter of `module` that has a gradient in `grads`:
    /// `p -= lr m̂ / (sqrt(v̂) + eps)` with bias-corrected moments.
    pub fn step<M: Module>(&mut self, module: M, grads: &Gradients, learning_rate: f64) -> M {
        let mut mapper = AdamMapper {
            adam: self,
            grads,
            learning_rate,
            index: 0,
        };
        module.map(&mut mapper)
    }
}

struct AdamMapper<'a> {
    adam: &'a mut Adam,
    grads: &'a Gradients,
    learning_rate: f64,
    index: usize,
}

impl ModuleMapper for AdamMapper<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let i = self.index;
        self.index += 1;
        let s = &mut self.adam.state;
        if s.steps.len() <= i {
            s.steps.resize(i + 1, 0);
            s.m.resize(i + 1, None);
            s.v.resize(i + 1, None);
        }
        let (id, value, mapper) = param.consume();
        let Some(grad) = value.grad(self.grads) else {
            return Param::from_mapped_value(id, value, mapper);
        };
        let c = &self.adam.config;
        let dims = value.dims();
        let n: usize = dims.iter().product();
        let g = grad.reshape([n]);
        s.steps[i] += 1;
        let t = s.steps[i] as i32;
        let scalars = AdamScalars::at_step(c, t, self.learning_rate);
        let (m, v) = (s.m[i].take(), s.v[i].take());
        let value = value.inner().reshape([n]);
        let (p, m, v) = match flex_update(value, &g, m, v, scalars) {
            Ok(updated) => updated,
            Err(given_back) => {
                let (value, m, v) = *given_back;
                tensor_update(value, g, m, v, scalars)
            }
        };
        s.m[i] = Some(m);
        s.v[i] = Some(v);
        let p = Tensor::from_inner(p.reshape(dims)).require_grad();
        Param::from_mapped_value(id, p, mapper)
    }
}

/// The numbers of one parameter's Adam update (`bias1`, `bias2`: `1 - beta^t`).
#[derive(Debug, Clone, Copy)]
struct AdamScalars {
    beta1: f64,
    beta2: f64,
    epsilon: f64,
    bias1: f64,
    bias2: f64,
    learning_rate: f64,
}

impl AdamScalars {
    /// The numbers of step `t` (1 for a parameter's first update).
    fn at_step(c: &OptimConfig, t: i32, learning_rate: f64) -> Self {
        AdamScalars {
            beta1: c.beta1,
            beta2: c.beta2,
            epsilon: c.epsilon,
            bias1: 1.0 - c.beta1.powi(t),
            bias2: 1.0 - c.beta2.powi(t),
            learning_rate,
        }
    }
}

/// One parameter's update with tensor operations (any backend): the new parameter and
/// moments.
///
/// # Shapes
/// - `p`, `g`, `m`, `v` and the three outputs: `[n]`
fn tensor_update(
    p: Tensor<1>,
    g: Tensor<1>,
    m: Option<Tensor<1>>,
    v: Option<Tensor<1>>,
    c: AdamScalars,
) -> (Tensor<1>, Tensor<1>, Tensor<1>) {
    let m = match m {
        Some(m) => m.mul_scalar(c.beta1) + g.clone().mul_scalar(1.0 - c.beta1),
        None => g.clone().mul_scalar(1.0 - c.beta1),
    };
    let v = match v {
        Some(v) => v.mul_scalar(c.beta2) + g.clone().square().mul_scalar(1.0 - c.beta2),
        None => g.square().mul_scalar(1.0 - c.beta2),
    };
    // PyTorch: p -= (lr / bias1) m / (sqrt(v) / sqrt(bias2) + eps).
    let denom = v
        .clone()
        .sqrt()
        .div_scalar(c.bias2.sqrt())
        .add_scalar(c.epsilon);
    let update = m.clone().div(denom).mul_scalar(c.learning_rate / c.bias1);
    (p - update, m, v)
}

/// Elements per parallel chunk of [`flex_update`].
const FLEX_CHUNK: usize = 1 << 14;

/// [`tensor_update`] on flex as one pass over the elements on rayon's threads, or the
/// tensors given back (nothing computed) when one is not a contiguous `f32` flex tensor.
/// Each element sees the same `f32` operations in the same order as [`tensor_update`]
/// (scalars rounded to `f32` first, as burn's scalar operations do), so both give identical
/// bits; a test checks it. The operations composed from tensors allocate and walk the
/// parameter a dozen times, on one thread: about a seventh of the main thread's time in a
/// `quick` step. The moments are updated where they lie (they live only in [`AdamState`]);
/// so is the parameter when nothing else holds it. A parameter its caller still holds
/// (a module passed as a clone) keeps its values, and the new ones are written to a new
/// buffer in the same pass, instead of being copied on one thread first.
fn flex_update(
    p: Tensor<1>,
    g: &Tensor<1>,
    m: Option<Tensor<1>>,
    v: Option<Tensor<1>>,
    c: AdamScalars,
) -> Result<(Tensor<1>, Tensor<1>, Tensor<1>), GivenBack> {
    use burn::backend::Flex;
    use burn::backend::flex::FlexTensor;
    use rayon::prelude::*;
    let flex = |t: &Tensor<1>| {
        t.clone()
            .try_into_primitive::<Flex>()
            .ok()
            .filter(|f| f.as_slice::<f32>().is_some())
    };
    let (Some(gf), Some(pf)) = (flex(g), flex(&p)) else {
        return Err(Box::new((p, m, v)));
    };
    let (mf, vf) = match (&m, &v) {
        (Some(mt), Some(vt)) => match (flex(mt), flex(vt)) {
            (Some(a), Some(b)) => (Some(a), Some(b)),
            _ => return Err(Box::new((p, m, v))),
        },
        (None, None) => (None, None),
        _ => return Err(Box::new((p, m, v))),
    };
    let n = p.dims()[0];
    let len = |f: &FlexTensor| f.as_slice::<f32>().map_or(0, <[f32]>::len);
    if len(&gf) != n
        || len(&pf) != n
        || [&mf, &vf]
            .iter()
            .any(|f| f.as_ref().is_some_and(|f| len(f) != n))
    {
        return Err(Box::new((p, m, v)));
    }
    // The flex tensors are now the only holders of the values, unless someone else is.
    drop((p, m, v));
    let first = mf.is_none();
    let (mut m_buf, mut v_buf) = (
        mf.map_or_else(|| Values::Fresh(vec![0.0; n]), Values::of),
        vf.map_or_else(|| Values::Fresh(vec![0.0; n]), Values::of),
    );
    let gs = gf.as_slice::<f32>().unwrap_or_default();
    let beta1 = c.beta1 as f32;
    let beta2 = c.beta2 as f32;
    let one_minus_beta1 = (1.0 - c.beta1) as f32;
    let one_minus_beta2 = (1.0 - c.beta2) as f32;
    let sqrt_bias2 = c.bias2.sqrt() as f32;
    let epsilon = c.epsilon as f32;
    let step = (c.learning_rate / c.bias1) as f32;
    // One element: updates its moments and gives the new parameter.
    let update = |p: f32, m: &mut f32, v: &mut f32, g: f32| -> f32 {
        let new_m = if first {
            g * one_minus_beta1
        } else {
            *m * beta1 + g * one_minus_beta1
        };
        let new_v = if first {
            (g * g) * one_minus_beta2
        } else {
            *v * beta2 + (g * g) * one_minus_beta2
        };
        let denom = new_v.sqrt() / sqrt_bias2 + epsilon;
        *m = new_m;
        *v = new_v;
        p - (new_m / denom) * step
    };
    let (ms, vs) = (m_buf.values(), v_buf.values());
    let mut pf = pf;
    let p = if writable_in_place(&mut pf) {
        // Unshared (the graph that held it is gone and the caller gave it up): updated
        // where it lies.
        let ps = pf
            .try_storage_mut::<f32>()
            .expect("a tensor found unshared stays unshared");
        ps.par_chunks_mut(FLEX_CHUNK)
            .zip(ms.par_chunks_mut(FLEX_CHUNK))
            .zip(vs.par_chunks_mut(FLEX_CHUNK))
            .zip(gs.par_chunks(FLEX_CHUNK))
            .for_each(|(((ps, ms), vs), gs)| {
                for (((p, m), v), &g) in ps.iter_mut().zip(ms).zip(vs).zip(gs) {
                    *p = update(*p, m, v, g);
                }
            });
        Values::Owned(pf)
    } else {
        // Shared (a module its caller still holds): the new values are collected into a
        // new buffer on rayon's threads as they are computed (rayon's indexed collect writes
        // each value once, at its place), instead of a copy made first on one thread.
        let source = pf.as_slice::<f32>().unwrap_or_default();
        let mut out = Vec::new();
        source
            .par_iter()
            .zip(ms.par_iter_mut())
            .zip(vs.par_iter_mut())
            .zip(gs.par_iter())
            .with_min_len(FLEX_CHUNK)
            .map(|(((&p, m), v), &g)| update(p, m, v, g))
            .collect_into_vec(&mut out);
        Values::Fresh(out)
    };
    Ok((p.tensor(n), m_buf.tensor(n), v_buf.tensor(n)))
}

/// The parameter and moments [`flex_update`] gives back when it cannot take them.
type GivenBack = Box<(Tensor<1>, Option<Tensor<1>>, Option<Tensor<1>>)>;

/// Whether `t`'s storage is exactly its `f32` values and nothing else holds it.
fn writable_in_place(t: &mut burn::backend::flex::FlexTensor) -> bool {
    let whole = t
        .as_slice::<f32>()
        .is_some_and(|s| s.len() == t.storage::<f32>().len());
    whole && t.try_storage_mut::<f32>().is_some()
}

/// The values [`flex_update`] writes: a flex tensor's own storage when nothing else holds
/// it, else a new buffer.
enum Values {
    /// A contiguous `f32` flex tensor that nothing else holds (its storage is exactly its
    /// values).
    Owned(burn::backend::flex::FlexTensor),
    /// A copy, new values, or zeros for a moment's first step.
    Fresh(Vec<f32>),
}

impl Values {
    /// `t`'s storage when it can be written in place, else a copy of its values.
    fn of(mut t: burn::backend::flex::FlexTensor) -> Self {
        if writable_in_place(&mut t) {
            Values::Owned(t)
        } else {
            Values::Fresh(t.as_slice::<f32>().unwrap_or_default().to_vec())
        }
    }

    fn values(&mut self) -> &mut [f32] {
        match self {
            // Nothing can have taken a share since `Values::of` checked.
            Values::Owned(t) => t
                .try_storage_mut::<f32>()
                .expect("a tensor found unshared stays unshared"),
            Values::Fresh(v) => v,
        }
    }

    fn tensor(self, n: usize) -> Tensor<1> {
        use burn::backend::Flex;
        use burn::backend::flex::FlexTensor;
        let t = match self {
            Values::Owned(t) => t,
            Values::Fresh(v) => FlexTensor::from_data(TensorData::new(v, [n])),
        };
        Tensor::from_primitive::<Flex>(t)
    }
}

/// Every float parameter of a module, flattened, in visiting order (host `f32`).
pub fn parameters_host<M: Module>(module: &M) -> Vec<(Vec<usize>, Vec<f32>)> {
    struct Collect(Vec<(Vec<usize>, Vec<f32>)>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let t = param.val();
            let dims = t.dims().to_vec();
            let data = bitt_stdx::to_host(t.inner()).unwrap_or_default();
            self.0.push((dims, data));
        }
    }
    let mut c = Collect(Vec::new());
    module.visit(&mut c);
    c.0
}

/// Replaces every float parameter of `module` by `values` (visiting order, as
/// [`parameters_host`] gives them). Fails with a message on a count or shape mismatch.
pub fn load_parameters<M: Module>(
    module: M,
    values: &[(Vec<usize>, Vec<f32>)],
    device: &Device,
) -> Result<M, String> {
    struct Load<'a> {
        values: &'a [(Vec<usize>, Vec<f32>)],
        index: usize,
        device: Device,
        error: Option<String>,
    }
    impl ModuleMapper for Load<'_> {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let i = self.index;
            self.index += 1;
            let (id, value, mapper) = param.consume();
            let dims = value.dims();
            match self.values.get(i) {
                Some((shape, data)) if shape.as_slice() == dims.as_slice() => {
                    let t =
                        Tensor::<D>::from_data(TensorData::new(data.clone(), dims), &self.device)
                            .require_grad();
                    Param::from_mapped_value(id, t, mapper)
                }
                other => {
                    if self.error.is_none() {
                        self.error = Some(match other {
                            Some((shape, _)) => {
                                format!(
                                    "parameter {i} has shape {shape:?}, the network needs {dims:?}"
                                )
                            }
                            None => format!("parameter {i} is missing"),
                        });
                    }
                    Param::from_mapped_value(id, value, mapper)
                }
            }
        }
    }
    let mut load = Load {
        values,
        index: 0,
        device: device.clone(),
        error: None,
    };
    let module = module.map(&mut load);
    if let Some(e) = load.error {
        return Err(e);
    }
    if load.index != values.len() {
        return Err(format!(
            "{} parameters saved, the network has {}",
            values.len(),
            load.index
        ));
    }
    Ok(module)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::Module;
    use burn::nn::{Linear, LinearConfig};

    #[derive(Module, Debug)]
    struct Net {
        a: Linear,
    }

    /// A linear layer, initialised holding the trainer's lock on flex's random generator
    /// (a draw here while a trainer initialises on another test thread would shift its
    /// weights).
    fn linear(inputs: usize, outputs: usize, device: &Device) -> Linear {
        let _only_us = crate::trainer::NETS_INIT
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        LinearConfig::new(inputs, outputs).init(device)
    }

    /// Two Adam steps on `f(p) = sum(w p)` match PyTorch's update rule computed by hand.
    #[test]
    fn adam_matches_the_pytorch_update() {
        let device = Device::flex().autodiff();
        let net = Net {
            a: linear(2, 1, &device),
        };
        let before = parameters_host(&net);
        let mut adam = Adam::new(OptimConfig::default());
        let x = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, -2.0], [1, 2]), &device);
        let mut net = net;
        for _ in 0..2 {
            let y = net.a.forward(x.clone()).sum();
            let grads = y.backward();
            net = adam.step(net, &grads, 0.1);
        }
        let after = parameters_host(&net);
        // Constant gradients g: m̂ = g, v̂ = g^2, so each step moves p by -lr sign(g) (up to
        // eps): weight gradient = x, bias gradient = 1.
        let grads = [[1.0f32, -2.0].to_vec(), vec![1.0]];
        for ((_, b), ((_, a), g)) in before.iter().zip(after.iter().zip(grads.iter())) {
            for k in 0..b.len() {
                let want = b[k] - 2.0 * 0.1 * g[k].signum();
                assert!((a[k] - want).abs() < 1e-5, "{} vs {want}", a[k]);
            }
        }
    }

    /// The one-pass update on flex gives the same bits as the tensor operations, at the first
    /// step (no moments yet) and a later one, over several parallel chunks.
    #[test]
    fn flex_update_matches_the_tensor_operations_bit_for_bit() {
        let device = Device::flex();
        let n = 2 * FLEX_CHUNK + 123;
        let mut seed = 7u32;
        let mut values = |scale: f32, offset: f32| -> Tensor<1> {
            let v: Vec<f32> = (0..n)
                .map(|_| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    offset + scale * ((seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5)
                })
                .collect();
            Tensor::<1>::from_data(TensorData::new(v, [n]), &device)
        };
        let (p, g) = (values(2.0, 0.0), values(1e-2, 0.0));
        let (m, v) = (values(1e-2, 0.0), values(1e-4, 1e-4));
        let c = OptimConfig::default();
        let p_before = bitt_testkit::to_vec(p.clone());
        for (t, moments) in [(1, None), (57, Some((m, v)))] {
            let scalars = AdamScalars::at_step(&c, t, 1e-3);
            let moments_before = moments.as_ref().map(|(m, _)| {
                Tensor::<1>::from_data(
                    TensorData::new(bitt_testkit::to_vec(m.clone()), [n]),
                    &device,
                )
            });
            let (m, v) = moments.unzip();
            let bits = |t: &Tensor<1>| -> Vec<u32> {
                bitt_testkit::to_vec(t.clone())
                    .iter()
                    .map(|x| x.to_bits())
                    .collect()
            };
            let composed = tensor_update(p.clone(), g.clone(), m.clone(), v.clone(), scalars);
            // Shared tensors (these clones are also held here) are copied, unshared ones
            // (fresh copies of the values) updated in place; both give the same bits.
            let unshared = |t: &Tensor<1>| {
                Tensor::<1>::from_data(
                    TensorData::new(bitt_testkit::to_vec(t.clone()), [n]),
                    &device,
                )
            };
            let shared = flex_update(p.clone(), &g, m.clone(), v.clone(), scalars)
                .expect("flex tensors take the one-pass update");
            let in_place = flex_update(
                unshared(&p),
                &g,
                m.as_ref().map(unshared),
                v.as_ref().map(unshared),
                scalars,
            )
            .expect("flex tensors take the one-pass update");
            for fused in [&shared, &in_place] {
                for (a, b) in [
                    (&fused.0, &composed.0),
                    (&fused.1, &composed.1),
                    (&fused.2, &composed.2),
                ] {
                    assert_eq!(bits(a), bits(b), "step {t}");
                }
            }
            assert_ne!(bits(&shared.0), bits(&p), "step {t}: the parameter moved");
            assert_eq!(
                bitt_testkit::to_vec(p.clone()),
                p_before,
                "a shared parameter was written"
            );
            // The shared inputs are untouched.
            if let (Some(m0), Some(m1)) = (&m, &moments_before) {
                assert_eq!(bits(m0), bits(m1), "step {t}: a shared moment was written");
            }
        }
    }

    #[test]
    fn parameters_round_trip_and_mismatches_are_named() {
        let device = Device::flex().autodiff();
        let net = Net {
            a: linear(3, 2, &device),
        };
        let values = parameters_host(&net);
        let other = Net {
            a: linear(3, 2, &device),
        };
        let other = load_parameters(other, &values, &device).unwrap();
        assert_eq!(parameters_host(&other), values);
        let wrong = Net {
            a: linear(2, 2, &device),
        };
        let e = load_parameters(wrong, &values, &device).unwrap_err();
        assert!(e.contains("shape"), "{e}");
    }
}
