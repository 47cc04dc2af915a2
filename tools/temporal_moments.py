"""Temporal FLR that accumulates FLR's cell moments instead of the light, in numpy
on top of tools/flr_mirror.py (FLR's defaults op for op, without the firefly
clamp), to measure the design before it is built: a history of one moment vector
per 8×8 cell instead of one record per pixel, so that a frame costs about one FLR.

Per frame:
1. FLR's block moments of the AO-demodulated noisy light, in this frame's guide
   normalisation (z = (g − mean) / std per guide).
2. The accumulated moments of the previous frame are moved into this frame's
   normalisation (an affine map of each guide: the moments map exactly) and
   reprojected per cell: bilinear over the previous cell grid at the cell's
   mean motion (previous − current, pixels). Each of the 4 taps is kept where
   its cells' mean normal is within `--normal-limit` (cosine) of the current
   cell's and its mean depth within `--depth-limit` (relative), or both cells
   have no geometry (sky continues sky, as in the library's stage).
3. Depth changes as the camera moves (a dolly): each reprojected cell's depth
   moments are rescaled by the ratio of the current cell's mean depth to the
   history's (clamped to 0.5–2), so its samples sit at this frame's depth.
4. Blend: H = (1 − a) H_reprojected + a M with a = 1 / n, n the history
   length (the accepted taps' mean plus one, at most `--max-history`); the
   fast history F the same way over at most `--fast-history` frames.
   The lag test: where F's mean luminance over the cell's 3×3 cells differs
   from H's by more than `--lag-k` standard errors, H is replaced by F.
5. FLR's blur, solve, adaptive blend and apply on H; each window's variance is
   divided by the (window-blurred) history length, the samples it averages.

    python3 tools/temporal_moments.py SEQ_DIR... [--sigmas 3,6,12] [--per-frame]
        [--normal-limit 0.8] [--depth-limit 0.1] [--max-history 16] [--no-depth-rescale]
        [--fast-history 2] [--lag-k 3] [--lag-radius 1]

Prints the mean PSNR and flicker of each sequence's last 4 frames (docs/DATA.md's
metrics, as `lrd eval`'s sequence table has them) and their means. `--per-frame` is FLR per frame on
the same code (σ as given). Sequences as `tools/render.py --seq` writes them.
Choose settings on training sequences only.
"""
import argparse
import glob
import os
import sys

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import flr_mirror as fm  # noqa: E402
from flr_mirror import B  # noqa: E402

DEPTH = 3  # the depth's index among the guides (normal x, y, z, depth, ao)


def load(path):
    fr = fm.load(path)
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if "motion.X" in ch:
            fr["motion"] = np.stack([np.asarray(ch[f"motion.{c}"].pixels, dtype=np.float32) for c in "XY"], 0)
    return fr


def affine(m, q, a, b):
    """The moments (fm.moments' layout, C × gh × gw) of z' = a z + b, from those
    of z; `a`, `b`: per guide, shaped (q, 1, 1) or per cell (q, gh, gw)."""
    n = m[0]
    s = m[1:1 + q]
    ss = m[1 + q:1 + q + q * q].reshape(q, q, *m.shape[1:])
    y = m[1 + q + q * q:4 + q + q * q]
    zy = m[4 + q + q * q:4 + 4 * q + q * q].reshape(q, 3, *m.shape[1:])
    e = m[4 + 4 * q + q * q]
    s2 = a * s + b * n
    ss2 = a[:, None] * a[None] * ss + a[:, None] * b[None] * s[:, None] + b[:, None] * a[None] * s[None] + b[:, None] * b[None] * n
    zy2 = a[:, None] * zy + b[:, None] * y[None]
    return np.concatenate([n[None], s2, ss2.reshape(q * q, *m.shape[1:]), y, zy2.reshape(q * 3, *m.shape[1:]), e[None]], 0)


def guide_means(m, q, mean, std):
    """Each cell's mean guides in raw units (q × gh × gw)."""
    return m[1:1 + q] / np.maximum(m[0], 1e-6) * std + mean


def reproject(H, nH, m, motion, q, mean, std, normal_limit, depth_limit, mix=False, sharpen=1.0, extra=None):
    """The history H (in this frame's normalisation) and its lengths nH at each
    current cell: bilinear over the previous grid at the cell's mean motion,
    taps judged by their mean normal and depth. Cells without a kept tap get 0."""
    gh, gw = m.shape[1:]
    mv = fm.block_sum(motion, B) / (B * B)
    cy, cx = np.meshgrid(np.arange(gh), np.arange(gw), indexing="ij")
    px, py = cx + mv[0] / B, cy + mv[1] / B
    x0, y0 = np.floor(px).astype(int), np.floor(py).astype(int)
    fx, fy = px - x0, py - y0
    if sharpen != 1.0:
        # bilinear weights raised to a power per axis and renormalised: less blur per frame
        fx = fx**sharpen / (fx**sharpen + (1 - fx) ** sharpen)
        fy = fy**sharpen / (fy**sharpen + (1 - fy) ** sharpen)
    cur, hist = guide_means(m, q, mean, std), guide_means(H, q, mean, std)
    unit = lambda v: v / np.maximum(np.linalg.norm(v, axis=0), 1e-6)
    empty = lambda v: np.linalg.norm(v, axis=0) < 1e-6
    nc = unit(cur[:3])
    out, n_out, wsum = np.zeros_like(H), np.zeros((gh, gw)), np.zeros((gh, gw))
    ext = None if extra is None else np.zeros_like(extra)
    taps = []
    for dy, dx, w in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        tx, ty = x0 + dx, y0 + dy
        inside = (tx >= 0) & (tx < gw) & (ty >= 0) & (ty < gh) & (w > 0)
        tx, ty = np.clip(tx, 0, gw - 1), np.clip(ty, 0, gh - 1)
        taps.append((tx, ty, np.where(inside, w, 0.0)))

    def ok_of(th):
        # (no geometry on both sides: sky continues sky)
        sky = empty(cur[:3]) & empty(th[:3])
        ok = ((nc * unit(th[:3])).sum(0) >= normal_limit) | sky
        return ok & ((np.abs(th[DEPTH] - cur[DEPTH]) <= depth_limit * np.abs(cur[DEPTH])) | sky)

    mix_ok = np.zeros((gh, gw), bool)
    if mix:
        # the taps' mixture, judged as a whole: a cell whose normals vary keeps a
        # history that covers the same mix of surfaces though no single tap matches
        mx = sum(w[None] * H[:, ty, tx] for tx, ty, w in taps)
        mix_ok = (sum(taps_w for _, _, taps_w in taps) > 1e-3) & ok_of(guide_means(mx, q, mean, std))
    for tx, ty, w in taps:
        th = hist[:, ty, tx]
        ok = (w > 0) & (ok_of(th) | mix_ok)
        w = np.where(ok, w, 0.0)
        out += w[None] * H[:, ty, tx]
        if ext is not None:
            ext += w[None] * extra[:, ty, tx]
        n_out += w * nH[ty, tx]
        wsum += w
    has = wsum > 1e-3
    if ext is not None:
        ext = np.where(has[None], ext / np.maximum(wsum, 1e-9)[None], 0.0)
        return np.where(has[None], out / np.maximum(wsum, 1e-9)[None], 0.0), np.where(has, n_out / np.maximum(wsum, 1e-9), 0.0), ext
    return np.where(has[None], out / np.maximum(wsum, 1e-9)[None], 0.0), np.where(has, n_out / np.maximum(wsum, 1e-9), 0.0)


def rescale_depth(R, m, q, mean, std):
    """R's depth moments scaled per cell by the current cell's mean depth over R's."""
    hd, cd = guide_means(R, q, mean, std)[DEPTH], guide_means(m, q, mean, std)[DEPTH]
    ok = (R[0] > 1e-6) & (np.abs(hd) > 1e-6)
    r = np.clip(np.where(ok, cd / np.where(ok, hd, 1.0), 1.0), 0.5, 2.0)
    a, b = np.ones((q, *r.shape)), np.zeros((q, *r.shape))
    # depth' = r · depth in raw units, in z units: z' = r z + (r − 1) mean / std
    a[DEPTH], b[DEPTH] = r, (r - 1) * mean[DEPTH, 0, 0] / std[DEPTH, 0, 0]
    return affine(R, q, a, b)


def pooled(v, r):
    """Sums over the (2r+1)² cells around each cell (edges: what exists)."""
    out = np.zeros_like(v)
    gh, gw = v.shape[-2:]
    p = np.pad(v, [(0, 0)] * (v.ndim - 2) + [(r, r), (r, r)])
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            out += p[..., dy:dy + gh, dx:dx + gw]
    return out


def lag_test(H, nH, F, nF, q, a):
    """Cells whose fast history's mean luminance differs from the slow one's by
    more than `a.lag_k` standard errors, over the (2r+1)² cells around each
    (the library's `moment_history::lags`). F's frames are H's newest:
    d = (1 − nF/nH)(F − O), O the mean of H's older frames."""
    yi, ei = slice(1 + q + q * q, 4 + q + q * q), 4 + 4 * q + q * q
    PH, PF = pooled(H, a.lag_radius), pooled(F, a.lag_radius)
    n_h, n_f = np.maximum(PH[0], 1e-9), np.maximum(PF[0], 1e-9)
    l_h, l_f = np.tensordot(fm.LUMA, PH[yi], 1) / n_h, np.tensordot(fm.LUMA, PF[yi], 1) / n_f
    var = np.maximum(PH[ei] / n_h - l_h * l_h, 0.0)
    older = np.maximum(nH - nF, 1e-9)
    se = np.sqrt(var / n_h * (older / np.maximum(nH, 1e-9)) ** 2 * (1 / nF + 1 / older))
    return (nH > nF) & (np.abs(l_f - l_h) > a.lag_k * se + 1e-9 * (np.abs(l_h) + np.abs(l_f)))


def tone_mapped(est, fr):
    """The albedo-modulated image and reference, tone mapped as scored (docs/DATA.md)."""
    albedo, ref = fr["albedo"].astype(np.float64), fr["reference"].astype(np.float64)
    i, r = albedo * est, albedo * ref
    lum = np.mean(fm.LUMA[0] * r[0] + fm.LUMA[1] * r[1] + fm.LUMA[2] * r[2])
    k = 0.5 / lum if lum > 0 else 1.0
    tm = lambda v: (np.maximum(v, 0) * k / (1 + np.maximum(v, 0) * k)) ** (1 / 2.2)
    return tm(i), tm(r)


def warp(img, motion):
    """`img` (3 × h × w) at each pixel's previous position, bilinear; NaN where a tap leaves it."""
    _, h, w = img.shape
    ys, xs = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    px, py = xs + motion[0], ys + motion[1]
    fx, fy = np.floor(px), np.floor(py)
    inside = (fx >= 0) & (fy >= 0) & (fx + 1 < w) & (fy + 1 < h)  # false for NaN motion
    x, y = (np.clip(np.nan_to_num(v), 0, n - 2).astype(int) for v, n in ((fx, w), (fy, h)))
    ax, ay = px - fx, py - fy
    out = (1 - ay) * ((1 - ax) * img[:, y, x] + ax * img[:, y, x + 1]) + ay * ((1 - ax) * img[:, y + 1, x] + ax * img[:, y + 1, x + 1])
    return np.where(inside[None], out, np.nan)


def flicker(o, r, prev, motion):
    """`lrd eval`'s flicker (`metrics::flicker`): the RMS of (O − W O') − (R − W R')."""
    po, pr = warp(prev[0], motion), warp(prev[1], motion)
    d = (o - po) - (r - pr)
    return float(np.sqrt(np.nanmean(d * d)))


def sequence(paths, a):
    """PSNR and flicker (None for the first frame) of each frame of one sequence."""
    scores, flickers, H, nH, prev, prev_tm = [], [], None, None, None, None
    F, nF, lagged = None, None, 0
    for path in paths:
        fr = load(path)
        y, g = fm.prep(fr)
        ao = np.nan_to_num(fr["ao"][0].astype(np.float64), nan=1.0, posinf=1.0, neginf=1.0)
        s = np.sqrt(np.clip(ao, 0, 1) + 0.1)[None]
        mean = g.mean(axis=(1, 2), keepdims=True)
        std = np.maximum(g.std(axis=(1, 2), ddof=1, keepdims=True), 1e-6)
        z = (g - mean) / std
        q = z.shape[0]
        m = fm.moments(y / s, z)
        if a.per_frame or H is None or "motion" not in fr:
            H, nH = m, np.ones(m.shape[1:])
            F, nF = m, np.ones(m.shape[1:])
        else:
            pm, ps = prev
            H = affine(H, q, ps / std, (pm - mean) / std)
            F = affine(F, q, ps / std, (pm - mean) / std)
            motion = np.nan_to_num(fr["motion"].astype(np.float64))
            R, nR, RF = reproject(H, nH, m, motion, q, mean, std, a.normal_limit, a.depth_limit, a.mix, a.sharpen, extra=F)
            if not a.no_depth_rescale:
                R = rescale_depth(R, m, q, mean, std)
                RF = rescale_depth(RF, m, q, mean, std)
            nH = np.minimum(nR + 1.0, a.max_history)
            nF = np.minimum(nR + 1.0, a.fast_history)
            H = (1 - 1 / nH)[None] * R + (1 / nH)[None] * m
            F = (1 - 1 / nF)[None] * RF + (1 / nF)[None] * m
            if a.lag_k > 0:
                lag = lag_test(H, nH, F, nF, q, a)
                lagged += int(lag.sum())
                H = np.where(lag[None], F, H)
                nH = np.where(lag, nF, nH)
        prev = (mean, std)
        est = fm.fit_moments(H, z, a.sigmas, frames=nH) * s
        scores.append(fm.psnr(est, fr))
        tm = tone_mapped(est, fr)
        flickers.append(flicker(*tm, prev_tm, fr["motion"].astype(np.float64)) if prev_tm and "motion" in fr else None)
        prev_tm = tm
    if a.lag_k > 0:
        print(f"  cells shortened: {lagged} ({lagged / (len(paths) * H[0].size):.1%} of cell-frames)")
    return scores, flickers


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("seqs", nargs="+")
    ap.add_argument("--sigmas", default="3,6,12", type=lambda v: tuple(float(x) for x in v.split(",")))
    ap.add_argument("--per-frame", action="store_true")
    ap.add_argument("--normal-limit", type=float, default=0.8)
    ap.add_argument("--depth-limit", type=float, default=0.1)
    ap.add_argument("--max-history", type=float, default=16.0)
    ap.add_argument("--no-depth-rescale", action="store_true")
    ap.add_argument("--sharpen", type=float, default=1.0, help="bilinear weights per axis raised to this power, renormalised")
    ap.add_argument("--mix", action="store_true", help="keep every tap where the taps' mixture passes the test")
    ap.add_argument("--fast-history", type=float, default=2.0, help="the fast history's longest length (the lag test's)")
    ap.add_argument("--lag-k", type=float, default=3.0, help="standard errors past which the slow history is shortened to the fast one (0: off)")
    ap.add_argument("--lag-radius", type=int, default=1, help="cells summed each side for the lag test")
    a = ap.parse_args()
    last4, fl4 = [], []
    for d in a.seqs:
        sc, fl = sequence(sorted(glob.glob(os.path.join(d, "frame_*.exr"))), a)
        last4.append(float(np.mean(sc[-4:])))
        fl4.append(float(np.mean([f for f in fl[-4:] if f is not None])))
        print(f"{os.path.basename(d.rstrip('/'))}: last 4 {last4[-1]:.2f} dB, all {np.mean(sc):.2f} dB, flicker of the last 4 {fl4[-1]:.4f}", flush=True)
    print(f"mean of the last 4 frames over {len(last4)} sequences: {np.mean(last4):.2f} dB, flicker {np.mean(fl4):.4f}")


if __name__ == "__main__":
    main()
