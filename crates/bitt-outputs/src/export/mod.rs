//! Writing posed hands: Wavefront OBJ (with UVs) and glTF 2.0 binary (`.glb`) with an
//! optional texture image per hand (the atomic writes are `bitt_stdx::write`).
//!
//! Coordinates are written as given (the callers pass camera-frame vertices, OpenCV axes:
//! x right, y down, z forward). The glTF scene adds one root node that turns OpenCV axes
//! into glTF's (y up, looking down -z), so viewers show the hands as the camera saw them.

use std::path::Path;

use glam::{DVec2, DVec3};
use serde_json::json;

use crate::OutputError;
use bitt_mesh::annotation::PosedTwoHands;
use bitt_mesh::model::UvLayout;
use bitt_mesh::{HandPair, Side};
use bitt_stdx::FileErrorExt;

mod skinned;
mod xr;
pub use skinned::{
    RiggedHand, RiggedScene, gltf_vertex_sources, rigged_glb_bytes, skinned_vertices,
    skinned_vertices_posed,
};
pub use xr::{
    METACARPAL_FRACTIONS, OPENXR_JOINTS, THUMB_TWIST_DEGREES, WEBXR_JOINTS, XrConvention, XrHand,
    XrJoint, XrSkeleton, xr_glb_bytes,
};

/// One hand to export.
#[derive(Debug, Clone, Copy)]
pub struct ExportHand<'a> {
    /// Object / mesh name (e.g. `"left_hand"`).
    pub name: &'a str,
    /// Vertex positions.
    pub vertices: &'a [DVec3],
    /// Triangles (counter-clockwise seen from outside).
    pub faces: &'a [[u32; 3]],
    /// UV layout (v = 0 at the bottom of the texture), if any.
    pub uv: Option<&'a UvLayout>,
    /// Texture image for this hand (needs `uv`), if any.
    pub texture: Option<&'a image::RgbImage>,
}

/// The first line of every text file the writers here make (OBJ, MTL): how a later export
/// tells its own earlier output from a user's file of the same name.
pub const WRITTEN_BY: &str = "# written by bitt (two-hand texture reconstruction)";

fn check_hand(h: &ExportHand) -> Result<(), OutputError> {
    let err = |d: String| Err(OutputError::Invalid(format!("export of {}: {d}", h.name)));
    let n = h.vertices.len();
    if h.vertices.iter().any(|p| !p.is_finite()) {
        return err("a vertex is NaN or infinite".into());
    }
    if let Some(f) = h.faces.iter().find(|f| f.iter().any(|&i| i as usize >= n)) {
        return err(format!("face {f:?} indexes past {n} vertices"));
    }
    if let Some(uv) = h.uv {
        if uv.faces.len() != h.faces.len() {
            return err(format!(
                "{} UV faces for {} faces",
                uv.faces.len(),
                h.faces.len()
            ));
        }
        if uv
            .faces
            .iter()
            .flatten()
            .any(|&i| i as usize >= uv.uvs.len())
        {
            return err("a UV face indexes past the UV coordinates".into());
        }
    }
    if h.texture.is_some() && h.uv.is_none() {
        return err("a texture needs a UV layout".into());
    }
    Ok(())
}

/// The OBJ text of `hands` (one `o` object each, in the given order), with `vt` UVs where a
/// hand has a layout. `mtllib` names a material library to reference (one material per
/// hand, named after it), as written by [`mtl_text`].
pub(crate) fn obj_text(hands: &[ExportHand], mtllib: Option<&str>) -> Result<String, OutputError> {
    use std::fmt::Write as _;
    let mut s = format!("{WRITTEN_BY}\n");
    if let Some(m) = mtllib {
        let _ = writeln!(s, "mtllib {m}");
    }
    let (mut v_base, mut vt_base) = (1usize, 1usize);
    for h in hands {
        check_hand(h)?;
        let _ = writeln!(s, "o {}", h.name);
        for p in h.vertices {
            let _ = writeln!(s, "v {:.7} {:.7} {:.7}", p.x, p.y, p.z);
        }
        if let Some(uv) = h.uv {
            for t in &uv.uvs {
                let _ = writeln!(s, "vt {:.7} {:.7}", t.x, t.y);
            }
        }
        if mtllib.is_some() {
            let _ = writeln!(s, "usemtl {}", h.name);
        }
        for (i, f) in h.faces.iter().enumerate() {
            match h.uv {
                Some(uv) => {
                    let t = uv.faces[i];
                    let _ = writeln!(
                        s,
                        "f {}/{} {}/{} {}/{}",
                        f[0] as usize + v_base,
                        t[0] as usize + vt_base,
                        f[1] as usize + v_base,
                        t[1] as usize + vt_base,
                        f[2] as usize + v_base,
                        t[2] as usize + vt_base
                    );
                }
                None => {
                    let _ = writeln!(
                        s,
                        "f {} {} {}",
                        f[0] as usize + v_base,
                        f[1] as usize + v_base,
                        f[2] as usize + v_base
                    );
                }
            }
        }
        v_base += h.vertices.len();
        vt_base += h.uv.map_or(0, |u| u.uvs.len());
    }
    Ok(s)
}

/// A material library giving each hand (by name) its texture file, if it has one.
pub(crate) fn mtl_text(materials: &[(&str, Option<&str>)]) -> String {
    let mut s = format!("{WRITTEN_BY}\n");
    for (name, texture) in materials {
        s.push_str(&format!(
            "newmtl {name}\nKd 1.0 1.0 1.0\nKa 0 0 0\nKs 0 0 0\nillum 1\n"
        ));
        if let Some(t) = texture {
            s.push_str(&format!("map_Kd {t}\n"));
        }
        s.push('\n');
    }
    s
}

/// Writes `hands` as one OBJ file. Hands with a texture get a `.mtl` beside the OBJ and their
/// texture saved as `<stem>_<hand name>.png`, where `<stem>` is the OBJ's file stem with
/// whitespace replaced by `_` (OBJ's `mtllib` and MTL's `map_Kd` split names at spaces).
///
/// The files appear together: each is written to a temporary file first, then all are
/// renamed into place, the OBJ last. A file of those names that exists must be an earlier
/// output of this writer (an OBJ or MTL starting with [`WRITTEN_BY`], a PNG that such an
/// MTL names); anything else is refused before anything is written.
///
/// # Errors
/// [`OutputError::Invalid`] for a user's file in the way (named) or bad hands; an I/O error
/// naming the path.
pub fn write_obj(path: &Path, hands: &[ExportHand]) -> Result<(), OutputError> {
    let textured = hands.iter().any(|h| h.texture.is_some());
    let stem: String = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "hands".into())
        .chars()
        .map(|c| if c.is_whitespace() { '_' } else { c })
        .collect();
    let dir = path.parent().unwrap_or(Path::new(""));
    // Every file, in the order they are renamed into place (the OBJ last).
    let mut files: Vec<(std::path::PathBuf, Vec<u8>)> = Vec::new();
    let mut mtllib = None;
    if textured {
        let mut materials = Vec::new();
        for h in hands {
            let file = h.texture.map(|_| format!("{stem}_{}.png", h.name));
            if let (Some(file), Some(tex)) = (&file, h.texture) {
                files.push((dir.join(file), png_bytes(tex)?));
            }
            materials.push((h.name, file));
        }
        let materials: Vec<(&str, Option<&str>)> =
            materials.iter().map(|(n, f)| (*n, f.as_deref())).collect();
        let mtl = format!("{stem}.mtl");
        files.push((dir.join(&mtl), mtl_text(&materials).into_bytes()));
        mtllib = Some(mtl);
    }
    files.push((
        path.to_path_buf(),
        obj_text(hands, mtllib.as_deref())?.into_bytes(),
    ));
    check_obj_outputs(path, mtllib.as_deref().map(|m| dir.join(m)), &files)?;
    Ok(bitt_stdx::write_all_or_none(&files)?)
}

/// Refuses the OBJ writer's `files` when one exists that it did not write (see
/// [`write_obj`]): the OBJ and the MTL must start with [`WRITTEN_BY`], a PNG must be named by
/// the existing MTL (`map_Kd`).
fn check_obj_outputs(
    obj: &Path,
    mtl: Option<std::path::PathBuf>,
    files: &[(std::path::PathBuf, Vec<u8>)],
) -> Result<(), OutputError> {
    let ours = |p: &Path| -> Result<bool, OutputError> {
        let text = std::fs::read(p).map_err(|e| OutputError::io(p, e))?;
        Ok(text.starts_with(WRITTEN_BY.as_bytes()))
    };
    let listed: Vec<String> = match &mtl {
        Some(m) if m.is_file() && ours(m)? => std::fs::read_to_string(m)
            .map_err(|e| OutputError::io(m, e))?
            .lines()
            .filter_map(|l| l.strip_prefix("map_Kd "))
            .map(str::to_string)
            .collect(),
        _ => Vec::new(),
    };
    let mut foreign = Vec::new();
    for (p, _) in files {
        if !p.exists() {
            continue;
        }
        let is_text = p == obj || Some(p) == mtl.as_ref();
        let mine = if p.is_dir() {
            false
        } else if is_text {
            ours(p)?
        } else {
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
            name.is_some_and(|n| listed.contains(&n))
        };
        if !mine {
            foreign.push(p.display().to_string());
        }
    }
    if !foreign.is_empty() {
        return Err(OutputError::Invalid(format!(
            "writing {} would replace {}, which this tool did not write; nothing was written \
             (choose another output name)",
            obj.display(),
            foreign.join(", ")
        )));
    }
    Ok(())
}

/// PNG encoding of an RGB image.
pub fn png_bytes(img: &image::RgbImage) -> Result<Vec<u8>, OutputError> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| OutputError::Invalid(format!("cannot encode PNG: {e}")))?;
    Ok(out.into_inner())
}

/// Pads `buf` with `byte` to a multiple of 4 bytes (glTF chunk and view alignment).
fn pad_to_4(buf: &mut Vec<u8>, byte: u8) {
    buf.resize(buf.len().next_multiple_of(4), byte);
}

/// Binary-chunk builder: appends 4-byte-aligned views and the accessors over them.
pub(crate) struct BinBuilder {
    pub(crate) bin: Vec<u8>,
    pub(crate) views: Vec<serde_json::Value>,
    pub(crate) accessors: Vec<serde_json::Value>,
}

/// glTF buffer-view target of vertex attributes.
const ARRAY_BUFFER: u32 = 34962;
/// glTF buffer-view target of indices.
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// Component-wise bounds of `width`-wide elements (`min`, `max`), as glTF wants them.
pub(crate) fn bounds(data: &[f32], width: usize) -> (Vec<f32>, Vec<f32>) {
    let mut lo = vec![f32::INFINITY; width];
    let mut hi = vec![f32::NEG_INFINITY; width];
    for c in data.chunks_exact(width) {
        for k in 0..width {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
    }
    (lo, hi)
}

/// Little-endian bytes of floats.
pub(crate) fn f32_bytes(data: &[f32]) -> Vec<u8> {
    data.iter().flat_map(|x| x.to_le_bytes()).collect()
}

impl BinBuilder {
    pub(crate) fn new() -> Self {
        BinBuilder {
            bin: Vec::new(),
            views: Vec::new(),
            accessors: Vec::new(),
        }
    }

    pub(crate) fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        pad_to_4(&mut self.bin, 0);
        let mut v = json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// Adds an accessor and returns its index.
    pub(crate) fn accessor(&mut self, accessor: serde_json::Value) -> usize {
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// Float elements of `width` components (`type_`: `"SCALAR"`, `"VEC3"`, ...) as a vertex
    /// attribute (`attribute`) or as animation data; with their bounds when asked.
    pub(crate) fn floats(
        &mut self,
        data: &[f32],
        width: usize,
        type_: &str,
        with_bounds: bool,
    ) -> usize {
        self.floats_for(data, width, type_, with_bounds, Some(ARRAY_BUFFER))
    }

    pub(crate) fn floats_for(
        &mut self,
        data: &[f32],
        width: usize,
        type_: &str,
        with_bounds: bool,
        target: Option<u32>,
    ) -> usize {
        let view = self.view(&f32_bytes(data), target);
        let mut a = json!({"bufferView": view, "componentType": 5126, "count": data.len() / width, "type": type_});
        if with_bounds {
            let (lo, hi) = bounds(data, width);
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        self.accessor(a)
    }

    pub(crate) fn indices(&mut self, data: &[u32]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessor(json!({"bufferView": view, "componentType": 5125, "count": data.len(), "type": "SCALAR"}))
    }
}

/// A hand split into glTF vertices: one per distinct (mesh vertex, UV vertex) corner pair,
/// since glTF attributes are per vertex.
pub(crate) struct SplitVertices {
    /// The mesh vertex each glTF vertex copies.
    pub(crate) source: Vec<u32>,
    /// UVs (glTF convention, v = 0 at the top), when the hand has a layout.
    pub(crate) uvs: Option<Vec<f32>>,
    /// Triangle indices into the glTF vertices.
    pub(crate) indices: Vec<u32>,
}

impl SplitVertices {
    /// Splits `faces` at the seams of `uv`.
    pub(crate) fn new(num_vertices: usize, faces: &[[u32; 3]], uv: Option<&UvLayout>) -> Self {
        match uv {
            None => SplitVertices {
                source: (0..num_vertices as u32).collect(),
                uvs: None,
                indices: faces.iter().flatten().copied().collect(),
            },
            Some(uv) => {
                let mut map = std::collections::HashMap::new();
                let (mut source, mut tex, mut indices) = (Vec::new(), Vec::new(), Vec::new());
                for (f, t) in faces.iter().zip(&uv.faces) {
                    for k in 0..3 {
                        let next = map.len() as u32;
                        let i = *map.entry((f[k], t[k])).or_insert_with(|| {
                            source.push(f[k]);
                            let q: DVec2 = uv.uvs[t[k] as usize];
                            tex.extend([q.x as f32, 1.0 - q.y as f32]);
                            next
                        });
                        indices.push(i);
                    }
                }
                SplitVertices {
                    source,
                    uvs: Some(tex),
                    indices,
                }
            }
        }
    }

    /// Per-vertex values of the mesh (`[V]`) copied to the glTF vertices, flattened.
    pub(crate) fn gather(&self, values: &[DVec3]) -> Vec<f32> {
        self.source
            .iter()
            .flat_map(|&v| {
                let p = values[v as usize];
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect()
    }
}

/// The metallic-roughness material the avatar's hands get.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PbrMaterial {
    /// glTF `roughnessFactor` (0 mirror, 1 fully rough).
    pub roughness: f64,
    /// glTF `metallicFactor` (0 for skin, a dielectric).
    pub metallic: f64,
}

impl Default for PbrMaterial {
    /// A matte dielectric (roughness 0.8, metallic 0).
    fn default() -> Self {
        PbrMaterial {
            roughness: 0.8,
            metallic: 0.0,
        }
    }
}

/// The images, textures and materials of a glTF document being built.
#[derive(Default)]
pub(crate) struct Materials {
    pub(crate) materials: Vec<serde_json::Value>,
    pub(crate) textures: Vec<serde_json::Value>,
    pub(crate) images: Vec<serde_json::Value>,
}

impl Materials {
    /// Adds the material of a hand named `name`: `pbr` with the base colour `texture` (an
    /// sRGB PNG embedded in the binary chunk) or a skin tone; returns its index.
    pub(crate) fn add(
        &mut self,
        b: &mut BinBuilder,
        name: &str,
        texture: Option<&image::RgbImage>,
        pbr: &PbrMaterial,
    ) -> Result<usize, OutputError> {
        let mut material = json!({
            "name": name,
            "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.62, 0.52, 1.0], "metallicFactor": pbr.metallic, "roughnessFactor": pbr.roughness},
            "doubleSided": false
        });
        if let Some(img) = texture {
            let view = b.view(&png_bytes(img)?, None);
            self.images
                .push(json!({"bufferView": view, "mimeType": "image/png", "name": name}));
            self.textures
                .push(json!({"source": self.images.len() - 1, "sampler": 0}));
            material["pbrMetallicRoughness"]["baseColorFactor"] = json!([1.0, 1.0, 1.0, 1.0]);
            material["pbrMetallicRoughness"]["baseColorTexture"] =
                json!({"index": self.textures.len() - 1, "texCoord": 0});
        }
        self.materials.push(material);
        Ok(self.materials.len() - 1)
    }

    /// Puts the materials, textures, images and the sampler into `doc`.
    pub(crate) fn finish(self, doc: &mut serde_json::Value) {
        doc["materials"] = json!(self.materials);
        if !self.images.is_empty() {
            doc["images"] = json!(self.images);
            doc["textures"] = json!(self.textures);
            doc["samplers"] =
                json!([{"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071}]);
        }
    }
}

/// Rotation of pi about x as a glTF quaternion: (x, y, z) -> (x, -y, -z), OpenCV camera axes
/// to glTF's.
pub(crate) const OPENCV_TO_GLTF: [f64; 4] = [1.0, 0.0, 0.0, 0.0];

/// The glTF 2.0 binary (`.glb`) bytes of `hands`: one mesh and node per hand under a root
/// node converting OpenCV camera axes to glTF axes; textured hands get a PBR material whose
/// base colour is the embedded PNG.
pub fn glb_bytes(hands: &[ExportHand]) -> Result<Vec<u8>, OutputError> {
    glb_bytes_with_material(hands, &PbrMaterial::default())
}

/// [`glb_bytes`] with the hands' material.
pub(crate) fn glb_bytes_with_material(
    hands: &[ExportHand],
    pbr: &PbrMaterial,
) -> Result<Vec<u8>, OutputError> {
    let mut b = BinBuilder::new();
    let mut materials = Materials::default();
    let (mut meshes, mut nodes) = (vec![], vec![]);
    for h in hands {
        check_hand(h)?;
        let split = SplitVertices::new(h.vertices.len(), h.faces, h.uv);
        let normals = bitt_mesh::model::vertex_normals(h.vertices, h.faces);
        let mut attributes = json!({
            "POSITION": b.floats(&split.gather(h.vertices), 3, "VEC3", true),
            "NORMAL": b.floats(&split.gather(&normals), 3, "VEC3", false),
        });
        if let Some(tex) = &split.uvs {
            attributes["TEXCOORD_0"] = json!(b.floats(tex, 2, "VEC2", false));
        }
        let material = materials.add(&mut b, h.name, h.texture, pbr)?;
        let primitive = json!({"attributes": attributes, "indices": b.indices(&split.indices), "mode": 4, "material": material});
        meshes.push(json!({"name": h.name, "primitives": [primitive]}));
        nodes.push(json!({"name": h.name, "mesh": meshes.len() - 1}));
    }
    let children: Vec<usize> = (1..=nodes.len()).collect();
    let root =
        json!({"name": "opencv_camera_to_gltf", "rotation": OPENCV_TO_GLTF, "children": children});
    let mut all_nodes = vec![root];
    all_nodes.extend(nodes);
    let mut doc = json!({
        "scene": 0,
        "scenes": [{"name": "hands", "nodes": [0]}],
        "nodes": all_nodes,
        "meshes": meshes,
    });
    materials.finish(&mut doc);
    assemble_glb(doc, b)
}

/// The `.glb` container of a glTF document `doc` (without `asset`, `accessors`,
/// `bufferViews` and `buffers`, which are added here) and its binary chunk.
pub(crate) fn assemble_glb(
    mut doc: serde_json::Value,
    mut b: BinBuilder,
) -> Result<Vec<u8>, OutputError> {
    pad_to_4(&mut b.bin, 0);
    doc["asset"] =
        json!({"version": "2.0", "generator": concat!("bitt ", env!("CARGO_PKG_VERSION"))});
    doc["accessors"] = json!(b.accessors);
    doc["bufferViews"] = json!(b.views);
    doc["buffers"] = json!([{"byteLength": b.bin.len()}]);
    let mut json_bytes =
        serde_json::to_vec(&doc).map_err(|e| OutputError::Invalid(format!("glTF JSON: {e}")))?;
    pad_to_4(&mut json_bytes, b' ');
    let total = 12 + 8 + json_bytes.len() + 8 + b.bin.len();
    let total = u32::try_from(total)
        .map_err(|_| OutputError::Invalid("glTF file would exceed 4 GiB".into()))?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(b.bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b.bin);
    Ok(out)
}

/// Writes `hands` as a `.glb` file (atomically).
pub(crate) fn write_glb(path: &Path, hands: &[ExportHand]) -> Result<(), OutputError> {
    Ok(bitt_stdx::write_atomically(path, &glb_bytes(hands)?)?)
}

/// Writes the posed hands (left then right, untextured, named `left_hand` and
/// `right_hand`) as an OBJ file and, with `glb`, also as a glTF binary.
///
/// # Errors
/// Unwritable files.
pub fn write_posed(
    posed: &PosedTwoHands,
    models: &HandPair,
    obj: &Path,
    glb: Option<&Path>,
) -> Result<(), OutputError> {
    let names = ["left_hand", "right_hand"];
    let hands: Vec<ExportHand> = Side::BOTH
        .iter()
        .zip(names)
        .filter_map(|(&side, name)| {
            let p = posed.get(side)?;
            let m = models.get(side);
            Some(ExportHand {
                name,
                vertices: &p.vertices,
                faces: &m.faces,
                uv: m.uv.as_ref(),
                texture: None,
            })
        })
        .collect();
    write_obj(obj, &hands)?;
    if let Some(glb) = glb {
        write_glb(glb, &hands)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> (Vec<DVec3>, Vec<[u32; 3]>, UvLayout) {
        let v = vec![DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        let f = vec![[0, 1, 2], [0, 2, 3]];
        // A seam: the second triangle uses its own copy of corner 0.
        let uv = UvLayout {
            uvs: vec![
                DVec2::ZERO,
                DVec2::X,
                DVec2::ONE,
                DVec2::Y,
                DVec2::new(0.0, 0.01),
            ],
            faces: vec![[0, 1, 2], [4, 2, 3]],
        };
        (v, f, uv)
    }

    #[test]
    fn obj_has_both_objects_with_offset_indices() {
        let (v, f, uv) = quad();
        let a = ExportHand {
            name: "left_hand",
            vertices: &v,
            faces: &f,
            uv: Some(&uv),
            texture: None,
        };
        let b = ExportHand {
            name: "right_hand",
            vertices: &v,
            faces: &f,
            uv: None,
            texture: None,
        };
        let s = obj_text(&[a, b], None).unwrap();
        assert!(s.contains("o left_hand\n") && s.contains("o right_hand\n"));
        assert_eq!(s.lines().filter(|l| l.starts_with("v ")).count(), 8);
        assert_eq!(s.lines().filter(|l| l.starts_with("vt ")).count(), 5);
        assert!(s.contains("f 1/5 3/3 4/4\n"), "{s}");
        assert!(s.contains("f 5 6 7\n"), "{s}");
    }

    #[test]
    fn glb_is_valid_gltf_with_split_seam_vertices() {
        let (v, f, uv) = quad();
        let tex = image::RgbImage::from_pixel(4, 4, image::Rgb([200, 150, 120]));
        let a = ExportHand {
            name: "left_hand",
            vertices: &v,
            faces: &f,
            uv: Some(&uv),
            texture: Some(&tex),
        };
        let bytes = glb_bytes(&[a]).unwrap();
        let g = gltf::Gltf::from_slice(&bytes).expect("valid glTF");
        let mesh = g.meshes().next().unwrap();
        let prim = mesh.primitives().next().unwrap();
        assert_eq!(
            prim.get(&gltf::Semantic::Positions).unwrap().count(),
            5,
            "seam splits one vertex"
        );
        assert_eq!(prim.indices().unwrap().count(), 6);
        assert!(
            prim.material()
                .pbr_metallic_roughness()
                .base_color_texture()
                .is_some()
        );
        assert_eq!(g.images().count(), 1);
    }

    #[test]
    fn bad_faces_are_rejected_before_writing() {
        let (v, _, _) = quad();
        let f = vec![[0, 1, 9]];
        let h = ExportHand {
            name: "h",
            vertices: &v,
            faces: &f,
            uv: None,
            texture: None,
        };
        let dir = std::env::temp_dir().join(format!("bitt-export-{}", std::process::id()));
        let path = dir.join("bad.obj");
        assert!(write_obj(&path, &[h]).is_err());
        assert!(!path.exists(), "nothing half-written");
    }

    #[test]
    fn obj_outputs_never_replace_users_files_and_name_companions_without_spaces() {
        let (v, f, uv) = quad();
        let tex = image::RgbImage::from_pixel(4, 4, image::Rgb([200, 150, 120]));
        let hands = [
            ExportHand {
                name: "left_hand",
                vertices: &v,
                faces: &f,
                uv: Some(&uv),
                texture: Some(&tex),
            },
            ExportHand {
                name: "right_hand",
                vertices: &v,
                faces: &f,
                uv: Some(&uv),
                texture: Some(&tex),
            },
        ];
        let tmp = std::env::temp_dir().join(format!("bitt-obj-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir_all(&tmp).unwrap();
        let listing = || {
            let mut names: Vec<String> = std::fs::read_dir(&tmp)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            names.sort();
            names
        };

        // A space in the name: the companions' names have none (OBJ splits `mtllib` there).
        let obj = tmp.join("my hand.obj");
        write_obj(&obj, &hands).unwrap();
        let text = std::fs::read_to_string(&obj).unwrap();
        assert!(text.contains("\nmtllib my_hand.mtl\n"), "{text}");
        let mtl = std::fs::read_to_string(tmp.join("my_hand.mtl")).unwrap();
        assert!(mtl.starts_with(WRITTEN_BY));
        assert!(mtl.contains("map_Kd my_hand_left_hand.png\n"), "{mtl}");
        assert_eq!(
            listing(),
            [
                "my hand.obj",
                "my_hand.mtl",
                "my_hand_left_hand.png",
                "my_hand_right_hand.png"
            ]
        );
        // Written again over its own output: fine.
        write_obj(&obj, &hands).unwrap();

        // A user's own MTL, PNG or OBJ of those names: refused, nothing written or touched.
        for (user_file, bytes) in [
            ("m.mtl", &b"newmtl mine\n"[..]),
            ("m_right_hand.png", &b"\x89PNG my picture"[..]),
            ("m.obj", &b"o my_mesh\nv 0 0 0\n"[..]),
        ] {
            let before = listing();
            std::fs::write(tmp.join(user_file), bytes).unwrap();
            let e = write_obj(&tmp.join("m.obj"), &hands)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(user_file) && e.contains("nothing was written"),
                "{e}"
            );
            assert_eq!(std::fs::read(tmp.join(user_file)).unwrap(), bytes);
            let mut expected = before.clone();
            expected.push(user_file.to_string());
            expected.sort();
            assert_eq!(listing(), expected, "only the user's file is new");
            std::fs::remove_file(tmp.join(user_file)).unwrap();
        }

        // A writer killed before its rename left a temporary: the next write removes it (no
        // process has that id: ids are below 2^22 on Linux).
        let stale = tmp.join(".my hand.obj.tmp4999999");
        std::fs::write(&stale, b"half").unwrap();
        write_obj(&obj, &hands).unwrap();
        if Path::new("/proc/self").exists() {
            assert!(!stale.exists(), "a dead writer's temporary is removed");
        }
        std::fs::remove_dir_all(&tmp).unwrap();
    }

    /// A one-hand scene writes an OBJ with only that hand and a GLB beside it.
    #[test]
    fn posed_hands_write_obj_and_glb() {
        let models = bitt_mesh::procedural_pair();
        let posed = PosedTwoHands {
            left: None,
            right: Some(
                models
                    .right
                    .forward(&bitt_mesh::HandParams::mean_pose())
                    .unwrap(),
            ),
        };
        let dir = std::env::temp_dir().join(format!("bitt-posed-write-{}", std::process::id()));
        let (obj, glb) = (dir.join("h.obj"), dir.join("h.glb"));
        write_posed(&posed, &models, &obj, Some(&glb)).unwrap();
        let text = std::fs::read_to_string(&obj).unwrap();
        assert!(text.contains("right_hand") && !text.contains("left_hand"));
        let vertices = text.lines().filter(|l| l.starts_with("v ")).count();
        assert_eq!(vertices, models.right.num_vertices());
        assert!(std::fs::read(&glb).unwrap().starts_with(b"glTF"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
