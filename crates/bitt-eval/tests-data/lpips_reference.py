"""Reference LPIPS-VGG values for crates/bitt-eval/src/lpips.rs (run: python3 lpips_reference.py).

Needs numpy, torch and the `lpips` package (`python3 -m pip install lpips`); no download:
the VGG16 backbone is built with `pnet_rand=True` and every parameter (backbone and the
five 1x1 "lin" layers) is then overwritten with weights from an integer hash, which the
Rust test rebuilds bit for bit. This checks the architecture (layers, ReLU taps, pooling,
scaling layer, channel normalisation, lin layers, spatial mean, sum) independently of the
real weights, which cannot be downloaded on every machine.

Images: the pairs of metrics_reference.py (8-bit levels / 255, in [0, 1]); LPIPS is called
with normalize=True (inputs in [0, 1] mapped to [-1, 1]) and, for the first pair, also on
the raw [0, 1] tensors with normalize=False (how BiTT's reference code calls it).
"""

import math

import lpips
import numpy as np
import torch

from metrics_reference import Lcg, base_image, noisy, shifted, to_float  # noqa: F401

# torchvision vgg16 `features` indices of the 13 convolutions, with (in, out) channels.
CONVS = [
    (0, 3, 64), (2, 64, 64),
    (5, 64, 128), (7, 128, 128),
    (10, 128, 256), (12, 256, 256), (14, 256, 256),
    (17, 256, 512), (19, 512, 512), (21, 512, 512),
    (24, 512, 512), (26, 512, 512), (28, 512, 512),
]
LIN_CHANNELS = [64, 128, 256, 512, 512]


def hashed(n, salt):
    """n integers in [0, 2^32): a multiplicative hash of (index, salt), exact in uint64."""
    i = np.arange(n, dtype=np.uint64)
    m = np.uint64(0xFFFFFFFF)
    x = (i * np.uint64(2654435761) + np.uint64(salt) * np.uint64(97531)) & m
    x ^= x >> np.uint64(15)
    x = (x * np.uint64(2246822519)) & m
    x ^= x >> np.uint64(13)
    return x


def signed_unit(n, salt):
    """Values in [-1, 1] (multiples of 1/1000), float64."""
    return (hashed(n, salt) % np.uint64(2001)).astype(np.int64).astype(np.float64) / 1000.0 - 1.0


def formula_weights():
    """name -> float32 array, in the safetensors naming of lpips.rs."""
    out = {}
    for k, (idx, cin, cout) in enumerate(CONVS):
        n = cout * cin * 9
        scale = math.sqrt(6.0 / (cin * 9))
        w = (signed_unit(n, 2 * k + 1) * scale).astype(np.float32).reshape(cout, cin, 3, 3)
        b = (signed_unit(cout, 2 * k + 2) * 0.05).astype(np.float32)
        out[f"features.{idx}.weight"] = w
        out[f"features.{idx}.bias"] = b
    for k, c in enumerate(LIN_CHANNELS):
        v = (hashed(c, 100 + k) % np.uint64(1001)).astype(np.float64) / 1000.0
        out[f"lin{k}.weight"] = v.astype(np.float32).reshape(1, c, 1, 1)
    return out


def main():
    torch.set_grad_enabled(False)
    model = lpips.LPIPS(net="vgg", pretrained=True, pnet_rand=True, verbose=False).eval()
    w = formula_weights()
    sd = model.state_dict()
    for name in list(sd):
        if name.startswith("net.slice"):
            idx = name.split(".")[2]
            src = f"features.{idx}.{name.split('.')[-1]}"
        elif name.startswith("lins."):  # the same modules as lin0..lin4
            src = f"lin{name.split('.')[1]}.weight"
        elif name.startswith("lin"):
            src = f"lin{name[3]}.weight"
        else:
            continue
        assert tuple(sd[name].shape) == w[src].shape, (name, sd[name].shape, w[src].shape)
        sd[name] = torch.from_numpy(w[src])
    model.load_state_dict(sd)
    checksum = sum(float(np.abs(v.astype(np.float64)).sum()) for v in w.values())
    print(f"weights_abs_sum = {checksum!r}")

    def t(img8):
        return torch.from_numpy(to_float(img8))[None]

    a = base_image(3, 64, 64, 1)
    pairs = [
        ("small_noise", a, noisy(a, 2, 4)),
        ("small_shift", a, shifted(a)),
        ("rect_noise", base_image(3, 48, 80, 11), noisy(base_image(3, 48, 80, 11), 12, 2)),
    ]
    for name, x, y in pairs:
        d = model(t(x), t(y), normalize=True).item()
        print(f"{name} = {d!r}")
    d = model(t(pairs[0][1]), t(pairs[0][2]), normalize=False).item()
    print(f"small_noise_raw01 = {d!r}")
    print(f"identical = {model(t(a), t(a), normalize=True).item()!r}")


if __name__ == "__main__":
    main()
