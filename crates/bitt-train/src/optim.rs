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
        let m = match s.m[i].take() {
            Some(m) => m.mul_scalar(c.beta1) + g.clone().mul_scalar(1.0 - c.beta1),
            None => g.clone().mul_scalar(1.0 - c.beta1),
        };
        let v = match s.v[i].take() {
            Some(v) => v.mul_scalar(c.beta2) + g.clone().square().mul_scalar(1.0 - c.beta2),
            None => g.square().mul_scalar(1.0 - c.beta2),
        };
        s.steps[i] += 1;
        let t = s.steps[i] as i32;
        let bias1 = 1.0 - c.beta1.powi(t);
        let bias2 = 1.0 - c.beta2.powi(t);
        // PyTorch: p -= (lr / bias1) m / (sqrt(v) / sqrt(bias2) + eps).
        let denom = v
            .clone()
            .sqrt()
            .div_scalar(bias2.sqrt())
            .add_scalar(c.epsilon);
        let update = m.clone().div(denom).mul_scalar(self.learning_rate / bias1);
        let p = value.inner().reshape([n]) - update;
        s.m[i] = Some(m);
        s.v[i] = Some(v);
        let p = Tensor::from_inner(p.reshape(dims)).require_grad();
        Param::from_mapped_value(id, p, mapper)
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
