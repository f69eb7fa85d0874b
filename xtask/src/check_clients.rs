//! `cargo xtask check-clients [--run DIR] [--iterations N] [--only chromium|xr|blender]
//! [--screenshot PNG] [--xr-screenshot PNG] [--chromium PATH] [--bitt PATH] [--render PNG]
//! [--blender PATH]`:
//! opens a run's outputs in the programs people view them with, headless, and checks what they
//! show (not part of CI; see `docs/clients.md`).
//!
//! The run: `--run DIR` (an existing run folder, used as it is), or a tiny run trained with the
//! release `bitt` (`train-scene --preset tiny`, the built-in demo scene) into
//! `runs/check-clients/run`, replacing the previous one.
//!
//! Each client is one function taking the run folder:
//! - [`chromium`]: `report.html`'s 3D view (three.js on WebGL, SwiftShader in a headless
//!   Chromium): the viewer draws both hands, and a screenshot of its `#viewer-only` mode
//!   shows them lit, textured and centred on the canvas (saved to
//!   `docs/images/report_viewer.png`).
//! - [`xr`]: `xr/xr.html`, the per-hand XR avatars driven by three.js's own
//!   `XRHandMeshModel` from stub WebXR joint poses (headless Chromium again): in its test mode,
//!   a novel pose's hands in pure colours from the scene's camera, compared pixel by pixel with
//!   `bitt render-avatar --masks` of the same pose (IoU per hand at least 0.95); and a
//!   screenshot of the page as it opens (saved to `docs/images/xr_hands.png`).
//! - [`blender`]: `avatar.glb` in Blender (Debian's `blender`, headless, `check_blender.py`):
//!   two armatures of at least 21 bones; rotating `right_index1` by 45 degrees moves the right
//!   index finger's vertices and not the thumb's; a Cycles render (saved to
//!   `docs/images/avatar_blender.png`); and `xr/left.glb`, `xr/right.glb`: one armature each,
//!   its bones named exactly as the convention's joints (25 WebXR, 26 OpenXR).

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};
use serde_json::Value;

/// Command-line options.
struct Options {
    run: Option<PathBuf>,
    iterations: usize,
    screenshot: PathBuf,
    xr_screenshot: PathBuf,
    chromium: Option<PathBuf>,
    bitt: Option<PathBuf>,
    render: PathBuf,
    blender: Option<PathBuf>,
    only: Option<String>,
}

/// The clients `--only` takes.
const CLIENTS: [&str; 3] = ["chromium", "xr", "blender"];

impl Options {
    fn parse(args: &[String]) -> Result<Self> {
        let mut o = Options {
            run: None,
            iterations: 300,
            screenshot: crate::root().join("docs/images/report_viewer.png"),
            xr_screenshot: crate::root().join("docs/images/xr_hands.png"),
            chromium: std::env::var_os("BITT_CHROMIUM").map(PathBuf::from),
            bitt: None,
            render: crate::root().join("docs/images/avatar_blender.png"),
            blender: std::env::var_os("BITT_BLENDER").map(PathBuf::from),
            only: None,
        };
        let mut it = args.iter();
        while let Some(a) = it.next() {
            let mut value = || it.next().with_context(|| format!("{a} needs a value"));
            match a.as_str() {
                "--run" => o.run = Some(PathBuf::from(value()?)),
                "--iterations" => o.iterations = value()?.parse().context("--iterations")?,
                "--screenshot" => o.screenshot = PathBuf::from(value()?),
                "--xr-screenshot" => o.xr_screenshot = PathBuf::from(value()?),
                "--chromium" => o.chromium = Some(PathBuf::from(value()?)),
                "--bitt" => o.bitt = Some(PathBuf::from(value()?)),
                "--render" => o.render = PathBuf::from(value()?),
                "--blender" => o.blender = Some(PathBuf::from(value()?)),
                "--only" => {
                    let v = value()?.clone();
                    if !CLIENTS.contains(&v.as_str()) {
                        bail!("--only takes {}, not `{v}`", CLIENTS.join(", "));
                    }
                    o.only = Some(v);
                }
                other => bail!(
                    "unknown option `{other}`; usage: cargo xtask check-clients [--run DIR] \
                     [--iterations N] [--only chromium|xr|blender] [--screenshot PNG] \
                     [--xr-screenshot PNG] [--chromium PATH] [--bitt PATH] [--render PNG] \
                     [--blender PATH]"
                ),
            }
        }
        Ok(o)
    }
}

/// `cargo xtask check-clients`: prepares the run, then checks every client.
pub fn check_clients(args: &[String]) -> Result<()> {
    let o = Options::parse(args)?;
    let run = prepare_run(o.run.as_deref(), o.iterations)?;
    let wants = |client: &str| o.only.as_deref().is_none_or(|only| only == client);
    if wants("chromium") {
        chromium(&run, &o.screenshot, o.chromium.as_deref())?;
    }
    if wants("xr") {
        let bitt = match &o.bitt {
            Some(p) => p.clone(),
            None => crate::build_bitt()?,
        };
        xr(&run, &o.xr_screenshot, o.chromium.as_deref(), &bitt)?;
    }
    if wants("blender") {
        blender(&run, &o.render, o.blender.as_deref())?;
    }
    Ok(())
}

/// The run folder to check: `run` as given, or a tiny run of the demo scene trained now.
fn prepare_run(run: Option<&Path>, iterations: usize) -> Result<PathBuf> {
    if let Some(run) = run {
        if !run.join("report.html").is_file() {
            bail!("{} holds no report.html: not a run folder", run.display());
        }
        return Ok(std::fs::canonicalize(run)?);
    }
    let bin = crate::build_bitt()?;
    let dir = crate::root().join("runs/check-clients/run");
    if dir.exists() {
        if !dir.join("config.json").is_file() {
            bail!("{} exists and is not a run: move it away", dir.display());
        }
        std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
    }
    println!(
        "check-clients: training a tiny run ({iterations} iterations) into {}",
        dir.display()
    );
    let out = Command::new(bin)
        .args(["train-scene", "--preset", "tiny", "--turntable", "0"])
        .args(["--iterations", &iterations.to_string()])
        .arg("--out")
        .arg(&dir)
        .output()
        .context("running bitt train-scene")?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = stderr.lines().rev().take(20).collect();
        bail!(
            "bitt train-scene failed ({}):\n{}",
            out.status,
            tail.into_iter().rev().collect::<Vec<_>>().join("\n")
        );
    }
    Ok(std::fs::canonicalize(&dir)?)
}

/// The browser's window in CSS pixels (device scale factor 1: one pixel each), unless a check
/// needs another size.
const WINDOW: (u32, u32) = (960, 640);

/// Flags for every headless Chromium run here: no GPU, WebGL through SwiftShader (ANGLE),
/// a throw-away profile, a `window` of that many CSS pixels (a screenshot has exactly that
/// size), and virtual time so the page's scripts (module parsing, the GLB's decoding, the
/// first frames) finish before the DOM or the screenshot is taken.
fn chromium_flags(profile: &Path, window: (u32, u32)) -> Vec<String> {
    let mut flags = vec![
        "--headless".to_string(),
        "--disable-gpu".into(),
        "--use-angle=swiftshader".into(),
        "--enable-unsafe-swiftshader".into(),
        "--force-device-scale-factor=1".into(),
        "--hide-scrollbars".into(),
        "--no-first-run".into(),
        "--no-default-browser-check".into(),
        "--mute-audio".into(),
        "--enable-logging=stderr".into(),
        "--v=0".into(),
        format!("--window-size={},{}", window.0, window.1),
        "--virtual-time-budget=20000".into(),
        format!("--user-data-dir={}", profile.display()),
    ];
    // Chromium refuses to run as root with its sandbox.
    if is_root() {
        flags.push("--no-sandbox".into());
    }
    flags
}

fn is_root() -> bool {
    std::fs::read_to_string("/proc/self/status").is_ok_and(|s| {
        s.lines()
            .find(|l| l.starts_with("Uid:"))
            .and_then(|l| l.split_whitespace().nth(1))
            == Some("0")
    })
}

/// The first of `names` that is a file in a folder of `PATH`.
fn on_path(names: &[&str]) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .flat_map(|dir| names.iter().map(move |n| dir.join(n)))
        .find(|p| p.is_file())
}

/// The Chromium to run: `program`, else the first of the usual names on `PATH`.
fn find_chromium(program: Option<&Path>) -> Result<PathBuf> {
    if let Some(p) = program {
        return Ok(p.to_path_buf());
    }
    let names = [
        "chromium",
        "chromium-browser",
        "google-chrome",
        "google-chrome-stable",
    ];
    if let Some(p) = on_path(&names) {
        return Ok(p);
    }
    bail!(
        "no Chromium found ({} on PATH); install one (Debian: apt-get install chromium) or \
         pass --chromium PATH / set BITT_CHROMIUM",
        names.join(", ")
    )
}

/// A headless Chromium and its throw-away profile.
struct Chromium {
    program: PathBuf,
    profile: PathBuf,
}

impl Chromium {
    /// Runs Chromium on `url` in a `window` with `extra` flags; returns stdout. Fails with
    /// the page's console messages when Chromium fails.
    fn run(&self, window: (u32, u32), extra: &[String], url: &str) -> Result<String> {
        let program = &self.program;
        let out = Command::new(program)
            .args(chromium_flags(&self.profile, window))
            .args(extra)
            .arg(url)
            .output()
            .with_context(|| format!("running {}", program.display()))?;
        if !out.status.success() {
            bail!(
                "{} failed ({}) on {url}:\n{}",
                program.display(),
                out.status,
                console(&out.stderr)
            );
        }
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    }

    /// The page at `url` after its scripts ran (`--dump-dom`).
    fn dom(&self, window: (u32, u32), url: &str) -> Result<String> {
        self.run(window, &["--dump-dom".to_string()], url)
    }

    /// A screenshot of the page at `url`, `window` pixels, written to `png` and returned.
    fn screenshot(&self, window: (u32, u32), url: &str, png: &Path) -> Result<Vec<u8>> {
        self.run(window, &[format!("--screenshot={}", png.display())], url)?;
        std::fs::read(png).context("Chromium wrote no screenshot")
    }

    /// Runs the measuring `page` (written to `path`) and returns the JSON it writes into
    /// `<pre id="stats">`; fails when it reports an `error`.
    fn measure(&self, path: &Path, page: &str) -> Result<Value> {
        std::fs::write(path, page)?;
        let dom = self.dom(WINDOW, &file_url(path))?;
        let stats = dom
            .split("<pre id=\"stats\">")
            .nth(1)
            .and_then(|s| s.split("</pre>").next())
            .context("the measuring page wrote nothing")?;
        let stats: Value =
            serde_json::from_str(stats).with_context(|| format!("measurements `{stats}`"))?;
        if let Some(e) = stats["error"].as_str() {
            bail!("measuring the screenshot failed: {e}");
        }
        Ok(stats)
    }
}

/// The page's console messages in Chromium's log (`--enable-logging=stderr`).
fn console(stderr: &[u8]) -> String {
    String::from_utf8_lossy(stderr)
        .lines()
        .filter(|l| l.contains(":CONSOLE") || l.contains("Uncaught"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// A `file://` URL for an absolute path.
fn file_url(path: &Path) -> String {
    let mut url = String::from("file://");
    for b in path.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            url.push(b as char);
        } else {
            url.push_str(&format!("%{b:02X}"));
        }
    }
    url
}

/// The viewer's status (`<output id="bitt-viewer-status" data-state=...>JSON</output>`) in
/// a DOM dump.
fn viewer_status(dom: &str) -> Result<Value> {
    page_status(dom, "bitt-viewer-status", "3D viewer")
}

/// A page's status element (`<output id="ID" data-state=... [data-warnings=JSON]>JSON
/// </output>`) in a DOM dump: its JSON text with `state` and, where the element has them,
/// `warnings` added. `what` names the page in the error when there is none.
fn page_status(dom: &str, id: &str, what: &str) -> Result<Value> {
    let start = dom
        .find(&format!("id=\"{id}\""))
        .with_context(|| format!("the page has no {what} (no #{id})"))?;
    let element = &dom[start..];
    let open_end = element.find('>').context("unterminated status element")?;
    let close = element
        .find("</output>")
        .context("unterminated status element")?;
    let attribute = |name: &str| {
        element[..open_end]
            .split(&format!("{name}=\""))
            .nth(1)
            .and_then(|s| s.split('"').next())
            .map(unescape_html)
    };
    let text = unescape_html(&element[open_end + 1..close]);
    let mut v: Value = if text.trim().is_empty() {
        serde_json::json!({})
    } else {
        serde_json::from_str(&text).with_context(|| format!("{what} status `{text}`"))?
    };
    v["state"] = attribute("data-state").unwrap_or_default().into();
    if let Some(w) = attribute("data-warnings") {
        v["warnings"] =
            serde_json::from_str(&w).with_context(|| format!("{what} warnings `{w}`"))?;
    }
    Ok(v)
}

/// Text or an attribute value of a DOM dump with the entities Chromium writes decoded.
fn unescape_html(s: &str) -> String {
    s.replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&nbsp;", "\u{a0}")
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&")
}

/// Checks `report.html` of `run` in headless Chromium: the 3D view loads and draws both hands
/// (its status), in the report as it opens and alone (`#viewer-only`); then a screenshot of
/// the view alone is saved to `screenshot` and its canvas region must show the hands: enough
/// pixels off the background, centred, lit and textured (statistics computed by Chromium on
/// the PNG itself, embedded as a data URL in a scratch page).
pub fn chromium(run: &Path, screenshot: &Path, program: Option<&Path>) -> Result<()> {
    let scratch = std::env::temp_dir().join(format!("bitt-check-chromium-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let browser = Chromium {
        program: find_chromium(program)?,
        profile: scratch.join("profile"),
    };
    let report = std::fs::canonicalize(run.join("report.html"))
        .with_context(|| format!("{}/report.html", run.display()))?;
    let report_url = file_url(&report);

    // 1. The report as it opens, and the viewer alone: the viewer's own status.
    let mut canvas = None;
    for url in [report_url.clone(), format!("{report_url}#viewer-only")] {
        let dom = browser.dom(WINDOW, &url)?;
        let status = viewer_status(&dom)?;
        if status["state"] != "ready" {
            bail!("{url}: the 3D view did not draw: {status}");
        }
        let hands = status["hands"].as_array().map_or(0, Vec::len);
        if hands != 2 || status["meshes"].as_u64().unwrap_or(0) < 2 {
            bail!("{url}: the 3D view does not hold both hands: {status}");
        }
        println!("check-clients chromium: {url}: viewer ready: {status}");
        canvas = Some(status["canvas"].clone());
    }
    let rect = u32s(canvas.as_ref());
    let [x, y, w, h] = rect[..] else {
        bail!("the viewer did not report its canvas: {canvas:?}");
    };
    if w < WINDOW.0 || h < WINDOW.1 / 2 {
        bail!("#viewer-only: the canvas is {w}x{h}, not the window");
    }

    // 2. The screenshot.
    if let Some(parent) = screenshot.parent() {
        std::fs::create_dir_all(parent)?;
    }
    let shot = scratch.join("report_viewer.png");
    let png = browser.screenshot(WINDOW, &format!("{report_url}#viewer-only"), &shot)?;

    // 3. Its canvas region, measured by Chromium on the PNG.
    let stats = browser.measure(
        &scratch.join("measure.html"),
        &measure_page(&png, [x, y, w]),
    )?;
    let num = |k: &str| stats[k].as_f64().unwrap_or(f64::NAN);
    let (covered, cx, cy) = (num("covered"), num("cx"), num("cy"));
    let (mean, spread, colours) = (num("mean"), num("std"), num("colours"));
    let mut problems = Vec::new();
    if !(0.03..=0.9).contains(&covered) {
        problems.push(format!(
            "the hands cover {:.1}% of the canvas (want 3-90%)",
            100.0 * covered
        ));
    }
    if !(0.3..=0.7).contains(&cx) || !(0.3..=0.7).contains(&cy) {
        problems.push(format!(
            "the hands' centre is at ({cx:.2}, {cy:.2}) of the canvas"
        ));
    }
    if mean.is_nan() || mean < 40.0 {
        problems.push(format!(
            "the hands are dark (mean brightness {mean:.0} of 255)"
        ));
    }
    if spread.is_nan() || spread < 3.0 || colours < 50.0 {
        problems.push(format!(
            "the hands look flat (brightness spread {spread:.1}, {colours} colours)"
        ));
    }
    std::fs::copy(&shot, screenshot)
        .with_context(|| format!("saving the screenshot to {}", screenshot.display()))?;
    let _ = std::fs::remove_dir_all(&scratch);
    println!(
        "check-clients chromium: screenshot {} ({}x{} canvas): hands cover {:.1}%, centre \
         ({cx:.2}, {cy:.2}), mean brightness {mean:.0}, spread {spread:.1}, {colours} colours",
        screenshot.display(),
        stats["width"],
        stats["height"],
        100.0 * covered
    );
    if !problems.is_empty() {
        bail!("report.html's 3D view: {}", problems.join("; "));
    }
    println!("check-clients chromium: passed");
    Ok(())
}

/// The non-negative integers of a JSON array (a status's rectangle or size).
fn u32s(v: Option<&Value>) -> Vec<u32> {
    v.and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(Value::as_u64)
                .map(|x| x as u32)
                .collect()
        })
        .unwrap_or_default()
}

/// A page that measures the region of `png` from `x, y`, `w` wide, down to its bottom (the
/// viewer's canvas in `#viewer-only` mode): the fraction of pixels off the
/// background (the region's bottom-left pixel), their centroid (0..1 of the region), mean
/// and standard deviation of their brightness (0..255) and how many distinct colours they
/// have (5 bits a channel); written as JSON into `<pre id="stats">`.
fn measure_page(png: &[u8], [x, y, w]: [u32; 3]) -> String {
    format!(
        r#"<!doctype html><meta charset="utf-8"><img id="shot" src="data:image/png;base64,{png}">
<pre id="stats"></pre>
<script>
const out = document.getElementById('stats');
const img = document.getElementById('shot');
const measure = () => {{ try {{
  const c = document.createElement('canvas');
  c.width = img.naturalWidth;
  c.height = img.naturalHeight;
  const g = c.getContext('2d');
  g.drawImage(img, 0, 0);
  // The canvas's left, top and width; it reaches the window's bottom.
  const [x, y] = [{x}, {y}];
  const [w, h] = [Math.min({w}, c.width - x), c.height - y];
  const d = g.getImageData(x, y, w, h).data;
  const at = (i, j) => 4 * (j * w + i);
  const b = at(2, h - 3);
  const bg = [d[b], d[b + 1], d[b + 2]];
  let n = 0, sx = 0, sy = 0, s = 0, s2 = 0;
  const colours = new Set();
  for (let j = 0; j < h; j++) for (let i = 0; i < w; i++) {{
    const k = at(i, j);
    const off = Math.max(Math.abs(d[k] - bg[0]), Math.abs(d[k + 1] - bg[1]), Math.abs(d[k + 2] - bg[2]));
    if (off <= 12) continue;
    const l = 0.299 * d[k] + 0.587 * d[k + 1] + 0.114 * d[k + 2];
    n++; sx += i; sy += j; s += l; s2 += l * l;
    colours.add(((d[k] >> 3) << 10) | ((d[k + 1] >> 3) << 5) | (d[k + 2] >> 3));
  }}
  const mean = n ? s / n : 0;
  out.textContent = JSON.stringify({{
    covered: n / (w * h), cx: n ? sx / n / w : 0, cy: n ? sy / n / h : 0,
    mean, std: n ? Math.sqrt(Math.max(s2 / n - mean * mean, 0)) : 0,
    colours: colours.size, background: bg, width: w, height: h,
  }});
}} catch (e) {{ out.textContent = JSON.stringify({{ error: String(e) }}); }} }};
// The load event, not img.decode(): headless Chromium's virtual time waits for the former.
if (img.complete) measure(); else img.addEventListener('load', measure);
</script>
"#,
        png = base64(png)
    )
}

/// The files of a run's `xr/` folder the XR check reads (`bitt train-scene` and `bitt export
/// --xr webxr` write them).
const XR_FILES: [&str; 5] = [
    "left.glb",
    "right.glb",
    "joints.json",
    "playback.json",
    "xr.html",
];

/// The smallest IoU per hand between the XR page's test screenshot and the project's masks.
const MIN_XR_IOU: f64 = 0.95;

/// The side at which a small square frame is compared once more (the tiny preset's images
/// are 32 pixels: a hand is a hundred pixels there, so its outline is compared here too).
const XR_COMPARE_SIZE: u32 = 256;

/// What the XR check compares: frame `frame` of `playback.json` (novel pose `novel_pose` of
/// the run, or the training pose), whose camera is `size` pixels.
struct XrFrame {
    page: PathBuf,
    frame: usize,
    novel_pose: Option<u64>,
    name: String,
    size: (u32, u32),
}

/// The run's XR page and the frame to compare: the first novel pose (frames say which novel
/// pose they are, `novel_pose`; `null` for the training pose), else the first frame.
fn xr_frame(run: &Path) -> Result<XrFrame> {
    let dir = run.join("xr");
    let missing: Vec<&str> = XR_FILES
        .into_iter()
        .filter(|f| !dir.join(f).is_file())
        .collect();
    if !missing.is_empty() {
        bail!(
            "{}: no {} (bitt train-scene and bitt export --xr webxr write them)",
            dir.display(),
            missing.join(", ")
        );
    }
    let playback: Value = serde_json::from_slice(&std::fs::read(dir.join("playback.json"))?)
        .context("xr/playback.json is not JSON")?;
    let frames = playback["frames"].as_array().map_or(&[][..], Vec::as_slice);
    let frame = frames
        .iter()
        .position(|f| f["novel_pose"].is_u64())
        .unwrap_or(0);
    let f = frames
        .get(frame)
        .context("xr/playback.json has no frames")?;
    let side = |k: &str| {
        f["camera"][k]
            .as_u64()
            .filter(|&v| (1..=8192).contains(&v))
            .map(|v| v as u32)
            .with_context(|| format!("xr/playback.json: frame {frame}'s camera has no {k}"))
    };
    Ok(XrFrame {
        page: std::fs::canonicalize(dir.join("xr.html"))?,
        frame,
        novel_pose: f["novel_pose"].as_u64(),
        name: f["name"].as_str().unwrap_or("").to_string(),
        size: (side("width")?, side("height")?),
    })
}

/// Checks `xr/xr.html` of `run` in headless Chromium (see the module docs): the test mode of
/// a novel pose against `bitt render-avatar --masks` of that pose (the release `bitt` at
/// `bitt`), then the page as it opens, whose screenshot is saved to `screenshot`.
pub fn xr(run: &Path, screenshot: &Path, program: Option<&Path>, bitt: &Path) -> Result<()> {
    let xr = xr_frame(run)?;
    let scratch = std::env::temp_dir().join(format!("bitt-check-xr-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let browser = Chromium {
        program: find_chromium(program)?,
        profile: scratch.join("profile"),
    };
    let url = file_url(&xr.page);
    let (w, h) = xr.size;
    println!(
        "check-clients xr: playback frame {} `{}` ({}), {w}x{h}",
        xr.frame,
        xr.name,
        xr.novel_pose
            .map_or("the training pose".to_string(), |k| format!(
                "novel pose {k}"
            ))
    );

    // 1-3. At the frame's own size, and a small square frame at XR_COMPARE_SIZE too.
    compare_xr(&browser, &xr, &scratch, bitt, run, None)?;
    if w == h && w < XR_COMPARE_SIZE {
        compare_xr(&browser, &xr, &scratch, bitt, run, Some(XR_COMPARE_SIZE))?;
    }

    // 4. The page as it opens, and its screenshot.
    let status = xr_status(&browser, WINDOW, &url)?;
    let rect = u32s(Some(&status["rect"]));
    let [x, y, cw, _] = rect[..] else {
        bail!("{url}: the page did not report its canvas: {status}");
    };
    let png = browser.screenshot(WINDOW, &url, &scratch.join("xr_hands.png"))?;
    let stats = browser.measure(
        &scratch.join("measure.html"),
        &measure_page(&png, [x, y, cw]),
    )?;
    let num = |k: &str| stats[k].as_f64().unwrap_or(f64::NAN);
    let (covered, spread, colours) = (num("covered"), num("std"), num("colours"));
    if let Some(parent) = screenshot.parent() {
        std::fs::create_dir_all(parent)?;
    }
    std::fs::write(screenshot, &png)
        .with_context(|| format!("saving the screenshot to {}", screenshot.display()))?;
    println!(
        "check-clients xr: screenshot {}: hands cover {:.1}% of the canvas, brightness spread \
         {spread:.1}, {colours} colours",
        screenshot.display(),
        100.0 * covered
    );
    if !((0.01..=0.9).contains(&covered) && spread >= 3.0 && colours >= 50.0) {
        bail!(
            "xr.html as it opens: the hands cover {:.1}% of the canvas (want 1-90%), \
             brightness spread {spread:.1} (want at least 3), {colours} colours (want at least \
             50: textured)",
            100.0 * covered
        );
    }
    let _ = std::fs::remove_dir_all(&scratch);
    println!("check-clients xr: passed");
    Ok(())
}

/// Compares the XR page's test mode with the project's masks of the same frame, at the
/// frame's size or `size` pixels square (the intrinsics scaled, `render-avatar --size`):
/// 1. the test page draws the frame at that size, every bone bound;
/// 2. its screenshot and `bitt render-avatar --masks` of the same pose and camera;
/// 3. each hand's IoU ([`check_ious`]).
fn compare_xr(
    browser: &Chromium,
    xr: &XrFrame,
    scratch: &Path,
    bitt: &Path,
    run: &Path,
    size: Option<u32>,
) -> Result<()> {
    let (w, h) = size.map_or(xr.size, |s| (s, s));
    let test_url = match size {
        None => format!("{}#test={}", file_url(&xr.page), xr.frame),
        Some(s) => format!("{}#test={}&size={s}", file_url(&xr.page), xr.frame),
    };
    // The canvas is w x h at the top left; the window no smaller than the usual one (in a
    // tiny window headless Chromium may never finish a screenshot).
    let window = (w.max(WINDOW.0), h.max(WINDOW.1));
    let status = xr_status(browser, window, &test_url)?;
    if u32s(Some(&status["canvas"])) != [w, h] || !u32s(Some(&status["rect"])).starts_with(&[0, 0])
    {
        bail!("{test_url}: the canvas is not {w}x{h} at the top left: {status}");
    }
    let shot = browser.screenshot(window, &test_url, &scratch.join(format!("xr_{w}.png")))?;
    let masks = render_masks(
        bitt,
        run,
        xr.novel_pose,
        size,
        &scratch.join(format!("masks_{w}.png")),
    )?;
    let stats = browser.measure(&scratch.join("iou.html"), &iou_page(&shot, &masks, (w, h)))?;
    println!("check-clients xr: at {w}x{h}:");
    check_ious(&stats)
}

/// The XR page's status at `url` in a `window`: it must be ready and its hand models must
/// have found every bone (`XRHandMeshModel` warns "Couldn't find <joint> in <hand> hand
/// mesh" otherwise); other warnings are printed.
fn xr_status(browser: &Chromium, window: (u32, u32), url: &str) -> Result<Value> {
    let dom = browser.dom(window, url)?;
    let status = page_status(&dom, "bitt-xr-status", "XR page")?;
    if status["state"] != "ready" {
        bail!("{url}: the XR page did not draw: {status}");
    }
    let warnings: Vec<&str> = status["warnings"]
        .as_array()
        .map(|w| w.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default();
    let unbound: Vec<&str> = warnings
        .iter()
        .copied()
        .filter(|w| w.contains("Couldn't find"))
        .collect();
    if !unbound.is_empty() {
        bail!(
            "{url}: XRHandMeshModel could not bind bones:\n{}",
            unbound.join("\n")
        );
    }
    for w in &warnings {
        println!("check-clients xr: warning on {url}: {w}");
    }
    println!("check-clients xr: {url}: ready: {status}");
    Ok(status)
}

/// `bitt render-avatar --run RUN [--novel-pose K] [--size S] --masks --out OUT`: the
/// project's own render of the pose as per-hand masks (left red, right green, black
/// elsewhere); returns the PNG.
fn render_masks(
    bitt: &Path,
    run: &Path,
    novel_pose: Option<u64>,
    size: Option<u32>,
    out: &Path,
) -> Result<Vec<u8>> {
    let mut command = Command::new(bitt);
    command.args(["render-avatar", "--masks", "--run"]).arg(run);
    if let Some(k) = novel_pose {
        command.args(["--novel-pose", &k.to_string()]);
    }
    if let Some(s) = size {
        command.args(["--size", &s.to_string()]);
    }
    let result = command
        .arg("--out")
        .arg(out)
        .output()
        .with_context(|| format!("running {}", bitt.display()))?;
    if !result.status.success() {
        bail!(
            "bitt render-avatar --masks failed ({}):\n{}",
            result.status,
            String::from_utf8_lossy(&result.stderr)
        );
    }
    std::fs::read(out).context("bitt render-avatar --masks wrote no PNG")
}

/// Checks the IoU of each hand (the measurements of [`iou_page`]): at least [`MIN_XR_IOU`]
/// where either image shows the hand; a hand neither shows (a frame without it) is skipped,
/// but at least one hand must be compared.
fn check_ious(stats: &Value) -> Result<()> {
    let mut compared = 0;
    let mut low = Vec::new();
    for hand in ["left", "right"] {
        let s = &stats[hand];
        let count = |k: &str| s[k].as_u64().unwrap_or(0);
        let (shot, render) = (count("shot"), count("render"));
        let Some(iou) = s["iou"].as_f64() else {
            println!("  {hand} hand: in neither image");
            continue;
        };
        compared += 1;
        println!(
            "  {hand} hand: IoU {iou:.4} (XRHandMeshModel {shot} px, bitt render-avatar \
             {render} px, both {} px)",
            count("both")
        );
        if iou < MIN_XR_IOU {
            low.push(format!("{hand} {iou:.4}"));
        }
    }
    if compared == 0 {
        bail!("neither image shows a hand: {stats}");
    }
    if !low.is_empty() {
        bail!(
            "the XR page's hands do not overlap the project's render (IoU {} < {MIN_XR_IOU})",
            low.join(", ")
        );
    }
    Ok(())
}

/// A page that compares the XR page's test screenshot `shot` with the masks `masks` (both
/// `w x h`, the screenshot at least): per hand, the pixels each shows (left: red, r > 128,
/// g < 100, b < 100; right: green, the same with r and g swapped), those both show, and their
/// IoU (null where neither shows the hand); written as JSON into `<pre id="stats">`.
fn iou_page(shot: &[u8], masks: &[u8], (w, h): (u32, u32)) -> String {
    format!(
        r#"<!doctype html><meta charset="utf-8">
<img id="shot" src="data:image/png;base64,{shot}"><img id="masks" src="data:image/png;base64,{masks}">
<pre id="stats"></pre>
<script>
const out = document.getElementById('stats');
const images = [document.getElementById('shot'), document.getElementById('masks')];
const [w, h] = [{w}, {h}];
const hand = (d, k) =>
  d[k] > 128 && d[k + 1] < 100 && d[k + 2] < 100 ? 'left'
  : d[k + 1] > 128 && d[k] < 100 && d[k + 2] < 100 ? 'right' : null;
const measure = () => {{ try {{
  const [shot, masks] = images;
  if (shot.naturalWidth < w || shot.naturalHeight < h)
    throw new Error(`the screenshot is ${{shot.naturalWidth}}x${{shot.naturalHeight}}, not ${{w}}x${{h}}`);
  if (masks.naturalWidth !== w || masks.naturalHeight !== h)
    throw new Error(`the masks are ${{masks.naturalWidth}}x${{masks.naturalHeight}}, not ${{w}}x${{h}}`);
  const [a, b] = images.map((img) => {{
    const c = document.createElement('canvas');
    c.width = w;
    c.height = h;
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    return g.getImageData(0, 0, w, h).data;
  }});
  const stats = {{ width: w, height: h }};
  for (const name of ['left', 'right']) {{
    let shot = 0, render = 0, both = 0;
    for (let k = 0; k < 4 * w * h; k += 4) {{
      const x = hand(a, k) === name, y = hand(b, k) === name;
      shot += x; render += y; both += x && y;
    }}
    const union = shot + render - both;
    stats[name] = {{ shot, render, both, iou: union ? both / union : null }};
  }}
  out.textContent = JSON.stringify(stats);
}} catch (e) {{ out.textContent = JSON.stringify({{ error: String(e) }}); }} }};
// The load events, not decode(): headless Chromium's virtual time waits for the former.
let pending = images.length;
const loaded = () => {{ if (--pending === 0) measure(); }};
for (const img of images) {{
  if (img.complete) loaded();
  else {{ img.addEventListener('load', loaded); img.addEventListener('error', loaded); }}
}}
</script>
"#,
        shot = base64(shot),
        masks = base64(masks)
    )
}

fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let n = chunk
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, &b)| n | (u32::from(b) << (16 - 8 * i)));
        for k in 0..4 {
            out.push(if k <= chunk.len() {
                T[((n >> (18 - 6 * k)) & 63) as usize] as char
            } else {
                '='
            });
        }
    }
    out
}

/// The Blender script (`blender -b --python check_blender.py -- GLB PNG REPORT`).
const BLENDER_SCRIPT: &str = include_str!("check_blender.py");

/// Opens the run's `avatar.glb` in Blender, headless (see the module docs), and writes the
/// Cycles render to `render`.
pub fn blender(run: &Path, render: &Path, program: Option<&Path>) -> Result<()> {
    let program = match program {
        Some(p) => p.to_path_buf(),
        None => on_path(&["blender"]).context(
            "no Blender found on PATH; install Debian's (apt-get install blender python3-numpy) \
             or pass --blender PATH / set BITT_BLENDER",
        )?,
    };
    let glb = run.join("avatar.glb");
    if !glb.is_file() {
        bail!("{}: no avatar.glb in the run", run.display());
    }
    let scratch = std::env::temp_dir().join(format!("bitt-check-blender-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let script = scratch.join("check_blender.py");
    std::fs::write(&script, BLENDER_SCRIPT)?;
    let png = scratch.join("render.png");
    println!(
        "check-clients: Blender ({}) on {}",
        program.display(),
        glb.display()
    );
    let report = run_blender(
        &program,
        &script,
        &glb,
        Some(&png),
        &scratch.join("report.json"),
    )?;
    let armatures = report["armatures"].as_array().cloned().unwrap_or_default();
    let bones = |a: &Value| a["bones"].as_array().map_or(0, Vec::len);
    println!(
        "  armatures: {}",
        armatures
            .iter()
            .map(|a| format!("{} ({} bones)", a["name"].as_str().unwrap_or("?"), bones(a)))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if armatures.len() != 2 || armatures.iter().any(|a| bones(a) < 21) {
        bail!("Blender should find 2 armatures of at least 21 bones: {armatures:?}");
    }
    let moved = |k: &str| report[k].as_f64().unwrap_or(f64::NAN);
    let (index, thumb) = (moved("index_moved_max_m"), moved("thumb_moved_max_m"));
    println!(
        "  right_index1 rotated 45 deg: index finger vertices move up to {:.1} mm ({} vertices), \
         thumb vertices up to {:.4} mm ({} vertices)",
        1e3 * index,
        report["index_vertices"],
        1e3 * thumb,
        report["thumb_vertices"]
    );
    if !(index > 5e-3 && thumb < 1e-6) {
        bail!(
            "rotating right_index1 should move the index finger (moved {index} m) and not the \
             thumb (moved {thumb} m)"
        );
    }
    let bytes = std::fs::read(&png).context("Blender's render")?;
    if bytes.len() < 10_000 {
        bail!("Blender's render is only {} bytes", bytes.len());
    }
    if let Some(dir) = render.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(render, &bytes)?;
    println!("  Cycles render: {}", render.display());
    if run.join("xr").is_dir() {
        blender_xr(&program, &script, run, &scratch)?;
    } else {
        println!("  no xr/ folder in the run: the XR hands' armatures are not checked");
    }
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// Runs `script` (`check_blender.py`) in Blender on `glb`, rendering to `png` (none: no
/// render), and returns the report it writes to `report`.
fn run_blender(
    program: &Path,
    script: &Path,
    glb: &Path,
    png: Option<&Path>,
    report: &Path,
) -> Result<Value> {
    let out = Command::new(program)
        .args([
            "-b",
            "--factory-startup",
            "--python-exit-code",
            "3",
            "--python",
        ])
        .arg(script)
        .arg("--")
        .arg(glb)
        .arg(png.map_or(Path::new("-"), |p| p))
        .arg(report)
        .output()
        .with_context(|| format!("running {}", program.display()))?;
    let log =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    if !out.status.success() || !report.is_file() {
        let hint = if log.contains("No module named 'numpy'") {
            "\n(Blender's Python has no numpy: apt-get install python3-numpy)"
        } else {
            ""
        };
        let tail: Vec<&str> = log.lines().rev().take(25).collect();
        bail!(
            "Blender failed ({}) on {}:\n{}{hint}",
            out.status,
            glb.display(),
            tail.into_iter().rev().collect::<Vec<_>>().join("\n")
        );
    }
    serde_json::from_slice(&std::fs::read(report)?).context("Blender's report")
}

/// The run's per-hand XR avatars (`xr/left.glb`, `xr/right.glb`) in Blender: each imports as
/// one armature whose bones are exactly the bones `joints.json` lists for that hand, as many
/// as the convention has joints (WebXR 25, OpenXR 26). (That the names are WebXR's own is
/// checked by the `xr` client: `XRHandMeshModel` binds its bones by them.)
fn blender_xr(program: &Path, script: &Path, run: &Path, scratch: &Path) -> Result<()> {
    let dir = run.join("xr");
    let joints: Value =
        serde_json::from_slice(&std::fs::read(dir.join("joints.json")).context("xr/joints.json")?)
            .context("xr/joints.json is not JSON")?;
    let convention = joints["convention"]
        .as_str()
        .context("xr/joints.json names no convention")?;
    for side in ["left", "right"] {
        let glb = dir.join(format!("{side}.glb"));
        let report = run_blender(
            program,
            script,
            &glb,
            None,
            &scratch.join(format!("xr_{side}.json")),
        )?;
        let armatures = report["armatures"].as_array().cloned().unwrap_or_default();
        let [armature] = &armatures[..] else {
            bail!(
                "{}: Blender finds {} armatures, not one",
                glb.display(),
                armatures.len()
            );
        };
        let mut bones: Vec<String> = armature["bones"]
            .as_array()
            .map(|b| {
                b.iter()
                    .filter_map(|n| n.as_str().map(String::from))
                    .collect()
            })
            .unwrap_or_default();
        let mut expected: Vec<String> = joints[side]
            .as_array()
            .map(|j| {
                j.iter()
                    .filter_map(|j| j["bone"].as_str().map(String::from))
                    .collect()
            })
            .unwrap_or_default();
        let count = match convention {
            "webxr" => 25,
            "openxr" => 26,
            other => bail!("xr/joints.json: unknown convention `{other}`"),
        };
        if expected.len() != count {
            bail!(
                "xr/joints.json lists {} bones for the {side} hand, not {convention}'s {count} joints",
                expected.len()
            );
        }
        bones.sort();
        expected.sort();
        if bones != expected {
            let missing: Vec<&String> = expected.iter().filter(|n| !bones.contains(n)).collect();
            let extra: Vec<&String> = bones.iter().filter(|n| !expected.contains(n)).collect();
            bail!(
                "{}: the armature's {} bones are not {convention}'s {} joints (missing {missing:?}, \
                 not joints {extra:?})",
                glb.display(),
                bones.len(),
                expected.len()
            );
        }
        println!(
            "  xr/{side}.glb: one armature ({}), {} bones, those joints.json lists ({convention})",
            armature["name"].as_str().unwrap_or("?"),
            bones.len()
        );
    }
    Ok(())
}
