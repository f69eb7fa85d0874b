//! `results.md`: the tables in the paper's layout and which of the paper's claims hold.

use bitt::metrics::ImageMetrics;
use bitt::real::{HandSource, PriorSource};

use super::{
    MeanMetrics, MeshSetting, Method, MethodSummary, PhotoConsistency, PhotoMetrics, PhotoScores,
    SceneResult, Summary, TexelErrors,
};

/// ` (per scene: +0.31 ± 0.20 dB, better in 3 of 4)` for the pair, or nothing.
fn paired_note(s: &Summary, setting: MeshSetting, a: Method, b: Method) -> String {
    s.paired
        .iter()
        .find(|p| p.setting == setting && p.a == a && p.b == b)
        .map_or(String::new(), |p| {
            let se = p.stderr_db.map_or(String::new(), |e| format!(" ± {e:.2}"));
            format!(
                " (per scene: {:+.2}{se} dB, better in {} of {})",
                p.mean_db, p.wins, p.scenes
            )
        })
}

/// A gain-fitted texel error with the raw one in brackets: `0.0412 (0.0530)`.
fn both(gain_fitted: Option<f64>, raw: Option<f64>) -> String {
    format!("{} ({})", fmt(gain_fitted, 4), fmt(raw, 4))
}

fn fmt(v: Option<f64>, digits: usize) -> String {
    v.map_or("n/a".to_string(), |v| format!("{v:.digits$}"))
}

/// The photo benchmark's table (`--photos`), one row per scene and method, or `None` when no
/// result is a photo scene. PSNR is given three ways: over the pixels both rendered and hand
/// in the photo (issue 34's table), over the photo's hand mask (uncovered hand pixels count
/// as black) and, as in the tables above, over the meshes' silhouettes.
/// One table row per photo-scored method of each scene, from `row(training photo, method,
/// its photo scores)`; `None` leaves the method out.
fn photo_rows(
    results: &[&SceneResult],
    row: impl Fn(&str, Method, &PhotoScores) -> Option<String>,
) -> Vec<String> {
    results
        .iter()
        .flat_map(|r| {
            let train = &r.photos.as_ref().expect("filtered").train;
            r.methods
                .iter()
                .filter_map(|(method, scores)| row(train, *method, scores.photo.as_ref()?))
                .collect::<Vec<_>>()
        })
        .collect()
}

pub fn photos_markdown(
    results: &[SceneResult],
    consistency: &[PhotoConsistency],
) -> Option<String> {
    let photo_results: Vec<&SceneResult> = results.iter().filter(|r| r.photos.is_some()).collect();
    if photo_results.is_empty() {
        return None;
    }
    let mut md = String::from(
        "## Real photos: trained on one photo, scored on the others (novel pose)\n\n\
         The hand mask is the photo's pixels with mean RGB above 0.15. PSNR (dB): `rendered & \
         hand` over the pixels that are both rendered and hand, `hand` over every hand pixel \
         (uncovered ones count as black), `mesh` over the meshes' silhouettes (Table 1's \
         protocol). Coverage: the hand pixels the render covers; holes: the hand pixels \
         inside the rendered outline (closed by 3 px at 256) left uncovered. Detail: the \
         correlation of the render's and the photo's high-pass (each pixel minus the mean of \
         its 5 x 5 window) over the rendered hand pixels: 1 with every vein, hair and crease \
         in place, 0 with none.\n\n\
         | trained on -> scored on | method | PSNR rendered & hand | PSNR hand | SSIM hand | \
         L1 hand | PSNR mesh | coverage | holes | detail |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    let row = |label: &str, m: &str, p: &PhotoMetrics, mesh: f64| {
        format!(
            "| {label} | {m} | {:.2} | {:.2} | {:.4} | {:.4} | {mesh:.2} | {:.1} % | {:.2} % | {} |\n",
            p.rendered_and_hand.psnr,
            p.hand_mask.psnr,
            p.hand_mask.ssim,
            p.hand_mask.l1,
            100.0 * p.coverage,
            100.0 * p.holes,
            p.detail.map_or("n/a".into(), |d| format!("{d:.3}"))
        )
    };
    for &r in &photo_results {
        let names = r.photos.as_ref().expect("filtered");
        for (input, label) in [
            (true, format!("{0} -> {0} (input view)", names.train)),
            (
                false,
                format!("{} -> {}", names.train, names.novel_poses.join(", ")),
            ),
        ] {
            for (method, scores) in &r.methods {
                let Some(photo) = scores.photo else { continue };
                let (p, mesh) = if input {
                    (Some(photo.input_view), Some(scores.input_view.psnr))
                } else {
                    (photo.novel_poses, scores.novel_poses.map(|m| m.psnr))
                };
                if let (Some(p), Some(mesh)) = (p, mesh) {
                    md.push_str(&row(&label, method.key(), &p, mesh));
                }
            }
        }
    }
    let split = photo_rows(&photo_results, |train, method, photo| {
        let s = photo.novel_poses?.seen_split?;
        let psnr = |m: Option<ImageMetrics>| m.map_or("n/a".into(), |m| format!("{:.2}", m.psnr));
        Some(format!(
            "| {train} | {} | {:.0} % | {} | {} |\n",
            method.key(),
            100.0 * s.seen_fraction,
            psnr(s.seen),
            psnr(s.unseen)
        ))
    });
    if !split.is_empty() {
        md.push_str(
            "\nSeen and unseen texels at the novel poses: the pixels both rendered and hand, \
             split by whether the texel drawn there was seen in the training photo (its \
             visible-texel mask rendered at the target's meshes). Where it was, the texture can \
             hold that photo's own skin; elsewhere only what the method filled in.\n\n\
             | trained on | method | pixels of seen texels | PSNR there | PSNR on the others |\n\
             |---|---|---|---|---|\n",
        );
        md.extend(split);
    }
    let shade = photo_rows(&photo_results, |train, method, photo| {
        let v = photo.albedo_in_shade?;
        Some(format!("| {train} | {} | {v:.3} |\n", method.key()))
    });
    if !shade.is_empty() {
        md.push_str(
            "\nAlbedo in shade: on the texels the training photo shows, the texture's mean \
             luminance where the training pose's ambient occlusion is below 0.6 over that where \
             it is above 0.9. Below 1: the photo's crease shadows went into the texture.\n\n\
             | trained on | method | albedo in shade |\n|---|---|---|\n",
        );
        md.extend(shade);
    }
    let palm = photo_rows(&photo_results, |train, method, photo| {
        let d = photo.unseen_palm?;
        Some(format!(
            "| {train} | {} | {} | {:.4} | {:.4} | {:.4} |\n",
            method.key(),
            d.texels,
            d.invented,
            d.prior,
            d.shift
        ))
    });
    if !palm.is_empty() {
        md.push_str(&format!(
            "\nUnseen palm: on the palm-side texels neither hand's training photo shows, the \
             detail the texture adds to its prior's (mean absolute high-pass of texture - prior, \
             the high-pass being a texel minus the mean of its {w} x {w} UV window), the \
             prior's own detail there (the same high-pass of the prior) and how far the colour \
             moved (mean |texture - prior|); [0, 1] values.\n\n\
             | trained on | method | texels | invented detail | prior's detail | colour shift |\n\
             |---|---|---|---|---|---|\n",
            w = bitt::evaluate::DETAIL_WINDOW
        ));
        md.extend(palm);
    }
    if !consistency.is_empty() {
        md.push_str(
            "\nConsistency: BiTT's fine textures of two photos on the texels both show (the \
             same hands should get the same albedo); L1 on [0, 1] values, raw and after one \
             gain per colour channel.\n\n| photos | shared texels | L1 | L1 gain-fitted |\n\
             |---|---|---|---|\n",
        );
        for c in consistency {
            md.push_str(&format!(
                "| {} & {} | {} | {} | {} |\n",
                c.photos[0],
                c.photos[1],
                c.shared_texels,
                fmt(c.l1, 4),
                fmt(c.l1_gain_fitted, 4)
            ));
        }
    }
    Some(md)
}

/// A method's row label. `alb`: the albedo consistency weight BiTT was trained with, when
/// known (the plan's `train.loss.alb`); at 0, as the photo preset trains
/// (`TrainConfig::preset_for_photo`), BiTT's row says so instead of naming the loss.
fn row_label(m: Method, alb: Option<f64>) -> &'static str {
    match (m, alb) {
        (Method::Bitt, Some(0.0)) => "BiTT (L_alb weight 0)",
        _ => m.label(),
    }
}

/// The hand models and texture prior an evaluation's plan names (`config.json`'s `models`,
/// [`super::EvalPlan::models`]), for `results.md`: the procedural ones when it names none.
pub fn models_text(models: Option<&serde_json::Value>) -> String {
    let sources = models.and_then(|m| {
        let hands = serde_json::from_value::<HandSource>(m["hands"].clone()).ok()?;
        let prior = serde_json::from_value::<PriorSource>(m["prior"].clone()).ok()?;
        Some((hands, prior))
    });
    let hands = match &sources {
        Some((HandSource::Mano { dir }, _)) => format!("MANO hands (`{}`)", dir.display()),
        _ => "the procedural hands".to_string(),
    };
    let prior = match &sources {
        Some((_, PriorSource::Html { dir })) => format!("the HTML prior (`{}`)", dir.display()),
        _ => "the procedural texture PCA".to_string(),
    };
    format!("{hands} with {prior}")
}

/// `results.md`: the tables in the paper's layout and which of its claims hold here. `alb`:
/// the albedo consistency weight of the training configuration, when known ([`row_label`]);
/// `models`: the hands and prior ([`models_text`]).
pub fn results_markdown(s: &Summary, lpips_note: &str, alb: Option<f64>, models: &str) -> String {
    let mut md = String::new();
    md.push_str("# Evaluation results\n\n");
    md.push_str(&format!(
        "{} scene(s) (seeds or scene ids {}), preset {}, {models}. Every method is trained per \
         scene on the input view only. LPIPS: {lpips_note}. MS-SSIM needs images larger than \
         160 px (n/a at 128 px). Image metrics are on the hand image (ground truth times its \
         hand masks, black elsewhere), so PSNRs are higher than the paper's.\n\n",
        s.seeds.len(),
        s.seeds
            .iter()
            .map(|x| format!("{x:#x}"))
            .collect::<Vec<_>>()
            .join(", "),
        s.presets.join(", ")
    ));
    let row = |m: &Option<MeanMetrics>| -> String {
        match m {
            Some(m) => format!(
                "{:.4} | {} | {:.2} | {:.4} | {}",
                m.l1,
                fmt(m.lpips, 4),
                m.psnr,
                m.ssim,
                fmt(m.ms_ssim, 4)
            ),
            None => "n/a | n/a | n/a | n/a | n/a".to_string(),
        }
    };
    let table1 = [
        Method::S2HandLike,
        Method::Html,
        Method::HarpLike,
        Method::Bitt,
        Method::BittRefined,
    ];
    for (setting, title) in [
        (MeshSetting::GtMesh, "Table 1a: with ground-truth meshes"),
        (
            MeshSetting::NoisyMesh,
            "Table 1b: without ground-truth meshes (perturbed meshes)",
        ),
    ] {
        let Some(per) = s.settings.get(&setting) else {
            continue;
        };
        md.push_str(&format!("## {title}\n\n"));
        md.push_str("| method | novel pose L1 ↓ | LPIPS ↓ | PSNR ↑ | SSIM ↑ | MS-SSIM ↑ | novel view L1 ↓ | LPIPS ↓ | PSNR ↑ | SSIM ↑ | MS-SSIM ↑ |\n");
        md.push_str("|---|---|---|---|---|---|---|---|---|---|---|\n");
        for m in table1 {
            if let Some(x) = per.get(&m) {
                md.push_str(&format!(
                    "| {} | {} | {} |\n",
                    row_label(m, alb),
                    row(&x.novel_poses),
                    row(&x.novel_views)
                ));
            }
        }
        md.push_str(
            "\n### Appearance reconstruction (input view) and texture-space L1\n\nTexel L1 after \
             one gain per colour channel fitted on the texels visible in the input (the \
             albedo/light split is ambiguous up to that scale; docs/evaluation.md), raw L1 in \
             brackets.\n\n",
        );
        md.push_str("| method | input L1 ↓ | input PSNR ↑ | input SSIM ↑ | texels visible ↓ | usable by symmetry ↓ | invisible on both ↓ | all not visible ↓ | s / scene |\n");
        md.push_str("|---|---|---|---|---|---|---|---|---|\n");
        for m in Method::ALL {
            if let Some(x) = per.get(&m) {
                let (l1, psnr, ssim) =
                    x.input_view
                        .map_or(("n/a".into(), "n/a".into(), "n/a".into()), |v| {
                            (
                                format!("{:.4}", v.l1),
                                format!("{:.2}", v.psnr),
                                format!("{:.4}", v.ssim),
                            )
                        });
                md.push_str(&format!(
                    "| {} | {l1} | {psnr} | {ssim} | {} | {} | {} | {} | {:.0} |\n",
                    row_label(m, alb),
                    both(x.texture_gain_fitted.visible, x.texture.visible),
                    both(x.texture_gain_fitted.symmetric, x.texture.symmetric),
                    both(x.texture_gain_fitted.invisible, x.texture.invisible),
                    both(x.texture_gain_fitted.not_visible, x.texture.not_visible),
                    x.seconds
                ));
            }
        }
        md.push('\n');
    }
    if let Some(per) = s.settings.get(&MeshSetting::GtMesh) {
        md.push_str(
            "## Table 4: ablation (mean of novel poses and novel views, ground-truth meshes)\n\n",
        );
        md.push_str("| coarse stage | sym. tex. | L_alb | L1 ↓ | LPIPS ↓ | PSNR ↑ | SSIM ↑ |\n|---|---|---|---|---|---|---|\n");
        for (m, marks) in [
            (Method::BittNoSym, "✓ | | "),
            (Method::BittNoAlb, "✓ | ✓ | "),
            (Method::Bitt, "✓ | ✓ | ✓"),
        ] {
            if let Some(x) = per.get(&m).and_then(novel_mean) {
                md.push_str(&format!(
                    "| {marks} | {:.4} | {} | {:.2} | {:.4} |\n",
                    x.l1,
                    fmt(x.lpips, 4),
                    x.psnr,
                    x.ssim
                ));
            }
        }
        md.push('\n');
    }
    if let Some(t) = &s.stats {
        md.push_str("## Table 3: texture statistics of these scenes (% of texels)\n\n");
        md.push_str("| left visible | right visible | usable by symmetry | invisible |\n|---|---|---|---|\n");
        md.push_str(&format!(
            "| {:.1} | {:.1} | {:.1} | {:.1} |\n\n",
            t.left_visible, t.right_visible, t.symmetric_usable, t.invisible
        ));
    }
    md.push_str("## The paper's claims on this benchmark\n\n");
    for line in claims(s) {
        md.push_str(&format!("- {line}\n"));
    }
    md
}

/// Mean of the novel-pose and novel-view metrics (Table 4's "novel poses and viewpoints").
fn novel_mean(x: &MethodSummary) -> Option<MeanMetrics> {
    let (p, v) = (x.novel_poses?, x.novel_views?);
    Some(MeanMetrics {
        l1: 0.5 * (p.l1 + v.l1),
        psnr: 0.5 * (p.psnr + v.psnr),
        ssim: 0.5 * (p.ssim + v.ssim),
        ms_ssim: p.ms_ssim.zip(v.ms_ssim).map(|(a, b)| 0.5 * (a + b)),
        lpips: p.lpips.zip(v.lpips).map(|(a, b)| 0.5 * (a + b)),
    })
}

/// Each qualitative claim of the paper that these results can test, and whether it holds.
pub fn claims(s: &Summary) -> Vec<String> {
    let mut out = Vec::new();
    let verdict = |ok: bool| if ok { "**holds**" } else { "**does not hold**" };
    for (setting, per) in &s.settings {
        let get = |m: Method| per.get(&m);
        let nv = |m: Method| get(m).and_then(|x| x.novel_views);
        if let Some(b) = nv(Method::Bitt) {
            for other in [Method::Html, Method::HarpLike, Method::S2HandLike] {
                if let Some(o) = nv(other) {
                    let ok = b.psnr > o.psnr && b.ssim > o.ssim;
                    out.push(format!(
                        "{}: BiTT beats {} on novel views (PSNR {:.2} vs {:.2} dB, SSIM {:.4} vs {:.4}){}: {}.",
                        setting.key(),
                        other.label(),
                        b.psnr,
                        o.psnr,
                        b.ssim,
                        o.ssim,
                        paired_note(s, *setting, Method::Bitt, other),
                        verdict(ok)
                    ));
                }
            }
        }
        // Texture claims are judged on the gain-fitted texel L1 (the albedo/light split is
        // ambiguous up to a gain per channel); the raw L1 is quoted beside it.
        let tex = |m: Method, f: fn(&TexelErrors) -> Option<f64>| {
            get(m).and_then(|x| Some((f(&x.texture_gain_fitted)?, f(&x.texture)?)))
        };
        type TexelClass = fn(&TexelErrors) -> Option<f64>;
        let texture_claims: [(Method, TexelClass, &str); 2] = [
            (
                Method::HarpLike,
                |t| t.not_visible,
                "BiTT reconstructs the sides the camera did not see better than HARP-like",
            ),
            (
                Method::Html,
                |t| t.symmetric,
                "BiTT fills the texels seen only on the other hand better than its coarse stage HTML, through the layout's symmetry",
            ),
        ];
        for (other, class, claim) in texture_claims {
            if let (Some(b), Some(h)) = (tex(Method::Bitt, class), tex(other, class)) {
                out.push(format!(
                    "{}: {claim} (gain-fitted texel L1 {:.4} vs {:.4}; raw {:.4} vs {:.4}): {}.",
                    setting.key(),
                    b.0,
                    h.0,
                    b.1,
                    h.1,
                    verdict(b.0 < h.0)
                ));
            }
        }
        // The paper's Table 1a: HARP fits the input view best (appearance reconstruction).
        // Judged on the input view's image, not on texels: a directly optimised texture
        // carries its own light's scale, so its texel values need not match the albedo.
        if let (Some(h), Some(b)) = (
            get(Method::HarpLike).and_then(|x| x.input_view),
            get(Method::Bitt).and_then(|x| x.input_view),
        ) {
            out.push(format!(
                "{}: HARP-like excels on the visible side (input-view PSNR {:.2} vs BiTT {:.2} dB): {}.",
                setting.key(),
                h.psnr,
                b.psnr,
                verdict(h.psnr >= b.psnr)
            ));
        }
        if *setting == MeshSetting::GtMesh {
            let steps = [Method::BittNoSym, Method::BittNoAlb, Method::Bitt];
            for w in steps.windows(2) {
                if let (Some(a), Some(b)) = (
                    get(w[0]).and_then(novel_mean),
                    get(w[1]).and_then(novel_mean),
                ) {
                    out.push(format!(
                        "ablation: {} improves on the row above (PSNR {:.2} vs {:.2} dB, SSIM {:.4} vs {:.4}){}: {}.",
                        w[1].label(),
                        b.psnr,
                        a.psnr,
                        b.ssim,
                        a.ssim,
                        paired_note(s, MeshSetting::GtMesh, w[1], w[0]),
                        verdict(b.psnr > a.psnr && b.ssim > a.ssim)
                    ));
                }
            }
            if let (Some(a), Some(b)) = (
                tex(Method::BittNoSym, |t| t.symmetric),
                tex(Method::BittNoAlb, |t| t.symmetric),
            ) {
                out.push(format!(
                    "ablation: symmetric information improves the texels seen only on the other hand (gain-fitted L1 {:.4} vs {:.4}; raw {:.4} vs {:.4}): {}.",
                    b.0,
                    a.0,
                    b.1,
                    a.1,
                    verdict(b.0 < a.0)
                ));
            }
        }
    }
    if let (Some(g), Some(n)) = (
        s.settings
            .get(&MeshSetting::GtMesh)
            .and_then(|p| p.get(&Method::Bitt))
            .and_then(|x| x.novel_views),
        s.settings
            .get(&MeshSetting::NoisyMesh)
            .and_then(|p| p.get(&Method::Bitt))
            .and_then(|x| x.novel_views),
    ) {
        out.push(format!(
            "BiTT stays robust without ground-truth meshes (novel-view PSNR {:.2} dB with perturbed meshes vs {:.2} dB with true ones; the paper loses about 1 dB): {}.",
            n.psnr,
            g.psnr,
            verdict(g.psnr - n.psnr < 2.0)
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_synth::TexelStats;

    use crate::benchmark::{MethodScores, SCENE_RESULT_FORMAT, SceneResult, summarize};
    use bitt::metrics::ImageMetrics;

    fn metrics(psnr: f64) -> ImageMetrics {
        ImageMetrics {
            l1: 0.01,
            psnr,
            ssim: 0.9 + psnr / 1000.0,
            ms_ssim: None,
            lpips: Some(psnr / 100.0),
        }
    }

    fn result(seed: u64, setting: MeshSetting, bitt: f64, html: f64) -> SceneResult {
        let scores = |p: f64, vis: f64| MethodScores {
            input_view: metrics(p),
            novel_views: Some(metrics(p)),
            novel_poses: Some(metrics(p - 1.0)),
            texture: TexelErrors {
                visible: Some(vis),
                symmetric: Some(0.05),
                invisible: Some(0.06),
                not_visible: Some(0.055),
            },
            texture_gain_fitted: TexelErrors {
                visible: Some(vis / 2.0),
                symmetric: Some(0.04),
                invisible: Some(0.05),
                not_visible: Some(0.045),
            },
            seconds: 10.0,
            photo: None,
        };
        SceneResult {
            format: SCENE_RESULT_FORMAT.into(),
            seed,
            setting,
            preset: "tiny".into(),
            iterations: 6,
            stats: TexelStats {
                table3: bitt_render::scene::TexelVisibilityStats {
                    num_texels: 10,
                    left_visible: 0.3,
                    right_visible: 0.4,
                    symmetric_usable: 0.3,
                    invisible: 0.5,
                },
                symmetry_gain: 0.2,
                reachable: 0.5,
            },
            methods: [
                (Method::Bitt, scores(bitt, 0.03)),
                (Method::Html, scores(html, 0.04)),
            ]
            .into_iter()
            .collect(),
            photos: None,
        }
    }

    /// A photo scene's novel poses get the seen / unseen split, with `n/a` for an empty
    /// part; results made before the split leave its table out.
    #[test]
    fn photo_tables_show_the_seen_and_unseen_texels() {
        use crate::benchmark::{PhotoNames, SeenSplit};
        let photo = |split: Option<SeenSplit>| PhotoMetrics {
            hand_mask: metrics(17.0),
            rendered_and_hand: metrics(23.5),
            coverage: 0.9,
            holes: 0.01,
            detail: Some(0.1),
            seen_split: split,
        };
        let scene = |split: Option<SeenSplit>| {
            let mut r = result(1, MeshSetting::GtMesh, 30.0, 28.0);
            r.photos = Some(PhotoNames {
                train: "01".into(),
                novel_poses: vec!["02".into()],
            });
            for scores in r.methods.values_mut() {
                scores.photo = Some(PhotoScores {
                    input_view: photo(None),
                    novel_poses: Some(photo(split)),
                    albedo_in_shade: None,
                    unseen_palm: None,
                });
            }
            r
        };
        let split = SeenSplit {
            seen_fraction: 0.78,
            seen: Some(metrics(23.84)),
            unseen: None,
        };
        let md = photos_markdown(&[scene(Some(split))], &[]).unwrap();
        assert!(
            md.contains("Seen and unseen texels at the novel poses"),
            "{md}"
        );
        assert!(md.contains("| 01 | bitt | 78 % | 23.84 | n/a |"), "{md}");
        let old = photos_markdown(&[scene(None)], &[]).unwrap();
        assert!(!old.contains("Seen and unseen"), "{old}");
    }

    #[test]
    fn summary_averages_scenes_and_states_the_claims() {
        let results = [
            result(1, MeshSetting::GtMesh, 30.0, 28.0),
            result(2, MeshSetting::GtMesh, 32.0, 33.0),
            result(1, MeshSetting::NoisyMesh, 29.5, 27.0),
        ];
        let s = summarize(&results);
        let gt = &s.settings[&MeshSetting::GtMesh];
        assert_eq!(gt[&Method::Bitt].scenes, 2);
        assert!((gt[&Method::Bitt].novel_views.unwrap().psnr - 31.0).abs() < 1e-12);
        assert!((gt[&Method::Html].novel_poses.unwrap().psnr - 29.5).abs() < 1e-12);
        // LPIPS is averaged like the other metrics and printed in the tables.
        assert!((gt[&Method::Bitt].novel_views.unwrap().lpips.unwrap() - 0.31).abs() < 1e-12);
        // Per scene BiTT - HTML: +2 and -1 dB with GT meshes.
        let p = s
            .paired
            .iter()
            .find(|p| p.setting == MeshSetting::GtMesh && p.b == Method::Html)
            .unwrap();
        assert_eq!((p.scenes, p.wins), (2, 1));
        assert!((p.mean_db - 0.5).abs() < 1e-12);
        assert!((p.stderr_db.unwrap() - 1.5).abs() < 1e-12);
        let md = results_markdown(&s, "test weights", Some(0.2), &models_text(None));
        assert!(md.contains("| BiTT (+ L_alb) |"), "{md}");
        assert!(
            md.contains("the procedural hands with the procedural texture PCA."),
            "{md}"
        );
        let photo = results_markdown(&s, "test weights", Some(0.0), "m");
        assert!(
            photo.contains("| BiTT (L_alb weight 0) |") && !photo.contains("BiTT (+ L_alb)"),
            "{photo}"
        );
        assert!(
            md.contains("(per scene: +0.50 ± 1.50 dB, better in 1 of 2)"),
            "{md}"
        );
        assert!(md.contains("| 0.0100 | 0.3100 | 31.00 |"), "{md}");
        assert_eq!(s.seeds, vec![1, 2]);
        let stats = s.stats.unwrap();
        assert!((stats.left_visible - 30.0).abs() < 1e-9);
        let claims = claims(&s);
        // 31.0 vs 30.5 dB with GT meshes, 29.5 vs 27 with noisy ones (1.5 dB lost): BiTT wins both.
        assert!(
            claims
                .iter()
                .any(|c| c.starts_with("gt-mesh: BiTT beats HTML")
                    && c.contains("31.00 vs 30.50")
                    && c.ends_with("**holds**."))
        );
        assert!(
            claims
                .iter()
                .any(|c| c.contains("robust") && c.contains("**holds**"))
        );
        let md = results_markdown(&s, "unavailable", None, "m");
        assert!(md.contains("## Table 1a"));
        assert!(md.contains("## Table 1b"));
        assert!(md.contains("| 30.0 | 40.0 | 30.0 | 50.0 |"));
    }
}
