"""Reference values for crates/bitt-eval/src/metrics.rs (run: python3 metrics_reference.py).

Needs numpy, torch, scikit-image and pytorch-msssim
(`python3 -m pip install scikit-image pytorch-msssim`). The test images are made from integer
arithmetic only (a 32-bit LCG and integer gradients), so the Rust tests rebuild them bit for
bit; pixel values are 8-bit levels / 255 in float32, as decoded PNGs are.

Printed: for each pair, L1, PSNR (skimage), SSIM (skimage, gaussian_weights=True, sigma=1.5,
use_sample_covariance=False, data_range=1, float64), SSIM and MS-SSIM (pytorch_msssim,
data_range=1, size_average=True, computed in float64 and in float32), and the masked metrics
of the last pair as metrics.rs defines them (L1 / PSNR over masked pixels, SSIM / MS-SSIM of
the images multiplied by the mask).
"""

import numpy as np
import torch
from pytorch_msssim import ms_ssim, ssim
from skimage.metrics import peak_signal_noise_ratio, structural_similarity


class Lcg:
    """Numerical Recipes LCG: x <- 1664525 x + 1013904223 (mod 2^32); a byte is x >> 24."""

    def __init__(self, seed):
        self.x = seed & 0xFFFFFFFF

    def byte(self):
        self.x = (1664525 * self.x + 1013904223) & 0xFFFFFFFF
        return self.x >> 24


def clamp(v):
    return max(0, min(255, v))


def base_image(c, h, w, seed):
    """Gradients, 8x8 checker blocks and 4-bit noise, as 8-bit levels [c][h][w]."""
    rng = Lcg(seed)
    img = np.zeros((c, h, w), dtype=np.int64)
    for ch in range(c):
        for r in range(h):
            for col in range(w):
                v = 30 + (r * 150) // h + (col * 60) // w + ch * 20
                v += ((r // 8 + col // 8) % 2) * 30
                v += rng.byte() % 16
                img[ch, r, col] = clamp(v)
    return img


def noisy(img, seed, amp_div):
    """img + (byte - 128) / amp_div (integer division toward -inf), clamped."""
    rng = Lcg(seed)
    c, h, w = img.shape
    out = np.zeros_like(img)
    for ch in range(c):
        for r in range(h):
            for col in range(w):
                out[ch, r, col] = clamp(img[ch, r, col] + (rng.byte() - 128) // amp_div)
    return out


def shifted(img):
    """One pixel right (wrapping), 90% brightness (integer), +5 on channel 0."""
    c, h, w = img.shape
    out = np.zeros_like(img)
    for ch in range(c):
        for r in range(h):
            for col in range(w):
                v = (img[ch, r, (col + w - 1) % w] * 9) // 10 + (5 if ch == 0 else 0)
                out[ch, r, col] = clamp(v)
    return out


def disk_mask(h, w):
    """1 inside the ellipse centred in the image with semi-axes h/3, w/3 (integer test)."""
    m = np.zeros((h, w), dtype=np.int64)
    for r in range(h):
        for col in range(w):
            dy = 2 * r + 1 - h
            dx = 2 * col + 1 - w
            # (dy / (2h/3))^2 + (dx / (2w/3))^2 <= 1, times (2h/3 * 2w/3)^2 * 9 / 4, all integer
            if 9 * dy * dy * w * w + 9 * dx * dx * h * h <= 4 * h * h * w * w:
                m[r, col] = 1
    return m


def to_float(img):
    return (img.astype(np.float32) / np.float32(255.0)).astype(np.float32)


def report(name, a8, b8, mask=None):
    a = to_float(a8)
    b = to_float(b8)
    c, h, w = a.shape
    print(f"== {name} [{c}, {h}, {w}]")
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    if mask is None:
        l1 = np.abs(a64 - b64).mean()
        psnr = peak_signal_noise_ratio(a64, b64, data_range=1.0)
        sa, sb = a64, b64
    else:
        sel = np.broadcast_to(mask[None] > 0, a.shape)
        d = (a64 - b64)[sel]
        l1 = np.abs(d).mean()
        psnr = -10.0 * np.log10((d * d).mean())
        sa, sb = a64 * mask[None], b64 * mask[None]
        print(f"mask_pixels = {int(mask.sum())}")
    print(f"l1 = {l1!r}")
    print(f"psnr = {psnr!r}")
    sk = structural_similarity(
        sa, sb, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
        data_range=1.0, channel_axis=0,
    )
    print(f"ssim_skimage = {sk!r}")
    for dt in (torch.float64, torch.float32):
        ta = torch.from_numpy(sa).to(dt)[None]
        tb = torch.from_numpy(sb).to(dt)[None]
        s = ssim(ta, tb, data_range=1.0, size_average=True).item()
        print(f"ssim_pytorch_msssim_{str(dt)[6:]} = {s!r}")
        if min(h, w) > 160:
            m = ms_ssim(ta, tb, data_range=1.0, size_average=True).item()
            print(f"ms_ssim_pytorch_msssim_{str(dt)[6:]} = {m!r}")


if __name__ == "__main__":
    a = base_image(3, 64, 64, 1)
    report("small_noise", a, noisy(a, 2, 4))
    a = base_image(3, 180, 200, 3)
    report("large_noise", a, noisy(a, 4, 3))
    a = base_image(3, 181, 203, 5)
    report("odd_shift", a, shifted(a))
    a = base_image(1, 170, 170, 7)
    report("gray_noise", a, noisy(a, 8, 2))
    a = base_image(3, 180, 200, 9)
    report("masked", a, noisy(a, 10, 3), mask=disk_mask(180, 200))
