//! The report's interactive 3D view of the avatar: an HTML fragment that shows a run's
//! `avatar.glb` with three.js, lit by the estimated light.
//!
//! The fragment is self-contained and works offline, from `file://` too: three.js (vendored
//! in `crates/bitt-outputs/assets/vendor/three/`, see its README) is embedded as ES modules behind an
//! import map whose entries are `data:text/javascript;base64,...` URLs, and the GLB is
//! embedded as base64 and handed to `GLTFLoader.parse`. A data URL has no hierarchy, so the
//! modules' relative imports (`./three.core.js`, `../utils/...`) are rewritten here to bare
//! specifiers the import map names.
//!
//! What the view does:
//! - shades as the trainer renders (PyTorch3D's Phong with the reference's material, which
//!   has no specular term: `(ambient + diffuse max(0, n.l)) albedo`, a point light without
//!   falloff), on the textures' own values (no colour management), so the first frame looks
//!   like the training view's fine render;
//! - starts on the ray from the training camera through the hands' centre, framed on their
//!   bounding box, and orbits and zooms about that centre (OrbitControls);
//! - moves the light with two sliders, azimuth about the vertical through the hands' centre
//!   (0 = towards the training camera, positive = to its right) and elevation, at the
//!   estimated light's distance; they start at the estimated location;
//! - shows both hands, the left or the right one (nodes `left_hand` / `right_hand`, or meshes
//!   under them);
//! - plays and pauses the GLB's first animation clip, with a button shown only when there is
//!   one.
//!
//! With the page's URL ending in `#viewer-only` only the viewer is shown, filling the window
//! (used for screenshots: `cargo xtask check-clients`, `docs/clients.md`). Once the first
//! frame is drawn, the hidden `<output id="bitt-viewer-status" data-state="ready">` holds a
//! JSON summary (meshes, hands found, animations, the canvas's rectangle); on failure
//! `data-state="error"` and the message is shown under the canvas.

use std::path::Path;

use bitt_render::scene::LightValues;

use crate::OutputError;
use crate::outputs::base64;
use bitt_stdx::FileErrorExt;

/// The vendored three.js release (`crates/bitt-outputs/assets/vendor/three/README.md`).
pub(crate) const THREE_VERSION: &str = "0.187.0";

/// The ids of the viewer's elements: canvas, controls, status.
pub mod ids {
    /// The WebGL canvas.
    pub(crate) const CANVAS: &str = "bitt-canvas";
    /// Hands shown: `both`, `left_hand`, `right_hand`.
    pub(crate) const HANDS: &str = "bitt-hands";
    /// Light azimuth slider (degrees).
    pub(crate) const LIGHT_AZIMUTH: &str = "bitt-light-azimuth";
    /// Light elevation slider (degrees).
    pub(crate) const LIGHT_ELEVATION: &str = "bitt-light-elevation";
    /// Puts the light back at the estimated location.
    pub(crate) const LIGHT_RESET: &str = "bitt-light-reset";
    /// Play / pause of the animation clip (hidden without one).
    pub(crate) const PLAY: &str = "bitt-play";
    /// JSON summary once the first frame is drawn (`data-state` `ready` or `error`).
    pub(crate) const STATUS: &str = "bitt-viewer-status";
    /// Every id above.
    pub const ALL: [&str; 7] = [
        CANVAS,
        HANDS,
        LIGHT_AZIMUTH,
        LIGHT_ELEVATION,
        LIGHT_RESET,
        PLAY,
        STATUS,
    ];
}

/// One vendored ES module: its import-map specifier, its source and the rewrites of its
/// relative imports to bare specifiers.
pub(crate) struct Module {
    pub(crate) specifier: &'static str,
    pub(crate) source: &'static str,
    pub(crate) rewrites: &'static [(&'static str, &'static str)],
}

/// The vendored three.js modules the viewer imports (and the XR page, `xr_page.rs`, with
/// one more).
pub(crate) const MODULES: [Module; 6] = [
    Module {
        specifier: "three",
        source: include_str!("../assets/vendor/three/three.module.min.js"),
        rewrites: &[("\"./three.core.js\"", "\"three/core\"")],
    },
    Module {
        specifier: "three/core",
        source: include_str!("../assets/vendor/three/three.core.min.js"),
        rewrites: &[],
    },
    Module {
        specifier: "three/addons/utils/BufferGeometryUtils.js",
        source: include_str!("../assets/vendor/three/BufferGeometryUtils.min.js"),
        rewrites: &[],
    },
    Module {
        specifier: "three/addons/utils/SkeletonUtils.js",
        source: include_str!("../assets/vendor/three/SkeletonUtils.min.js"),
        rewrites: &[],
    },
    Module {
        specifier: "three/addons/loaders/GLTFLoader.js",
        source: include_str!("../assets/vendor/three/GLTFLoader.min.js"),
        rewrites: &[
            (
                "\"../utils/BufferGeometryUtils.js\"",
                "\"three/addons/utils/BufferGeometryUtils.js\"",
            ),
            (
                "\"../utils/SkeletonUtils.js\"",
                "\"three/addons/utils/SkeletonUtils.js\"",
            ),
        ],
    },
    Module {
        specifier: "three/addons/controls/OrbitControls.js",
        source: include_str!("../assets/vendor/three/OrbitControls.min.js"),
        rewrites: &[],
    },
];

/// The import map of `modules`: each one a base64 `data:` URL, its relative imports
/// rewritten.
pub(crate) fn import_map<'a>(modules: impl IntoIterator<Item = &'a Module>) -> String {
    let imports: serde_json::Map<String, serde_json::Value> = modules
        .into_iter()
        .map(|m| {
            let source = m
                .rewrites
                .iter()
                .fold(m.source.to_string(), |s, (from, to)| s.replace(from, to));
            (
                m.specifier.to_string(),
                format!("data:text/javascript;base64,{}", base64(source.as_bytes())).into(),
            )
        })
        .collect();
    serde_json::json!({ "imports": imports }).to_string()
}

/// The viewer: a `<section id="bitt-viewer">` with its style, controls, canvas, the GLB
/// (base64), the light and the scripts, for `glb` (a run's `avatar.glb`) lit by `light`
/// (training camera frame, OpenCV axes, as `light.json`).
pub(crate) fn viewer_html(glb: &[u8], light: &LightValues) -> String {
    let finite = |v: [f32; 3]| v.map(|x| if x.is_finite() { x } else { 0.0 });
    let light_json = serde_json::json!({
        "ambient": finite(light.ambient),
        "diffuse": finite(light.diffuse),
        "specular": finite(light.specular),
        "location": finite(light.location),
    })
    .to_string()
    .replace("</", "<\\/");
    let swatch = |name: &str, c: [f32; 3]| {
        let c = finite(c);
        let byte = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
        format!(
            "{name} <span class=\"bitt-swatch\" style=\"background:rgb({},{},{})\"></span> \
             ({:.2}, {:.2}, {:.2})",
            byte(c[0]),
            byte(c[1]),
            byte(c[2]),
            c[0],
            c[1],
            c[2]
        )
    };
    let mut html = String::with_capacity(glb.len() * 4 / 3 + 1_300_000);
    html.push_str(&format!(
        "<!-- 3D view: three.js {THREE_VERSION}, Copyright 2010-2026 Three.js Authors, \
         MIT licence (https://github.com/mrdoob/three.js/blob/dev/LICENSE), embedded below. -->\n\
         <section id=\"bitt-viewer\"><style>{STYLE}</style>\n\
         <div class=\"bitt-viewer-bar\">\
         <label>Show <select id=\"{hands}\"><option value=\"both\">both hands</option>\
         <option value=\"left_hand\">left hand</option>\
         <option value=\"right_hand\">right hand</option></select></label>\
         <span>Light azimuth <input type=\"range\" id=\"{az}\" min=\"-180\" max=\"180\" \
         step=\"1\" value=\"0\"> elevation <input type=\"range\" id=\"{el}\" min=\"-89\" \
         max=\"89\" step=\"1\" value=\"0\"> <output id=\"bitt-light-value\"></output></span>\
         <button type=\"button\" id=\"{reset}\">Estimated light</button>\
         <button type=\"button\" id=\"{play}\" hidden>Play</button></div>\n\
         <canvas id=\"{canvas}\"></canvas>\n\
         <p class=\"bitt-viewer-note\">The avatar (<code>avatar.glb</code>) lit as the trainer \
         renders it. Drag to orbit, scroll to zoom, right-drag to pan. The sliders move the \
         light about the hands (0\u{b0}, 0\u{b0}: from the training camera). Estimated light: \
         {ambient}; {diffuse}; {specular} (not used: the reference's material has no \
         specular term).</p>\n\
         <p id=\"bitt-viewer-error\" hidden></p>\
         <output id=\"{status}\" hidden></output>\n",
        hands = ids::HANDS,
        az = ids::LIGHT_AZIMUTH,
        el = ids::LIGHT_ELEVATION,
        reset = ids::LIGHT_RESET,
        play = ids::PLAY,
        canvas = ids::CANVAS,
        status = ids::STATUS,
        ambient = swatch("ambient", light.ambient),
        diffuse = swatch("diffuse", light.diffuse),
        specular = swatch("specular", light.specular),
    ));
    html.push_str(&format!(
        "<script type=\"application/json\" id=\"bitt-light\">{light_json}</script>\n"
    ));
    html.push_str("<script type=\"application/octet-stream\" id=\"bitt-avatar-glb\">");
    html.push_str(&base64(glb));
    html.push_str("</script>\n<script type=\"importmap\">");
    html.push_str(&import_map(&MODULES));
    html.push_str("</script>\n<script type=\"module\">");
    html.push_str(APP);
    html.push_str("</script></section>\n");
    html
}

/// The viewer of a run's avatar: [`viewer_html`] for the GLB at `glb_path` and the light
/// JSON at `light_path` (a run folder's `avatar.glb` and `light.json`). The light is read
/// leniently (a non-finite value, written as `null`, becomes 0) so that a report is still
/// written for a run whose light estimate broke down.
///
/// # Errors
/// [`OutputError`] when either file cannot be read or the light is not a JSON object.
pub fn run_viewer_html(glb_path: &Path, light_path: &Path) -> Result<String, OutputError> {
    let read = |path: &Path| std::fs::read(path).map_err(|e| OutputError::io(path, e));
    let glb = read(glb_path)?;
    let value: serde_json::Value = serde_json::from_slice(&read(light_path)?)
        .map_err(|e| OutputError::format(light_path, format!("not JSON: {e}")))?;
    if !value.is_object() {
        return Err(OutputError::format(light_path, "not a light"));
    }
    let rgb = |key: &str| -> [f32; 3] {
        std::array::from_fn(|i| value[key][i].as_f64().map_or(f32::NAN, |x| x as f32))
    };
    let light = LightValues {
        ambient: rgb("ambient"),
        diffuse: rgb("diffuse"),
        specular: rgb("specular"),
        location: rgb("location"),
    };
    Ok(viewer_html(&glb, &light))
}

const STYLE: &str = "\
#bitt-viewer{position:relative;max-width:960px;margin:1em 0}\
#bitt-viewer canvas{display:block;width:100%;aspect-ratio:3/2;border:1px solid #ccc;\
background:#30343b;touch-action:none}\
.bitt-viewer-bar{display:flex;flex-wrap:wrap;gap:.4em 1.2em;align-items:center;\
padding:.4em .6em;font-size:.9em;background:#eef0f3;border:1px solid #ccc;border-bottom:none}\
.bitt-viewer-bar input[type=range]{width:9em;vertical-align:middle}\
.bitt-viewer-note{font-size:.85em;color:#444}\
.bitt-swatch{display:inline-block;width:.9em;height:.9em;border:1px solid #888;\
vertical-align:middle}\
#bitt-viewer-error{color:#a00}\
html.bitt-viewer-only body{margin:0;overflow:hidden}\
html.bitt-viewer-only body>*:not(#bitt-viewer){display:none}\
html.bitt-viewer-only #bitt-viewer{position:fixed;inset:0;max-width:none;margin:0;\
display:flex;flex-direction:column}\
html.bitt-viewer-only #bitt-viewer canvas{flex:1;min-height:0;width:100%;height:auto;\
aspect-ratio:auto;border:none}\
html.bitt-viewer-only .bitt-viewer-bar{border:none;border-bottom:1px solid #ccc}\
html.bitt-viewer-only .bitt-viewer-note{display:none}";

/// The viewer's script (an ES module importing three.js through the import map).
const APP: &str = r##"
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const $ = (id) => document.getElementById(id);
const canvas = $('bitt-canvas');
const status = $('bitt-viewer-status');
const light = JSON.parse($('bitt-light').textContent);
const BACKGROUND = 0x30343b;
const HANDS = ['left_hand', 'right_hand'];

const viewerOnly = () =>
  document.documentElement.classList.toggle('bitt-viewer-only', location.hash === '#viewer-only');
viewerOnly();
window.addEventListener('hashchange', viewerOnly);

function fail(message) {
  status.dataset.state = 'error';
  status.textContent = JSON.stringify({ error: String(message) });
  const note = $('bitt-viewer-error');
  note.textContent = '3D view unavailable: ' + message;
  note.hidden = false;
}

// The textures and the light are values of the training images: shade them as the trainer
// does, with no colour-space conversion on the way in or out.
THREE.ColorManagement.enabled = false;
let renderer;
try {
  renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
} catch (e) {
  fail(e.message || e);
  throw e;
}
renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
renderer.setClearColor(BACKGROUND, 1);

const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(30, 1, 0.001, 100);
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = true;
let dirty = true;
controls.addEventListener('change', () => { dirty = true; });

// The trainer shades (La + Ld max(0, n.l)) albedo with a point light without falloff (the
// reference's material has no specular term); three's Lambert BRDF divides by pi.
const rgb = (c) => new THREE.Color(c[0], c[1], c[2]);
const ambient = new THREE.AmbientLight(rgb(light.ambient), Math.PI);
const point = new THREE.PointLight(rgb(light.diffuse), Math.PI, 0, 0);
scene.add(ambient, point);

// OpenCV camera axes (x right, y down, z forward) to glTF's (y up, z backward).
const fromCamera = (p) => new THREE.Vector3(p[0], -p[1], -p[2]);

function resize() {
  const w = Math.max(canvas.clientWidth, 1), h = Math.max(canvas.clientHeight, 1);
  const r = renderer.getPixelRatio();
  if (canvas.width !== Math.floor(w * r) || canvas.height !== Math.floor(h * r)) {
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    dirty = true;
  }
}

// The hand a mesh belongs to: its own name or its nearest named ancestor's.
function handOf(object) {
  for (let o = object; o; o = o.parent) if (HANDS.includes(o.name)) return o.name;
  return null;
}

// Puts the camera on the ray from the training camera (the origin) through the hands'
// centre, far enough back that every corner of their box is in view.
function frame(box) {
  resize();
  const center = box.getCenter(new THREE.Vector3());
  const back = center.lengthSq() > 0
    ? center.clone().normalize().negate()
    : new THREE.Vector3(0, 0, 1);
  camera.position.copy(center).add(back);
  camera.up.set(0, 1, 0);
  camera.lookAt(center);
  camera.updateMatrixWorld();
  const right = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 0);
  const up = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
  const tanV = 0.9 * Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2);
  const tanH = tanV * camera.aspect;
  let distance = 0;
  let radius = 0;
  for (let i = 0; i < 8; i++) {
    const corner = new THREE.Vector3(
      i & 1 ? box.max.x : box.min.x,
      i & 2 ? box.max.y : box.min.y,
      i & 4 ? box.max.z : box.min.z,
    ).sub(center);
    const z = corner.dot(back);
    distance = Math.max(
      distance,
      z + Math.abs(corner.dot(right)) / tanH,
      z + Math.abs(corner.dot(up)) / tanV,
    );
    radius = Math.max(radius, corner.length());
  }
  distance = Math.max(distance, 1e-3);
  radius = Math.max(radius, 1e-3);
  camera.position.copy(center).addScaledVector(back, distance);
  camera.near = Math.max(distance - 4 * radius, distance / 100);
  camera.far = distance + 4 * radius;
  camera.updateProjectionMatrix();
  controls.target.copy(center);
  controls.minDistance = radius / 2;
  controls.maxDistance = distance * 10;
  controls.update();
  return { center, radius };
}

const glb = Uint8Array.from(atob($('bitt-avatar-glb').textContent.trim()), (c) => c.charCodeAt(0));
new GLTFLoader().parse(glb.buffer, '', (gltf) => {
  const model = gltf.scene;
  const meshes = [];
  model.traverse((o) => {
    if (!o.isMesh) return;
    const old = o.material;
    const map = old.map || null;
    if (map) {
      map.colorSpace = THREE.NoColorSpace;
      map.needsUpdate = true;
    }
    o.material = new THREE.MeshLambertMaterial({
      map,
      color: map ? 0xffffff : old.color,
      side: old.side,
    });
    old.dispose();
    meshes.push(o);
  });
  scene.add(model);
  model.updateMatrixWorld(true);
  const { center, radius } = frame(new THREE.Box3().setFromObject(model, true));

  // The light: azimuth about the vertical through the hands' centre (0 = towards the
  // training camera, positive = to its right) and elevation above the horizontal, at the
  // estimated light's distance from that centre.
  const estimated = fromCamera(light.location).sub(center);
  const lightDistance = Math.max(estimated.length(), radius);
  const az = $('bitt-light-azimuth'), el = $('bitt-light-elevation');
  const setLight = () => {
    const a = THREE.MathUtils.degToRad(+az.value), e = THREE.MathUtils.degToRad(+el.value);
    point.position
      .set(Math.cos(e) * Math.sin(a), Math.sin(e), Math.cos(e) * Math.cos(a))
      .multiplyScalar(lightDistance)
      .add(center);
    $('bitt-light-value').textContent = `${az.value}\u00b0, ${el.value}\u00b0`;
    dirty = true;
  };
  const resetLight = () => {
    const d = estimated.lengthSq() > 0 ? estimated.clone().normalize() : new THREE.Vector3(0, 0, 1);
    az.value = Math.round(THREE.MathUtils.radToDeg(Math.atan2(d.x, d.z)));
    el.value = Math.round(THREE.MathUtils.radToDeg(Math.asin(THREE.MathUtils.clamp(d.y, -1, 1))));
    setLight();
  };
  az.addEventListener('input', setLight);
  el.addEventListener('input', setLight);
  $('bitt-light-reset').addEventListener('click', resetLight);
  resetLight();

  const show = $('bitt-hands');
  show.addEventListener('change', () => {
    for (const m of meshes) {
      const hand = handOf(m);
      m.visible = show.value === 'both' || hand === null || hand === show.value;
    }
    dirty = true;
  });

  let mixer = null;
  let playing = false;
  if (gltf.animations.length > 0) {
    mixer = new THREE.AnimationMixer(model);
    const action = mixer.clipAction(gltf.animations[0]);
    const play = $('bitt-play');
    play.hidden = false;
    play.addEventListener('click', () => {
      playing = !playing;
      action.paused = !playing;
      if (playing) action.play();
      play.textContent = playing ? 'Pause' : 'Play';
      dirty = true;
    });
  }

  const timer = new THREE.Timer();
  let frames = 0;
  renderer.setAnimationLoop((time) => {
    timer.update(time);
    resize();
    const delta = timer.getDelta();
    if (mixer && playing) {
      mixer.update(delta);
      dirty = true;
    }
    controls.update(delta);
    if (!dirty) return;
    dirty = false;
    renderer.render(scene, camera);
    if (++frames === 1) {
      const r = canvas.getBoundingClientRect();
      status.dataset.state = 'ready';
      status.textContent = JSON.stringify({
        meshes: meshes.length,
        hands: HANDS.filter((h) => meshes.some((m) => handOf(m) === h)),
        animations: gltf.animations.length,
        canvas: [r.left, r.top, r.width, r.height].map(Math.round),
        window: [window.innerWidth, window.innerHeight],
      });
    }
  });
}, (e) => fail(e.message || e));
"##;

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Base64 (RFC 4648, padded) back to bytes; panics on anything else.
    pub(crate) fn decode_base64(s: &str) -> Vec<u8> {
        let value = |c: u8| match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => panic!("not base64: {c}"),
        };
        let mut out = Vec::new();
        for chunk in s.as_bytes().chunks(4) {
            assert_eq!(chunk.len(), 4, "base64 length");
            let pad = chunk.iter().filter(|&&c| c == b'=').count();
            let n = chunk
                .iter()
                .map(|&c| if c == b'=' { 0 } else { u32::from(value(c)) })
                .fold(0u32, |n, v| (n << 6) | v);
            out.extend(&n.to_be_bytes()[1..4 - pad]);
        }
        out
    }

    /// The text between `start` and the next `end` after it.
    pub(crate) fn between<'a>(s: &'a str, start: &str, end: &str) -> &'a str {
        let i = s.find(start).unwrap_or_else(|| panic!("no {start}")) + start.len();
        let j = s[i..].find(end).unwrap_or_else(|| panic!("no {end}")) + i;
        &s[i..j]
    }

    /// The import map of a page, checked: every module a data URL, relative imports
    /// rewritten, and every bare specifier a module imports is in the map. Returns each
    /// specifier's decoded source.
    pub(crate) fn checked_import_map(html: &str) -> std::collections::BTreeMap<String, String> {
        let map: serde_json::Value =
            serde_json::from_str(between(html, "<script type=\"importmap\">", "</script>"))
                .unwrap();
        let imports = map["imports"].as_object().unwrap();
        let mut sources = std::collections::BTreeMap::new();
        for (specifier, url) in imports {
            let url = url.as_str().unwrap();
            let b64 = url
                .strip_prefix("data:text/javascript;base64,")
                .unwrap_or_else(|| panic!("{specifier}: {}", &url[..40.min(url.len())]));
            let source = String::from_utf8(decode_base64(b64)).unwrap();
            for quote in ['"', '\''] {
                for rel in ["./", "../"] {
                    let pattern = format!("from{quote}{rel}");
                    assert!(!source.contains(&pattern), "{specifier} imports {pattern}");
                }
            }
            let mut rest = source.as_str();
            while let Some(i) = rest.find("from\"") {
                let name = between(&rest[i..], "from\"", "\"");
                assert!(imports.contains_key(name), "{specifier} imports {name}");
                rest = &rest[i + 5..];
            }
            sources.insert(specifier.clone(), source);
        }
        sources
    }

    #[test]
    fn run_viewer_reads_the_avatar_and_light_files() {
        let dir = std::env::temp_dir().join(format!("bitt-viewer-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (glb, light) = (dir.join("avatar.glb"), dir.join("light.json"));
        assert!(run_viewer_html(&glb, &light).is_err(), "no avatar.glb");
        std::fs::write(&glb, b"glTF-bytes").unwrap();
        std::fs::write(
            &light,
            r#"{"ambient": [0.5, 0.5, 0.5], "diffuse": [null, 0.25, 0.25],
                "specular": [0, 0, 0], "location": [0, 0, 0.5], "frame": "camera"}"#,
        )
        .unwrap();
        let html = run_viewer_html(&glb, &light).unwrap();
        assert!(html.contains(&base64(b"glTF-bytes")));
        let l: serde_json::Value =
            serde_json::from_str(between(&html, "id=\"bitt-light\">", "</script>")).unwrap();
        assert_eq!(l["diffuse"], serde_json::json!([0.0, 0.25, 0.25]));
        assert_eq!(l["location"][2], 0.5);
        std::fs::write(&light, "[1, 2]").unwrap();
        assert!(run_viewer_html(&glb, &light).is_err(), "not a light");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn viewer_is_self_contained() {
        let glb: Vec<u8> = (0..1000u32).map(|i| (i * 7 + i / 13) as u8).collect();
        let light = LightValues {
            ambient: [0.5, 0.4, 0.3],
            diffuse: [0.2, 0.3, f32::NAN],
            specular: [0.1; 3],
            location: [0.1, -0.2, 0.3],
        };
        let html = viewer_html(&glb, &light);

        // The GLB comes back byte for byte.
        let embedded = between(&html, "id=\"bitt-avatar-glb\">", "</script>");
        assert_eq!(decode_base64(embedded), glb);

        // The light, finite.
        let l: serde_json::Value =
            serde_json::from_str(between(&html, "id=\"bitt-light\">", "</script>")).unwrap();
        assert_eq!(l["diffuse"][2], 0.0);
        assert!((l["location"][1].as_f64().unwrap() + 0.2).abs() < 1e-6);

        let imports = checked_import_map(&html);
        assert_eq!(imports.len(), MODULES.len());
        for specifier in [
            "three",
            "three/addons/loaders/GLTFLoader.js",
            "three/addons/controls/OrbitControls.js",
        ] {
            assert!(imports.contains_key(specifier), "{specifier}");
        }
        // The app's own imports are in the map too.
        for name in [
            "three",
            "three/addons/loaders/GLTFLoader.js",
            "three/addons/controls/OrbitControls.js",
        ] {
            assert!(APP.contains(&format!("from '{name}'")));
        }
        let core = MODULES
            .iter()
            .find(|m| m.specifier == "three/core")
            .unwrap();
        let revision = THREE_VERSION.split('.').nth(1).unwrap();
        assert!(
            core.source.contains(&format!("=\"{revision}\"")),
            "three.core is not r{revision}"
        );

        // Nothing from the network: the only URL is the licence comment's.
        let comment = between(&html, "<!--", "-->");
        let without_comment = html.replacen(comment, "", 1);
        for scheme in ["http://", "https://", "//cdn", "src=\"", "fetch("] {
            assert!(!without_comment.contains(scheme), "{scheme} in the viewer");
        }
        assert!(comment.contains("MIT licence"));

        // The controls.
        for id in ids::ALL {
            assert_eq!(
                html.matches(&format!("id=\"{id}\"")).count(),
                1,
                "element #{id}"
            );
            assert!(APP.contains(&format!("$('{id}')")), "the script uses #{id}");
        }
        // Only one module script, after the import map.
        assert!(html.find("type=\"importmap\"") < html.find("type=\"module\""));
        assert_eq!(html.matches("type=\"module\"").count(), 1);
    }
}
