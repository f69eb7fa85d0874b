//! Forward + backward timings of BTR, the albedo U-Net, or a whole four-network training
//! step with the Adam update, on any device (`bitt bench-nets`, `bitt gpu-check`).

use std::time::Instant;

use burn::module::Module;
use burn::tensor::{Device, Distribution, Gradients, Tensor};

use bitt_nets::BittNetsConfig;

use bitt::BittError;
use bitt::optim::Adam;

/// Which network is timed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BenchedNet {
    /// BTR, both hands, at the configuration's texel count.
    Btr,
    /// The albedo U-Net at the configuration's image size.
    Albedo,
    /// A training step of all four networks as the trainer runs them: light and HTML
    /// encoders on one image, the albedo U-Net on a batch of 4 (the hand image and the three
    /// consistency renders), BTR on both hands; forward, backward and the Adam update.
    Step,
}

impl BenchedNet {
    /// The name printed in results (`btr`, `albedo`, `step`).
    pub fn name(self) -> &'static str {
        match self {
            BenchedNet::Btr => "btr",
            BenchedNet::Albedo => "albedo",
            BenchedNet::Step => "step",
        }
    }
}

/// The timings of [`bench_net`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NetBench {
    /// The network timed.
    pub net: BenchedNet,
    /// Its parameter count (all four networks for [`BenchedNet::Step`]).
    pub params: usize,
    /// The input's shape.
    pub input_shape: Vec<usize>,
    /// Seconds of each timed run, the first included (no warm-up).
    pub seconds: Vec<f64>,
}

impl NetBench {
    /// `bitt bench-nets`' JSON line: the network, `preset` and `device` as named on the
    /// command line, `config`'s BTR convolution, the parameter count, input shape and timings.
    pub fn report(
        &self,
        config: &BittNetsConfig,
        preset: serde_json::Value,
        device: serde_json::Value,
    ) -> serde_json::Value {
        serde_json::json!({
            "net": self.net.name(),
            "preset": preset,
            "device": device,
            "conv": format!("{:?}", config.btr.conv),
            "params": self.params,
            "input_shape": self.input_shape,
            "seconds": self.seconds,
        })
    }
}

/// Holds the trainer's lock on flex's one random generator while networks and inputs are
/// drawn: a draw here while a trainer initialises on another thread (tests run in
/// parallel) would shift that trainer's weights.
fn host_rng() -> std::sync::MutexGuard<'static, ()> {
    bitt::trainer::NETS_INIT
        .lock()
        .unwrap_or_else(|e| e.into_inner())
}

fn mean_square<const D: usize>(t: Tensor<D>) -> Tensor<1> {
    t.square().mean()
}

/// One call; returns the seconds it took.
fn time_once(f: impl FnOnce() -> Result<(), BittError>) -> Result<f64, BittError> {
    let start = Instant::now();
    f()?;
    Ok(start.elapsed().as_secs_f64())
}

/// Times `runs` forward + backward passes of `net` built from `config` on `device` (a plain
/// device; autodiff is added here), on random inputs. Every run reads a gradient back (and,
/// for the step, an updated parameter), so asynchronous devices finish the work inside the
/// timing.
///
/// # Errors
/// An invalid configuration, no gradient reaching the parameters, a non-finite update.
pub fn bench_net(
    net: BenchedNet,
    config: &BittNetsConfig,
    runs: usize,
    device: &Device,
) -> Result<NetBench, BittError> {
    config.validate()?;
    let device = device.clone().autodiff();
    // As the trainer does: rayon's idle worker spins instead of sleeping between passes.
    let _awake = bitt_nets::awake::KeepAwake::on(&device);
    let (s, t) = (config.image_size, config.num_texels);
    let mut seconds = Vec::with_capacity(runs);
    let (params, input_shape) = match net {
        BenchedNet::Btr => {
            let (btr, left, right) = {
                let _rng = host_rng();
                (
                    config.btr.init(&device),
                    Tensor::<3>::random([1, 3, t], Distribution::Default, &device),
                    Tensor::<3>::random([1, 3, t], Distribution::Default, &device),
                )
            };
            for _ in 0..runs {
                seconds.push(time_once(|| {
                    let out = btr.forward(left.clone(), right.clone());
                    let grads = (mean_square(out.left) + mean_square(out.right)).backward();
                    check_grads(&btr, &grads)
                })?);
            }
            (btr.num_params(), vec![1, 3, t])
        }
        BenchedNet::Albedo => {
            let (albedo, image) = {
                let _rng = host_rng();
                (
                    config.albedo.init(&device),
                    Tensor::<4>::random([1, 3, s, s], Distribution::Default, &device),
                )
            };
            for _ in 0..runs {
                seconds.push(time_once(|| {
                    let grads = mean_square(albedo.forward(image.clone())).backward();
                    check_grads(&albedo, &grads)
                })?);
            }
            (albedo.num_params(), vec![1, 3, s, s])
        }
        BenchedNet::Step => {
            let (mut nets, image, batch, left, right) = {
                let _rng = host_rng();
                (
                    config.init(&device)?,
                    Tensor::<4>::random([1, 3, s, s], Distribution::Default, &device),
                    Tensor::<4>::random([4, 3, s, s], Distribution::Default, &device),
                    Tensor::<3>::random([1, 3, t], Distribution::Default, &device),
                    Tensor::<3>::random([1, 3, t], Distribution::Default, &device),
                )
            };
            let mut adam = Adam::new(bitt::OptimConfig::default());
            for _ in 0..runs {
                seconds.push(time_once(|| {
                    let out = nets.btr.forward(left.clone(), right.clone());
                    let loss = mean_square(nets.light.forward(image.clone()))
                        + mean_square(nets.html.forward(image.clone()))
                        + mean_square(nets.albedo.forward(batch.clone()))
                        + mean_square(out.left)
                        + mean_square(out.right);
                    let grads = loss.backward();
                    check_grads(&nets, &grads)?;
                    nets = adam.step(nets.clone(), &grads, 1e-3);
                    // Read a parameter back, so the timing includes the whole update.
                    check_params(&nets)
                })?);
            }
            (nets.num_params(), vec![1, 3, s, s])
        }
    };
    Ok(NetBench {
        net,
        params,
        input_shape,
        seconds,
    })
}

/// Reads the first parameter back (its sum must be finite).
fn check_params<M: Module>(net: &M) -> Result<(), BittError> {
    struct First {
        value: Option<f32>,
    }
    impl burn::module::ModuleVisitor for First {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            if self.value.is_none() {
                self.value = Some(param.val().sum().into_scalar::<f32>());
            }
        }
    }
    let mut first = First { value: None };
    net.visit(&mut first);
    match first.value {
        Some(v) if v.is_finite() => Ok(()),
        other => Err(BittError::NonFinite(format!(
            "the first parameter's sum is {other:?} after the update"
        ))),
    }
}

/// Reads one gradient back, so the timing includes the whole backward pass.
fn check_grads<M: Module>(net: &M, grads: &Gradients) -> Result<(), BittError> {
    struct First<'a> {
        grads: &'a Gradients,
        value: Option<f32>,
    }
    impl burn::module::ModuleVisitor for First<'_> {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            if self.value.is_none()
                && let Some(g) = param.val().grad(self.grads)
            {
                self.value = Some(g.sum().into_scalar::<f32>());
            }
        }
    }
    let mut first = First { grads, value: None };
    net.visit(&mut first);
    match first.value {
        Some(_) => Ok(()),
        None => Err(BittError::Invalid(
            "no parameter received a gradient".into(),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_nets::Preset;

    #[test]
    fn tiny_benches_time_every_run_on_flex() {
        let config = BittNetsConfig::preset(Preset::Tiny);
        for net in [BenchedNet::Btr, BenchedNet::Albedo, BenchedNet::Step] {
            let b = bench_net(net, &config, 2, &Device::flex()).unwrap();
            assert_eq!(b.seconds.len(), 2, "{net:?}");
            assert!(b.seconds.iter().all(|&s| s > 0.0 && s.is_finite()));
            assert!(b.params > 0);
        }
        let btr = bench_net(BenchedNet::Btr, &config, 1, &Device::flex()).unwrap();
        assert_eq!(btr.input_shape, vec![1, 3, config.num_texels]);
        let params = {
            let _rng = host_rng();
            config.btr.init(&Device::flex()).num_params()
        };
        assert_eq!(btr.params, params);
    }
}
