"""PyTorch baseline for `cargo xtask bench`: BTR, the albedo U-Net, and a training step of
all four networks (with the light and HTML encoders and Adam), written from the BiTT paper
(CVPR 2024, supplement D) for timing only.

Prints one JSON object: the network, its parameter count, the input shape and the wall
time of each forward+backward run (seconds). Same structure as crates/bitt-nets.
"""

import argparse
import json
import sys
import time

import torch
from torch import nn
import torch.nn.functional as F


class ConvGnSilu(nn.Module):
    def __init__(self, cin, cout, groups):
        super().__init__()
        self.conv = nn.Conv1d(cin, cout, 3, padding=1)
        self.norm = nn.GroupNorm(groups, cout)

    def forward(self, x):
        return F.silu(self.norm(self.conv(x)))


class Res1d(nn.Module):
    def __init__(self, cin, cout, groups=8):
        super().__init__()
        self.a = ConvGnSilu(cin, cout, groups)
        self.b = ConvGnSilu(cout, cout, groups)
        self.skip = nn.Conv1d(cin, cout, 1) if cin != cout else None

    def forward(self, x):
        s = x if self.skip is None else self.skip(x)
        return self.b(self.a(x)) + s


class Btr(nn.Module):
    """Bi-directional texture reconstruction: shared encoder, decoder mixing both hands."""

    def __init__(self, ch, groups=8, bidirectional=True):
        super().__init__()
        self.bidirectional = bidirectional
        self.stem = Res1d(3, ch[0], groups)
        self.down = nn.ModuleList(
            nn.ModuleList([Res1d(ch[i], ch[i + 1], groups), Res1d(ch[i + 1], ch[i + 1], groups)])
            for i in range(len(ch) - 1)
        )
        self.mid = nn.ModuleList([Res1d(ch[-1], ch[-1], groups), Res1d(ch[-1], ch[-1], groups)])
        self.up = nn.ModuleList(
            nn.ModuleList([Res1d(3 * ch[i + 1], ch[i], groups), Res1d(ch[i], ch[i], groups)])
            for i in reversed(range(len(ch) - 1))
        )
        self.head = nn.Sequential(nn.Conv1d(ch[0], 8, 1), nn.Conv1d(8, 3, 1))

    def forward(self, left, right):
        b = left.shape[0]
        h = self.stem(torch.cat([left, right], 0))
        lengths, skips = [], []
        for r1, r2 in self.down:
            h = r2(r1(h))
            lengths.append(h.shape[-1])
            h = F.max_pool1d(h, 2)
            skips.append(h)
        for r in self.mid:
            h = r(h)
        for r1, r2 in self.up:
            other = torch.cat([h[b:], h[:b]], 0)
            if not self.bidirectional:
                other = torch.zeros_like(other)
            h = r1(torch.cat([h, other, skips.pop()], 1))
            h = F.interpolate(h, scale_factor=2, mode="nearest")
            target = lengths.pop()
            if h.shape[-1] < target:
                h = torch.cat([h, h[:, :, -1:]], -1)
            h = r2(h)
        out = torch.sigmoid(self.head(h))
        return out[:b], out[b:]


class UnetLevel(nn.Module):
    """One U-Net level: down conv (k4 s2), inner part, nearest x2 up + conv, skip concat."""

    def __init__(self, cin, cinner, cout, inner, kind):
        super().__init__()
        self.kind = kind
        normed = kind in ("outer", "norm")
        self.down = nn.Conv2d(cin, cinner, 4, 2, 1, bias=not normed)
        self.inner = inner
        up_in = cinner if inner is None else 2 * cinner
        if kind == "outer":
            self.up = nn.Conv2d(up_in, cout, 3, 1, 1, padding_mode="replicate")
        else:
            self.up = nn.Conv2d(up_in, cout, 1, bias=not normed)

    def forward(self, x):
        if self.kind != "outer":
            x = F.leaky_relu(x, 0.2)
        h = self.down(x)
        if self.kind == "norm":
            h = F.instance_norm(h)
        if self.inner is not None:
            h = self.inner(h)
        h = self.up(F.interpolate(F.relu(h), scale_factor=2, mode="nearest"))
        if self.kind == "norm":
            h = F.instance_norm(h)
        if self.kind == "outer":
            return torch.sigmoid(h)
        return torch.cat([x, h], 1)


def albedo_unet(ngf=64, num_downs=6):
    c8 = ngf * 8
    net = UnetLevel(c8, c8, c8, None, "plain")
    for _ in range(num_downs - 5):
        net = UnetLevel(c8, c8, c8, net, "plain")
    net = UnetLevel(ngf * 4, c8, ngf * 4, net, "norm")
    net = UnetLevel(ngf * 2, ngf * 4, ngf * 2, net, "norm")
    net = UnetLevel(ngf, ngf * 2, ngf, net, "norm")
    return UnetLevel(3, ngf, 3, net, "outer")


class ConvEncoder(nn.Module):
    """The stride-2 encoder of the light and HTML networks (crates/bitt-nets/src/encoder.rs):
    log2(S) - 1 convs 4x4 stride 2 without bias (padding 1, the last 0), widths
    base * 2^i capped at 8 base, ReLU; a 1x1 conv to the outputs; tanh."""

    def __init__(self, outputs, image, base):
        super().__init__()
        n = image.bit_length() - 2
        widths = [min(base << i, 8 * base) for i in range(n)]
        layers, cin = [], 3
        for i, w in enumerate(widths):
            layers.append(nn.Conv2d(cin, w, 4, 2, 0 if i + 1 == n else 1, bias=False))
            cin = w
        self.layers = nn.ModuleList(layers)
        self.out = nn.Conv2d(cin, outputs, 1, bias=False)

    def forward(self, x):
        for layer in self.layers:
            x = F.relu(layer(x))
        return torch.tanh(self.out(x).flatten(1))


class FourNets(nn.Module):
    def __init__(self, args):
        super().__init__()
        self.light = ConvEncoder(12, args.image, args.light_base)
        self.html = ConvEncoder(2 * args.coefficients, args.image, args.html_base)
        self.albedo = albedo_unet(args.ngf, args.num_downs)
        self.btr = Btr([int(c) for c in args.channels.split(",")])


def main():
    p = argparse.ArgumentParser()
    p.add_argument("net", choices=["btr", "albedo", "step"])
    p.add_argument("--texels", type=int, default=206330)
    p.add_argument("--channels", default="16,64,128,256")
    p.add_argument("--image", type=int, default=256)
    p.add_argument("--ngf", type=int, default=64)
    p.add_argument("--num-downs", type=int, default=6)
    p.add_argument("--runs", type=int, default=2)
    p.add_argument("--light-base", type=int, default=32)
    p.add_argument("--html-base", type=int, default=64)
    p.add_argument("--coefficients", type=int, default=101)
    args = p.parse_args()
    torch.manual_seed(0)
    if args.net == "btr":
        net = Btr([int(c) for c in args.channels.split(",")])
        inputs = [torch.rand(1, 3, args.texels), torch.rand(1, 3, args.texels)]
        shape = [1, 3, args.texels]
    elif args.net == "albedo":
        net = albedo_unet(args.ngf, args.num_downs)
        inputs = [torch.rand(1, 3, args.image, args.image)]
        shape = [1, 3, args.image, args.image]
    else:
        net = FourNets(args)
        image = torch.rand(1, 3, args.image, args.image)
        batch = torch.rand(4, 3, args.image, args.image)
        texels = [torch.rand(1, 3, args.texels), torch.rand(1, 3, args.texels)]
        shape = [1, 3, args.image, args.image]
    params = sum(p.numel() for p in net.parameters())
    seconds = []
    if args.net == "step":
        adam = torch.optim.Adam(net.parameters(), lr=1e-3)
        for _ in range(args.runs):
            adam.zero_grad(set_to_none=True)
            start = time.perf_counter()
            left, right = net.btr(*texels)
            loss = (
                net.light(image).square().mean()
                + net.html(image).square().mean()
                + net.albedo(batch).square().mean()
                + left.square().mean()
                + right.square().mean()
            )
            loss.backward()
            adam.step()
            seconds.append(time.perf_counter() - start)
    for _ in range(args.runs if args.net != "step" else 0):
        net.zero_grad(set_to_none=True)
        start = time.perf_counter()
        out = net(*inputs)
        out = out if isinstance(out, tuple) else (out,)
        sum(o.square().mean() for o in out).backward()
        seconds.append(time.perf_counter() - start)
    print(json.dumps({
        "net": args.net,
        "params": params,
        "input_shape": shape,
        "threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "seconds": seconds,
    }))


if __name__ == "__main__":
    sys.exit(main())
