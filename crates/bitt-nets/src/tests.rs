//! Whole-crate tests: the reference parameter counts and every network's shapes at every
//! preset.

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::{BittNetsConfig, LightParams, Preset};
use bitt_testkit::{devices, random};

/// The parameter counts of the reference implementation (PyTorch), exactly.
#[test]
fn paper_parameter_counts_equal_the_reference() {
    let nets = BittNetsConfig::preset(Preset::Paper)
        .init(&Device::flex())
        .expect("paper preset");
    assert_eq!(nets.albedo.num_params(), 12_280_195, "albedo U-Net");
    assert_eq!(nets.light.num_params(), 3_838_464, "light encoder");
    assert_eq!(nets.html.num_params(), 15_441_920, "HTML encoder");
    assert_eq!(nets.btr.num_params(), 2_431_779, "BTR");
}

#[test]
fn presets_validate_and_round_trip_through_json() {
    for preset in Preset::ALL {
        let config = BittNetsConfig::preset(preset);
        config.validate().expect("preset is valid");
        let json = serde_json::to_string(&config).expect("serialise");
        let back: BittNetsConfig = serde_json::from_str(&json).expect("parse");
        assert_eq!(serde_json::to_string(&back).unwrap(), json, "{preset}");
        assert_eq!(preset.name().parse::<Preset>().unwrap(), preset);
    }
    assert!("huge".parse::<Preset>().is_err());
}

/// Runs every network once at `preset` and checks the output shapes. BTR runs at a short
/// odd length (it is fully convolutional; `T` only changes the length).
fn check_shapes(preset: Preset, name: &str, device: &Device) {
    let config = BittNetsConfig::preset(preset);
    let nets = config.init(device).expect("init");
    let s = config.image_size;
    let image = random([2, 3, s, s], 1, device)
        .add_scalar(1.0)
        .div_scalar(2.0);
    let albedo = nets.albedo.forward(image.clone());
    assert_eq!(albedo.dims(), [2, 3, s, s], "{preset} {name} albedo");
    let light = nets.light.forward(image.clone());
    assert_eq!(light.dims(), [2, 12], "{preset} {name} light");
    let LightParams {
        ambient,
        diffuse,
        specular,
        location,
    } = LightParams::from_raw(light);
    for t in [ambient, diffuse, specular, location] {
        assert_eq!(t.dims(), [2, 3], "{preset} {name} light params");
    }
    let html = nets.html.predict(image);
    assert_eq!(html.left.dims(), [2, 101], "{preset} {name} html");
    assert_eq!(html.right.dims(), [2, 101], "{preset} {name} html");
    let t = if preset == Preset::Tiny {
        config.num_texels
    } else {
        61
    };
    let out = nets
        .btr
        .forward(random([1, 3, t], 2, device), random([1, 3, t], 3, device));
    assert_eq!(out.left.dims(), [1, 3, t], "{preset} {name} btr");
    assert_eq!(out.right.dims(), [1, 3, t], "{preset} {name} btr");
}

#[test]
fn shapes_tiny_every_device() {
    for (name, device) in devices() {
        check_shapes(Preset::Tiny, name, &device);
    }
}

#[test]
fn shapes_quick_and_paper_flex() {
    let device = Device::flex();
    check_shapes(Preset::Quick, "flex", &device);
    check_shapes(Preset::Paper, "flex", &device);
}

/// Counts the float parameters that have (and lack) a gradient.
struct GradCheck<'a> {
    grads: &'a burn::tensor::Gradients,
    with: usize,
    without: usize,
}

impl burn::module::ModuleVisitor for GradCheck<'_> {
    fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
        match param.val().grad(self.grads) {
            Some(_) => self.with += 1,
            None => self.without += 1,
        }
    }
}

/// Gradients reach every parameter of every network (tiny preset).
#[test]
fn gradients_reach_every_parameter() {
    let device = Device::flex().autodiff();
    let config = BittNetsConfig::preset(Preset::Tiny);
    let nets = config.init(&device).unwrap();
    let s = config.image_size;
    let image = random([1, 3, s, s], 4, &device);
    let out = nets.btr.forward(
        random([1, 3, 33], 5, &device),
        random([1, 3, 33], 6, &device),
    );
    let loss = nets.albedo.forward(image.clone()).mean()
        + nets.light.forward(image.clone()).mean()
        + nets.html.forward(image).mean()
        + out.left.mean()
        + out.right.mean();
    let grads = loss.backward();
    let mut check = GradCheck {
        grads: &grads,
        with: 0,
        without: 0,
    };
    nets.visit(&mut check);
    assert!(check.with > 50, "{} parameters with gradients", check.with);
    assert_eq!(check.without, 0, "parameters without a gradient");
}
