//! Writing a run's files: images, textures, light, glTF avatar, loss plot, metrics and the
//! self-contained HTML report. Every file is written atomically.

use std::path::Path;

use crate::export::{ExportHand, glb_bytes, png_bytes};
use bitt_stdx::write_atomically;
use bitt_texture::TextureLayout;

use crate::OutputError;
pub use crate::plot::write_loss_plot;
use bitt_stdx::FileErrorExt;

/// `[3, H, W]` values in `[0, 1]` to an 8-bit RGB image (non-finite values are an error).
pub fn rgb_image(values: &[f32], h: usize, w: usize) -> Result<image::RgbImage, OutputError> {
    if values.len() != 3 * h * w {
        return Err(OutputError::Invalid(format!(
            "image has {} values, expected 3 x {h} x {w}",
            values.len()
        )));
    }
    if values.iter().any(|v| !v.is_finite()) {
        return Err(OutputError::NonFinite("image to write".into()));
    }
    let hw = h * w;
    let mut img = image::RgbImage::new(w as u32, h as u32);
    for (i, px) in img.pixels_mut().enumerate() {
        for ch in 0..3 {
            px.0[ch] = (values[ch * hw + i].clamp(0.0, 1.0) * 255.0).round() as u8;
        }
    }
    Ok(img)
}

/// The first 8 bytes of every PNG file.
pub(crate) const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// Writes `[3, H, W]` values as a PNG.
pub fn write_png(path: &Path, values: &[f32], h: usize, w: usize) -> Result<(), OutputError> {
    // An existing file that is not a PNG (a user's, named by mistake) is not replaced.
    bitt_stdx::check_replaceable(path, PNG_SIGNATURE, "PNG")?;
    let img = rgb_image(values, h, w)?;
    write_atomically(path, &png_bytes(&img)?)?;
    Ok(())
}

/// A grey `[1, H, W]`-style mask as a `[3, H, W]` image.
pub fn mask_rgb(mask: &[f32]) -> Vec<f32> {
    mask.iter().chain(mask).chain(mask).copied().collect()
}

/// A compact texture `[3, T]` as a UV image `[3, S, S]` (unused texels black).
pub fn texture_image(layout: &TextureLayout, compact: &[f32]) -> Result<Vec<f32>, OutputError> {
    Ok(layout.compact_to_image(compact, [0.0; 3])?)
}

/// Panels `[3, h, w]` side by side in rows of `columns` (grey background).
pub fn contact_sheet(
    panels: &[Vec<f32>],
    h: usize,
    w: usize,
    columns: usize,
) -> (Vec<f32>, usize, usize) {
    contact_sheet_on(panels, h, w, columns, 0.2)
}

/// [`contact_sheet`] on a `background` of that value in every channel (also the cells of
/// the last row no panel fills): `(image [3, gh, gw], gh, gw)`.
pub fn contact_sheet_on(
    panels: &[Vec<f32>],
    h: usize,
    w: usize,
    columns: usize,
    background: f32,
) -> (Vec<f32>, usize, usize) {
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns).max(1);
    let (gh, gw) = (rows * h, columns * w);
    let mut out = vec![background; 3 * gh * gw];
    for (k, p) in panels.iter().enumerate() {
        let (r0, c0) = ((k / columns) * h, (k % columns) * w);
        for ch in 0..3 {
            for r in 0..h {
                for c in 0..w {
                    out[ch * gh * gw + (r0 + r) * gw + c0 + c] = p[ch * h * w + r * w + c];
                }
            }
        }
    }
    (out, gh, gw)
}

/// Sets every channel of the texels of a compact texture `[3, T]` that `visible` marks
/// hidden to `value` (a figure's way of showing which texels an image did not see).
pub fn fill_hidden_texels(texels: &mut [f32], visible: &[bool], value: f32) {
    let t = visible.len();
    for (k, _) in visible.iter().enumerate().filter(|(_, v)| !**v) {
        for c in 0..3 {
            texels[c * t + k] = value;
        }
    }
}

/// Both hands as a textured glTF binary (`avatar.glb`).
pub fn write_avatar_glb(
    path: &Path,
    hands: &[(
        &str,
        &[bitt_mesh::glam::DVec3],
        &bitt_mesh::HandModel,
        &image::RgbImage,
    ); 2],
) -> Result<(), OutputError> {
    let export: Vec<ExportHand> = hands
        .iter()
        .map(|(name, vertices, model, texture)| ExportHand {
            name,
            vertices,
            faces: &model.faces,
            uv: model.uv.as_ref(),
            texture: Some(texture),
        })
        .collect();
    write_atomically(path, &glb_bytes(&export)?)?;
    Ok(())
}

/// Writes JSON (pretty) atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), OutputError> {
    write_atomically(path, &json_bytes(path, value)?)?;
    Ok(())
}

/// `value` as the pretty JSON [`write_json`] writes (`path` names the file in the error).
pub fn json_bytes<T: serde::Serialize>(path: &Path, value: &T) -> Result<Vec<u8>, OutputError> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| OutputError::format(path, format!("cannot encode JSON: {e}")))?;
    Ok(text.into_bytes())
}

/// `[3, H, W]` values as the PNG bytes [`write_png`] writes.
pub fn png_file_bytes(values: &[f32], h: usize, w: usize) -> Result<Vec<u8>, OutputError> {
    png_bytes(&rgb_image(values, h, w)?)
}

/// Writes the output folder of a command (`fit-hands`, `refine-hands`, `detect-hands`) as a
/// whole ([`bitt_stdx::write_folder_atomically`]): a kill leaves the earlier folder or
/// the new one, never a mix of the two. `names` are all the names the command writes (the
/// `files` are some of them), `marker` the one that marks its output. An existing folder is
/// replaced only when it is ours ([`check_own_folder`]); anything else is refused.
///
/// # Errors
/// A folder that is not ours, or a write failure (naming the path).
pub fn write_own_folder(
    out: &Path,
    marker: &str,
    command: &str,
    names: &[&str],
    files: &[(String, Vec<u8>)],
) -> Result<(), OutputError> {
    check_own_folder(out, marker, command, names)?;
    bitt_stdx::write_folder_atomically(out, files, |d| only_names(d, marker, names))?;
    Ok(())
}

/// Whether the folder `dir` holds `marker`, or nothing but files named in `names` (a folder
/// an older version left half-written when it was killed).
fn only_names(dir: &Path, marker: &str, names: &[&str]) -> bool {
    if dir.join(marker).is_file() {
        return true;
    }
    std::fs::read_dir(dir).is_ok_and(|entries| {
        entries.flatten().all(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            e.path().is_file() && names.contains(&name.as_str())
        })
    })
}

/// The JSON file at `path`, or `None` when there is no file.
///
/// # Errors
/// A file that is there but cannot be read or is not JSON (naming it).
pub fn read_json_if_present(path: &Path) -> Result<Option<serde_json::Value>, OutputError> {
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|e| OutputError::io(path, e))?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| OutputError::format(path, format!("not JSON: {e}")))
}

/// Base64 of bytes (for images embedded in the HTML report).
pub fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(T[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The enlargement of an overlay drawn on an image `width` pixels wide: at least 512 wide.
pub fn overlay_scale(width: usize) -> usize {
    512usize.div_ceil(width.max(1)).clamp(1, 8)
}

/// Refuses an output folder that exists, is not empty and holds no `marker` file (so is not an
/// earlier output of `command`) nor only files of the command's `names`: nothing of the
/// user's is overwritten.
///
/// # Errors
/// [`OutputError::Invalid`] naming the folder.
pub fn check_own_folder(
    out: &Path,
    marker: &str,
    command: &str,
    names: &[&str],
) -> Result<(), OutputError> {
    if out.is_dir() {
        let mut entries = std::fs::read_dir(out).map_err(|e| OutputError::io(out, e))?;
        if entries.next().is_some() && !only_names(out, marker, names) {
            return Err(OutputError::Invalid(format!(
                "{}: the folder exists and is not a {command} output (no {marker}); choose \
                 another --out",
                out.display()
            )));
        }
    } else if out.exists() {
        return Err(OutputError::Invalid(format!(
            "{}: exists and is not a folder",
            out.display()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 38, class 9: a command's folder appears whole, replaces its own earlier output
    /// as a whole (no new `hands.json` beside an old `fit.json`), takes over a folder an
    /// older version left half-written, and refuses a folder of the user's.
    #[test]
    fn command_folders_are_written_whole() {
        let tmp = std::env::temp_dir().join(format!("bitt-own-folder-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        let out = tmp.join("fit");
        const NAMES: [&str; 3] = ["hands.json", "overlay.png", "fit.json"];
        let files = |tag: &str, with_overlay: bool| {
            let mut f = vec![("hands.json".to_string(), tag.as_bytes().to_vec())];
            if with_overlay {
                f.push(("overlay.png".into(), b"png".to_vec()));
            }
            f.push(("fit.json".into(), tag.as_bytes().to_vec()));
            f
        };
        let listing = |d: &Path| {
            let mut n: Vec<String> = std::fs::read_dir(d)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        };
        write_own_folder(&out, "fit.json", "fit-hands", &NAMES, &files("one", true)).unwrap();
        assert_eq!(listing(&out), ["fit.json", "hands.json", "overlay.png"]);
        // Its own output is replaced as a whole: no file of the earlier one stays.
        write_own_folder(&out, "fit.json", "fit-hands", &NAMES, &files("two", false)).unwrap();
        assert_eq!(listing(&out), ["fit.json", "hands.json"]);
        assert_eq!(std::fs::read(out.join("fit.json")).unwrap(), b"two");
        assert_eq!(listing(&tmp), ["fit"], "no temporary folder is left");
        // A folder an older version left with hands.json only is taken over.
        std::fs::remove_file(out.join("fit.json")).unwrap();
        check_own_folder(&out, "fit.json", "fit-hands", &NAMES).unwrap();
        write_own_folder(&out, "fit.json", "fit-hands", &NAMES, &files("three", true)).unwrap();
        assert_eq!(std::fs::read(out.join("hands.json")).unwrap(), b"three");
        // A folder with anything else in it is the user's: refused, untouched.
        let mine = tmp.join("mine");
        std::fs::create_dir_all(&mine).unwrap();
        std::fs::write(mine.join("hands.json"), "mine").unwrap();
        std::fs::write(mine.join("notes.txt"), "mine").unwrap();
        let e = write_own_folder(&mine, "fit.json", "fit-hands", &NAMES, &files("x", true))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a fit-hands output"), "{e}");
        assert_eq!(std::fs::read(mine.join("hands.json")).unwrap(), b"mine");
        assert_eq!(listing(&mine), ["hands.json", "notes.txt"]);
        std::fs::remove_dir_all(&tmp).unwrap();
    }

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }

    #[test]
    fn contact_sheet_places_panels_row_by_row() {
        let panel = |v: f32| vec![v; 3 * 2 * 2];
        let (img, gh, gw) = contact_sheet_on(&[panel(1.0), panel(2.0), panel(3.0)], 2, 2, 2, 0.0);
        assert_eq!((gh, gw), (4, 4));
        // Channel 1, rows 0..4: [1 1 2 2], [1 1 2 2], [3 3 0 0], [3 3 0 0].
        let ch1 = &img[16..32];
        assert_eq!(&ch1[..4], &[1.0, 1.0, 2.0, 2.0]);
        assert_eq!(&ch1[8..12], &[3.0, 3.0, 0.0, 0.0]);
        let (grey, _, _) = contact_sheet(&[panel(1.0)], 2, 2, 2);
        assert_eq!(grey[2], 0.2);
    }

    #[test]
    fn hidden_texels_are_filled() {
        let mut t = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        fill_hidden_texels(&mut t, &[true, false], 0.25);
        assert_eq!(t, [1.0, 0.25, 3.0, 0.25, 5.0, 0.25]);
    }

    #[test]
    fn non_finite_images_are_refused() {
        assert!(rgb_image(&[f32::NAN, 0.0, 0.0], 1, 1).is_err());
        assert!(rgb_image(&[0.0; 2], 1, 1).is_err());
        let img = rgb_image(&[1.0, 0.5, 0.0], 1, 1).unwrap();
        assert_eq!(img.get_pixel(0, 0).0, [255, 128, 0]);
    }
}
