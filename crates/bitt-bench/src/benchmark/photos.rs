//! The real-photo benchmark (`bitt eval --photos`): photos of the same hands, each one the
//! input view once while every other is a novel pose, scored in the photo's own hand mask
//! (pixels whose mean RGB is above [`MASK_THRESHOLD`]) rather than in the meshes' silhouettes.

use bitt_stdx::FileErrorExt;
use std::path::{Path, PathBuf};

use super::SceneResult;
use bitt::BittError;
use bitt::metrics::{ImageMetrics, SsimWindow, detail_correlation, masked_image_metrics};
use bitt::real::{RealScene, RealView, annotation_view};
use bitt::refine::{MASK_THRESHOLD, holes, threshold_mask};
use bitt_stdx::WithContext;

/// A photo of the benchmark: the image and its hands (a BiTT annotation pickle or a
/// `hands.json` of `refine-hands` / `fit-hands`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Photo {
    /// The image (the annotation's camera is for its 256 x 256 crop).
    pub image: PathBuf,
    /// Its hands.
    pub annotation: PathBuf,
}

impl Photo {
    /// Parses `IMAGE:ANNOTATION`.
    ///
    /// # Errors
    /// No `:`, or an empty side.
    pub fn parse(s: &str) -> Result<Self, BittError> {
        match s.rsplit_once(':') {
            Some((image, annotation)) if !image.is_empty() && !annotation.is_empty() => Ok(Photo {
                image: image.into(),
                annotation: annotation.into(),
            }),
            _ => Err(BittError::Invalid(format!(
                "--photos {s}: expected IMAGE:ANNOTATION (a photo and its pickle or hands.json)"
            ))),
        }
    }

    /// The photo's file stem (`01` for `01.jpg`).
    pub fn name(&self) -> String {
        self.image.file_stem().map_or_else(
            || self.image.display().to_string(),
            |s| s.to_string_lossy().into(),
        )
    }
}

/// BiTT's fine textures `[3, T]` (left, right) on one scene and the texels its input view
/// shows, per hand.
pub type SceneTextures = ([Vec<f32>; 2], [Vec<bool>; 2]);

/// The photo-mask scores of one render against its photo.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotoMetrics {
    /// Over the photo's hand pixels (mean RGB above [`MASK_THRESHOLD`]); a hand pixel the
    /// render leaves uncovered counts as black.
    pub hand_mask: ImageMetrics,
    /// Over the pixels that are both rendered and hand in the photo (issue 34's table).
    pub rendered_and_hand: ImageMetrics,
    /// The fraction of the photo's hand pixels the render covers.
    pub coverage: f64,
    /// Holes: the fraction of the photo's hand pixels inside the rendered hands' outline
    /// that the render leaves uncovered ([`bitt::refine::holes`]).
    pub holes: f64,
    /// How much of the photo's fine detail (veins, hair, creases) the render has in place,
    /// over the pixels that are both rendered and hand ([`detail_correlation`]; issue 34).
    /// `None` in results made before it, or where there is too little to correlate.
    #[serde(default)]
    pub detail: Option<f64>,
    /// The pixels both rendered and hand, split by whether the texel drawn there was seen in
    /// the training photo ([`bitt::evaluate::seen_pixels`]; issue 34). `None` in results
    /// made before it.
    #[serde(default)]
    pub seen_split: Option<SeenSplit>,
}

/// [`PhotoMetrics::seen_split`]: where a novel pose shows the training photo's own skin and
/// where only what the method filled in.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SeenSplit {
    /// The fraction of the pixels both rendered and hand whose texel the training photo
    /// showed.
    pub seen_fraction: f64,
    /// Scores over those pixels (`None` when there are none).
    pub seen: Option<ImageMetrics>,
    /// Scores over the others.
    pub unseen: Option<ImageMetrics>,
}

/// A photo scene's scores per method: the input view and the mean over the other photos.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotoScores {
    /// The training photo.
    pub input_view: PhotoMetrics,
    /// Mean over the other photos (novel poses).
    pub novel_poses: Option<PhotoMetrics>,
    /// The method's albedo in shade against in the open, on the texels the training photo
    /// shows ([`bitt::evaluate::albedo_in_shade`], the training view's ambient occlusion):
    /// below 1 where the photo's shadows went into the texture. `None` in results made
    /// before it, or with too few texels in either class.
    #[serde(default)]
    pub albedo_in_shade: Option<f64>,
    /// Detail the method's texture added to its prior's on the palm-side texels neither
    /// hand's training photo shows ([`bitt::evaluate::unseen_detail`]; issue 34, palm).
    /// `None` for methods without a prior, and in results made before it.
    #[serde(default)]
    pub unseen_palm: Option<bitt::evaluate::UnseenDetail>,
}

/// The mean of several [`PhotoMetrics`] (`None` for none).
pub fn mean_photo_metrics(all: &[PhotoMetrics]) -> Option<PhotoMetrics> {
    let n = all.len() as f64;
    let mean = |f: &dyn Fn(&PhotoMetrics) -> f64| all.iter().map(f).sum::<f64>() / n;
    let hand: Vec<ImageMetrics> = all.iter().map(|m| m.hand_mask).collect();
    let both: Vec<ImageMetrics> = all.iter().map(|m| m.rendered_and_hand).collect();
    let splits: Option<Vec<SeenSplit>> = all.iter().map(|m| m.seen_split).collect();
    // Each part averaged over the photos that have pixels in it.
    let part = |splits: &[SeenSplit], f: &dyn Fn(&SeenSplit) -> Option<ImageMetrics>| {
        bitt::evaluate::mean_metrics(&splits.iter().filter_map(f).collect::<Vec<_>>())
    };
    Some(PhotoMetrics {
        hand_mask: bitt::evaluate::mean_metrics(&hand)?,
        rendered_and_hand: bitt::evaluate::mean_metrics(&both)?,
        coverage: mean(&|m| m.coverage),
        holes: mean(&|m| m.holes),
        detail: all
            .iter()
            .map(|m| m.detail)
            .sum::<Option<f64>>()
            .map(|s| s / n),
        seen_split: splits.map(|s| SeenSplit {
            seen_fraction: s.iter().map(|x| x.seen_fraction).sum::<f64>() / n,
            seen: part(&s, &|x| x.seen),
            unseen: part(&s, &|x| x.unseen),
        }),
    })
}

/// Scores `render` `[3, S, S]` against `photo` `[3, S, S]` in the photo's hand mask, with
/// `rendered` `[S, S]` the render's silhouette (either hand) and, when given, `seen` `[S, S]`
/// the pixels whose texel the training photo showed ([`bitt::evaluate::seen_pixels`]). `None`
/// when the photo has no hand pixel or the render covers none of them.
pub fn photo_metrics(
    render: &[f32],
    photo: &[f32],
    rendered: &[f32],
    seen: Option<&[bool]>,
    size: usize,
) -> Option<PhotoMetrics> {
    let hw = size * size;
    let hand = threshold_mask(photo, hw, MASK_THRESHOLD);
    let drawn: Vec<bool> = rendered.iter().map(|&m| m >= 0.5).collect();
    let both: Vec<f32> = hand
        .iter()
        .zip(&drawn)
        .map(|(&m, &d)| if m >= 0.5 && d { 1.0 } else { 0.0 })
        .collect();
    let dims = [3, size, size];
    let window = SsimWindow::PytorchMsssim;
    let hand_mask = masked_image_metrics(render, photo, &hand, dims, window)?;
    let rendered_and_hand = masked_image_metrics(render, photo, &both, dims, window)?;
    let hand_pixels = hand.iter().filter(|&&m| m >= 0.5).count() as f64;
    let covered = both.iter().filter(|&&m| m >= 0.5).count() as f64;
    let hand_bool: Vec<bool> = hand.iter().map(|&m| m >= 0.5).collect();
    let seen_split = seen.filter(|s| s.len() == hw).map(|seen| {
        let part = |want: bool| -> Vec<f32> {
            both.iter()
                .zip(seen)
                .map(|(&b, &s)| if b >= 0.5 && s == want { 1.0 } else { 0.0 })
                .collect()
        };
        let (on, off) = (part(true), part(false));
        SeenSplit {
            seen_fraction: on.iter().sum::<f32>() as f64 / covered,
            seen: masked_image_metrics(render, photo, &on, dims, window),
            unseen: masked_image_metrics(render, photo, &off, dims, window),
        }
    });
    Some(PhotoMetrics {
        hand_mask,
        rendered_and_hand,
        coverage: covered / hand_pixels,
        holes: holes(&drawn, &hand_bool, [size, size]),
        detail: detail_correlation(render, photo, &both, dims),
        seen_split,
    })
}

/// The scenes of the photo benchmark: scene `k` trains on photo `k`; every other photo is
/// one of its novel poses (named `pose_NN` by its index in `photos`).
///
/// # Errors
/// Fewer than two photos, or a photo that [`annotation_view`] refuses (naming it).
pub fn photo_scenes(
    photos: &[Photo],
    models: &bitt_mesh::HandPair,
    size: usize,
) -> Result<Vec<RealScene>, BittError> {
    if photos.len() < 2 {
        return Err(BittError::Invalid(format!(
            "--photos needs at least two photos of the same hands (got {}): each is scored as \
             a novel pose of the others",
            photos.len()
        )));
    }
    let views: Vec<RealView> = photos
        .iter()
        .map(|p| {
            annotation_view(&p.image, &p.annotation, models, size)
                .context_with(|| format!("photo {}", p.image.display()))
        })
        .collect::<Result<_, _>>()?;
    Ok((0..photos.len())
        .map(|k| RealScene {
            train: views[k].clone(),
            novel_views: Vec::new(),
            novel_poses: views
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != k)
                .map(|(j, v)| RealView {
                    name: format!("pose_{j:02}"),
                    ..v.clone()
                })
                .collect(),
        })
        .collect())
}

/// Which photos a photo scene trained on and was scored on.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PhotoNames {
    /// The training photo's name (file stem).
    pub train: String,
    /// The other photos' names.
    pub novel_poses: Vec<String>,
}

/// `textures/{id:016x}.safetensors`: BiTT's fine textures of a photo scene and the texels its
/// photo shows, for [`photo_consistency`].
pub fn scene_textures_path(out: &Path, id: u64) -> PathBuf {
    out.join("textures").join(format!("{id:016x}.safetensors"))
}

/// Writes a photo scene's [`SceneTextures`] ([`scene_textures_path`]).
///
/// # Errors
/// Mismatched lengths, or a write failure.
pub fn write_scene_textures(
    out: &Path,
    id: u64,
    textures: &SceneTextures,
) -> Result<(), BittError> {
    let (fine, visible) = textures;
    let t = visible[0].len();
    if fine.iter().any(|f| f.len() != 3 * t) || visible[1].len() != t {
        return Err(BittError::Invalid(format!(
            "scene {id:016x}: textures of {} / {} values for {t} texels",
            fine[0].len(),
            fine[1].len()
        )));
    }
    let path = scene_textures_path(out, id);
    let dir = out.join("textures");
    std::fs::create_dir_all(&dir).map_err(|e| BittError::io(&dir, e))?;
    let mut entries: Vec<bitt_stdx::st::Entry> = Vec::new();
    for (k, side) in ["left", "right"].into_iter().enumerate() {
        entries.push((
            format!("fine.{side}"),
            safetensors::Dtype::F32,
            vec![3, t],
            bitt_stdx::st::f32_bytes(&fine[k]),
        ));
        let v: Vec<f32> = visible[k].iter().map(|&b| f32::from(u8::from(b))).collect();
        entries.push((
            format!("visible.{side}"),
            safetensors::Dtype::F32,
            vec![t],
            bitt_stdx::st::f32_bytes(&v),
        ));
    }
    let meta = std::collections::HashMap::from([(
        "format".to_string(),
        "bitt-eval-photo-textures: `fine.SIDE` [3, T] BiTT's fine texture, `visible.SIDE` [T] \
         1 where the training photo shows the texel"
            .to_string(),
    )]);
    Ok(bitt_stdx::st::write(&path, &entries, meta)?)
}

/// Reads [`write_scene_textures`]' file.
///
/// # Errors
/// An unreadable or corrupt file (named).
pub fn read_scene_textures(path: &Path) -> Result<SceneTextures, BittError> {
    let bytes = bitt_stdx::st::read_file(path)?;
    let r = bitt_stdx::st::Reader::open(&bytes, path)?;
    let (shape, left) = r.finite_f32s("fine.left", Some(&[Some(3), None]))?;
    let t = shape[1];
    let (_, right) = r.finite_f32s("fine.right", Some(&[Some(3), Some(t)]))?;
    let mask = |name: &str| -> Result<Vec<bool>, BittError> {
        Ok(r.finite_f32s(name, Some(&[Some(t)]))?
            .1
            .iter()
            .map(|&v| v > 0.5)
            .collect())
    };
    Ok((
        [left, right],
        [mask("visible.left")?, mask("visible.right")?],
    ))
}

/// Two photos' BiTT textures compared on the texels both photos show (issue 34,
/// consistency): the same hands should get the same albedo.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotoConsistency {
    /// The two photos' names.
    pub photos: [String; 2],
    /// Texels (both hands together) both photos show.
    pub shared_texels: usize,
    /// Mean absolute difference on them (all channels).
    pub l1: Option<f64>,
    /// The same after one gain per colour channel fitted from the first photo's texture to
    /// the second's (a light the networks split differently into albedo and light).
    pub l1_gain_fitted: Option<f64>,
}

/// Every pair of photo scenes in `results` whose textures are in `out` (in the order of their
/// photos' names): how far their BiTT textures differ on the texels both photos show. Pairs
/// without texture files are skipped.
///
/// # Errors
/// A corrupt texture file.
pub fn photo_consistency(
    out: &Path,
    results: &[SceneResult],
) -> Result<Vec<PhotoConsistency>, BittError> {
    let mut scenes = Vec::new();
    for r in results {
        let Some(names) = &r.photos else { continue };
        let path = scene_textures_path(out, r.seed);
        if path.is_file() {
            scenes.push((names.train.clone(), read_scene_textures(&path)?));
        }
    }
    scenes.sort_by(|a, b| a.0.cmp(&b.0));
    let mut pairs = Vec::new();
    for i in 0..scenes.len() {
        for j in i + 1..scenes.len() {
            let ((a, (ta, va)), (b, (tb, vb))) = (&scenes[i], &scenes[j]);
            if va[0].len() != vb[0].len() {
                continue;
            }
            let both: [Vec<bool>; 2] =
                std::array::from_fn(|h| va[h].iter().zip(&vb[h]).map(|(&x, &y)| x && y).collect());
            let e = bitt::metrics::texture_errors(ta, tb, &both);
            pairs.push(PhotoConsistency {
                photos: [a.clone(), b.clone()],
                shared_texels: both.iter().flatten().filter(|&&v| v).count(),
                l1: e.raw.visible,
                l1_gain_fitted: e.gain_fitted.visible,
            });
        }
    }
    Ok(pairs)
}

/// Accepts `path` only as a file (a missing photo is named before any work).
pub fn require_photo_files(photos: &[Photo]) -> Result<(), BittError> {
    for p in photos {
        for f in [&p.image, &p.annotation] {
            if !Path::new(f).is_file() {
                return Err(BittError::io(
                    f,
                    std::io::Error::new(std::io::ErrorKind::NotFound, "--photos: file not found"),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photo_metrics_count_uncovered_hand_pixels() {
        let s = 16;
        let hw = s * s;
        // The photo's hand: a bright 8 x 8 square; the render covers it but for one
        // inside pixel, and has the photo's colour.
        let mut photo = vec![0.0f32; 3 * hw];
        let mut rendered = vec![0.0f32; hw];
        for y in 4..12 {
            for x in 4..12 {
                for c in 0..3 {
                    photo[c * hw + y * s + x] = 0.6;
                }
                rendered[y * s + x] = 1.0;
            }
        }
        rendered[7 * s + 7] = 0.0;
        let render: Vec<f32> = (0..3 * hw)
            .map(|i| {
                if rendered[i % hw] > 0.5 {
                    photo[i]
                } else {
                    0.0
                }
            })
            .collect();
        let m = photo_metrics(&render, &photo, &rendered, None, s).unwrap();
        assert!((m.coverage - 63.0 / 64.0).abs() < 1e-9, "{}", m.coverage);
        assert!((m.holes - 1.0 / 64.0).abs() < 1e-9, "{}", m.holes);
        assert!(m.rendered_and_hand.psnr.is_infinite());
        // The uncovered pixel counts as black (0.6 off in 3 of 192 values).
        assert!(
            (m.hand_mask.l1 - 0.6 / 64.0).abs() < 1e-6,
            "{}",
            m.hand_mask.l1
        );
        // A flat square has no detail to correlate, and too few pixels anyway.
        assert_eq!(m.detail, None);
        assert!(photo_metrics(&render, &vec![0.0; 3 * hw], &rendered, None, s).is_none());
        assert_eq!(m.seen_split, None);
    }

    /// The rendered hand pixels split by whether their texel was seen: each part scored on
    /// its own pixels, and the split averaged over photos.
    #[test]
    fn photo_metrics_split_seen_from_unseen_texels() {
        let s = 16;
        let hw = s * s;
        // An 8 x 8 hand, all rendered; the left 2 columns' texels were seen. The render
        // matches the photo there and is 0.1 too bright elsewhere.
        let mut photo = vec![0.0f32; 3 * hw];
        let mut rendered = vec![0.0f32; hw];
        let mut seen = vec![false; hw];
        let mut render = vec![0.0f32; 3 * hw];
        for y in 4..12 {
            for x in 4..12 {
                let p = y * s + x;
                rendered[p] = 1.0;
                seen[p] = x < 6;
                for c in 0..3 {
                    photo[c * hw + p] = 0.5;
                    render[c * hw + p] = if x < 6 { 0.5 } else { 0.6 };
                }
            }
        }
        // A seen pixel outside the hand does not count.
        seen[0] = true;
        let m = photo_metrics(&render, &photo, &rendered, Some(&seen), s).unwrap();
        let split = m.seen_split.expect("a seen mask was given");
        assert!((split.seen_fraction - 0.25).abs() < 1e-9, "{split:?}");
        let (on, off) = (split.seen.unwrap(), split.unseen.unwrap());
        assert!(on.psnr.is_infinite() && on.l1 < 1e-9, "{on:?}");
        assert!((off.l1 - 0.1).abs() < 1e-6, "{off:?}");
        assert!((off.psnr - 20.0).abs() < 1e-3, "{off:?}");
        // Nothing seen: the seen part has no pixel.
        let none = photo_metrics(&render, &photo, &rendered, Some(&vec![false; hw]), s)
            .unwrap()
            .seen_split
            .unwrap();
        assert_eq!((none.seen_fraction, none.seen), (0.0, None));
        // The mean over photos averages the fractions, and each part's scores over the photos
        // that have pixels in it; a photo without a split leaves the mean without one.
        let all = photo_metrics(&render, &photo, &rendered, Some(&vec![true; hw]), s).unwrap();
        let mean = mean_photo_metrics(&[m, all]).unwrap().seen_split.unwrap();
        assert!((mean.seen_fraction - 0.625).abs() < 1e-9, "{mean:?}");
        assert!((mean.unseen.unwrap().l1 - 0.1).abs() < 1e-6, "{mean:?}");
        let bare = photo_metrics(&render, &photo, &rendered, None, s).unwrap();
        assert_eq!(mean_photo_metrics(&[m, bare]).unwrap().seen_split, None);
    }

    #[test]
    fn photo_arguments_parse_and_name() {
        let p = Photo::parse("a/01.jpg:b/hands.json").unwrap();
        assert_eq!(p.image, PathBuf::from("a/01.jpg"));
        assert_eq!(p.name(), "01");
        for bad in ["01.jpg", ":x", "x:"] {
            assert!(Photo::parse(bad).is_err(), "{bad}");
        }
    }
}
