//! The shape report of `bitt nets`: each network's parameter count, input and output shapes.

use burn::module::Module;
use burn::tensor::{Device, Distribution, Tensor};

use bitt_nets::{BittNetsConfig, LightParams};

use bitt::BittError;

fn dims<const D: usize>(t: &Tensor<D>) -> Vec<usize> {
    t.dims().to_vec()
}

/// Builds the four networks of `config` on `device` and reports, as JSON, the image size,
/// the texel count, the configuration and per network (`albedo`, `light`, `html`, `btr`) its
/// parameter count and input shapes; with `run`, also the output shapes of one forward pass
/// on random inputs (and the light parameters' shapes).
///
/// # Errors
/// A configuration the networks cannot be built from.
pub fn net_shapes(
    config: &BittNetsConfig,
    run: bool,
    device: &Device,
) -> Result<serde_json::Value, BittError> {
    // flex's one random generator is shared: hold the trainer's lock on it while drawing
    // (a trainer initialising on another thread would otherwise get shifted weights).
    let _rng = bitt::trainer::NETS_INIT
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let nets = config.init(device)?;
    let (s, t) = (config.image_size, config.num_texels);
    let image_shape = vec![1, 3, s, s];
    let texel_shape = vec![1, 3, t];
    let mut out = serde_json::json!({
        "image_size": s,
        "num_texels": t,
        "networks": {
            "albedo": { "params": nets.albedo.num_params(), "input": [image_shape] },
            "light": { "params": nets.light.num_params(), "input": [image_shape] },
            "html": { "params": nets.html.num_params(), "input": [image_shape] },
            "btr": {
                "params": nets.btr.num_params(),
                "input": [texel_shape, texel_shape],
                "bidirectional": nets.btr.bidirectional(),
            },
        },
        "config": config,
    });
    if run {
        let image = Tensor::<4>::random([1, 3, s, s], Distribution::Default, device);
        let n = &mut out["networks"];
        n["albedo"]["output"] = serde_json::json!([dims(&nets.albedo.forward(image.clone()))]);
        let raw = nets.light.forward(image.clone());
        n["light"]["output"] = serde_json::json!([dims(&raw)]);
        let light = LightParams::from_raw(raw);
        n["light"]["light_params"] = serde_json::json!({
            "ambient": dims(&light.ambient),
            "diffuse": dims(&light.diffuse),
            "specular": dims(&light.specular),
            "location": dims(&light.location),
        });
        let html = nets.html.predict(image);
        n["html"]["output"] = serde_json::json!([dims(&html.left), dims(&html.right)]);
        let x = Tensor::<3>::random([1, 3, t], Distribution::Default, device);
        let y = nets.btr.forward(x.clone(), x);
        n["btr"]["output"] = serde_json::json!([dims(&y.left), dims(&y.right)]);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_nets::Preset;

    /// The tiny preset reports its four networks; the run adds the output shapes, which
    /// match the inputs' batch and the texel count.
    #[test]
    fn tiny_preset_shapes() {
        let config = BittNetsConfig::preset(Preset::Tiny);
        let device = Device::flex();
        let plain = net_shapes(&config, false, &device).unwrap();
        assert!(plain["networks"]["btr"].get("output").is_none());
        assert!(plain["networks"]["albedo"]["params"].as_u64().unwrap() > 0);
        let run = net_shapes(&config, true, &device).unwrap();
        let t = config.num_texels as u64;
        assert_eq!(
            run["networks"]["btr"]["output"][0],
            serde_json::json!([1, 3, t])
        );
        assert_eq!(run["num_texels"], t);
        assert_eq!(run["networks"]["light"]["light_params"]["ambient"][0], 1);
    }
}
