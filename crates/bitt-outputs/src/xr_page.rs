//! `xr.html`: the per-hand XR avatars (`left.glb`, `right.glb`) shown by three.js's own
//! `XRHandMeshModel`, driven by tracked joint poses: the scene's poses played back, or live
//! WebXR hand tracking when a headset is present.
//!
//! The page is self-contained and works offline, from `file://` too, built as the report's
//! viewer is (`viewer.rs`): the vendored three.js r187 modules, plus
//! `examples/jsm/webxr/XRHandMeshModel.js` (unchanged, see
//! `crates/bitt-outputs/assets/vendor/three/README.md`), are embedded as `data:` URLs behind an import
//! map; the two GLBs are embedded as base64 and parsed with `GLTFLoader.parseAsync` into the
//! asset cache `XRHandMeshModel` takes (`{'bitt/left.glb': gltf, 'bitt/right.glb': gltf}`),
//! so its default CDN path is never used.
//!
//! The playback (`playback.json`, embedded as JSON) holds frames of 25 WebXR joint poses per
//! hand (column-major 4x4, the frame's camera space with WebXR axes, metres: what
//! `XRFrame.getJointPose(joint, space).transform.matrix` returns) and each frame's pinhole
//! camera. Playback goes through three's real input path: per hand a `WebXRController`, a stub
//! `XRInputSource` (`hand`: a map of joint spaces) and a stub `XRFrame` whose `getJointPose`
//! returns the frame's poses; `controller.update()` moves the hand space's joints and
//! `XRHandMeshModel.updateMesh()` copies them onto the GLB's bones before each render. A hand
//! that a frame lacks (`null`) is reported untracked (`update` without an input source), so
//! three hides it.
//!
//! Modes (the URL's fragment):
//! - default: play / pause through the frames (one a second), a frame selector, orbit and zoom
//!   from the frame's camera (its intrinsics letterboxed into the canvas), hemisphere and
//!   directional light on the GLBs' own materials; `#frame=K` starts at frame K. When
//!   `navigator.xr` supports `immersive-vr` / `immersive-ar`, "Enter VR" / "Enter AR" start a
//!   session (`hand-tracking`, `local-floor` optional) and `XRHandMeshModel` follows the live
//!   hands (`renderer.xr.getHand(0/1)`), the playback hidden meanwhile;
//! - `#test=K`: frame K alone for a pixel comparison (`cargo xtask check-clients`,
//!   `docs/clients.md`): the canvas exactly the frame's width x height at pixel ratio 1, black,
//!   no antialiasing, each hand unlit in a pure colour (left `#ff0000`, right `#00ff00`), the
//!   frame's camera exactly. `#test=K&size=S`: the same at S pixels wide, the intrinsics
//!   scaled by S / width (as `bitt render-avatar --size S` scales a square camera).
//!
//! The hidden `<output id="bitt-xr-status">` has `data-state` `loading`, `ready` (once the
//! first frame is drawn; its text is a JSON summary) or `error`, and `data-warnings`: the
//! page's `console.warn` messages as a JSON array (`XRHandMeshModel` warns "Couldn't find
//! <joint> in <hand> hand mesh" for a bone it cannot bind).

use crate::outputs::base64;
use crate::viewer::{MODULES, Module, THREE_VERSION, import_map};

/// The ids of the page's elements.
pub mod ids {
    /// The WebGL canvas.
    pub(crate) const CANVAS: &str = "bitt-xr-canvas";
    /// Play / pause of the playback.
    pub(crate) const PLAY: &str = "bitt-xr-play";
    /// The frame shown (a `<select>`).
    pub const FRAME: &str = "bitt-xr-frame";
    /// Back to the frame's camera view.
    pub(crate) const RESET_VIEW: &str = "bitt-xr-reset-view";
    /// Starts an `immersive-vr` session (hidden unless supported).
    pub(crate) const ENTER_VR: &str = "bitt-xr-enter-vr";
    /// Starts an `immersive-ar` session (hidden unless supported).
    pub(crate) const ENTER_AR: &str = "bitt-xr-enter-ar";
    /// Error message (hidden unless something failed).
    pub(crate) const ERROR: &str = "bitt-xr-error";
    /// `data-state` `loading` / `ready` / `error`, `data-warnings`, JSON summary once ready.
    pub(crate) const STATUS: &str = "bitt-xr-status";
    /// The playback JSON.
    pub(crate) const PLAYBACK: &str = "bitt-xr-playback";
    /// `left.glb`, base64.
    pub(crate) const LEFT_GLB: &str = "bitt-xr-left-glb";
    /// `right.glb`, base64.
    pub(crate) const RIGHT_GLB: &str = "bitt-xr-right-glb";
    /// Every id above.
    pub const ALL: [&str; 11] = [
        CANVAS, PLAY, FRAME, RESET_VIEW, ENTER_VR, ENTER_AR, ERROR, STATUS, PLAYBACK, LEFT_GLB,
        RIGHT_GLB,
    ];
}

/// three.js r187's `XRHandMeshModel` (vendored unchanged), its imports rewritten to the
/// import map's specifiers.
const XR_HAND_MESH_MODEL: Module = Module {
    specifier: "three/addons/webxr/XRHandMeshModel.js",
    source: include_str!("../assets/vendor/three/XRHandMeshModel.min.js"),
    rewrites: &[
        (
            "\"../loaders/GLTFLoader.js\"",
            "\"three/addons/loaders/GLTFLoader.js\"",
        ),
        (
            "\"../utils/SkeletonUtils.js\"",
            "\"three/addons/utils/SkeletonUtils.js\"",
        ),
    ],
};

/// The XR page: a complete HTML document showing `left_glb` and `right_glb` (the per-hand XR
/// avatars) driven by `playback_json` (the `bitt-xr-playback` JSON; see the module docs). The
/// JSON is embedded as it is, with every `<` written `\u003c` so that no string in it can end
/// the script element.
pub(crate) fn xr_html(left_glb: &[u8], right_glb: &[u8], playback_json: &str) -> String {
    let mut html = String::with_capacity((left_glb.len() + right_glb.len()) * 4 / 3 + 1_300_000);
    html.push_str(&format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <title>BiTT: your hands in XR</title>\n\
         <!-- three.js {THREE_VERSION} with examples/jsm/webxr/XRHandMeshModel.js, Copyright \
         2010-2026 Three.js Authors, MIT licence \
         (https://github.com/mrdoob/three.js/blob/dev/LICENSE), embedded below. -->\n\
         <style>{STYLE}</style></head><body>\n\
         <div class=\"bitt-xr-bar\">\
         <button type=\"button\" id=\"{play}\">Play</button>\
         <label>Frame <select id=\"{frame}\"></select></label>\
         <button type=\"button\" id=\"{reset}\">Camera view</button>\
         <button type=\"button\" id=\"{vr}\" hidden>Enter VR</button>\
         <button type=\"button\" id=\"{ar}\" hidden>Enter AR</button>\
         <span class=\"bitt-xr-note\">Each hand (<code>left.glb</code>, <code>right.glb</code>) \
         is three.js's <code>XRHandMeshModel</code> driven by the scene's poses as tracked \
         WebXR joint poses. Drag to orbit, scroll to zoom.</span></div>\n\
         <canvas id=\"{canvas}\"></canvas>\n\
         <p id=\"{error}\" hidden></p>\
         <output id=\"{status}\" data-state=\"loading\" data-warnings=\"[]\" hidden></output>\n",
        play = ids::PLAY,
        frame = ids::FRAME,
        reset = ids::RESET_VIEW,
        vr = ids::ENTER_VR,
        ar = ids::ENTER_AR,
        canvas = ids::CANVAS,
        error = ids::ERROR,
        status = ids::STATUS,
    ));
    html.push_str(&format!(
        "<script type=\"application/json\" id=\"{}\">{}</script>\n",
        ids::PLAYBACK,
        playback_json.replace('<', "\\u003c")
    ));
    for (id, glb) in [(ids::LEFT_GLB, left_glb), (ids::RIGHT_GLB, right_glb)] {
        html.push_str(&format!(
            "<script type=\"application/octet-stream\" id=\"{id}\">{}</script>\n",
            base64(glb)
        ));
    }
    html.push_str("<script type=\"importmap\">");
    html.push_str(&import_map(MODULES.iter().chain([&XR_HAND_MESH_MODEL])));
    html.push_str("</script>\n<script type=\"module\">");
    html.push_str(APP);
    html.push_str("</script>\n</body></html>\n");
    html
}

const STYLE: &str = "\
html,body{margin:0;height:100%;overflow:hidden;font:14px system-ui,sans-serif}\
body{display:flex;flex-direction:column}\
.bitt-xr-bar{display:flex;flex-wrap:wrap;gap:.4em 1em;align-items:center;padding:.4em .6em;\
background:#eef0f3;border-bottom:1px solid #ccc}\
.bitt-xr-note{font-size:.85em;color:#444}\
#bitt-xr-canvas{display:block;flex:1;min-height:0;width:100%;background:#30343b;\
touch-action:none}\
#bitt-xr-error{margin:0;padding:.4em .6em;color:#a00}\
html.bitt-xr-test body{display:block;background:#000}\
html.bitt-xr-test .bitt-xr-bar,html.bitt-xr-test #bitt-xr-error{display:none}\
html.bitt-xr-test #bitt-xr-canvas{flex:none;background:#000}";

/// The page's script (an ES module importing three.js through the import map).
const APP: &str = r##"
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { XRHandMeshModel } from 'three/addons/webxr/XRHandMeshModel.js';

const $ = (id) => document.getElementById(id);
const status = $('bitt-xr-status');

// Every console.warn (XRHandMeshModel's "Couldn't find <joint> in <hand> hand mesh" among
// them) goes into the status element too.
const warnings = [];
const consoleWarn = console.warn.bind(console);
console.warn = (...args) => {
  warnings.push(args.map(String).join(' '));
  status.dataset.warnings = JSON.stringify(warnings);
  consoleWarn(...args);
};

function fail(message) {
  status.dataset.state = 'error';
  status.textContent = JSON.stringify({ error: String(message) });
  const note = $('bitt-xr-error');
  note.textContent = 'XR hands unavailable: ' + message;
  note.hidden = false;
}
window.addEventListener('error', (e) => fail(e.message || e));
window.addEventListener('unhandledrejection', (e) => fail((e.reason && e.reason.message) || e.reason));

// The asset path and cache key XRHandMeshModel builds ('bitt/left.glb', 'bitt/right.glb'):
// the embedded GLBs, never its default CDN.
const PATH = 'bitt/';
const HANDS = [['left', 0xff0000], ['right', 0x00ff00]];
const NEAR = 0.01, FAR = 100;
const BACKGROUND = 0x30343b;

const playback = JSON.parse($('bitt-xr-playback').textContent);
const JOINTS = playback.joints;
const frames = playback.frames;
const testMatch = /^#test=(\d+)(?:&size=(\d+))?$/.exec(location.hash);
const test = testMatch ? Number(testMatch[1]) : null;
const testWidth = testMatch && testMatch[2] ? Number(testMatch[2]) : null;
const startMatch = /^#frame=(\d+)$/.exec(location.hash);
document.documentElement.classList.toggle('bitt-xr-test', test !== null);

function checkPlayback() {
  if (playback.format !== 'bitt-xr-playback') throw new Error(`not a BiTT XR playback: ${playback.format}`);
  if (playback.convention !== 'webxr') throw new Error(`joint poses in the ${playback.convention} convention; the page plays WebXR's`);
  if (!Array.isArray(JOINTS) || JOINTS.length !== 25) throw new Error('the playback does not list the 25 WebXR joints');
  if (!Array.isArray(frames) || frames.length === 0) throw new Error('the playback has no frames');
  if (test !== null && !(test < frames.length)) throw new Error(`#test=${test}: the playback has ${frames.length} frames`);
  if (testWidth !== null && !(testWidth >= 8 && testWidth <= 4096)) throw new Error(`size=${testWidth}: not 8 to 4096 pixels`);
}

// A projection from a frame's pinhole intrinsics (pixel centres at +0.5, row 0 at the top),
// its image scaled to fit a W x H canvas and centred (letterboxed). At the frame's own size
// it is the frame's camera exactly.
function setProjection(camera, cam, W, H) {
  const s = Math.min(W / cam.width, H / cam.height);
  const fx = cam.fx * s, fy = cam.fy * s;
  const cx = cam.cx * s + (W - cam.width * s) / 2, cy = cam.cy * s + (H - cam.height * s) / 2;
  const n = NEAR, f = FAR;
  camera.projectionMatrix.fromArray([
    2 * fx / W, 0, 0, 0,
    0, 2 * fy / H, 0, 0,
    1 - 2 * cx / W, 2 * cy / H - 1, -(f + n) / (f - n), -1,
    0, 0, -2 * f * n / (f - n), 0,
  ]);
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
}

// A stub XRFrame for one hand: getJointPose returns the frame's pose of the joint (null when
// the frame has none), as an XRJointPose.
function stubFrame(poses) {
  const index = new Map(JOINTS.map((name, i) => [name, i]));
  return {
    session: { visibilityState: 'visible' },
    getJointPose(joint) {
      const m = poses ? poses[index.get(joint.jointName)] : null;
      if (!m) return null;
      const p = new THREE.Vector3(), q = new THREE.Quaternion(), s = new THREE.Vector3();
      new THREE.Matrix4().fromArray(m).decompose(p, q, s);
      return {
        transform: {
          position: { x: p.x, y: p.y, z: p.z, w: 1 },
          orientation: { x: q.x, y: q.y, z: q.z, w: q.w },
          matrix: new Float32Array(m),
        },
        radius: 0.008,
      };
    },
    getPose() { return null; },
  };
}

const decode = (id) => Uint8Array.from(atob($(id).textContent.trim()), (c) => c.charCodeAt(0));

// Both embedded GLBs, parsed. GLTFLoader decodes textures with createImageBitmap where the
// browser has it, and headless Chromium's virtual time (cargo xtask check-clients) does not
// wait for that decode, so the page could be captured before it drew: createImageBitmap is
// hidden while the parsers are made (synchronously, in parseAsync), so that they load <img>
// elements (three's TextureLoader, every browser's path), which virtual time waits for.
function parseGlbs(loader) {
  const createImageBitmap = window.createImageBitmap;
  window.createImageBitmap = undefined;
  try {
    return Promise.all(HANDS.map(([handedness]) =>
      loader.parseAsync(decode(`bitt-xr-${handedness}-glb`).buffer, '')));
  } finally {
    window.createImageBitmap = createImageBitmap;
  }
}

async function main() {
  checkPlayback();
  const canvas = $('bitt-xr-canvas');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: test === null, alpha: true });
  renderer.setClearColor(test === null ? BACKGROUND : 0x000000, 1);
  if (test !== null) {
    // Pure colours stay pure: no output conversion, one pixel per CSS pixel.
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    renderer.setPixelRatio(1);
  } else {
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  }

  const scene = new THREE.Scene();
  const hemisphere = new THREE.HemisphereLight(0xffffff, 0x50505a, 1.6);
  const sun = new THREE.DirectionalLight(0xffffff, 2.2);
  sun.position.set(0.4, 1, 0.8);
  scene.add(hemisphere, sun);

  const parsed = await parseGlbs(new GLTFLoader());
  const cache = {};
  HANDS.forEach(([handedness], i) => { cache[`${PATH}${handedness}.glb`] = parsed[i]; });

  // One WebXRController per hand, as WebXRManager keeps: its hand space, a stub input source
  // (25 joint spaces), connected; XRHandMeshModel binds the GLB's bones to the hand space's
  // joints.
  const hands = HANDS.map(([handedness, colour]) => {
    const controller = new THREE.WebXRController();
    const space = controller.getHandSpace();
    const handModel = new THREE.Object3D();
    space.add(handModel);
    scene.add(space);
    const source = {
      handedness,
      profiles: ['generic-hand'],
      hand: new Map(JOINTS.map((jointName) => [jointName, { jointName }])),
    };
    controller.connect(source);
    const model = new XRHandMeshModel(handModel, space, PATH, handedness, null, null, cache);
    if (test !== null) {
      handModel.traverse((o) => {
        if (o.isMesh) o.material = new THREE.MeshBasicMaterial({ color: colour, side: THREE.DoubleSide });
      });
    }
    return { handedness, controller, space, source, model };
  });
  const bones = Object.fromEntries(hands.map((h) => [h.handedness, h.model.bones.filter(Boolean).length]));

  const camera = new THREE.PerspectiveCamera();
  camera.near = NEAR;
  camera.far = FAR;
  const select = test === null ? $('bitt-xr-frame') : null;
  let current = test ?? Math.min(Number(startMatch ? startMatch[1] : 0), frames.length - 1);
  let dirty = true, playing = false, switched = 0, controls = null;

  // Frame k as tracked joint poses, through three's own update path; updateMesh() right
  // after, so the render shows this frame (XRHandModel would lag one frame behind).
  function showFrame(k) {
    current = k;
    const frame = frames[k];
    for (const h of hands) {
      const poses = frame[h.handedness];
      h.controller.update(poses ? h.source : null, stubFrame(poses), {});
      h.model.updateMesh();
    }
    if (select) select.value = String(k);
    dirty = true;
  }

  function size() {
    if (test !== null) {
      const { width, height } = frames[test].camera;
      if (testWidth === null) return [width, height];
      return [testWidth, Math.round(height * testWidth / width)];
    }
    return [Math.max(canvas.clientWidth, 1), Math.max(canvas.clientHeight, 1)];
  }
  function resize() {
    const [w, h] = size();
    const r = renderer.getPixelRatio();
    if (canvas.width !== Math.floor(w * r) || canvas.height !== Math.floor(h * r)) {
      renderer.setSize(w, h, test !== null);
      dirty = true;
    }
  }

  // The frame's camera (origin, looking down -z), orbiting about the point on its axis at
  // the depth of the hands' joints.
  function cameraView() {
    const frame = frames[current];
    let depth = 0, n = 0;
    for (const [side] of HANDS) for (const m of frame[side] || []) if (m) { depth -= m[14]; n++; }
    depth = n && depth / n > NEAR ? depth / n : 0.5;
    camera.position.set(0, 0, 0);
    camera.quaternion.identity();
    camera.up.set(0, 1, 0);
    if (controls) {
      controls.target.set(0, 0, -depth);
      controls.minDistance = depth / 10;
      controls.maxDistance = depth * 10;
      controls.update();
    }
    dirty = true;
  }

  showFrame(current);
  if (test === null) {
    controls = new OrbitControls(camera, canvas);
    controls.addEventListener('change', () => { dirty = true; });
    setupUi();
  }
  cameraView();

  function setupUi() {
    frames.forEach((f, k) => select.add(new Option(`${k}: ${f.name || 'frame ' + k}`, String(k))));
    select.value = String(current);
    select.addEventListener('change', () => { showFrame(Number(select.value)); cameraView(); });
    const play = $('bitt-xr-play');
    play.disabled = frames.length < 2;
    play.addEventListener('click', () => {
      playing = !playing;
      play.textContent = playing ? 'Pause' : 'Play';
      switched = performance.now();
    });
    $('bitt-xr-reset-view').addEventListener('click', cameraView);
    // Back from a session: the playback's hands and the frame's camera again.
    offerXr(renderer, scene, hands, cache, () => { showFrame(current); cameraView(); });
  }

  let drawn = 0;
  function draw() {
    resize();
    const [w, h] = size();
    setProjection(camera, frames[current].camera, w, h);
    renderer.render(scene, camera);
    dirty = false;
    if (++drawn === 1) {
      const r = canvas.getBoundingClientRect();
      status.dataset.state = 'ready';
      status.textContent = JSON.stringify({
        mode: test === null ? 'playback' : 'test',
        frame: current,
        frames: frames.length,
        name: frames[current].name,
        hands: hands.filter((h) => h.space.visible).map((h) => h.handedness),
        bones,
        canvas: [canvas.width, canvas.height],
        rect: [r.left, r.top, r.width, r.height].map(Math.round),
        window: [window.innerWidth, window.innerHeight],
      });
    }
  }

  // The test mode draws its one frame now (a tiny headless window may never get an
  // animation frame).
  if (test !== null) {
    draw();
    return;
  }
  renderer.setAnimationLoop((time) => {
    if (renderer.xr.isPresenting) {
      for (const model of liveModels) if (model) model.updateMesh();
      renderer.render(scene, camera);
      return;
    }
    if (playing && time - switched >= 1000) {
      switched = time;
      showFrame((current + 1) % frames.length);
    }
    resize();
    controls.update();
    if (dirty) draw();
  });
}

// Live hand tracking: the XRHandMeshModel of each tracked hand (renderer.xr.getHand(i)).
const liveModels = [null, null];

// "Enter VR" / "Enter AR" where the browser has a device for them; in a session, three's
// WebXRManager drives renderer.xr.getHand(0/1) and XRHandMeshModel follows them, the
// playback hands hidden.
function offerXr(renderer, scene, hands, cache, ended) {
  if (!navigator.xr) return;
  for (let i = 0; i < 2; i++) {
    const hand = renderer.xr.getHand(i);
    const handModel = new THREE.Object3D();
    hand.add(handModel);
    scene.add(hand);
    hand.addEventListener('connected', (event) => {
      const source = event.data;
      if (!source.hand || liveModels[i]) return;
      liveModels[i] = new XRHandMeshModel(handModel, hand, PATH, source.handedness, null, null, cache);
    });
    hand.addEventListener('disconnected', () => {
      handModel.clear();
      liveModels[i] = null;
    });
  }
  let session = null;
  const buttons = [['immersive-vr', $('bitt-xr-enter-vr'), 'VR'], ['immersive-ar', $('bitt-xr-enter-ar'), 'AR']];
  for (const [mode, button, label] of buttons) {
    navigator.xr.isSessionSupported(mode).then((supported) => {
      button.hidden = !supported;
    }, () => { button.hidden = true; });
    button.addEventListener('click', async () => {
      if (session) {
        session.end();
        return;
      }
      try {
        session = await navigator.xr.requestSession(mode, {
          optionalFeatures: ['hand-tracking', 'local-floor'],
        });
      } catch (e) {
        $('bitt-xr-error').textContent = `${label}: ${e.message || e}`;
        $('bitt-xr-error').hidden = false;
        return;
      }
      const floor = !session.enabledFeatures || session.enabledFeatures.includes('local-floor');
      renderer.xr.enabled = true;
      renderer.xr.setReferenceSpaceType(floor ? 'local-floor' : 'local');
      for (const h of hands) h.space.visible = false;
      if (mode === 'immersive-ar') renderer.setClearAlpha(0);
      button.textContent = `Exit ${label}`;
      session.addEventListener('end', () => {
        session = null;
        button.textContent = `Enter ${label}`;
        renderer.setClearAlpha(1);
        ended();
      });
      await renderer.xr.setSession(session);
    });
  }
}

main().catch((e) => fail(e.message || e));
"##;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::viewer::tests::{between, checked_import_map, decode_base64};

    fn playback() -> String {
        serde_json::json!({
            "format": "bitt-xr-playback",
            "convention": "webxr",
            "joints": ["wrist"],
            "frames": [{"name": "a </script><!-- <script> b", "left": null, "right": null,
                        "camera": {"width": 4, "height": 3, "fx": 1, "fy": 1, "cx": 2, "cy": 1.5}}],
        })
        .to_string()
    }

    #[test]
    fn xr_page_is_self_contained() {
        let left: Vec<u8> = (0..1000u32).map(|i| (i * 7 + i / 13) as u8).collect();
        let right: Vec<u8> = (0..777u32).map(|i| (i * 11 + 3) as u8).collect();
        let json = playback();
        let html = xr_html(&left, &right, &json);

        // The payloads come back byte for byte and value for value.
        let glb = |id: &str| decode_base64(between(&html, &format!("id=\"{id}\">"), "</script>"));
        assert_eq!(glb(ids::LEFT_GLB), left);
        assert_eq!(glb(ids::RIGHT_GLB), right);
        let embedded = between(&html, &format!("id=\"{}\">", ids::PLAYBACK), "</script>");
        assert!(!embedded.contains('<'), "{embedded}");
        let back: serde_json::Value = serde_json::from_str(embedded).unwrap();
        assert_eq!(
            back,
            serde_json::from_str::<serde_json::Value>(&json).unwrap()
        );

        // The import map: the viewer's modules and XRHandMeshModel, three's own file with its
        // imports rewritten, every import resolved; the page's imports are in the map.
        let imports = checked_import_map(&html);
        assert_eq!(imports.len(), MODULES.len() + 1);
        let xr = &imports["three/addons/webxr/XRHandMeshModel.js"];
        assert!(xr.contains("updateMesh()") && xr.contains("Couldn't find"));
        assert!(xr.contains("from\"three/addons/loaders/GLTFLoader.js\""));
        assert!(xr.contains("from\"three/addons/utils/SkeletonUtils.js\""));
        let mut rest = APP;
        while let Some(i) = rest.find("from '") {
            let name = between(&rest[i..], "from '", "'");
            assert!(imports.contains_key(name), "the page imports {name}");
            rest = &rest[i + 6..];
        }
        assert!(APP.contains("from 'three/addons/webxr/XRHandMeshModel.js'"));

        // Nothing from the network: the only URL is the licence comment's, and every
        // XRHandMeshModel is given the page's path and the embedded GLBs (its default path is
        // a CDN).
        let comment = between(&html, "<!--", "-->");
        assert!(comment.contains("MIT licence"));
        let without_comment = html.replacen(comment, "", 1);
        for scheme in ["http://", "https://", "//cdn", "src=\"", "fetch("] {
            assert!(!without_comment.contains(scheme), "{scheme} in the page");
        }
        let calls: Vec<&str> = APP.split("new XRHandMeshModel(").skip(1).collect();
        assert_eq!(calls.len(), 2);
        for call in calls {
            let args = &call[..call.find(')').unwrap()];
            assert!(
                args.contains(", PATH, ") && args.ends_with(", null, null, cache"),
                "{args}"
            );
        }
        assert!(APP.contains("const PATH = 'bitt/';"));

        // The elements, each once; the script uses them.
        for id in ids::ALL {
            assert_eq!(html.matches(&format!("id=\"{id}\"")).count(), 1, "#{id}");
            if ![ids::LEFT_GLB, ids::RIGHT_GLB].contains(&id) {
                assert!(APP.contains(&format!("$('{id}')")), "the script uses #{id}");
            }
        }
        assert!(APP.contains("decode(`bitt-xr-${handedness}-glb`)"));
        assert!(APP.contains("[['left', 0xff0000], ['right', 0x00ff00]]"));
        assert!(html.contains("data-state=\"loading\""));
        // A whole document; the import map before the only module script.
        assert!(html.starts_with("<!doctype html>") && html.trim_end().ends_with("</html>"));
        assert!(html.find("type=\"importmap\"") < html.find("type=\"module\""));
        assert_eq!(html.matches("type=\"module\"").count(), 1);
        assert_eq!(html.matches("type=\"importmap\"").count(), 1);
    }

    #[test]
    fn xr_hand_mesh_model_is_three_r187s() {
        // The file esbuild makes of r187's examples/jsm/webxr/XRHandMeshModel.js (README).
        let src = XR_HAND_MESH_MODEL.source;
        assert_eq!(src.len(), 1650);
        assert!(src.starts_with("import{GLTFLoader as m}from\"../loaders/GLTFLoader.js\";"));
        assert!(src.trim_end().ends_with("export{u as XRHandMeshModel};"));
        for (from, _) in XR_HAND_MESH_MODEL.rewrites {
            assert_eq!(src.matches(from).count(), 1, "{from}");
        }
    }
}
