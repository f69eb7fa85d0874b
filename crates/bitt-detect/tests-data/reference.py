#!/usr/bin/env python3
# Generates the expected values pasted into `crates/bitt-detect/src/tests/reference_values.rs`
# by running MediaPipe Hands' two TFLite models (palm_detection_full.tflite and
# hand_landmark_full.tflite from the mediapipe 0.10.21 wheel) through the genuine TFLite
# interpreter (LiteRT) on deterministic synthetic inputs that the Rust tests rebuild exactly.
#
# Usage:
#   pip install ai-edge-litert numpy
#   python reference.py --wheel-dir DIR            # DIR = an unpacked mediapipe-0.10.21 wheel
#   python reference.py --wheel-dir DIR --dump-tensors OUT_DIR   # debug: per-tensor sums
#
# The models are Apache-2.0 (Google MediaPipe); they are read from the wheel, never copied here.
#
# Inputs (NHWC float32, batch 1): value(y, x, c) for pattern p is computed in float64, with x, y,
# c as float64 and the operations in exactly this order, then cast to float32 (round to nearest):
#   p = 0: 0.5 + 0.5 * sin(0.11*x + 0.07*y + 1.3*c) * cos(0.05*x - 0.09*y + 0.7*c)
#          i.e. 0.5 + ((0.5 * sin(((0.11*x) + (0.07*y)) + (1.3*c))) * cos(((0.05*x) - (0.09*y)) + (0.7*c)))
#   p = 1: frac(((x*0.618034) + (y*0.414214)) + (c*0.333333)), frac(t) = t - floor(t)
#
# The interpreter runs with OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES (the plain TFLite
# CPU kernels, no XNNPACK), so that --dump-tensors can read every intermediate tensor and the
# values agree with the dump; pass --xnnpack to use the default delegate instead (differences are
# at the float32 rounding level).
#
# Floats are written as the shortest decimal that round-trips the float32 value (so that
# clippy::excessive_precision stays quiet); sums are float64 accumulations written with repr().

import argparse
import os
import subprocess
import sys

import numpy as np
from ai_edge_litert.interpreter import Interpreter, OpResolverType

PALM_REL = "mediapipe/modules/palm_detection/palm_detection_full.tflite"
LANDMARK_REL = "mediapipe/modules/hand_landmark/hand_landmark_full.tflite"
PALM_FIXED_ANCHORS = [0, 1, 100, 577, 1000, 1151, 1500, 2015]
TOP_K = 8


def pattern(h, w, p):
    y = np.arange(h, dtype=np.float64)[:, None, None]
    x = np.arange(w, dtype=np.float64)[None, :, None]
    c = np.arange(3, dtype=np.float64)[None, None, :]
    if p == 0:
        v = 0.5 + 0.5 * np.sin(0.11 * x + 0.07 * y + 1.3 * c) * np.cos(0.05 * x - 0.09 * y + 0.7 * c)
    elif p == 1:
        t = x * 0.618034 + y * 0.414214 + c * 0.333333
        v = t - np.floor(t)
    else:
        raise ValueError(p)
    v = np.broadcast_to(v, (h, w, 3))
    return v.astype(np.float32)[None]


def make_interpreter(path, xnnpack, preserve=False):
    kind = OpResolverType.AUTO if xnnpack else OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES
    it = Interpreter(
        model_path=path,
        experimental_op_resolver_type=kind,
        experimental_preserve_all_tensors=preserve,
        num_threads=1,
    )
    it.allocate_tensors()
    return it


def run(it, x):
    inp = it.get_input_details()
    assert len(inp) == 1 and list(inp[0]["shape"]) == list(x.shape), inp
    it.set_tensor(inp[0]["index"], x)
    it.invoke()
    return {d["name"]: it.get_tensor(d["index"]).copy() for d in it.get_output_details()}


def f32(v):
    """Shortest decimal that round-trips the float32 value, as a Rust literal."""
    v = np.float32(v)
    if not np.isfinite(v):
        raise ValueError(f"non-finite value {v}")
    a = abs(float(v))
    if a == 0.0 or 1e-4 <= a < 1e7:
        s = np.format_float_positional(v, unique=True, trim="0")
    else:
        s = np.format_float_scientific(v, unique=True, trim="0")
    assert np.float32(float(s)) == v, (s, v)
    return s


def f64(v):
    s = repr(float(v))
    return s if ("." in s or "e" in s or "inf" in s or "nan" in s) else s + ".0"


def arr(vals):
    return "[" + ", ".join(f32(v) for v in vals) + "]"


def palm_items(out, p, x):
    reg = out["Identity"]
    logit = out["Identity_1"]
    assert reg.shape == (1, 2016, 18), reg.shape
    assert logit.shape == (1, 2016, 1), logit.shape
    reg = reg[0]
    logit = logit[0, :, 0]
    top = np.argsort(-logit.astype(np.float64), kind="stable")[:TOP_K]
    anchors = sorted(set(PALM_FIXED_ANCHORS) | set(int(i) for i in top))
    n = len(anchors)
    pre = f"PALM_P{p}"
    lines = [
        f"/// Sum of the whole palm input tensor (pattern {p}, 192x192x3), float64 accumulation.",
        f"pub(crate) const {pre}_INPUT_SUM: f64 = {f64(x.astype(np.float64).sum())};",
        f"/// Anchor indices checked for pattern {p}: fixed ones plus the {TOP_K} largest logits"
        f" ({', '.join(str(int(i)) for i in top)}).",
        f"pub(crate) const {pre}_ANCHORS: [usize; {n}] = [{', '.join(str(a) for a in anchors)}];",
        f"/// `Identity` (regressors) rows for `{pre}_ANCHORS`.",
        f"pub(crate) const {pre}_REGRESSORS: [[f32; 18]; {n}] = ["
        + ", ".join(arr(reg[a]) for a in anchors)
        + "];",
        f"/// `Identity_1` (logits) for `{pre}_ANCHORS`.",
        f"pub(crate) const {pre}_LOGITS: [f32; {n}] = {arr(logit[anchors])};",
        f"/// Sum of all 2016x18 regressors, float64 accumulation.",
        f"pub(crate) const {pre}_REGRESSOR_SUM: f64 = {f64(reg.astype(np.float64).sum())};",
        f"/// Sum of all 2016 logits, float64 accumulation.",
        f"pub(crate) const {pre}_LOGIT_SUM: f64 = {f64(logit.astype(np.float64).sum())};",
    ]
    return lines


def landmark_items(out, p, x):
    scr, pres, hand, world = (out[k] for k in ("Identity", "Identity_1", "Identity_2", "Identity_3"))
    assert scr.shape == (1, 63) and world.shape == (1, 63), (scr.shape, world.shape)
    assert pres.shape == (1, 1) and hand.shape == (1, 1), (pres.shape, hand.shape)
    pre = f"LANDMARK_P{p}"
    return [
        f"/// Sum of the whole landmark input tensor (pattern {p}, 224x224x3), float64 accumulation.",
        f"pub(crate) const {pre}_INPUT_SUM: f64 = {f64(x.astype(np.float64).sum())};",
        f"/// `Identity`: 21 screen landmarks (x, y, z) in 224x224 input pixels.",
        f"pub(crate) const {pre}_SCREEN: [f32; 63] = {arr(scr[0])};",
        f"/// `Identity_1`: hand presence score (the model output, already in [0, 1]).",
        f"pub(crate) const {pre}_PRESENCE: f32 = {f32(pres[0, 0])};",
        f"/// `Identity_2`: handedness score (the model output, already in [0, 1]).",
        f"pub(crate) const {pre}_HANDEDNESS: f32 = {f32(hand[0, 0])};",
        f"/// `Identity_3`: 21 world landmarks (x, y, z) in metres.",
        f"pub(crate) const {pre}_WORLD: [f32; 63] = {arr(world[0])};",
    ]


def dump(it, x, path):
    run(it, x)
    with open(path, "w") as f:
        for d in sorted(it.get_tensor_details(), key=lambda d: d["index"]):
            if not d["name"]:
                continue  # interpreter scratch tensors (im2col etc.), not part of the model
            try:
                t = it.get_tensor(d["index"])
                if t is None or t.dtype.kind not in "fiub":
                    continue
                t = t.astype(np.float64)
            except Exception:
                continue
            shape = "x".join(str(int(s)) for s in d["shape"]) or "scalar"
            f.write(f"{d['index']} {d['name']} {shape} {f64(t.sum())} {f64(np.abs(t).sum())}\n")
    print(f"wrote {path}")


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--wheel-dir", required=True, help="unpacked mediapipe-0.10.21 wheel")
    ap.add_argument("--out", default=os.path.join(here, "..", "src", "tests", "reference_values.rs"))
    ap.add_argument("--xnnpack", action="store_true", help="use the default XNNPACK delegate")
    ap.add_argument("--dump-tensors", metavar="OUT_DIR", help="write per-tensor sums for p=0 and exit")
    args = ap.parse_args()

    palm_path = os.path.join(args.wheel_dir, PALM_REL)
    lm_path = os.path.join(args.wheel_dir, LANDMARK_REL)

    if args.dump_tensors:
        os.makedirs(args.dump_tensors, exist_ok=True)
        dump(make_interpreter(palm_path, False, True), pattern(192, 192, 0),
             os.path.join(args.dump_tensors, "palm_p0_tensors.txt"))
        dump(make_interpreter(lm_path, False, True), pattern(224, 224, 0),
             os.path.join(args.dump_tensors, "landmark_p0_tensors.txt"))
        return

    palm = make_interpreter(palm_path, args.xnnpack)
    lm = make_interpreter(lm_path, args.xnnpack)
    body = []
    for p in (0, 1):
        x = pattern(192, 192, p)
        body += palm_items(run(palm, x), p, x) + [""]
    for p in (0, 1):
        x = pattern(224, 224, p)
        body += landmark_items(run(lm, x), p, x) + [""]

    try:
        import importlib.metadata as md
        litert = md.version("ai-edge-litert")
    except Exception:
        litert = "unknown"
    cmd = "python " + " ".join([os.path.basename(sys.argv[0])] + sys.argv[1:])
    header = [
        "//! Expected outputs of MediaPipe Hands' TFLite models (mediapipe 0.10.21 palm_detection_full"
        " and hand_landmark_full, Apache-2.0) on synthetic inputs; generated by `tests-data/reference.py`,"
        " do not edit by hand.",
        f"// Generated with: {cmd}",
        f"// Interpreter: ai-edge-litert {litert}, "
        + ("default delegates (XNNPACK)." if args.xnnpack else "BUILTIN_WITHOUT_DEFAULT_DELEGATES (no XNNPACK).")
        + " Input patterns: see the header of tests-data/reference.py.",
        "",
    ]
    out = os.path.abspath(args.out)
    with open(out, "w") as f:
        f.write("\n".join(header + body).rstrip("\n") + "\n")
    print(f"wrote {out}")
    try:
        subprocess.run(["rustfmt", "--edition", "2024", out], check=True)
        print("formatted with rustfmt --edition 2024")
    except (OSError, subprocess.CalledProcessError) as e:
        print(f"warning: rustfmt failed ({e}); run `rustfmt --edition 2024 {out}`", file=sys.stderr)


if __name__ == "__main__":
    main()
