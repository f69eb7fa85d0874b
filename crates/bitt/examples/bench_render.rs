//! The renderer benchmark: per-stage forward and backward timings of the renderer on two
//! procedural hands (the demo scene), printed as one JSON line. `cargo xtask bench render`
//! runs it per device and prints the table:
//!
//! `target/release/examples/bench_render [--device flex|ndarray|wgpu] [--runs N] [--size N]
//! [--texture-size N]` (built by `cargo build --release --workspace --all-targets`).
//!
//! Each stage is timed on its own, with the inputs of earlier stages prepared (and
//! synchronised) outside the timing:
//!
//! * forward: the stage's call, then a read-back of a scalar of its output (so lazy and
//!   asynchronous backends finish the work);
//! * backward: the forward is built and synchronised untimed; then `loss.backward()` of a
//!   weighted sum over the stage's output, with the stage's own inputs requiring grad, and
//!   the read-back of one gradient.
//!
//! One warm-up run, then the median of `--runs` repetitions.

use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use bitt_mesh::{PinholeCamera, Side, procedural_pair};
use bitt_render::ops::{Raster, Topology};
use bitt_render::scene::{
    Camera, DepthRange, LightValues, Material, PointLight, TexelSurface, UnwrapSettings, phong,
    vertex_normals,
};
use bitt_render::{antialias, interpolate, rasterize, texture};
use bitt_texture::TextureLayout;
use burn::tensor::{Device, Distribution, Tensor, TensorData};

/// The benchmark's options.
#[derive(Debug)]
struct BenchRenderArgs {
    /// Device to time (`flex`, `ndarray` or `wgpu`).
    device: String,
    /// Timed repetitions per measurement (after one warm-up).
    runs: usize,
    /// Image side in pixels.
    size: usize,
    /// Texture side in texels (also the unwrap layout's side).
    texture_size: usize,
}

impl BenchRenderArgs {
    /// Parses the command line (defaults: flex, 5 runs, 256 px, 1024 texels).
    fn parse(args: impl IntoIterator<Item = String>) -> Result<Self> {
        let mut out = BenchRenderArgs {
            device: "flex".into(),
            runs: 5,
            size: 256,
            texture_size: 1024,
        };
        let mut args = args.into_iter();
        while let Some(flag) = args.next() {
            let value = args
                .next()
                .with_context(|| format!("{flag} takes a value"))?;
            let number = || {
                value
                    .parse::<usize>()
                    .with_context(|| format!("{flag} takes a number"))
            };
            match flag.as_str() {
                "--device" => out.device = value.clone(),
                "--runs" => out.runs = number()?,
                "--size" => out.size = number()?,
                "--texture-size" => out.texture_size = number()?,
                _ => bail!(
                    "usage: bench_render [--device flex|ndarray|wgpu] [--runs N] [--size N] \
                     [--texture-size N]"
                ),
            }
        }
        Ok(out)
    }

    /// The device named by `--device`.
    #[allow(deprecated)] // burn-ndarray is deprecated upstream but still supported here
    fn device(&self) -> Result<Device> {
        Ok(match self.device.as_str() {
            "flex" => Device::flex(),
            "ndarray" => Device::ndarray(),
            "wgpu" => bitt_testkit::wgpu().context("no wgpu adapter")?,
            other => bail!("--device {other}: expected flex, ndarray or wgpu"),
        })
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// Warm-up once, then the median seconds of `runs` timed calls of `timed` (each after an
/// untimed `setup`).
fn measure<S>(
    runs: usize,
    mut setup: impl FnMut() -> Result<S>,
    mut timed: impl FnMut(S) -> Result<()>,
) -> Result<f64> {
    let mut seconds = Vec::with_capacity(runs);
    for i in 0..=runs {
        let state = setup()?;
        let start = Instant::now();
        timed(state)?;
        if i > 0 {
            seconds.push(start.elapsed().as_secs_f64());
        }
    }
    Ok(median(seconds))
}

/// Forces the computation of `t` (reads a scalar back).
fn sync<const D: usize>(t: Tensor<D>) -> Result<f32> {
    let v = t.sum().into_scalar::<f32>();
    if v.is_finite() {
        Ok(v)
    } else {
        Err(anyhow!("a benchmark value is not finite ({v})"))
    }
}

/// Backward of `loss` and a read-back of the gradient of `wrt`.
fn backward<const D: usize>(loss: Tensor<1>, wrt: &Tensor<D>) -> Result<()> {
    let grads = loss.backward();
    let g = wrt.grad(&grads).context("an input received no gradient")?;
    sync(g)?;
    Ok(())
}

/// Backward of `loss` and read-backs of the gradients of two inputs.
fn backward_pair<const A: usize, const B: usize>(
    (loss, a, b): (Tensor<1>, Tensor<A>, Tensor<B>),
) -> Result<()> {
    let grads = loss.backward();
    sync(
        a.grad(&grads)
            .context("the first input received no gradient")?,
    )?;
    sync(
        b.grad(&grads)
            .context("the second input received no gradient")?,
    )?;
    Ok(())
}

fn tensor<const D: usize>(values: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// A fixed pseudo-random weight tensor, so losses are not plain sums.
fn weights<const D: usize>(shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::random(shape, Distribution::Uniform(-1.0, 1.0), device)
}

/// One stage's timings in seconds.
#[derive(Debug, serde::Serialize)]
struct Stage {
    name: &'static str,
    forward: f64,
    backward: f64,
}

fn main() -> Result<()> {
    let args = &BenchRenderArgs::parse(std::env::args().skip(1))?;
    anyhow::ensure!(args.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(
        (16..=2048).contains(&args.size) && (16..=4096).contains(&args.texture_size),
        "--size must be 16 to 2048 and --texture-size 16 to 4096"
    );
    let device = args.device()?.autodiff();
    let runs = args.runs;
    let (h, w) = (args.size, args.size);

    // The demo scene, its camera scaled to the image size.
    let models = procedural_pair();
    let scene = bitt::demo::demo_scene(&models);
    let posed = scene.pose_in_camera(&models)?;
    let scale = args.size as f64 / f64::from(scene.camera.width);
    let camera = Camera::Pinhole(PinholeCamera::looking_down_z(
        560.0 * scale,
        w as u32,
        h as u32,
    ));
    let mut faces = Vec::new();
    let mut uv_faces = Vec::new();
    let mut uvs = Vec::new();
    let mut verts = Vec::new();
    for side in Side::BOTH {
        let model = models.get(side);
        let uv = model
            .uv
            .as_ref()
            .context("the procedural hand has no UV layout")?;
        let (v0, u0) = (verts.len() as u32, uvs.len() as u32);
        faces.extend(model.faces.iter().map(|f| f.map(|i| i + v0)));
        uv_faces.extend(uv.faces.iter().map(|f| f.map(|i| i + u0)));
        uvs.extend(uv.uvs.iter().map(|p| [p.x as f32, p.y as f32]));
        verts.extend(
            posed
                .get(side)
                .context("the demo scene has both hands")?
                .vertices
                .iter()
                .copied(),
        );
    }
    let topology = Topology::new(faces.clone(), verts.len())?;
    let flat: Vec<f32> = verts
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let vertices = tensor(flat, [verts.len(), 3], &device);
    let depth = DepthRange::default();
    let clip = camera.clip_positions(vertices.clone(), depth)?;
    let raster = rasterize(clip.clone(), &topology, h, w)?;
    let n = raster.num_covered();
    anyhow::ensure!(n > 0, "the hands cover no pixel");
    let uv_table: Vec<f32> = uvs.iter().flatten().copied().collect();
    let uv_table = tensor(uv_table, [uvs.len(), 2], &device);
    let tex_side = args.texture_size;
    let tex = Tensor::<3>::random([3, tex_side, tex_side], Distribution::Default, &device);
    let light = LightValues::default();
    let material = Material {
        specular: [0.3; 3],
        ..Material::default()
    };
    let mut stages = Vec::new();

    // rasterize: clip -> barycentrics, depth.
    let g_bary = weights([n, 3], &device);
    let g_depth = weights([n], &device);
    let clip_host = clip.clone().detach();
    stages.push(Stage {
        name: "rasterize",
        forward: measure(
            runs,
            || Ok(clip_host.clone()),
            |c| {
                let r = rasterize(c, &topology, h, w)?;
                sync(r.bary)?;
                Ok(())
            },
        )?,
        backward: measure(
            runs,
            || {
                let c = clip_host.clone().require_grad();
                let r = rasterize(c.clone(), &topology, h, w)?;
                anyhow::ensure!(r.num_covered() == n, "coverage changed between runs");
                let loss = (r.bary * g_bary.clone()).sum() + (r.depth * g_depth.clone()).sum();
                sync(loss.clone())?;
                Ok((loss, c))
            },
            |(loss, c)| backward(loss, &c),
        )?,
    });

    // Raster without gradient to the clip positions, for the later stages.
    let plain = rasterize(clip_host.clone(), &topology, h, w)?;
    let verts_host = vertices.clone().detach();
    let normals_v = vertex_normals(verts_host.clone(), &topology)?.detach();

    // interpolate: per-vertex attributes (positions, normals) -> pixels.
    let attrs = Tensor::cat(vec![verts_host.clone(), normals_v.clone()], 1);
    let g_attr = weights([n, 6], &device);
    stages.push(Stage {
        name: "interpolate",
        forward: measure(
            runs,
            || Ok(attrs.clone()),
            |a| {
                sync(interpolate(a, &plain)?)?;
                Ok(())
            },
        )?,
        backward: measure(
            runs,
            || {
                let a = attrs.clone().require_grad();
                let loss = (interpolate(a.clone(), &plain)? * g_attr.clone()).sum();
                sync(loss.clone())?;
                Ok((loss, a))
            },
            |(loss, a)| backward(loss, &a),
        )?,
    });

    // texture: 1024^2 texture at the pixels' UVs.
    let uv =
        bitt_render::ops::interpolate_with_faces(uv_table.clone(), &uv_faces, &plain)?.detach();
    let g_tex = weights([n, 3], &device);
    stages.push(Stage {
        name: "texture",
        forward: measure(
            runs,
            || Ok(uv.clone()),
            |u| {
                sync(texture(tex.clone(), u)?)?;
                Ok(())
            },
        )?,
        backward: measure(
            runs,
            || {
                let t = tex.clone().require_grad();
                let u = uv.clone().require_grad();
                let loss = (texture(t.clone(), u.clone())? * g_tex.clone()).sum();
                sync(loss.clone())?;
                Ok((loss, t, u))
            },
            backward_pair,
        )?,
    });

    // shade: Phong with a point light (specular on, to time the whole expression).
    let texels = texture(tex.clone(), uv.clone())?.detach();
    let normals = interpolate(normals_v.clone(), &plain)?.detach();
    let points = interpolate(verts_host.clone(), &plain)?.detach();
    let to_camera = (points.clone().neg()).detach();
    let light_t = tensor(light.to_array().to_vec(), [12], &device);
    let g_shade = weights([n, 3], &device);
    stages.push(Stage {
        name: "shade",
        forward: measure(
            runs,
            || Ok(PointLight::from_tensor(light_t.clone())?),
            |l| {
                let c = phong(
                    texels.clone(),
                    normals.clone(),
                    points.clone(),
                    to_camera.clone(),
                    &l,
                    &material,
                );
                sync(c)?;
                Ok(())
            },
        )?,
        backward: measure(
            runs,
            || {
                let (tx, nr, lt) = (
                    texels.clone().require_grad(),
                    normals.clone().require_grad(),
                    light_t.clone().require_grad(),
                );
                let l = PointLight::from_tensor(lt.clone())?;
                let c = phong(
                    tx.clone(),
                    nr,
                    points.clone(),
                    to_camera.clone(),
                    &l,
                    &material,
                );
                let loss = (c * g_shade.clone()).sum();
                sync(loss.clone())?;
                Ok((loss, tx, lt))
            },
            backward_pair,
        )?,
    });

    // antialias: the shaded image and the clip positions.
    let image = plain.to_image(texels.clone(), &[0.0; 3]).detach();
    let g_image = weights([3, h, w], &device);
    let raster_grad =
        |c: &Tensor<2>| -> Result<Raster> { Ok(rasterize(c.clone(), &topology, h, w)?) };
    let r_fixed = raster_grad(&clip_host)?;
    stages.push(Stage {
        name: "antialias",
        forward: measure(
            runs,
            || Ok(image.clone()),
            |im| {
                sync(antialias(im, &r_fixed, clip_host.clone(), &topology)?)?;
                Ok(())
            },
        )?,
        backward: measure(
            runs,
            || {
                let im = image.clone().require_grad();
                let c = clip_host.clone().require_grad();
                let r = raster_grad(&c)?;
                let out = antialias(im.clone(), &r, c.clone(), &topology)?;
                let loss = (out * g_image.clone()).sum();
                sync(loss.clone())?;
                Ok((loss, im, c))
            },
            backward_pair,
        )?,
    });

    // unwrap: the image onto both hands' texels (layout at the texture size).
    let mut surfaces = Vec::new();
    for side in Side::BOTH {
        let model = models.get(side);
        let uv = model
            .uv
            .as_ref()
            .context("the procedural hand has no UV layout")?;
        let layout = TextureLayout::from_uv(uv, tex_side, tex_side, 0)?;
        let surface = TexelSurface::new(&layout, &model.faces, model.num_vertices())?;
        let vs = posed.get(side).context("both hands")?.vertices.clone();
        surfaces.push((surface, vs));
    }
    let settings = UnwrapSettings {
        depth,
        ..UnwrapSettings::default()
    };
    let unwrap_both = |im: &Tensor<3>| -> Result<Tensor<1>> {
        let mut total = Tensor::<1>::zeros([1], &device);
        for (surface, vs) in &surfaces {
            let u =
                bitt_render::scene::unwrap(im.clone(), &camera, surface, vs, &plain, &settings)?;
            total = total + u.texels.sum();
        }
        Ok(total)
    };
    stages.push(Stage {
        name: "unwrap",
        forward: measure(
            runs,
            || Ok(image.clone()),
            |im| {
                sync(unwrap_both(&im)?)?;
                Ok(())
            },
        )?,
        backward: measure(
            runs,
            || {
                let im = image.clone().require_grad();
                let loss = unwrap_both(&im)?;
                sync(loss.clone())?;
                Ok((loss, im))
            },
            |(loss, im)| backward(loss, &im),
        )?,
    });

    // The transfer cost of `rasterize` on a device: the whole op vs the host core alone.
    let host_clip: Vec<[f32; 4]> = clip_host
        .clone()
        .try_into_vec_as::<f32>()
        .map_err(|e| anyhow!("reading clip positions: {e:?}"))?
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    let cpu_core = measure(
        runs,
        || Ok(()),
        |()| {
            let f = bitt_render::cpu::rasterize(&host_clip, &faces, w, h)?;
            anyhow::ensure!(f.face.iter().filter(|&&x| x >= 0).count() == n);
            Ok(())
        },
    )?;
    // The clip read-back alone.
    let readback = measure(
        runs,
        || Ok(clip_host.clone()),
        |c| {
            c.try_into_vec_as::<f32>()
                .map_err(|e| anyhow!("reading clip positions: {e:?}"))?;
            Ok(())
        },
    )?;
    // Host round trips (`bitt_render::host_readbacks`) of one forward call of each way to
    // rasterize, and the dense op's time: `rasterize` reads the clip positions back for the
    // CPU core; `rasterize_dense` is the CubeCL kernel on wgpu (0) and that core elsewhere.
    let count = |f: &dyn Fn() -> Result<()>| -> Result<u64> {
        let before = bitt_render::host_readbacks();
        f()?;
        Ok(bitt_render::host_readbacks() - before)
    };
    let readbacks_sparse = count(&|| {
        rasterize(clip_host.clone(), &topology, h, w)?;
        Ok(())
    })?;
    let dense = |c: Tensor<2>| -> Result<()> {
        let d = bitt_render::rasterize_dense(c, &topology, h, w)?;
        sync(d.depth.clamp_max(1.0))?;
        Ok(())
    };
    let readbacks_dense = count(&|| dense(clip_host.clone()))?;
    let probe = bitt_render::rasterize_dense(clip_host.clone(), &topology, h, w)?;
    let dense_kernel = match probe.host_reason {
        None => format!("{:?}", probe.kernel),
        Some(why) => format!("{:?} ({why})", probe.kernel),
    };
    let dense_forward = measure(runs, || Ok(clip_host.clone()), dense)?;
    // The dense op's face ids against the CPU core's at the benchmark's size.
    let core = bitt_render::cpu::rasterize(&host_clip, &faces, w, h)?;
    let dense_faces: Vec<i32> = probe
        .face
        .into_data()
        .convert::<i32>()
        .try_to_vec()
        .map_err(|e| anyhow!("reading face ids: {e:?}"))?;
    let dense_mismatches = core
        .face
        .iter()
        .zip(&dense_faces)
        .filter(|(a, b)| a != b)
        .count();
    // A training step renders a fixed view: `SceneGeometry::new` once per view and scene
    // (it rasterizes), then `shade` every step.
    let scene_mesh = bitt_render::scene::TexturedMesh::new(
        faces.clone(),
        verts.len(),
        uv_faces.clone(),
        uvs.clone(),
    )?;
    let render_scene = bitt_render::scene::Scene::new(&[&scene_mesh])?;
    let settings = bitt_render::scene::RenderSettings::default();
    let geometry = std::cell::RefCell::new(None);
    let readbacks_geometry = count(&|| {
        let g = bitt_render::scene::SceneGeometry::new(
            &render_scene,
            std::slice::from_ref(&verts_host),
            &camera,
            &settings,
            &[[tex_side, tex_side]],
        )?;
        *geometry.borrow_mut() = Some(g);
        Ok(())
    })?;
    let point_light = PointLight::from_tensor(light_t.clone())?;
    let readbacks_shade = count(&|| {
        let g = geometry.borrow();
        let g = g.as_ref().context("no scene geometry")?;
        sync(g.shade(
            std::slice::from_ref(&tex),
            &point_light,
            &material,
            [0.0; 3],
        )?)?;
        Ok(())
    })?;
    let rasterize_forward = stages[0].forward;
    let out = serde_json::json!({
        "device": args.device,
        "runs": runs,
        "image": [h, w],
        "texture": [tex_side, tex_side],
        "vertices": verts.len(),
        "faces": faces.len(),
        "covered_pixels": n,
        "stages": stages,
        "rasterize_transfer": {
            "rasterize": rasterize_forward,
            "cpu_core": cpu_core,
            "clip_readback": readback,
            "overhead": rasterize_forward - cpu_core,
        },
        "rasterize_dense": {
            "kernel": dense_kernel,
            "forward": dense_forward,
            "face_ids_differing_from_cpu_core": dense_mismatches,
        },
        "host_readbacks": {
            "rasterize": readbacks_sparse,
            "rasterize_dense": readbacks_dense,
            "scene_geometry_new": readbacks_geometry,
            "shade_step": readbacks_shade,
        },
    });
    println!("{out}");
    Ok(())
}
