//! HTML texture-model files (`model.pkl`, `uvs.pkl`) built in the test with HTML's keys,
//! dtypes and index semantics (a small 16x16 texture instead of 1024x1024), loaded by
//! `bitt-texture` and compared with a direct implementation of the reference code:
//!
//! ```python
//! img1d = np.zeros(3 * S * S); img1d[index_map] = np.clip((mean + basis @ a) / 255, 0, 1)
//! image = img1d.reshape(3, S, S).transpose(2, 1, 0)   # [row][col][c], row 0 at the top
//! ```

use std::path::{Path, PathBuf};

use bitt_tests::pickle_writer::{PyValue, write_protocol2, write_protocol4};
use bitt_tests::rng::Rng;
use bitt_texture::pca::TexturePca;
use bitt_texture::{
    TextureError, TextureLayout, convert_html, load_html_model_sized, load_html_uvs,
};
use burn::tensor::{Device, Tensor, TensorData};

const S: usize = 16;
const K: usize = 5;

/// A synthetic HTML model: which pixels are valid (`mask[row * S + col]`), the compact
/// arrays in the file's own order, and the index map.
struct RawHtml {
    mean: Vec<f64>,
    basis: Vec<f64>, // [3T, K] row-major
    index_map: Vec<i64>,
}

fn valid_pixels(seed: u64) -> Vec<bool> {
    // About 100 of 256 pixels: a blob plus scattered texels.
    let mut r = Rng::new(seed);
    (0..S * S)
        .map(|p| {
            let (row, col) = ((p / S) as f64, (p % S) as f64);
            let blob = (row - 6.0).powi(2) + (col - 9.0).powi(2) < 20.0;
            blob || r.unit() < 0.25
        })
        .collect()
}

/// HTML's own order: numpy's `np.where` over the flat `3 x S x S` image, i.e. ascending
/// `flat = c*S*S + col*S + row`: three channel blocks, each column-major.
fn html_order(mask: &[bool]) -> Vec<i64> {
    let mut out = Vec::new();
    for c in 0..3 {
        for col in 0..S {
            for row in 0..S {
                if mask[row * S + col] {
                    out.push((c * S * S + col * S + row) as i64);
                }
            }
        }
    }
    out
}

fn raw_html(index_map: Vec<i64>, seed: u64) -> RawHtml {
    let n = index_map.len();
    let mut r = Rng::new(seed);
    let mut mean: Vec<f64> = (0..n).map(|_| r.uniform(60.0, 200.0)).collect();
    let mut basis: Vec<f64> = (0..n * K).map(|_| r.uniform(-12.0, 12.0)).collect();
    // Two values leave 0..255 for the test parameters (sum 1.3): the clamp is exercised.
    mean[0] = 250.0;
    mean[1] = 5.0;
    basis[..K].fill(12.0);
    basis[K..2 * K].fill(-12.0);
    RawHtml {
        mean,
        basis,
        index_map,
    }
}

fn model_pickle(raw: &RawHtml, skip: Option<&str>) -> PyValue {
    let n = raw.mean.len();
    let items = vec![
        ("mean", PyValue::f64_array(&[n], raw.mean.clone())),
        ("basis", PyValue::f64_array(&[n, K], raw.basis.clone())),
        (
            "index_map",
            PyValue::NdArrayI64 {
                shape: vec![n],
                data: raw.index_map.clone(),
                fortran: false,
            },
        ),
    ];
    PyValue::dict(
        items
            .into_iter()
            .filter(|(k, _)| Some(*k) != skip)
            .collect(),
    )
}

/// The reference: `[3, S, S]` image (row 0 = top) for parameters `a`, background 0.
fn reference_image(raw: &RawHtml, a: &[f64]) -> Vec<f32> {
    let mut img1d = vec![0f64; 3 * S * S];
    for (i, &f) in raw.index_map.iter().enumerate() {
        let v: f64 = raw.mean[i] + (0..K).map(|k| raw.basis[i * K + k] * a[k]).sum::<f64>();
        img1d[f as usize] = (v / 255.0).clamp(0.0, 1.0);
    }
    // reshape(3, S, S).transpose(2, 1, 0): image[row][col][c] = img1d[c][col][row].
    let mut out = vec![0f32; 3 * S * S];
    for c in 0..3 {
        for row in 0..S {
            for col in 0..S {
                out[c * S * S + row * S + col] = img1d[c * S * S + col * S + row] as f32;
            }
        }
    }
    out
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bitt-html-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

fn params() -> ([f32; K], [f64; K]) {
    let a = [0.9f32, -1.3, 0.4, 2.0, -0.7];
    (a, a.map(f64::from))
}

fn check_model(model: &TexturePca, raw: &RawHtml, what: &str) {
    let (a, a64) = params();
    let want = reference_image(raw, &a64);
    assert_eq!(model.num_components, K, "{what}");
    assert_eq!((model.layout.width, model.layout.height), (S, S), "{what}");
    assert_eq!(model.layout.num_texels() * 3, raw.mean.len(), "{what}");
    let tex = model.texture(&a).unwrap();
    let img = model.layout.compact_to_image(&tex, [0.0; 3]).unwrap();
    for (i, (g, w)) in img.iter().zip(&want).enumerate() {
        assert!((g - w).abs() < 1e-6, "{what}: value {i}: {g} vs {w}");
    }
    // The valid-texel mask is the set of pixels index_map addresses.
    let mask = model.layout.mask_image();
    for &f in &raw.index_map {
        let f = f as usize % (S * S);
        assert_eq!(mask[(f % S) * S + f / S], 1.0, "{what}");
    }
    // The same through burn (flex), as the pipeline runs it.
    let device = Device::flex();
    let pt = model.to_device(&device);
    let t = pt.texture(Tensor::from_data(TensorData::new(a.to_vec(), [K]), &device));
    let img_t = model.layout.compact_to_image_tensor(t, [0.0; 3]);
    let got: Vec<f32> = img_t.into_data().try_into_vec_as::<f32>().unwrap();
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert!(
            (g - w).abs() < 1e-5,
            "{what} (tensor): value {i}: {g} vs {w}"
        );
    }
}

#[test]
fn html_model_pickles_load_and_match_the_reference() {
    let dir = temp_dir("model");
    let mask = valid_pixels(1);
    let t = mask.iter().filter(|&&m| m).count();
    assert!((80..140).contains(&t), "{t} texels");
    let raw = raw_html(html_order(&mask), 2);
    let (a, a64) = params();
    assert!(reference_image(&raw, &a64).contains(&1.0));
    for (proto, bytes) in [
        (2, write_protocol2(&model_pickle(&raw, None))),
        (4, write_protocol4(&model_pickle(&raw, None))),
    ] {
        let p = dir.join(format!("model_p{proto}.pkl"));
        write(&p, &bytes);
        let model = load_html_model_sized(&p, S).unwrap();
        assert_eq!(model.scale, 1.0 / 255.0);
        // HTML's order needs no permutation: the compact vector is the file's.
        let want_mean: Vec<f32> = raw.mean.iter().map(|&x| x as f32).collect();
        assert_eq!(model.mean, want_mean);
        // The layout's first texels follow index_map: column-major within channel 0.
        let f0 = raw.index_map[0] as usize;
        assert_eq!(model.layout.texels[0], ((f0 % S) as u32, (f0 / S) as u32));
        check_model(&model, &raw, &format!("protocol {proto}"));
        let tex = model.texture(&a).unwrap();
        assert_eq!((tex[0], tex[1]), (1.0, 0.0));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn other_channel_and_texel_orders_are_permuted_into_channel_major() {
    let dir = temp_dir("perm");
    let mask = valid_pixels(3);
    let html = html_order(&mask);
    let t = html.len() / 3;
    // Interleaved RGB per texel, texels in a shuffled order, channels in order B, R, G.
    let mut r = Rng::new(4);
    let mut order: Vec<usize> = (0..t).collect();
    for i in (1..t).rev() {
        order.swap(i, r.below(i + 1));
    }
    let mut index_map = Vec::new();
    for &ti in &order {
        for c in [2, 0, 1] {
            index_map.push(html[c * t + ti]);
        }
    }
    let raw = raw_html(index_map, 5);
    let p = dir.join("model.pkl");
    write(&p, &write_protocol2(&model_pickle(&raw, None)));
    let model = load_html_model_sized(&p, S).unwrap();
    check_model(&model, &raw, "interleaved");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn broken_html_pickles_give_named_errors() {
    let dir = temp_dir("broken");
    let mask = valid_pixels(6);
    let good = html_order(&mask);
    let cases: Vec<(&str, RawHtml, Option<&str>, &str)> = vec![
        (
            "no_basis",
            raw_html(good.clone(), 7),
            Some("basis"),
            "missing key `basis`",
        ),
        (
            "no_index",
            raw_html(good.clone(), 7),
            Some("index_map"),
            "missing key `index_map`",
        ),
        (
            "out_of_range",
            raw_html(
                {
                    let mut m = good.clone();
                    m[4] = (3 * S * S) as i64;
                    m
                },
                7,
            ),
            None,
            "outside the 3x16x16 image",
        ),
        (
            "negative",
            raw_html(
                {
                    let mut m = good.clone();
                    m[0] = -1;
                    m
                },
                7,
            ),
            None,
            "entry 0 = -1",
        ),
        (
            "duplicate",
            raw_html(
                {
                    let mut m = good.clone();
                    m[9] = m[8];
                    m
                },
                7,
            ),
            None,
            "repeats",
        ),
        (
            "channels_differ",
            raw_html(
                {
                    // A green entry at a pixel the red channel lacks.
                    let mut m = good.clone();
                    let t = m.len() / 3;
                    let free = (0..S * S).find(|&p| !mask[(p % S) * S + p / S]).unwrap();
                    m[t] = (S * S + free) as i64;
                    m
                },
                7,
            ),
            None,
            "the red channel does not have",
        ),
    ];
    for (name, raw, skip, want) in cases {
        let p = dir.join(format!("{name}.pkl"));
        write(&p, &write_protocol2(&model_pickle(&raw, skip)));
        let e = load_html_model_sized(&p, S).unwrap_err();
        let msg = e.to_string();
        assert!(
            matches!(e, TextureError::File(bitt_stdx::FileError::Format { .. })),
            "{name}: {msg}"
        );
        assert!(
            msg.contains(&format!("{name}.pkl")) && msg.contains(want),
            "{name}: {msg}"
        );
    }
    // Wrong basis shape.
    let raw = raw_html(good.clone(), 8);
    let n = raw.mean.len();
    let bad = PyValue::dict(vec![
        ("mean", PyValue::f64_array(&[n], raw.mean.clone())),
        (
            "basis",
            PyValue::f64_array(&[n - 3, K], raw.basis[..(n - 3) * K].to_vec()),
        ),
        (
            "index_map",
            PyValue::NdArrayI64 {
                shape: vec![n],
                data: good.clone(),
                fortran: false,
            },
        ),
    ]);
    let p = dir.join("shape.pkl");
    write(&p, &write_protocol4(&bad));
    let msg = load_html_model_sized(&p, S).unwrap_err().to_string();
    assert!(msg.contains("`basis` has shape"), "{msg}");
    // Not a pickle at all.
    let p = dir.join("text.pkl");
    write(&p, b"hello");
    assert!(matches!(
        load_html_model_sized(&p, S),
        Err(TextureError::Pickle(_))
    ));
    let _ = std::fs::remove_dir_all(&dir);
}

fn uv_pickle(verts: &[[f64; 2]], faces: &[[i64; 3]]) -> PyValue {
    PyValue::dict(vec![
        (
            "verts_uvs",
            PyValue::f64_array(&[verts.len(), 2], verts.iter().flatten().copied().collect()),
        ),
        (
            "faces_uvs",
            PyValue::NdArrayI64 {
                shape: vec![faces.len(), 3],
                data: faces.iter().flatten().copied().collect(),
                fortran: false,
            },
        ),
    ])
}

#[test]
fn html_uv_pickles_load_and_rasterize() {
    let dir = temp_dir("uvs");
    let verts = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]];
    let faces = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
    let p = dir.join("uvs_right.pkl");
    write(&p, &write_protocol4(&uv_pickle(&verts, &faces)));
    let uv = load_html_uvs(&p).unwrap();
    assert_eq!(uv.uvs.len(), 5);
    assert_eq!(uv.uvs[1], glam::DVec2::new(1.0, 0.0));
    assert_eq!(uv.faces, vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]);
    // The four triangles tile the square: every texel is covered.
    let layout = TextureLayout::from_uv(&uv, 8, 8, 0).unwrap();
    assert_eq!(layout.num_texels(), 64);
    // UV (0.5, 0.5) falls between texels; the bottom-left texel (row 7, col 0) is UV
    // (0, 0), on face 0 or face 3 at vertex 0.
    let (f, b) = layout.texel_faces().unwrap()[layout.compact_index(7, 0).unwrap()];
    assert!(f == 0 && (b[0] - 1.0).abs() < 1e-6 || f == 3 && (b[1] - 1.0).abs() < 1e-6);
    // A face pointing at a missing UV vertex.
    let p = dir.join("uvs_left.pkl");
    write(&p, &write_protocol4(&uv_pickle(&verts, &[[0, 1, 5]])));
    let msg = load_html_uvs(&p).unwrap_err().to_string();
    assert!(
        msg.contains("uvs_left.pkl") && msg.contains("UV vertex 5"),
        "{msg}"
    );
    // A missing key.
    let p = dir.join("uvs.pkl");
    write(
        &p,
        &write_protocol4(&PyValue::dict(vec![(
            "verts_uvs",
            PyValue::f64_array(&[1, 2], vec![0.0, 0.0]),
        )])),
    );
    let msg = load_html_uvs(&p).unwrap_err().to_string();
    assert!(msg.contains("missing key `faces_uvs`"), "{msg}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn convert_html_writes_a_loadable_safetensors_file() {
    // `convert_html` reads the real 1024x1024 size: build a sparse 1024 model (a few texels).
    let dir = temp_dir("convert");
    let src = dir.join("TextureBasis");
    let size = 1024usize;
    let pixels = [(0usize, 0usize), (1023, 5), (512, 700), (3, 1023)];
    let mut index_map = Vec::new();
    for c in 0..3 {
        let mut flat: Vec<i64> = pixels
            .iter()
            .map(|&(row, col)| (c * size * size + col * size + row) as i64)
            .collect();
        flat.sort_unstable();
        index_map.extend(flat);
    }
    let raw = raw_html(index_map, 9);
    write(
        &src.join("model_wosr").join("model.pkl"),
        &write_protocol2(&model_pickle(&raw, None)),
    );
    let verts = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    write(
        &src.join("uvs.pkl"),
        &write_protocol4(&uv_pickle(&verts, &[[0, 1, 2]])),
    );
    let out = convert_html(&src, &dir.join("out")).unwrap();
    assert!(out.ends_with("html.safetensors"));
    let model = TexturePca::load_safetensors(&out).unwrap();
    assert_eq!(model.layout.width, 1024);
    assert_eq!(model.layout.num_texels(), 4);
    // Sorted flat order: column-major, so (row 0, col 0), (row 1023, col 5), ...
    assert_eq!(
        model.layout.texels,
        vec![(0, 0), (1023, 5), (512, 700), (3, 1023)]
    );
    assert_eq!(model.layout.uv.as_ref().unwrap().faces, vec![[0, 1, 2]]);
    let (a, _) = params();
    let direct = load_html_model_sized(&src.join("model_wosr").join("model.pkl"), 1024).unwrap();
    assert_eq!(model.texture(&a).unwrap(), direct.texture(&a).unwrap());
    // A folder without a model.
    let e = convert_html(&dir.join("nothing"), &dir.join("out2")).unwrap_err();
    assert!(
        matches!(e, TextureError::File(bitt_stdx::FileError::Io { .. })),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The user's real HTML model, when `BITT_HTML_MODEL` names its `model.pkl` (run with
/// `--ignored`): HTML's published sizes, and a mean texture in [0, 1].
#[test]
#[ignore = "needs the licensed HTML model (set BITT_HTML_MODEL)"]
fn real_html_model_loads() {
    let Some(path) = std::env::var_os("BITT_HTML_MODEL") else {
        eprintln!("SKIPPED real_html_model_loads: BITT_HTML_MODEL is not set");
        return;
    };
    let start = std::time::Instant::now();
    let model = bitt_texture::load_html_model(Path::new(&path)).unwrap();
    eprintln!("loaded in {:.1} s", start.elapsed().as_secs_f64());
    assert_eq!(model.layout.num_texels(), 206_330);
    assert_eq!(model.num_components, 101);
    assert_eq!((model.layout.width, model.layout.height), (1024, 1024));
    let tex = model.texture(&[0.0; 101]).unwrap();
    assert!(tex.iter().all(|x| (0.0..=1.0).contains(x)));
}
