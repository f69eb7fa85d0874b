//! MANO files as distributed, built byte-for-byte in the test (protocol 2, latin-1 byte-string
//! keys, numpy `_reconstruct`, a Fortran-ordered `kintree_table`, a csc `J_regressor`, chumpy
//! `shapedirs`) with MANO's real shapes, loaded by `bitt-mesh` and posed; the posed vertices
//! are compared with a straightforward implementation written here from the MANO equations.

use std::path::{Path, PathBuf};

use bitt_mesh::Side;
use bitt_mesh::lbs::{HandParams, HandPose};
use bitt_mesh::mano::{load_mano_pkl, load_model_dir, save_safetensors};
use bitt_tests::pickle_writer::{PyValue, write_protocol2};
use bitt_tests::rng::Rng;
use glam::{DMat3, DVec3};

const NV: usize = 778;
const NF: usize = 1538;
const NJ: usize = 16;
const PARENTS: [i64; 16] = [-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14];

/// The raw arrays of a synthetic MANO file (row-major), kept to feed the reference code.
struct RawMano {
    v_template: Vec<f64>,
    faces: Vec<u32>,
    weights: Vec<f64>,
    j_regressor: Vec<f64>,    // dense [16, 778]
    shapedirs_full: Vec<f64>, // [778, 3, 20]
    posedirs: Vec<f64>,       // [778, 3, 135]
    components: Vec<f64>,     // [45, 45]
    mean: Vec<f64>,           // [45]
}

fn raw_mano(seed: u64) -> RawMano {
    let mut r = Rng::new(seed);
    let v_template = (0..NV * 3).map(|_| r.uniform(-0.08, 0.08)).collect();
    let faces = (0..NF * 3).map(|_| r.below(NV) as u32).collect();
    let mut weights = vec![0.0; NV * NJ];
    for v in 0..NV {
        // Up to 3 influencing joints, like MANO's sparse-ish weights.
        let js = [r.below(NJ), r.below(NJ), r.below(NJ)];
        let ws = [r.unit() + 0.1, r.unit(), r.unit() * 0.5];
        let s: f64 = ws.iter().sum();
        for (j, w) in js.iter().zip(ws) {
            weights[v * NJ + j] += w / s;
        }
    }
    // 1896 non-zeros in total, like MANO: 118 or 119 vertices per joint, rows summing to 1.
    let mut j_regressor = vec![0.0; NJ * NV];
    for j in 0..NJ {
        let n = if j < 8 { 119 } else { 118 };
        let mut picked = Vec::new();
        while picked.len() < n {
            let v = r.below(NV);
            if !picked.contains(&v) {
                picked.push(v);
            }
        }
        let ws: Vec<f64> = (0..n).map(|_| r.unit() + 0.01).collect();
        let s: f64 = ws.iter().sum();
        for (v, w) in picked.iter().zip(ws) {
            j_regressor[j * NV + v] = w / s;
        }
    }
    RawMano {
        v_template,
        faces,
        weights,
        j_regressor,
        shapedirs_full: (0..NV * 3 * 20).map(|_| r.uniform(-0.01, 0.01)).collect(),
        posedirs: (0..NV * 3 * 135)
            .map(|_| r.uniform(-0.005, 0.005))
            .collect(),
        components: (0..45 * 45).map(|_| r.uniform(-0.5, 0.5)).collect(),
        mean: (0..45).map(|_| r.uniform(-0.2, 0.2)).collect(),
    }
}

/// The pickle of a MANO file with the structure of the distributed ones.
fn mano_pickle(m: &RawMano) -> Vec<u8> {
    let s = |k: &str| PyValue::Str(k.to_string());
    // csc: column-major compressed storage of the dense regressor.
    let (mut data, mut indices, mut indptr) = (Vec::new(), Vec::new(), vec![0i32]);
    for v in 0..NV {
        for j in 0..NJ {
            let x = m.j_regressor[j * NV + v];
            if x != 0.0 {
                data.push(x);
                indices.push(j as i32);
            }
        }
        indptr.push(data.len() as i32);
    }
    assert_eq!(data.len(), 1896);
    // kintree_table [2, 16] i8 in Fortran order: column-major data.
    let mut kintree = Vec::new();
    for (j, p) in PARENTS.iter().enumerate() {
        kintree.push(if *p < 0 { 4_294_967_295 } else { *p });
        kintree.push(j as i64);
    }
    // shapedirs: Select over a Ch whose x is [778, 3, 20]; idxs pick [:, :, :10].
    let idxs: Vec<i64> = (0..NV * 3)
        .flat_map(|row| (0..10).map(move |b| (row * 20 + b) as i64))
        .collect();
    let entries = vec![
        (
            s("J_regressor_prior"),
            PyValue::Csc {
                shape: (NJ, NV),
                data: data.clone(),
                indices: indices.clone(),
                indptr: indptr.clone(),
            },
        ),
        (
            s("f"),
            PyValue::NdArrayU32 {
                shape: vec![NF, 3],
                data: m.faces.clone(),
            },
        ),
        (
            s("J_regressor"),
            PyValue::Csc {
                shape: (NJ, NV),
                data,
                indices,
                indptr,
            },
        ),
        (
            s("kintree_table"),
            PyValue::NdArrayI64 {
                shape: vec![2, NJ],
                data: kintree,
                fortran: true,
            },
        ),
        (
            s("J"),
            PyValue::NdArrayF64 {
                shape: vec![NJ, 3],
                data: vec![0.0; NJ * 3],
                fortran: false,
            },
        ),
        (
            s("weights_prior"),
            PyValue::NdArrayF64 {
                shape: vec![NV, NJ],
                data: m.weights.clone(),
                fortran: false,
            },
        ),
        (
            s("weights"),
            PyValue::NdArrayF64 {
                shape: vec![NV, NJ],
                data: m.weights.clone(),
                fortran: false,
            },
        ),
        (
            s("posedirs"),
            PyValue::NdArrayF64 {
                shape: vec![NV, 3, 135],
                data: m.posedirs.clone(),
                fortran: false,
            },
        ),
        (s("bs_style"), s("lbs")),
        (
            s("v_template"),
            PyValue::NdArrayF64 {
                shape: vec![NV, 3],
                data: m.v_template.clone(),
                fortran: false,
            },
        ),
        (
            s("hands_coeffs"),
            PyValue::NdArrayF64 {
                shape: vec![1554, 45],
                data: vec![0.0; 1554 * 45],
                fortran: false,
            },
        ),
        (
            s("hands_components"),
            PyValue::NdArrayF64 {
                shape: vec![45, 45],
                data: m.components.clone(),
                fortran: false,
            },
        ),
        (
            s("hands_mean"),
            PyValue::NdArrayF64 {
                shape: vec![45],
                data: m.mean.clone(),
                fortran: false,
            },
        ),
        (
            s("shapedirs"),
            PyValue::ChumpySelect {
                a: Box::new(PyValue::ChumpyCh(Box::new(PyValue::NdArrayF64 {
                    shape: vec![NV, 3, 20],
                    data: m.shapedirs_full.clone(),
                    fortran: false,
                }))),
                idxs,
                preferred_shape: vec![NV, 3, 10],
            },
        ),
        (s("bs_type"), s("lrotmin")),
    ];
    write_protocol2(&PyValue::Dict(entries))
}

// ---- The reference: MANO's equations, written plainly with row-major arrays. ----

type M3 = [[f64; 3]; 3];

fn mat_mul(a: &M3, b: &M3) -> M3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

fn mat_vec(a: &M3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

fn rodrigues(w: [f64; 3]) -> M3 {
    let theta = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    if theta < 1e-12 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let k = w.map(|x| x / theta);
    let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    let kx2 = mat_mul(&kx, &kx);
    let (s, c) = theta.sin_cos();
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = if i == j { 1.0 } else { 0.0 } + s * kx[i][j] + (1.0 - c) * kx2[i][j];
        }
    }
    r
}

/// Posed vertices: v = sum_j w_j (R_j^global (v_posed - J_j) + t_j^global) + trans.
fn reference_pose(
    m: &RawMano,
    shapedirs10: &[f64],
    root: &M3,
    pca: &[f64],
    betas: &[f64],
    trans: [f64; 3],
) -> Vec<[f64; 3]> {
    let v_shaped: Vec<[f64; 3]> = (0..NV)
        .map(|v| {
            [0, 1, 2].map(|c| {
                m.v_template[v * 3 + c]
                    + (0..10)
                        .map(|b| shapedirs10[(v * 3 + c) * 10 + b] * betas[b])
                        .sum::<f64>()
            })
        })
        .collect();
    let joints: Vec<[f64; 3]> = (0..NJ)
        .map(|j| {
            [0, 1, 2].map(|c| {
                (0..NV)
                    .map(|v| m.j_regressor[j * NV + v] * v_shaped[v][c])
                    .sum()
            })
        })
        .collect();
    let axis: Vec<f64> = (0..45)
        .map(|k| {
            m.mean[k]
                + (0..45)
                    .map(|i| pca[i] * m.components[i * 45 + k])
                    .sum::<f64>()
        })
        .collect();
    let mut local = vec![*root];
    for j in 1..NJ {
        local.push(rodrigues([
            axis[(j - 1) * 3],
            axis[(j - 1) * 3 + 1],
            axis[(j - 1) * 3 + 2],
        ]));
    }
    let mut feat = Vec::new();
    for r in &local[1..] {
        for (i, row) in r.iter().enumerate() {
            for (k, x) in row.iter().enumerate() {
                feat.push(x - if i == k { 1.0 } else { 0.0 });
            }
        }
    }
    let v_posed: Vec<[f64; 3]> = (0..NV)
        .map(|v| {
            [0, 1, 2].map(|c| {
                v_shaped[v][c]
                    + (0..135)
                        .map(|f| m.posedirs[(v * 3 + c) * 135 + f] * feat[f])
                        .sum::<f64>()
            })
        })
        .collect();
    // Global rotation and translation of each joint.
    let mut g_rot = vec![[[0.0; 3]; 3]; NJ];
    let mut g_t = vec![[0.0; 3]; NJ];
    for j in 0..NJ {
        if PARENTS[j] < 0 {
            g_rot[j] = local[j];
            g_t[j] = joints[j];
        } else {
            let p = PARENTS[j] as usize;
            g_rot[j] = mat_mul(&g_rot[p], &local[j]);
            let off = [0, 1, 2].map(|c| joints[j][c] - joints[p][c]);
            let ro = mat_vec(&g_rot[p], off);
            g_t[j] = [0, 1, 2].map(|c| g_t[p][c] + ro[c]);
        }
    }
    (0..NV)
        .map(|v| {
            let mut out = [0.0; 3];
            for j in 0..NJ {
                let w = m.weights[v * NJ + j];
                let rel = [0, 1, 2].map(|c| v_posed[v][c] - joints[j][c]);
                let moved = mat_vec(&g_rot[j], rel);
                for c in 0..3 {
                    out[c] += w * (moved[c] + g_t[j][c]);
                }
            }
            [0, 1, 2].map(|c| out[c] + trans[c])
        })
        .collect()
}

fn shapedirs10(m: &RawMano) -> Vec<f64> {
    m.shapedirs_full
        .chunks_exact(20)
        .flat_map(|row| row[..10].to_vec())
        .collect()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bitt-mano-test-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn random_params(seed: u64) -> (M3, Vec<f64>, Vec<f64>, [f64; 3]) {
    let mut r = Rng::new(seed);
    let root = rodrigues([
        r.uniform(-1.5, 1.5),
        r.uniform(-1.5, 1.5),
        r.uniform(-1.5, 1.5),
    ]);
    let pca = (0..45).map(|_| r.uniform(-1.0, 1.0)).collect();
    let betas = (0..10).map(|_| r.uniform(-2.0, 2.0)).collect();
    (
        root,
        pca,
        betas,
        [
            r.uniform(-0.2, 0.2),
            r.uniform(-0.2, 0.2),
            r.uniform(0.3, 0.8),
        ],
    )
}

fn to_params(root: &M3, pca: &[f64], betas: &[f64], trans: [f64; 3]) -> HandParams {
    HandParams {
        root_rotation: DMat3::from_cols_array_2d(root).transpose(),
        pose: HandPose::Pca(pca.to_vec()),
        betas: betas.to_vec(),
        trans: DVec3::from_array(trans),
    }
}

fn assert_close(got: &[DVec3], want: &[[f64; 3]], tol: f64) {
    assert_eq!(got.len(), want.len());
    let worst = got
        .iter()
        .zip(want)
        .map(|(g, w)| (*g - DVec3::from_array(*w)).abs().max_element())
        .fold(0.0, f64::max);
    assert!(worst < tol, "largest vertex difference {worst} >= {tol}");
}

#[test]
fn mano_pickle_loads_with_real_shapes_and_poses_like_the_equations() {
    let m = raw_mano(1);
    let dir = scratch("single");
    let path = dir.join("MANO_RIGHT.pkl");
    std::fs::write(&path, mano_pickle(&m)).unwrap();
    let model = load_mano_pkl(&path, Side::Right).unwrap();
    assert_eq!(model.num_vertices(), NV);
    assert_eq!(model.faces.len(), NF);
    assert_eq!(
        model.parents[1..],
        [0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14].map(Some)
    );
    assert_eq!(model.parents[0], None);
    let sd = shapedirs10(&m);
    assert_eq!(model.shape_dirs, sd, "Select must resolve to x[:, :, :10]");
    for seed in 0..3 {
        let (root, pca, betas, trans) = random_params(100 + seed);
        let posed = model
            .forward(&to_params(&root, &pca, &betas, trans))
            .unwrap();
        let want = reference_pose(&m, &sd, &root, &pca, &betas, trans);
        assert_close(&posed.vertices, &want, 1e-5);
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn left_shapedirs_fix_conversion_and_model_dir_loading() {
    let right = raw_mano(2);
    // The distributed left file carries the right file's shapedirs (the known bug).
    let mut left = raw_mano(3);
    left.shapedirs_full = right.shapedirs_full.clone();
    let dir = scratch("pair");
    std::fs::write(dir.join("MANO_RIGHT.pkl"), mano_pickle(&right)).unwrap();
    std::fs::write(dir.join("MANO_LEFT.pkl"), mano_pickle(&left)).unwrap();
    let pair = load_model_dir(&dir).unwrap();
    let mut fixed = shapedirs10(&left);
    for (i, x) in fixed.iter_mut().enumerate() {
        if (i / 10).is_multiple_of(3) {
            *x = -*x;
        }
    }
    assert_eq!(
        pair.left.shape_dirs, fixed,
        "x rows of the left shapedirs are negated"
    );
    assert_eq!(pair.right.shape_dirs, shapedirs10(&right));

    let (root, pca, betas, trans) = random_params(7);
    let want = reference_pose(&left, &fixed, &root, &pca, &betas, trans);
    let params = to_params(&root, &pca, &betas, trans);
    assert_close(&pair.left.forward(&params).unwrap().vertices, &want, 1e-5);

    // Converted files load instead of the pickles and pose identically.
    let converted = scratch("converted");
    save_safetensors(&pair.left, &converted.join("MANO_LEFT.safetensors")).unwrap();
    save_safetensors(&pair.right, &converted.join("MANO_RIGHT.safetensors")).unwrap();
    let again = load_model_dir(&converted).unwrap();
    assert_eq!(again.left.shape_dirs, fixed, "the fix is not applied twice");
    assert_eq!(
        again.left.forward(&params).unwrap().vertices,
        pair.left.forward(&params).unwrap().vertices
    );
    std::fs::remove_dir_all(dir).unwrap();
    std::fs::remove_dir_all(converted).unwrap();
}

#[test]
fn broken_mano_files_are_named_errors() {
    let m = raw_mano(4);
    let bytes = mano_pickle(&m);
    let dir = scratch("broken");
    let path = dir.join("MANO_RIGHT.pkl");
    // Truncated file.
    std::fs::write(&path, &bytes[..bytes.len() / 3]).unwrap();
    let e = load_mano_pkl(&path, Side::Right).unwrap_err().to_string();
    assert!(e.contains("MANO_RIGHT.pkl"), "{e}");
    // A valid pickle that is not a MANO file.
    std::fs::write(
        &path,
        write_protocol2(&PyValue::Dict(vec![(
            PyValue::Str("x".into()),
            PyValue::Int(1),
        )])),
    )
    .unwrap();
    let e = load_mano_pkl(&path, Side::Right).unwrap_err().to_string();
    assert!(
        e.contains("MANO_RIGHT.pkl") && e.contains("v_template"),
        "{e}"
    );
    // Missing folder entries.
    let e = load_model_dir(&dir).unwrap_err().to_string();
    assert!(e.contains("MANO_LEFT"), "{e}");
    let e = load_model_dir(Path::new("/nonexistent/bitt"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/bitt"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// The differentiable hand layer (`bitt::hand_layer`) poses a MANO pair exactly as the f64
/// forward pass does (vertices and the 21 joints, to 1e-5), with the pose given as PCA
/// coefficients through the layer's own PCA expansion, on flex and ndarray.
#[test]
fn hand_layer_matches_the_f64_forward_pass_on_mano() {
    use bitt::hand_layer::{HandLayer, HandLayerParams, has_learned_pose_pca};
    use burn::tensor::{Device, Tensor, TensorData};
    let dir = scratch("layer");
    std::fs::write(dir.join("MANO_RIGHT.pkl"), mano_pickle(&raw_mano(4))).unwrap();
    std::fs::write(dir.join("MANO_LEFT.pkl"), mano_pickle(&raw_mano(5))).unwrap();
    let pair = load_model_dir(&dir).unwrap();
    assert!(has_learned_pose_pca(&pair.left) && has_learned_pose_pca(&pair.right));
    let hands: Vec<HandParams> = (0..2)
        .map(|h| {
            let (root, pca, betas, trans) = random_params(40 + h);
            to_params(&root, &pca, &betas, trans)
        })
        .collect();
    #[allow(deprecated)]
    let devices = [Device::flex(), Device::ndarray()];
    for device in devices {
        let layer = HandLayer::new(&pair, &device).unwrap();
        let mut params = HandLayerParams::from_host(&pair, [&hands[0], &hands[1]], &device);
        // The same pose again, from the coefficients through the layer's PCA expansion.
        let coeffs: Vec<f32> = hands
            .iter()
            .flat_map(|p| match &p.pose {
                HandPose::Pca(c) => c.iter().map(|&x| x as f32).collect::<Vec<_>>(),
                _ => unreachable!(),
            })
            .collect();
        params.finger_pose =
            layer.pca_to_axis_angles(Tensor::from_data(TensorData::new(coeffs, [2, 45]), &device));
        let out = layer.forward(&params);
        let read = |t: Tensor<3>| {
            t.into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .unwrap()
        };
        let (verts, joints) = (read(out.vertices), read(out.joints));
        let mut worst = 0.0f64;
        for (h, side) in Side::BOTH.iter().enumerate() {
            let want = pair.get(*side).forward(&hands[h]).unwrap();
            let got =
                |flat: &[f32], n: usize, i: usize, c: usize| f64::from(flat[(h * n + i) * 3 + c]);
            for (i, p) in want.vertices.iter().enumerate() {
                for c in 0..3 {
                    worst = worst.max((got(&verts, NV, i, c) - p[c]).abs());
                }
            }
            for (i, p) in want.joints.iter().enumerate() {
                for c in 0..3 {
                    worst = worst.max((got(&joints, 21, i, c) - p[c]).abs());
                }
            }
        }
        assert!(worst < 1e-5, "largest difference {worst:e}");
    }
    std::fs::remove_dir_all(dir).unwrap();
}
