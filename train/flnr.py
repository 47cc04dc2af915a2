"""Train FLNR's guide network end to end through a differentiable FLR.

    python3 train/flnr.py --frames frames/train/*.exr frames/train2/*.exr --out train/flnr.bin \
        [--steps 2500] [--init train/flnr.bin] [--sigmas 6,12,20]
    python3 train/flnr.py --frames frames/train/*.exr --out /dev/null --check

Data recipe: frames from `tools/render.py --split train` (and more train-family seeds,
see train/README.md), never the test split nor `data/`. Network input (must match
`src/flnr.rs`): the guides normal (3), depth / frame-mean depth (1), AO (1), and
log1p(max(noisy, 0) / s) (3), s = the frame's mean noisy value; output: 2·Q' sigmoid
channels, X'_model then X'_map (Q' = 4). FLR is fitted on [normal, depth, AO, X'_model]
and applied to [normal, depth, AO, X'_map]: the network *adds* guides rather than
replacing them (the paper replaces them), so FLNR starts out as FLR and a short CPU
training can only improve on it.

FLR (B = 8, normalized ε, ϵ learned) is rebuilt here op for op like the library's:
block moments, separable Gaussian blur of the block grid, the normalized-correlation
regularized inverse (appendix eqs. 12–23) per cell, bilinear interpolation of the
per-cell models. By default it is the library's default, the adaptive window (σ 6/12/20
px, the larger two on the 2×2-pooled grid, blended per cell by 1 / (bias² + variance):
src/flr/adaptive.rs); `--sigmas 12` trains on one window. `--check` prints plain FLR's
PSNR per frame, to compare with `lrd eval` (on the train scenes: equal to the last digit
for both). Loss: SMAPE against the reference (adding the quality protocol's tone-mapped
error, docs/DATA.md, scored no better on the validation frames: train/README.md). `--val FRAMES` scores frames that are never trained on at the
end (plain FLR and FLNR PSNR), to choose between runs without touching the test split.
"""
import argparse
import math
import os
import random
import re
import time

import numpy as np
import OpenEXR
import torch
import torch.nn.functional as F

from unet import UNet, export, load_blob

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


def net_input(fr, flr_out=None):
    """The network's input planes (see the module docs; src/flnr.rs mirrors it); with
    `flr_out` (FLR's defaults on the frame), its ln(1 + max(·, 0) / s) as 3 more planes."""
    noisy = np.nan_to_num(fr["noisy"], nan=0.0, posinf=0.0, neginf=0.0)
    s = max(float(np.maximum(noisy, 0).mean()), 1e-6)
    d = fr["depth"]
    dm = float(d[np.isfinite(d) & (d > 0)].mean()) if np.any(np.isfinite(d) & (d > 0)) else 1.0
    planes = [fr["normal"], d / dm, fr["ao"], np.log1p(np.maximum(noisy, 0) / s)]
    if flr_out is not None:
        planes.append(np.log1p(np.maximum(flr_out, 0) / s))
    x = np.concatenate(planes, 0)
    return np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)


def flr_defaults(fr):
    """FLR's library defaults on the frame's own guides (normal, depth, AO; the adaptive
    window, ε = 1e-3, ϵ = 1e-2, AO demodulation 0.1): the network's last 3 input planes
    with `--flr-input` (src/flnr.rs runs the same before the network)."""
    noisy = np.nan_to_num(fr["noisy"], nan=0.0, posinf=0.0, neginf=0.0)
    x = torch.from_numpy(net_input(fr))[None]
    with torch.no_grad():
        out = flr(torch.from_numpy(noisy)[None], x[:, :5], x[:, :5], ADAPTIVE_SIGMAS, 1e-3, 1e-2, x[:, 4:5], DEFAULT_AO_OFFSET)
    return out[0].numpy().astype(np.float32)


LUMA = (0.2126, 0.7152, 0.0722)
# the library's adaptive window (src/flr/adaptive.rs): its σ set and bias discount K
ADAPTIVE_SIGMAS = (6.0, 12.0, 20.0)
BIAS_DISCOUNT = 0.5
POOL_MIN_SIGMA = 1.5  # larger windows with σ ≥ 1.5 B are fitted on the 2×2-pooled grid
DEFAULT_AO_OFFSET = 0.1  # the library's AO demodulation offset c


def moments(y, z):
    """Block sums of [1, z, z⊗z, y, z⊗y, ℓ²] (ℓ = luminance of y): (N, C, H/B, W/B)."""
    n_, q, h, w = z.shape
    ones = torch.ones_like(y[:, :1])
    luma = sum(LUMA[c] * y[:, c : c + 1] for c in range(3))
    feats = [ones, z, (z.unsqueeze(2) * z.unsqueeze(1)).reshape(n_, q * q, h, w), y, (z.unsqueeze(2) * y.unsqueeze(1)).reshape(n_, q * 3, h, w), luma * luma]
    return F.avg_pool2d(torch.cat(feats, 1), B) * (B * B)


def blur(m, sigma):
    """Gaussian blur of the block grid: σ in pixels → σ/B cells, truncated at 3σ, weights summing to 1."""
    sc = sigma / B
    radius = max(1, int(math.ceil(3 * float(sc))))
    t = torch.arange(-radius, radius + 1, dtype=m.dtype)
    k = torch.exp(-0.5 * (t / sc) ** 2)
    k = k / k.sum()
    c = m.shape[1]
    m = F.conv2d(m, k.view(1, 1, 1, -1).repeat(c, 1, 1, 1), padding=(0, radius), groups=c)
    return F.conv2d(m, k.view(1, 1, -1, 1).repeat(c, 1, 1, 1), padding=(radius, 0), groups=c)


def solve(m, q, eps_mul, eps_add):
    """Per-cell normalized regularized solve (appendix eqs. 12–23) of blurred moments
    m (N, C, gh, gw) → dict: intercept c0 (N gh gw 3), slopes beta (N gh gw q 3), and
    the window statistics the adaptive blend needs."""
    n_, _, gh, gw = m.shape
    m = m.permute(0, 2, 3, 1)  # N, gh, gw, C
    nn_ = m[..., 0:1].clamp_min(1e-6)
    mu = m[..., 1 : 1 + q] / nn_
    ss = m[..., 1 + q : 1 + q + q * q].reshape(n_, gh, gw, q, q) / nn_.unsqueeze(-1)
    muy = m[..., 1 + q + q * q : 4 + q + q * q] / nn_
    p = m[..., 4 + q + q * q : 4 + 4 * q + q * q].reshape(n_, gh, gw, q, 3) / nn_.unsqueeze(-1)
    e = m[..., 4 + 4 * q + q * q] / nn_[..., 0]
    cov = ss - mu.unsqueeze(-1) * mu.unsqueeze(-2)  # guides are already standardised
    wh = cov + eps_mul * mu.unsqueeze(-1) * mu.unsqueeze(-2)
    eye = torch.eye(q, dtype=m.dtype)
    wh = wh + eye * (eps_mul * mu * mu + eps_add).unsqueeze(-1)
    isig = 1.0 / torch.sqrt(torch.diagonal(wh, dim1=-2, dim2=-1).clamp_min(1e-30))
    wh = wh * isig.unsqueeze(-1) * isig.unsqueeze(-2) + eye * eps_add
    cxy = p - mu.unsqueeze(-1) * muy.unsqueeze(-2)
    beta = torch.linalg.solve(wh, cxy * isig.unsqueeze(-1)) * isig.unsqueeze(-1)
    c0 = muy - (beta * mu.unsqueeze(-1)).sum(-2)
    return dict(c0=c0, beta=beta, n=m[..., 0], mu=mu, cov=cov, muy=muy, cxy=cxy, e=e)


def luma(v):
    return v[..., 0] * LUMA[0] + v[..., 1] * LUMA[1] + v[..., 2] * LUMA[2]


def variance(s, q, sigma, cell=B * B):
    """v_s = r_s (Q + 1) / N_s (src/flr/adaptive.rs `variance`); `cell`: pixels per cell."""
    mean = luma(s["muy"])
    explained = (luma(s["beta"]) * luma(s["cxy"])).sum(-1)
    residual = (s["e"] - mean * mean - explained).clamp_min(0.0)
    area = 4 * math.pi * sigma * sigma
    samples = (area * (s["n"] / cell).clamp(max=1.0)).clamp_min(1.0)
    return residual * (q + 1) / samples


def gap(s, first):
    """d_s²: mean squared luminance-prediction difference from the smallest window over it."""
    dc = luma(s["c0"] - first["c0"])
    db = luma(s["beta"] - first["beta"])  # N gh gw q
    at_mean = dc + (db * first["mu"]).sum(-1)
    spread = (db.unsqueeze(-1) * first["cov"] * db.unsqueeze(-2)).sum((-1, -2)).clamp_min(0.0)
    return at_mean * at_mean + spread


def flr(y, gm, gmap, sigmas, eps_mul, eps_add, ao=None, ao_offset=0.0):
    """Differentiable FLR. y: (N,3,H,W), gm/gmap: (N,Q,H,W), H, W multiples of B.
    `sigmas`: one σ (one Gaussian window) or three (the adaptive window, the larger
    windows with σ ≥ 1.5 B on the 2×2-pooled grid, as the library fits them).
    `ao` (N,1,H,W) with `ao_offset` c > 0: the AO demodulation (src/kernels/demodulation.rs):
    y is divided by s = √(clamp(ao, 0, 1) + c) before the fit and the output multiplied by s."""
    if ao is not None and ao_offset > 0:
        s = torch.sqrt(torch.nan_to_num(ao, nan=1.0, posinf=1.0, neginf=1.0).clamp(0.0, 1.0) + ao_offset)
        return flr(y / s, gm, gmap, sigmas, eps_mul, eps_add) * s
    n_, q, h, w = gm.shape
    # standardise the model guides by their frame mean / std (the library's normalized mode)
    mean = gm.mean(dim=(2, 3), keepdim=True)
    std = gm.std(dim=(2, 3), keepdim=True).clamp_min(1e-6)
    z = (gm - mean) / std
    m = moments(y, z).double()
    if len(sigmas) == 1:
        fit = solve(blur(m, sigmas[0]), q, eps_mul, eps_add)
        c0, beta = fit["c0"], fit["beta"]
    else:
        fits, v = [], []
        for k, sg in enumerate(sigmas):
            pooled = k > 0 and sg >= POOL_MIN_SIGMA * B
            if not pooled:
                f = solve(blur(m, sg), q, eps_mul, eps_add)
                fits.append(f)
                v.append(variance(f, q, float(sg)))
                continue
            # the library's pooled grid: moments summed 2×2 (cells of 2B), σ in those
            # cells, the model and variance interpolated back to the block grid
            # (bilinear at i/2 − 1/4: weights ¼, ¾, one tap at the border)
            gh, gw = m.shape[2], m.shape[3]
            mp = F.avg_pool2d(m, 2, ceil_mode=True) * 4
            f = solve(blur(mp, sg / 2), q, eps_mul, eps_add)
            vp = variance(f, q, float(sg), cell=4 * B * B)
            up = lambda t: F.interpolate(t, scale_factor=2, mode="bilinear", align_corners=False)[:, :, :gh, :gw]
            cb = torch.cat([f["c0"], f["beta"].reshape(*f["beta"].shape[:3], q * 3), vp.unsqueeze(-1)], -1).permute(0, 3, 1, 2)
            cb = up(cb).permute(0, 2, 3, 1)
            fits.append(dict(c0=cb[..., :3], beta=cb[..., 3 : 3 + 3 * q].reshape(*cb.shape[:3], q, 3)))
            v.append(cb[..., -1])
        mse = [v[0]]
        for k in (1, 2):
            seen = (v[0] - v[k]).clamp_min(0.0)
            mse.append((gap(fits[k], fits[0]) - BIAS_DISCOUNT * seen).clamp_min(0.0) + v[k])
        wts = [1.0 / x.clamp_min(1e-30) for x in mse]
        tot = wts[0] + wts[1] + wts[2]
        c0 = sum(wk.unsqueeze(-1) * f["c0"] for wk, f in zip(wts, fits)) / tot.unsqueeze(-1)
        beta = sum(wk[..., None, None] * f["beta"] for wk, f in zip(wts, fits)) / tot[..., None, None]
    gh, gw = c0.shape[1], c0.shape[2]
    model = torch.cat([c0, beta.reshape(n_, gh, gw, q * 3)], -1).permute(0, 3, 1, 2).float()
    model = F.interpolate(model, size=(h, w), mode="bilinear", align_corners=False)
    zmap = (gmap - mean) / std
    c0 = model[:, :3]
    beta = model[:, 3:].reshape(n_, q, 3, h, w)
    return c0 + (beta * zmap.unsqueeze(2)).sum(1)


def smape(a, b):
    return ((a - b).abs() / (a.abs() + b.abs() + 1e-2)).mean()


class Flnr(torch.nn.Module):
    def __init__(self, widths, sigmas, ao_offset, cin=8):
        super().__init__()
        self.net = UNet(cin, 2 * QP, widths)
        # the map guides start equal to the model guides, so that an untrained FLNR is FLR with
        # QP more (random, smooth) guides rather than FLR applied to guides it never fitted; the
        # last layer's weights are scaled up so that those guides vary (a spread of ~1e-4 would
        # make the first optimiser steps, which move them apart, blow up FLR's standardisation)
        last = list(self.net.convs())[-1]
        with torch.no_grad():
            last.weight.mul_(10.0)
            last.weight[QP:] = last.weight[:QP]
            last.bias[QP:] = last.bias[:QP]
        self.sigmas = tuple(sigmas)
        self.ao_offset = ao_offset
        self.log_eps_mul = torch.nn.Parameter(torch.tensor(math.log(1e-3)))
        self.log_eps_add = torch.nn.Parameter(torch.tensor(math.log(1e-2)))

    def forward(self, x, y):
        g = self.net(x)
        base = x[:, :5]  # normal, depth, AO: FLR's own guides stay in both sets
        gm = torch.cat([base, g[:, :QP]], 1)
        gmap = torch.cat([base, g[:, QP:]], 1)
        return flr(y, gm, gmap, self.sigmas, self.log_eps_mul.exp(), self.log_eps_add.exp(), x[:, 4:5], self.ao_offset)


def psnr(est, fr):
    """The DATA.md protocol: albedo-modulated, tone-mapped at the reference's mean luminance."""
    albedo, ref = fr["albedo"].astype(np.float64), fr["reference"].astype(np.float64)
    i, r = albedo * est, albedo * ref
    lum = np.mean(LUMA[0] * r[0] + LUMA[1] * r[1] + LUMA[2] * r[2])
    tm = lambda v: (np.maximum(v, 0) * 0.5 / lum / (1 + np.maximum(v, 0) * 0.5 / lum)) ** (1 / 2.2)
    return -10 * np.log10(np.mean((np.clip(tm(i), 0, 1) - np.clip(tm(r), 0, 1)) ** 2))


def full_frame(model, fr, plain=False, sigmas=None):
    """Denoises a whole frame (H, W multiples of B) with the network, or with FLR's own
    guides only (`plain`: the library's FLR defaults, to check this module against it;
    `sigmas` another window set for it, e.g. one σ = 12 window)."""
    x = torch.from_numpy(fr["x"])[None]
    y = torch.from_numpy(fr["y"])[None]
    with torch.no_grad():
        if plain:
            base = x[:, :5]
            out = flr(y, base, base, sigmas or model.sigmas, 1e-3, 1e-2, x[:, 4:5], model.ao_offset)
        else:
            out = model(x, y)
    return out[0].clamp_min(0).numpy()


def random_rotation():
    """A uniformly random 3D rotation (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(np.random.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def crops(frames, size, batch, augment=True):
    """A batch of random crops, augmented so that the network cannot learn one renderer's
    conventions: a random rotation of the normals (world, view or any other frame: FLR's
    regression does not care, the network must not either), a random AO exponent (AO from
    other distances and ray counts), a random light colour, flips and 90° rotations.
    Exposure needs no augmentation: the network's input is divided by the frame's mean
    light and FLR is linear in the light. `augment=False`: crops and flips only."""
    xs, ys, rs = [], [], []
    for _ in range(batch):
        fr = random.choice(frames)
        _, h, w = fr["x"].shape
        oy, ox = random.randrange(0, h - size + 1), random.randrange(0, w - size + 1)
        sl = (slice(None), slice(oy, oy + size), slice(ox, ox + size))
        x, y, r = fr["x"][sl].copy(), fr["y"][sl], fr["r"][sl]
        f = fr["f"][sl] if "f" in fr else None
        if augment:
            x, y, r = recolour(x, y, r, fr["m"], f)
        if random.random() < 0.5:
            x, y, r = x[:, :, ::-1], y[:, :, ::-1], r[:, :, ::-1]
        if random.random() < 0.5:
            x, y, r = x[:, ::-1], y[:, ::-1], r[:, ::-1]
        if augment and random.random() < 0.5:
            x, y, r = x.transpose(0, 2, 1), y.transpose(0, 2, 1), r.transpose(0, 2, 1)
        xs.append(np.ascontiguousarray(x))
        ys.append(np.ascontiguousarray(y))
        rs.append(np.ascontiguousarray(r))
    return torch.from_numpy(np.stack(xs)), torch.from_numpy(np.stack(ys)), torch.from_numpy(np.stack(rs))


def recolour(x, y, r, means, f=None):
    """`crops`' augmentation of one crop: normals rotated, AO raised to a power, light tinted
    (`f`: the crop of FLR's output on the untinted frame, tinted the same; FLR is not
    refitted to the new AO and tint, which move its output little)."""
    x[0:3] = np.einsum("ij,jhw->ihw", random_rotation(), x[0:3]).astype(np.float32)
    x[4] = np.clip(x[4], 0.0, 1.0) ** math.exp(random.uniform(-0.7, 0.7))
    col = np.exp(np.random.uniform(-0.4, 0.4, size=(3, 1, 1))).astype(np.float32)
    y, r = y * col, r * col
    scale = max(float((col[:, 0, 0] * means).mean()), 1e-6)
    x[5:8] = np.log1p(np.maximum(y, 0) / scale)
    if f is not None:
        x[8:11] = np.log1p(np.maximum(f * col, 0) / scale)
    return x, y, r


def family(path):
    """`DIR/FAMILY`: a frame's folder and the name of its scene family (`gallery_31.exr`: gallery)."""
    d = os.path.basename(os.path.dirname(os.path.abspath(path)))
    return f"{d}/{re.sub(r'_[0-9]+$', '', os.path.splitext(os.path.basename(path))[0])}"


def oidn_psnr(fr):
    """OIDN 2 (pyoidn, RT filter, quality high; as tools/peers.py) on the frame, or None without pyoidn."""
    try:
        import pyoidn
    except ImportError:
        return None
    alb = fr["albedo"].transpose(1, 2, 0).astype(np.float32)
    col = (alb * fr["y"].transpose(1, 2, 0)).astype(np.float32)
    nrm = fr["normal"].transpose(1, 2, 0).astype(np.float32)
    out = np.asarray(pyoidn.denoise(col, alb, nrm, hdr=True, clean_aux=True, quality="high"), dtype=np.float64)
    est = np.where(alb > 0, out / np.maximum(alb, 1e-8), 0.0).transpose(2, 0, 1)
    return psnr(est, fr)


def family_table(model, group, title):
    """Prints mean PSNR per family: FLR defaults, FLR with one σ = 12 window, OIDN, FLNR."""
    rows = {}
    for fr in group:
        scores = (
            psnr(full_frame(model, fr, plain=True), fr),
            psnr(full_frame(model, fr, plain=True, sigmas=(12.0,)), fr),
            oidn_psnr(fr),
            psnr(full_frame(model, fr), fr),
        )
        rows.setdefault(family(fr["name"]), []).append(scores)
        print(f"{fr['name']}: " + ", ".join("–" if v is None else f"{v:.2f}" for v in scores), flush=True)
    everything = [sc for v in rows.values() for sc in v]
    mean = lambda sc, k: "–" if any(v[k] is None for v in sc) else f"{np.mean([v[k] for v in sc]):.2f}"
    print(f"\n{title}: mean PSNR (dB) per family\n")
    print("| family | frames | FLR defaults | FLR σ = 12 | OIDN 2 | FLNR | FLNR − FLR |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, sc in sorted(rows.items()) + [("**mean**", everything)]:
        d = np.mean([v[3] - v[0] for v in sc])
        print(f"| {name} | {len(sc)} | {mean(sc, 0)} | {mean(sc, 1)} | {mean(sc, 2)} | {mean(sc, 3)} | {d:+.2f} |")
    print(flush=True)


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
    ap.add_argument("--sigmas", default="6,12,20", help="FLR windows: one σ, or three (the adaptive window, the library's default)")
    ap.add_argument("--init", default=None, help="start from this blob's network weights and eps (same widths)")
    ap.add_argument("--ao-demodulation", type=float, default=0.1, help="offset c of FLR's AO demodulation (the library's default 0.1; 0: off)")
    ap.add_argument("--no-augment", action="store_true", help="train on plain crops and flips (no normal rotation, AO exponent or light colour)")
    ap.add_argument("--val", nargs="*", default=[], help="frames only scored (per family) at the end, to choose between runs; never trained on")
    ap.add_argument("--heldout", nargs="*", default=[], help="held-out families: scored once at the end (per family, with OIDN), never trained or chosen on")
    ap.add_argument("--threads", type=int, default=2, help="PyTorch's CPU threads")
    ap.add_argument("--flr-input", action="store_true", help="the network also reads FLR's defaults output (11 input planes); with --init from an 8-input blob, the new inputs start at zero weight")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--check", action="store_true", help="only print plain FLR's PSNR per frame (compare with `lrd eval`)")
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.set_num_threads(args.threads)
    def prepare(p):
        fr = load(p)
        y = np.nan_to_num(fr["noisy"], nan=0.0, posinf=0.0, neginf=0.0)
        m = np.maximum(y, 0).reshape(3, -1).mean(1)  # per-channel means: the light-colour augmentation rescales the input
        extra = {}
        if args.flr_input:
            extra["f"] = flr_defaults(fr)
        return {**extra, "x": net_input(fr, extra.get("f")), "y": y, "r": fr["reference"], "albedo": fr["albedo"], "normal": fr["normal"], "reference": fr["reference"], "m": m, "name": p}

    frames = [prepare(p) for p in args.frames]
    val = [prepare(p) for p in args.val]
    heldout = [prepare(p) for p in args.heldout]
    sigmas = [float(v) for v in args.sigmas.split(",")]
    print(f"{len(frames)} frames; widths {args.widths}; FLR windows {sigmas}; AO demodulation {args.ao_demodulation or 'off'}")
    model = Flnr([int(v) for v in args.widths.split(",")], sigmas, args.ao_demodulation, 11 if args.flr_input else 8)
    if args.check:
        for fr in frames:
            print(f"{fr['name']}: plain FLR {psnr(full_frame(model, fr, plain=True), fr):.2f} dB")
        return
    if args.init:
        # the network and the ε, ϵ it was trained with
        _, (eps_mul, eps_add), _ = load_blob(model.net, args.init, widen=True)
        with torch.no_grad():
            model.log_eps_mul.fill_(math.log(eps_mul))
            model.log_eps_add.fill_(math.log(eps_add))
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, args.steps)
    curve = []
    t0 = time.time()
    for step in range(1, args.steps + 1):
        x, y, r = crops(frames, args.crop, args.batch, not args.no_augment)
        out = model(x, y)
        loss = smape(out, r)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        curve.append((step, loss.item()))
        if step % 50 == 0 or step == 1:
            print(f"step {step} loss {np.mean([c[1] for c in curve[-50:]]):.4f} "
                  f"eps {float(model.log_eps_mul.exp()):.2e},{float(model.log_eps_add.exp()):.2e} {time.time() - t0:.0f}s", flush=True)
    model.net.round_to_f16()
    eps = (float(model.log_eps_mul.exp()), float(model.log_eps_add.exp()))
    export(model.net, args.out, sigmas, eps, args.ao_demodulation)
    if args.log:
        with open(args.log, "w") as f:
            f.write("step,loss\n" + "".join(f"{s},{l:.5f}\n" for s, l in curve))
    print(f"wrote {args.out}; FLR windows {sigmas} eps_mul {eps[0]:.2e} eps_add {eps[1]:.2e}")
    pairs = [(psnr(full_frame(model, fr, plain=True), fr), psnr(full_frame(model, fr), fr)) for fr in frames]
    print(f"train mean ({len(pairs)} frames): FLR defaults {np.mean([a for a, _ in pairs]):.3f} dB, FLNR {np.mean([b for _, b in pairs]):.3f} dB")
    if val:
        family_table(model, val, "validation (choose between runs on this)")
    if heldout:
        family_table(model, heldout, "held-out families (never trained or chosen on)")


if __name__ == "__main__":
    main()
