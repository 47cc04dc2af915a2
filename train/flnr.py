"""Train FLNR's guide network end to end through a differentiable FLR.

    python3 train/flnr.py --frames /tmp/frames/train/*.exr --out train/flnr.bin [--steps 1500]

Data recipe: frames from `tools/render.py --split train` (and more train-family seeds,
e.g. `--scenes box:3,clutter:3,room:2,colonnade:2,box:4,clutter:4 --ref-spp 512`),
never the test split nor `data/`. Network input (must match `src/flnr.rs`): the guides
normal (3), depth / frame-mean depth (1), AO (1), and log1p(max(noisy, 0) / s) (3),
s = the frame's mean noisy value; output: 2·Q' sigmoid channels, X'_model then X'_map
(Q' = 4). FLR is fitted on [normal, depth, AO, X'_model] and applied to [normal,
depth, AO, X'_map]: the network *adds* guides rather than replacing them (the paper
replaces them), so FLNR starts out as FLR and a short CPU training can only improve on it. FLR (B = 8, Gaussian σ, normalized ε, ϵ — all three learned) is rebuilt here
op for op like the library's: block moments, separable blur of the block grid, the
normalized-correlation regularized inverse (appendix eqs. 12–23) per cell, bilinear
interpolation of the per-cell affine models. Loss: SMAPE against the reference.
"""
import argparse
import math
import random
import time

import numpy as np
import OpenEXR
import torch
import torch.nn.functional as F

from unet import UNet, export

B = 8
QP = 4  # enhanced guides per set


def load(path):
    with OpenEXR.File(path) as f:
        ch = f.channels()

        def layer(name, comps):
            if name in ch:  # grouped by the OpenEXR module: (H, W) or (H, W, C)
                a = np.asarray(ch[name].pixels, dtype=np.float32)
                return a[None] if a.ndim == 2 else np.moveaxis(a, -1, 0)
            return np.stack([np.asarray(ch[f"{name}.{c}"].pixels, dtype=np.float32) for c in comps], 0)

        return {
            "noisy": layer("noisy", "RGB"),
            "reference": layer("reference", "RGB"),
            "albedo": layer("albedo", "RGB"),
            "normal": layer("normal", "XYZ"),
            "depth": layer("depth", "Z"),
            "ao": layer("ao", "Y"),
        }


def net_input(fr):
    """The network's input planes (see the module docs; src/flnr.rs mirrors it)."""
    noisy = np.nan_to_num(fr["noisy"], nan=0.0, posinf=0.0, neginf=0.0)
    s = max(float(np.maximum(noisy, 0).mean()), 1e-6)
    d = fr["depth"]
    dm = float(d[np.isfinite(d) & (d > 0)].mean()) if np.any(np.isfinite(d) & (d > 0)) else 1.0
    x = np.concatenate([fr["normal"], d / dm, fr["ao"], np.log1p(np.maximum(noisy, 0) / s)], 0)
    return np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)


def gauss_kernel(sigma_cells, radius):
    t = torch.arange(-radius, radius + 1, dtype=torch.float32)
    k = torch.exp(-0.5 * (t / sigma_cells) ** 2)
    return k / k.sum()


def flr(y, gm, gmap, sigma, eps_mul, eps_add):
    """Differentiable FLR. y: (N,3,H,W), gm/gmap: (N,Q,H,W), H, W multiples of B."""
    n_, q, h, w = gm.shape
    ones = torch.ones_like(y[:, :1])
    # standardise the model guides by their frame mean / std (the library's normalized mode)
    mean = gm.mean(dim=(2, 3), keepdim=True)
    std = gm.std(dim=(2, 3), keepdim=True).clamp_min(1e-6)
    z = (gm - mean) / std
    feats = [ones, z, (z.unsqueeze(2) * z.unsqueeze(1)).reshape(n_, q * q, h, w), y, (z.unsqueeze(2) * y.unsqueeze(1)).reshape(n_, q * 3, h, w)]
    m = torch.cat(feats, 1)
    m = F.avg_pool2d(m, B) * (B * B)  # block sums
    # Gaussian blur of the block grid, σ in pixels → σ/B cells, truncated at 3σ
    sc = sigma / B
    radius = max(1, int(math.ceil(3 * float(sc.detach()))))
    t = torch.arange(-radius, radius + 1, dtype=torch.float32)
    k = torch.exp(-0.5 * (t / sc) ** 2)
    k = k / k.sum()
    c = m.shape[1]
    m = F.conv2d(m, k.view(1, 1, 1, -1).repeat(c, 1, 1, 1), padding=(0, radius), groups=c)
    m = F.conv2d(m, k.view(1, 1, -1, 1).repeat(c, 1, 1, 1), padding=(radius, 0), groups=c)
    # per cell solve
    gh, gw = m.shape[2], m.shape[3]
    m = m.permute(0, 2, 3, 1)  # N, gh, gw, C
    nn_ = m[..., 0:1].clamp_min(1e-6)
    mu = m[..., 1 : 1 + q] / nn_
    ss = m[..., 1 + q : 1 + q + q * q].reshape(n_, gh, gw, q, q) / nn_.unsqueeze(-1)
    muy = m[..., 1 + q + q * q : 4 + q + q * q] / nn_
    p = m[..., 4 + q + q * q :].reshape(n_, gh, gw, q, 3) / nn_.unsqueeze(-1)
    cov = ss - mu.unsqueeze(-1) * mu.unsqueeze(-2)  # guides are already standardised
    muz = mu  # mean of standardised guides relative to the frame mean (0)
    wh = cov + eps_mul * muz.unsqueeze(-1) * muz.unsqueeze(-2)
    eye = torch.eye(q)
    wh = wh + eye * (eps_mul * muz * muz + eps_add).unsqueeze(-1)
    isig = 1.0 / torch.sqrt(torch.diagonal(wh, dim1=-2, dim2=-1).clamp_min(1e-30))
    wh = wh * isig.unsqueeze(-1) * isig.unsqueeze(-2) + eye * eps_add
    cxy = p - mu.unsqueeze(-1) * muy.unsqueeze(-2)
    bh = cxy * isig.unsqueeze(-1)
    beta = torch.linalg.solve(wh, bh) * isig.unsqueeze(-1)  # N gh gw q 3, per standardised guide
    c0 = muy - (beta * mu.unsqueeze(-1)).sum(-2)
    model = torch.cat([c0, beta.reshape(n_, gh, gw, q * 3)], -1).permute(0, 3, 1, 2)
    model = F.interpolate(model, size=(h, w), mode="bilinear", align_corners=False)
    zmap = (gmap - mean) / std
    c0 = model[:, :3]
    beta = model[:, 3:].reshape(n_, q, 3, h, w)
    return c0 + (beta * zmap.unsqueeze(2)).sum(1)


def smape(a, b):
    return ((a - b).abs() / (a.abs() + b.abs() + 1e-2)).mean()


class Flnr(torch.nn.Module):
    def __init__(self, widths):
        super().__init__()
        self.net = UNet(8, 2 * QP, widths)
        self.log_sigma = torch.nn.Parameter(torch.tensor(math.log(12.0)))
        self.log_eps_mul = torch.nn.Parameter(torch.tensor(math.log(1e-3)))
        self.log_eps_add = torch.nn.Parameter(torch.tensor(math.log(1e-2)))

    def forward(self, x, y):
        g = self.net(x)
        base = x[:, :5]  # normal, depth, AO: FLR's own guides stay in both sets
        gm = torch.cat([base, g[:, :QP]], 1)
        gmap = torch.cat([base, g[:, QP:]], 1)
        return flr(y, gm, gmap, self.log_sigma.exp(), self.log_eps_mul.exp(), self.log_eps_add.exp())


def crops(frames, size, batch):
    xs, ys, rs = [], [], []
    for _ in range(batch):
        fr = random.choice(frames)
        _, h, w = fr["x"].shape
        oy, ox = random.randrange(0, h - size + 1), random.randrange(0, w - size + 1)
        sl = (slice(None), slice(oy, oy + size), slice(ox, ox + size))
        x, y, r = fr["x"][sl], fr["y"][sl], fr["r"][sl]
        if random.random() < 0.5:
            x, y, r = x[:, :, ::-1], y[:, :, ::-1], r[:, :, ::-1]
            x = x.copy()
            x[0] = -x[0]  # a horizontal flip mirrors the normal's x (world axes: approximately)
        if random.random() < 0.5:
            x, y, r = x[:, ::-1], y[:, ::-1], r[:, ::-1]
        xs.append(np.ascontiguousarray(x))
        ys.append(np.ascontiguousarray(y))
        rs.append(np.ascontiguousarray(r))
    return torch.from_numpy(np.stack(xs)), torch.from_numpy(np.stack(ys)), torch.from_numpy(np.stack(rs))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", nargs="+", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--widths", default="16,32,64")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--crop", type=int, default=128)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--log", default=None, help="write the loss curve (step, loss) here")
    args = ap.parse_args()
    torch.manual_seed(0)
    random.seed(0)
    torch.set_num_threads(2)
    frames = []
    for p in args.frames:
        fr = load(p)
        y = np.nan_to_num(fr["noisy"], nan=0.0, posinf=0.0, neginf=0.0)
        frames.append({"x": net_input(fr), "y": y, "r": fr["reference"]})
    print(f"{len(frames)} frames; widths {args.widths}")
    model = Flnr([int(v) for v in args.widths.split(",")])
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, args.steps)
    curve = []
    t0 = time.time()
    for step in range(1, args.steps + 1):
        x, y, r = crops(frames, args.crop, args.batch)
        out = model(x, y)
        loss = smape(out, r)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        curve.append((step, float(loss)))
        if step % 50 == 0 or step == 1:
            print(f"step {step} loss {np.mean([c[1] for c in curve[-50:]]):.4f} sigma {float(model.log_sigma.exp()):.2f} "
                  f"eps {float(model.log_eps_mul.exp()):.2e},{float(model.log_eps_add.exp()):.2e} {time.time() - t0:.0f}s", flush=True)
    model.net.round_to_f16()
    flr_params = (float(model.log_sigma.exp()), float(model.log_eps_mul.exp()), float(model.log_eps_add.exp()))
    export(model.net, args.out, flr_params)
    if args.log:
        with open(args.log, "w") as f:
            f.write("step,loss\n" + "".join(f"{s},{l:.5f}\n" for s, l in curve))
    print(f"wrote {args.out}; FLR sigma {flr_params[0]:.2f} eps_mul {flr_params[1]:.2e} eps_add {flr_params[2]:.2e}")


if __name__ == "__main__":
    main()
