//! The dense rasterizer op against the CPU core on 50 random scenes of the synthetic
//! generator (both hands of each training view, 64x64), on flex and, where an adapter
//! exists, on wgpu (the CubeCL kernel).
//!
//! Face ids must agree everywhere except on exact ties (two faces at the same `f32` depth,
//! where both pick the lower index, so none are expected); barycentrics to 1e-5. The counts
//! are printed (`--nocapture`).

use bitt_mesh::{Side, procedural_pair};
use bitt_render::cpu::{Fragments, rasterize};
use bitt_render::scene::{DepthRange, Scene};
use bitt_render::{RasterKernel, Topology, rasterize_dense};
use bitt_synth::render::{camera_frame_camera, textured_mesh};
use bitt_synth::{SynthConfig, benchmark_seeds, generate_scene};
use burn::tensor::{Device, Tensor, TensorData};

/// Image side of the comparison.
const SIZE: usize = 64;
/// Number of scenes.
const SCENES: usize = 50;

/// The training view's clip positions (left hand, then right) and the two-hand topology.
fn scene_geometry(seed: u64, topology: &Topology) -> Vec<[f32; 4]> {
    let config = SynthConfig {
        size: SIZE as u32,
        texture_size: 64,
        novel_views: 0,
        novel_poses: 0,
        mesh_noise: None,
        degrade: false,
    };
    let scene = generate_scene(&config, seed, &Device::flex()).unwrap();
    let hands = &scene.train.hands;
    let posed = hands.pose_in_camera(&procedural_pair()).unwrap();
    let camera = camera_frame_camera(&hands.camera);
    let clip: Vec<[f32; 4]> = Side::BOTH
        .iter()
        .flat_map(|&side| posed.get(side).unwrap().vertices.clone())
        .map(|p| {
            let c = camera.clip_point(p, DepthRange::default());
            [c.x as f32, c.y as f32, c.z as f32, c.w as f32]
        })
        .collect();
    assert_eq!(clip.len(), topology.num_vertices());
    clip
}

/// The dense op's outputs on the host.
fn dense(clip: &[[f32; 4]], topology: &Topology, device: &Device) -> (Fragments, RasterKernel) {
    let flat: Vec<f32> = clip.iter().flatten().copied().collect();
    let clip_t = Tensor::<2>::from_data(TensorData::new(flat, [clip.len(), 4]), device);
    let out = rasterize_dense(clip_t, topology, SIZE, SIZE).unwrap();
    let face = out.face.into_data().convert::<i32>().try_to_vec().unwrap();
    let bary: Vec<f32> = out.bary.into_data().convert::<f32>().try_to_vec().unwrap();
    let depth = out.depth.into_data().convert::<f32>().try_to_vec().unwrap();
    let frags = Fragments {
        width: SIZE,
        height: SIZE,
        face,
        bary: bary.chunks_exact(3).map(|b| [b[0], b[1], b[2]]).collect(),
        depth,
    };
    (frags, out.kernel)
}

#[test]
fn dense_op_matches_the_cpu_core_on_fifty_synthetic_scenes() {
    let models = procedural_pair();
    let meshes = Side::BOTH.map(|side| textured_mesh(models.get(side)).unwrap());
    let topology = Scene::new(&[&meshes[0], &meshes[1]])
        .unwrap()
        .topology()
        .clone();
    let mut devices = vec![("flex", Device::flex())];
    devices.extend(bitt_testkit::wgpu().map(|d| ("wgpu", d)));
    let clips: Vec<Vec<[f32; 4]>> = benchmark_seeds(SCENES)
        .into_iter()
        .map(|seed| scene_geometry(seed, &topology))
        .collect();
    for (name, device) in devices {
        let (mut covered, mut differ, mut ties) = (0usize, 0usize, 0usize);
        let mut bary_max = 0.0f32;
        for clip in &clips {
            let reference = rasterize(clip, topology.faces(), SIZE, SIZE).unwrap();
            let (out, kernel) = dense(clip, &topology, &device);
            let expected = if name == "wgpu" {
                RasterKernel::Cube
            } else {
                RasterKernel::Host
            };
            assert_eq!(kernel, expected, "{name}");
            for p in 0..SIZE * SIZE {
                covered += usize::from(reference.face[p] >= 0);
                if reference.face[p] != out.face[p] {
                    differ += 1;
                    // An exact tie: the other face was drawn at the same f32 depth.
                    ties += usize::from(reference.depth[p] == out.depth[p]);
                    continue;
                }
                for k in 0..3 {
                    bary_max = bary_max.max((reference.bary[p][k] - out.bary[p][k]).abs());
                }
            }
        }
        eprintln!(
            "{name}: {SCENES} scenes {SIZE}x{SIZE}: {covered} covered pixels, {differ} face ids \
             differ ({ties} of them exact depth ties), max |bary diff| {bary_max:e}"
        );
        assert_eq!(differ, ties, "{name}: face ids differ off exact ties");
        assert!(
            bary_max <= 1e-5,
            "{name}: barycentrics differ by {bary_max}"
        );
    }
}
