//! Texture images on disk.
//!
//! Images in memory are planar `[3, H, W]` `f32` arrays in `[0, 1]`, row 0 the top row (what
//! [`TextureLayout::compact_to_image`] makes). They are written as 8-bit or 16-bit RGB PNG
//! and read back from PNG or JPEG (any bit depth, converted to RGB). Compact textures
//! round-trip exactly through safetensors ([`save_compact_texture`]).
//! Every write is atomic (a temporary file renamed into place); errors name the file.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::Path;

use bitt_stdx::FileErrorExt;
use image::{ImageBuffer, ImageFormat, Rgb};
use safetensors::Dtype;

use crate::TextureError;
use crate::layout::TextureLayout;
use crate::st;

/// The `format` metadata of a compact texture safetensors file.
pub(crate) const COMPACT_TEXTURE_FORMAT: &str = "bitt-compact-texture";

/// A planar RGB image: `data` is `[3, H, W]` (channel-major, row 0 = top) in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `[3, H, W]` values.
    pub data: Vec<f32>,
}

/// Mean and largest absolute difference of two images of one size, and each image's mean
/// (over every channel value).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageDifference {
    /// Mean of `|a - b|`.
    pub mean_abs_diff: f64,
    /// Largest `|a - b|`.
    pub max_abs_diff: f64,
    /// Mean of `a`.
    pub mean_a: f64,
    /// Mean of `b`.
    pub mean_b: f64,
}

impl ImageDifference {
    /// The difference of `a` and `b`; `None` when their sizes differ.
    pub fn between(a: &PlanarImage, b: &PlanarImage) -> Option<Self> {
        if (a.width, a.height) != (b.width, b.height) {
            return None;
        }
        let n = a.data.len().max(1) as f64;
        let (sum, max) = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| f64::from((x - y).abs()))
            .fold((0.0, 0.0f64), |(s, m), d| (s + d, m.max(d)));
        let mean = |d: &[f32]| d.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
        Some(ImageDifference {
            mean_abs_diff: sum / n,
            max_abs_diff: max,
            mean_a: mean(&a.data),
            mean_b: mean(&b.data),
        })
    }
}

/// Checks an image array and converts it to interleaved `[H, W, 3]` integers with
/// `round(x * max)` after clamping to `[0, 1]`.
fn interleave<T>(
    path: &Path,
    image: &[f32],
    width: usize,
    height: usize,
    max: f32,
    cast: impl Fn(f32) -> T,
) -> Result<(u32, u32, Vec<T>), TextureError> {
    let hw = width
        .checked_mul(height)
        .filter(|&n| n > 0)
        .ok_or_else(|| TextureError::Invalid(format!("{}: empty image size", path.display())))?;
    let (w, h) = match (u32::try_from(width), u32::try_from(height)) {
        (Ok(w), Ok(h)) => (w, h),
        _ => {
            return Err(TextureError::Invalid(format!(
                "{}: image size {width}x{height} is too large",
                path.display()
            )));
        }
    };
    if image.len() != 3 * hw {
        return Err(TextureError::Invalid(format!(
            "{}: image has {} values, expected 3 x {height} x {width}",
            path.display(),
            image.len()
        )));
    }
    if let Some(i) = image.iter().position(|x| x.is_nan()) {
        return Err(TextureError::Invalid(format!(
            "{}: image value {i} (channel {}, row {}, col {}) is NaN",
            path.display(),
            i / hw,
            (i % hw) / width,
            i % width
        )));
    }
    let mut out = Vec::with_capacity(3 * hw);
    for p in 0..hw {
        for c in 0..3 {
            out.push(cast((image[c * hw + p].clamp(0.0, 1.0) * max).round()));
        }
    }
    Ok((w, h, out))
}

fn write_png<P>(path: &Path, buf: ImageBuffer<P, Vec<P::Subpixel>>) -> Result<(), TextureError>
where
    P: image::Pixel + image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
{
    let mut bytes = Vec::new();
    buf.write_to(&mut Cursor::new(&mut bytes), ImageFormat::Png)
        .map_err(|e| TextureError::format(path, format!("cannot encode PNG: {e}")))?;
    bitt_stdx::write_atomically(path, &bytes)?;
    Ok(())
}

/// Writes a `[3, H, W]` image in `[0, 1]` as an 8-bit RGB PNG (values clamped, rounded to
/// the nearest of 256 levels). Fails on a wrong length or NaN.
pub fn save_png8(
    path: &Path,
    image: &[f32],
    width: usize,
    height: usize,
) -> Result<(), TextureError> {
    let (w, h, px) = interleave(path, image, width, height, 255.0, |x| x as u8)?;
    let buf = ImageBuffer::<Rgb<u8>, Vec<u8>>::from_raw(w, h, px)
        .ok_or_else(|| TextureError::Invalid(format!("{}: bad image buffer", path.display())))?;
    write_png(path, buf)
}

/// Writes a `[3, H, W]` image in `[0, 1]` as a 16-bit RGB PNG (values clamped, rounded to
/// the nearest of 65536 levels). Fails on a wrong length or NaN.
pub fn save_png16(
    path: &Path,
    image: &[f32],
    width: usize,
    height: usize,
) -> Result<(), TextureError> {
    let (w, h, px) = interleave(path, image, width, height, 65535.0, |x| x as u16)?;
    let buf = ImageBuffer::<Rgb<u16>, Vec<u16>>::from_raw(w, h, px)
        .ok_or_else(|| TextureError::Invalid(format!("{}: bad image buffer", path.display())))?;
    write_png(path, buf)
}

/// Why a JPEG's bytes are cut short, if they are: the last scan (`FF DA`) must be followed by
/// the end-of-image marker (`FF D9`). The decoder fills a cut-off scan with grey without an
/// error; entropy-coded data cannot hold `FF D9` (a data `FF` is written `FF 00`), and
/// thumbnails in the metadata come before the main image's scans, so the check sees only
/// the image itself (and, for multi-picture files, the last appended one). `None` for data
/// that is not a JPEG.
fn jpeg_truncation(bytes: &[u8]) -> Option<String> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return None;
    }
    let marker = |m: u8| bytes.windows(2).rposition(|w| w[0] == 0xFF && w[1] == m);
    match (marker(0xDA), marker(0xD9)) {
        (None, _) => {
            Some("truncated JPEG: it holds no image data (no start-of-scan marker)".into())
        }
        (Some(scan), end) if end.is_none_or(|e| e < scan) => Some(format!(
            "truncated JPEG: its image data stops at byte {} without the end-of-image marker \
             (the file was cut short)",
            bytes.len()
        )),
        _ => None,
    }
}

/// Reads a PNG or JPEG (format guessed from the content) as a planar `[3, H, W]` image in
/// `[0, 1]` (8-bit values `x / 255`, 16-bit `x / 65535`; grey and alpha images are
/// converted to RGB, alpha dropped).
pub fn load_image(path: &Path) -> Result<PlanarImage, TextureError> {
    let bytes = st::read_file(path)?;
    if let Some(problem) = jpeg_truncation(&bytes) {
        return Err(TextureError::format(path, problem));
    }
    let img = image::ImageReader::new(Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| TextureError::io(path, e))?
        .decode()
        .map_err(|e| TextureError::format(path, format!("cannot decode image: {e}")))?;
    drop(bytes);
    let rgb = img.to_rgb32f();
    let (width, height) = (rgb.width() as usize, rgb.height() as usize);
    let hw = width * height;
    let raw = rgb.into_raw();
    let mut data = vec![0f32; 3 * hw];
    for (p, px) in raw.chunks_exact(3).enumerate() {
        for (c, &v) in px.iter().enumerate() {
            data[c * hw + p] = v;
        }
    }
    Ok(PlanarImage {
        width,
        height,
        data,
    })
}

/// Writes a compact texture `[3, T]` of `layout` exactly (`f32`) as safetensors: tensor
/// `texture` `[3, T]`, metadata `format`, `width`, `height`, `num_texels` and the layout's
/// [`TextureLayout::fingerprint`] (hex). Atomic. Fails on a wrong length.
pub fn save_compact_texture(
    path: &Path,
    layout: &TextureLayout,
    texture: &[f32],
) -> Result<(), TextureError> {
    let t = layout.num_texels();
    if texture.len() != 3 * t {
        return Err(TextureError::Invalid(format!(
            "{}: compact texture has {} values, expected 3 x {t}",
            path.display(),
            texture.len()
        )));
    }
    let entries = vec![(
        "texture".to_string(),
        Dtype::F32,
        vec![3, t],
        st::f32_bytes(texture),
    )];
    let meta = HashMap::from([
        ("format".to_string(), COMPACT_TEXTURE_FORMAT.to_string()),
        ("width".to_string(), layout.width.to_string()),
        ("height".to_string(), layout.height.to_string()),
        ("num_texels".to_string(), t.to_string()),
        (
            "layout_fingerprint".to_string(),
            format!("{:016x}", layout.fingerprint()),
        ),
    ]);
    Ok(st::write(path, &entries, meta)?)
}

/// Reads a compact texture written by [`save_compact_texture`] for `layout` (`[3T]`,
/// bit-exact). Fails when the file belongs to another layout (size, texel count or
/// fingerprint differ) or is not such a file.
pub fn load_compact_texture(path: &Path, layout: &TextureLayout) -> Result<Vec<f32>, TextureError> {
    let bytes = st::read_file(path)?;
    let r = st::Reader::new(&bytes, path, COMPACT_TEXTURE_FORMAT)?;
    let width: usize = r.meta("width")?;
    let height: usize = r.meta("height")?;
    let t: usize = r.meta("num_texels")?;
    let fp: String = r.meta("layout_fingerprint")?;
    if (width, height, t) != (layout.width, layout.height, layout.num_texels())
        || fp != format!("{:016x}", layout.fingerprint())
    {
        return Err(r
            .err(format!(
                "texture is for a {width}x{height} layout with {t} texels (fingerprint {fp}), not \
             this {}x{} layout with {} texels (fingerprint {:016x})",
                layout.width,
                layout.height,
                layout.num_texels(),
                layout.fingerprint()
            ))
            .into());
    }
    let (_, v) = r.values::<f32>("texture", &[Some(3), Some(t)])?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The difference of two 1x2 images, and `None` for two sizes.
    #[test]
    fn image_difference() {
        let image = |width, data: Vec<f32>| PlanarImage {
            width,
            height: 1,
            data,
        };
        let a = image(2, vec![0.0, 1.0, 0.5, 0.5, 0.25, 0.75]);
        let b = image(2, vec![0.5, 1.0, 0.5, 0.0, 0.25, 0.75]);
        let d = ImageDifference::between(&a, &b).unwrap();
        assert_eq!(d.mean_abs_diff, 1.0 / 6.0);
        assert_eq!(d.max_abs_diff, 0.5);
        assert_eq!(d.mean_a, 0.5);
        assert_eq!(d.mean_b, 0.5);
        assert_eq!(ImageDifference::between(&a, &image(3, vec![0.0; 9])), None);
    }
    use bitt_testkit::Rng;

    use crate::test_util::temp_dir;

    /// A JPEG cut in half decodes without an error (the decoder fills the rest with grey), so
    /// it is refused by its missing end-of-image marker; the whole file still reads.
    #[test]
    fn a_truncated_jpeg_is_refused() {
        let dir = temp_dir("jpeg-cut");
        let (w, h) = (64u32, 48u32);
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            image::Rgb([(x * 4) as u8, (y * 5) as u8, ((x + y) * 2) as u8])
        });
        let mut bytes = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 90)
            .encode_image(&img)
            .unwrap();
        let whole = dir.join("whole.jpg");
        std::fs::write(&whole, &bytes).unwrap();
        let read = load_image(&whole).unwrap();
        assert_eq!((read.width, read.height), (64, 48));
        let cut = dir.join("cut.jpg");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        let e = load_image(&cut).unwrap_err().to_string();
        assert!(e.contains("cut.jpg") && e.contains("truncated JPEG"), "{e}");
        // Trailing bytes after the end marker (some cameras add them) are fine.
        let trailing = dir.join("trailing.jpg");
        let mut more = bytes.clone();
        more.extend_from_slice(b"trailer");
        std::fs::write(&trailing, &more).unwrap();
        assert!(load_image(&trailing).is_ok());
    }

    fn pattern(w: usize, h: usize, seed: u64) -> Vec<f32> {
        let mut r = Rng::new(seed);
        (0..3 * w * h).map(|_| r.uniform_f32(0.0, 1.0)).collect()
    }

    #[test]
    fn png_round_trips_within_quantisation() {
        let dir = temp_dir("png");
        let (w, h) = (7, 5);
        let img = pattern(w, h, 1);
        for (bits, levels) in [(8, 255.0f32), (16, 65535.0)] {
            let p = dir.join(format!("t{bits}.png"));
            if bits == 8 {
                save_png8(&p, &img, w, h).unwrap();
            } else {
                save_png16(&p, &img, w, h).unwrap();
            }
            let back = load_image(&p).unwrap();
            assert_eq!((back.width, back.height), (w, h));
            for (a, b) in img.iter().zip(&back.data) {
                // The nearest level.
                assert!((a - b).abs() <= 0.5 / levels + 1e-7);
            }
            // Orientation: channel 1, row 4, col 6 is pixel (x 6, y 4) of the file.
            let file = image::open(&p).unwrap().to_rgb32f();
            assert_eq!(file.get_pixel(6, 4)[1], back.data[w * h + 4 * w + 6]);
        }
        // Values outside [0, 1] are clamped.
        let mut out = img.clone();
        out[0] = -3.0;
        out[1] = 7.0;
        let p = dir.join("clamped.png");
        save_png16(&p, &out, w, h).unwrap();
        let back = load_image(&p).unwrap();
        assert_eq!((back.data[0], back.data[1]), (0.0, 1.0));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn jpeg_loads_as_planar_rgb() {
        let dir = temp_dir("jpeg");
        let (w, h) = (16, 8);
        // A flat colour survives JPEG almost exactly.
        let buf = ImageBuffer::<Rgb<u8>, Vec<u8>>::from_fn(w as u32, h as u32, |_, _| {
            Rgb([200, 100, 50])
        });
        let p = dir.join("flat.jpg");
        buf.save_with_format(&p, ImageFormat::Jpeg).unwrap();
        let img = load_image(&p).unwrap();
        assert_eq!((img.width, img.height, img.data.len()), (w, h, 3 * w * h));
        for (c, want) in [200.0f32, 100.0, 50.0].iter().enumerate() {
            for v in &img.data[c * w * h..(c + 1) * w * h] {
                assert!(
                    (v * 255.0 - want).abs() <= 3.0,
                    "channel {c}: {}",
                    v * 255.0
                );
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn bad_images_are_refused_with_the_file_name() {
        let dir = temp_dir("badimg");
        let p = dir.join("x.png");
        let mut img = pattern(3, 2, 2);
        let e = save_png8(&p, &img[..17], 3, 2).unwrap_err().to_string();
        assert!(e.contains("x.png") && e.contains("17 values"), "{e}");
        img[7] = f32::NAN;
        let e = save_png16(&p, &img, 3, 2).unwrap_err().to_string();
        assert!(
            e.contains("x.png") && e.contains("NaN") && e.contains("channel 1, row 0, col 1"),
            "{e}"
        );
        assert!(!p.exists());
        let e = save_png8(&p, &[], 0, 2).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");
        let junk = dir.join("junk.png");
        std::fs::write(&junk, b"\x89PNG\r\n\x1a\nnot really").unwrap();
        let e = load_image(&junk).unwrap_err();
        assert!(
            matches!(e, TextureError::File(bitt_stdx::FileError::Format { .. })),
            "{e}"
        );
        assert!(e.to_string().contains("junk.png"));
        let e = load_image(&dir.join("absent.png")).unwrap_err();
        assert!(
            matches!(e, TextureError::File(bitt_stdx::FileError::Io { .. }))
                && e.to_string().contains("absent.png")
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn compact_textures_round_trip_exactly() {
        let dir = temp_dir("compact");
        let layout = TextureLayout::from_texels(4, 3, vec![(0, 1), (2, 3), (1, 0)], None).unwrap();
        let tex = vec![
            0.1f32,
            1.0 / 3.0,
            f32::MIN_POSITIVE,
            0.999_999_9,
            -0.0,
            1e-30,
            0.5,
            0.25,
            0.7,
        ];
        let p = dir.join("t.safetensors");
        save_compact_texture(&p, &layout, &tex).unwrap();
        let back = load_compact_texture(&p, &layout).unwrap();
        assert_eq!(
            back.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            tex.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        // Another layout with the same size and texel count is told apart.
        let other = TextureLayout::from_texels(4, 3, vec![(0, 1), (2, 3), (1, 1)], None).unwrap();
        let e = load_compact_texture(&p, &other).unwrap_err().to_string();
        assert!(
            e.contains("t.safetensors") && e.contains("fingerprint"),
            "{e}"
        );
        let e = save_compact_texture(&p, &layout, &tex[..8])
            .unwrap_err()
            .to_string();
        assert!(e.contains("8 values"), "{e}");
        let bytes = std::fs::read(&p).unwrap();
        let cut = dir.join("cut.safetensors");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        let e = load_compact_texture(&cut, &layout).unwrap_err().to_string();
        assert!(
            e.contains("cut.safetensors") && e.contains("not a safetensors"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
