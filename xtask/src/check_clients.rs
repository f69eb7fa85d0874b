//! `cargo xtask check-clients [--run DIR] [--iterations N] [--only chromium|blender]
//! [--screenshot PNG] [--chromium PATH] [--render PNG] [--blender PATH]`:
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
//! - [`blender`]: `avatar.glb` in Blender (Debian's `blender`, headless, `check_blender.py`):
//!   two armatures of at least 21 bones; rotating `right_index1` by 45 degrees moves the right
//!   index finger's vertices and not the thumb's; a Cycles render (saved to
//!   `docs/images/avatar_blender.png`).

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};
use serde_json::Value;

/// Command-line options.
struct Options {
    run: Option<PathBuf>,
    iterations: usize,
    screenshot: PathBuf,
    chromium: Option<PathBuf>,
    render: PathBuf,
    blender: Option<PathBuf>,
    only: Option<String>,
}

impl Options {
    fn parse(args: &[String]) -> Result<Self> {
        let mut o = Options {
            run: None,
            iterations: 300,
            screenshot: crate::root().join("docs/images/report_viewer.png"),
            chromium: std::env::var_os("BITT_CHROMIUM").map(PathBuf::from),
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
                "--chromium" => o.chromium = Some(PathBuf::from(value()?)),
                "--render" => o.render = PathBuf::from(value()?),
                "--blender" => o.blender = Some(PathBuf::from(value()?)),
                "--only" => {
                    let v = value()?.clone();
                    if !["chromium", "blender"].contains(&v.as_str()) {
                        bail!("--only takes chromium or blender, not `{v}`");
                    }
                    o.only = Some(v);
                }
                other => bail!(
                    "unknown option `{other}`; usage: cargo xtask check-clients [--run DIR] \
                     [--iterations N] [--only chromium|blender] [--screenshot PNG] \
                     [--chromium PATH] [--render PNG] [--blender PATH]"
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
        .arg("--cache")
        .arg(crate::root().join("runs/cache"))
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

/// The browser's window in CSS pixels (device scale factor 1: one pixel each).
const WINDOW: (u32, u32) = (960, 640);

/// Flags for every headless Chromium run here: no GPU, WebGL through SwiftShader (ANGLE),
/// a throw-away profile, and virtual time so the page's scripts (module parsing, the GLB's
/// decoding, the first frames) finish before the DOM or the screenshot is taken.
fn chromium_flags(profile: &Path) -> Vec<String> {
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
        format!("--window-size={},{}", WINDOW.0, WINDOW.1),
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

/// Runs Chromium on `url` with `extra` flags; returns stdout. Fails with the page's console
/// messages when Chromium fails.
fn run_chromium(program: &Path, profile: &Path, extra: &[String], url: &str) -> Result<String> {
    let out = Command::new(program)
        .args(chromium_flags(profile))
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
    let start = dom
        .find("id=\"bitt-viewer-status\"")
        .context("the page has no 3D viewer (no #bitt-viewer-status)")?;
    let element = &dom[start..];
    let open_end = element.find('>').context("unterminated status element")?;
    let close = element
        .find("</output>")
        .context("unterminated status element")?;
    let state = element[..open_end]
        .split("data-state=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .unwrap_or("");
    let text = element[open_end + 1..close]
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&amp;", "&");
    let mut v: Value = if text.trim().is_empty() {
        serde_json::json!({})
    } else {
        serde_json::from_str(&text).with_context(|| format!("viewer status `{text}`"))?
    };
    v["state"] = state.into();
    Ok(v)
}

/// Checks `report.html` of `run` in headless Chromium: the 3D view loads and draws both hands
/// (its status), in the report as it opens and alone (`#viewer-only`); then a screenshot of
/// the view alone is saved to `screenshot` and its canvas region must show the hands: enough
/// pixels off the background, centred, lit and textured (statistics computed by Chromium on
/// the PNG itself, embedded as a data URL in a scratch page).
pub fn chromium(run: &Path, screenshot: &Path, program: Option<&Path>) -> Result<()> {
    let program = find_chromium(program)?;
    let scratch = std::env::temp_dir().join(format!("bitt-check-chromium-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let profile = scratch.join("profile");
    let report = std::fs::canonicalize(run.join("report.html"))
        .with_context(|| format!("{}/report.html", run.display()))?;
    let report_url = file_url(&report);
    let dump = ["--dump-dom".to_string()];

    // 1. The report as it opens, and the viewer alone: the viewer's own status.
    let mut canvas = None;
    for url in [report_url.clone(), format!("{report_url}#viewer-only")] {
        let dom = run_chromium(&program, &profile, &dump, &url)?;
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
    let rect: Vec<u32> = canvas
        .as_ref()
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|x| x.as_u64())
                .map(|x| x as u32)
                .collect()
        })
        .unwrap_or_default();
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
    run_chromium(
        &program,
        &profile,
        &[format!("--screenshot={}", shot.display())],
        &format!("{report_url}#viewer-only"),
    )?;
    let png = std::fs::read(&shot).context("Chromium wrote no screenshot")?;

    // 3. Its canvas region, measured by Chromium on the PNG.
    let page = scratch.join("measure.html");
    std::fs::write(&page, measure_page(&png, [x, y, w]))?;
    let dom = run_chromium(&program, &profile, &dump, &file_url(&page))?;
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
    let report_path = scratch.join("report.json");
    let png = scratch.join("render.png");
    println!(
        "check-clients: Blender ({}) on {}",
        program.display(),
        glb.display()
    );
    let out = Command::new(&program)
        .args([
            "-b",
            "--factory-startup",
            "--python-exit-code",
            "3",
            "--python",
        ])
        .arg(&script)
        .arg("--")
        .args([&glb, &png, &report_path])
        .output()
        .with_context(|| format!("running {}", program.display()))?;
    let log =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    if !out.status.success() || !report_path.is_file() {
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
    let report: Value =
        serde_json::from_slice(&std::fs::read(&report_path)?).context("Blender's report")?;
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
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}
