"""FLR in numpy, op for op like the library's defaults (a port of train/flnr.py's torch
mirror: 8×8 block moments, Gaussian blur of the block grid, the normalized-correlation
regularized solve, the adaptive window σ 6/12/20 px with the larger two on the 2×2-pooled
grid, bilinear model interpolation), for trying estimator changes without torch or a
rebuild. With no options it gives `lrd eval`'s FLR PSNR on frames that fill whole blocks
(e.g. the 256×256 renders of tools/render.py).

    python3 tools/flr_mirror.py frames/train/*.exr [--sigmas 6,12,20] [--lattice 32]
        [--shrink K] [--basis chol|eig] [--shrink-variance] [--mse-blur CELLS]
        [--weight-power P] [--chroma WINDOW] [--subsets 0123;... --subset-windows 0,1]
        [--area-box C] [--eps-windows a,b,c] [--shared-residual] [--leverage]
        [--ao-demod C|off]

Options the library has (same arithmetic, same PSNR as `lrd eval`):
  --subsets 0123 --subset-windows 0
                    also fit window 0 without AO (guides 0..3 of normal xyz, depth, ao),
                    a candidate blended like a window: variance r (Q' + 1) / N with its
                    own Q', bias² from its gap to window 0's full fit
                    (FlrConfig::adaptive_without_ao, `lrd --without-ao`, off by default)
  --ao-demod C|off  the noisy light divided by s = sqrt(clamp(ao, 0, 1) + C) before the
                    fit, the output multiplied by s (FlrConfig::ao_demodulation; the
                    library's default is C = 0.1; "off" is plain FLR)
Estimator variants the library does not have (each scored no better on the training
frames; docs/METHODS.md, FLR):
  --lattice N       frame guide mean/std from an N×N lattice of samples, not all pixels
  --shrink K        Wiener shrinkage of the guide coefficients, q²/(q² + K r/N) per
                    component of the whitened basis (--basis), every window
  --shrink-variance the blend's variance counts the shrunk components (1 + Σf) not Q + 1
  --mse-blur C      blur the blend's per-cell MSE estimates over C cells (Gaussian σ)
  --weight-power P  blend weights 1 / MSE^P
  --chroma S        one chromaticity per cell, from window S; only luminance per pixel
  --area-box C      variance area 4π(σ² + C b²/12), b the grid's cell side
  --eps-windows a,b,c  ϵ per window
  --shared-residual every window's variance from window 0's residual
  --leverage        each candidate's variance r (1 + E_cell[(x − μ)ᵀ M (x − μ)]) / N, the
                    cell's own leverage under the regularized inverse M (LEV_SCALE=s
                    scales it)
Training frames only: never tune on the test split (tools/render.py --split test).
"""
import math
import os
import glob
import numpy as np
import OpenEXR

B = 8
LUMA = np.array((0.2126, 0.7152, 0.0722))
BIAS_DISCOUNT = 0.5


def load(path):
    with OpenEXR.File(path) as f:
        ch = f.channels()

        def layer(name, comps):
            if name in ch:
                a = np.asarray(ch[name].pixels, dtype=np.float32)
                return a[None] if a.ndim == 2 else np.moveaxis(a, -1, 0)
            return np.stack([np.asarray(ch[f"{name}.{c}"].pixels, dtype=np.float32) for c in comps], 0)

        return {k: layer(k, c) for k, c in [("noisy", "RGB"), ("reference", "RGB"), ("albedo", "RGB"), ("normal", "XYZ"), ("depth", "Z"), ("ao", "Y")]}


def psnr(est, fr):
    albedo, ref = fr["albedo"].astype(np.float64), fr["reference"].astype(np.float64)
    i, r = albedo * est, albedo * ref
    lum = np.mean(LUMA[0] * r[0] + LUMA[1] * r[1] + LUMA[2] * r[2])
    tm = lambda v: (np.maximum(v, 0) * 0.5 / lum / (1 + np.maximum(v, 0) * 0.5 / lum)) ** (1 / 2.2)
    return -10 * np.log10(np.mean((np.clip(tm(i), 0, 1) - np.clip(tm(r), 0, 1)) ** 2))


def block_sum(x, b):
    c, h, w = x.shape
    return x.reshape(c, h // b, b, w // b, b).sum((2, 4))


def moments(y, z):
    q = z.shape[0]
    ones = np.ones_like(y[:1])
    l = np.tensordot(LUMA, y, 1)[None]
    zz = (z[:, None] * z[None]).reshape(q * q, *z.shape[1:])
    zy = (z[:, None] * y[None]).reshape(q * 3, *z.shape[1:])
    feats = np.concatenate([ones, z, zz, y, zy, l * l], 0).astype(np.float64)
    return block_sum(feats, B)


def sub_moments(m, q, keep):
    """Moment vector of the guide subset `keep` (indices into the q guides)."""
    keep = list(keep)
    idx = [0] + [1 + i for i in keep]
    idx += [1 + q + i * q + j for i in keep for j in keep]
    idx += [1 + q + q * q + c for c in range(3)]
    idx += [4 + q + q * q + i * 3 + c for i in keep for c in range(3)]
    idx += [4 + 4 * q + q * q]
    return m[idx]


def expand(f, q, keep):
    """A subset fit's model with zero coefficients for the dropped guides."""
    gh, gw = f["c0"].shape[:2]
    beta = np.zeros((gh, gw, q, 3))
    beta[..., list(keep), :] = f["beta"]
    return dict(c0=f["c0"], beta=beta)


def conv1d(m, k, axis):
    r = len(k) // 2
    pad = [(0, 0)] * m.ndim
    pad[axis] = (r, r)
    p = np.pad(m, pad)
    out = np.zeros_like(m)
    n = m.shape[axis]
    for i, kw in enumerate(k):
        out += kw * np.take(p, np.arange(i, i + n), axis=axis)
    return out


def blur(m, sigma):
    sc = sigma / B
    radius = max(1, int(math.ceil(3 * sc)))
    t = np.arange(-radius, radius + 1, dtype=np.float64)
    k = np.exp(-0.5 * (t / sc) ** 2)
    k /= k.sum()
    return conv1d(conv1d(m, k, 2), k, 1)


def solve(m, q, eps_mul, eps_add, shrink=0.0, sigma=None, cell=B * B, basis="chol"):
    m = np.moveaxis(m, 0, -1)  # gh gw C
    gh, gw = m.shape[:2]
    nn_ = np.maximum(m[..., 0:1], 1e-6)
    mu = m[..., 1:1 + q] / nn_
    ss = m[..., 1 + q:1 + q + q * q].reshape(gh, gw, q, q) / nn_[..., None]
    muy = m[..., 1 + q + q * q:4 + q + q * q] / nn_
    p = m[..., 4 + q + q * q:4 + 4 * q + q * q].reshape(gh, gw, q, 3) / nn_[..., None]
    e = m[..., 4 + 4 * q + q * q] / nn_[..., 0]
    cov = ss - mu[..., :, None] * mu[..., None, :]
    eye = np.eye(q)
    wh = cov + eps_mul * mu[..., :, None] * mu[..., None, :]
    wh = wh + eye * (eps_mul * mu * mu + eps_add)[..., None]
    isig = 1.0 / np.sqrt(np.maximum(np.diagonal(wh, axis1=-2, axis2=-1), 1e-30))
    wh = wh * isig[..., :, None] * isig[..., None, :] + eye * eps_add
    cxy = p - mu[..., :, None] * muy[..., None, :]
    rhs = cxy * isig[..., :, None]
    fsum = np.full((gh, gw), float(q))
    if shrink > 0:
        # residual variance of the luminance after the plain fit
        bs = np.linalg.solve(wh, rhs)
        mean = muy @ LUMA
        explained = ((bs @ LUMA) * (rhs @ LUMA)).sum(-1)
        resid = np.maximum(e - mean * mean - explained, 0.0)
        area = 4 * math.pi * sigma * sigma
        nsamp = np.maximum(area * np.minimum(m[..., 0] / cell, 1.0), 1.0)
        noise = resid / nsamp
        if basis == "chol":
            L = np.linalg.cholesky(wh)
            qv = np.linalg.solve(L, rhs)  # gh gw q 3
            ql = qv @ LUMA
            f = ql * ql / (ql * ql + shrink * noise[..., None] + 1e-300)
            bs = np.linalg.solve(np.swapaxes(L, -1, -2), qv * f[..., None])
        else:
            w, V = np.linalg.eigh(wh)
            qv = np.swapaxes(V, -1, -2) @ rhs / np.sqrt(w)[..., None]
            ql = qv @ LUMA
            f = ql * ql / (ql * ql + shrink * noise[..., None] + 1e-300)
            bs = V @ (qv * f[..., None] / np.sqrt(w)[..., None])
        fsum = f.sum(-1)
        beta = bs * isig[..., :, None]
    else:
        beta = np.linalg.solve(wh, rhs) * isig[..., :, None]
    c0 = muy - (beta * mu[..., :, None]).sum(-2)
    M = isig[..., :, None] * np.linalg.inv(wh) * isig[..., None, :]
    return dict(c0=c0, beta=beta, n=m[..., 0], mu=mu, cov=cov, muy=muy, cxy=cxy, e=e, fsum=fsum, M=M)


AREA_BOX = 0.0  # experiment: area 4π(σ² + AREA_BOX · b²/12) with b the grid's cell side
def variance(s, q, sigma, cell=B * B, use_f=False):
    mean = s["muy"] @ LUMA
    explained = ((s["beta"] @ LUMA) * (s["cxy"] @ LUMA)).sum(-1)
    residual = np.maximum(s["e"] - mean * mean - explained, 0.0)
    s["residual"] = residual
    area = 4 * math.pi * (sigma * sigma + AREA_BOX * cell / 12)
    samples = np.maximum(area * np.minimum(s["n"] / cell, 1.0), 1.0)
    k = (1 + s["fsum"]) if use_f else (q + 1)
    return residual * k / samples


LEVERAGE = False  # experiment: each candidate's variance r (1 + E_cell[(x − μ)ᵀ M (x − μ)]) / N at the block cell
LEV_SCALE = float(os.environ.get("LEV_SCALE", "1"))


def cell_stats(m, q):
    """The raw block cells' guide mean and covariance (unblurred moments)."""
    mm = np.moveaxis(m, 0, -1)
    n = np.maximum(mm[..., 0:1], 1e-6)
    mu = mm[..., 1:1 + q] / n
    ss = mm[..., 1 + q:1 + q + q * q].reshape(*mm.shape[:2], q, q) / n[..., None]
    return mu, ss - mu[..., :, None] * mu[..., None, :]


def leverage(mu_s, M, mu_c, cov_c):
    d = mu_c - mu_s
    return np.einsum("...a,...ab,...b->...", d, M, d) + np.einsum("...ab,...ba->...", M, cov_c)


def gap(s, first):
    dc = (s["c0"] - first["c0"]) @ LUMA
    db = (s["beta"] - first["beta"]) @ LUMA
    at_mean = dc + (db * first["mu"]).sum(-1)
    spread = np.maximum(np.einsum("...a,...ab,...b->...", db, first["cov"], db), 0.0)
    return at_mean * at_mean + spread


def resize_bilinear(x, oh, ow, sh, sw):
    """align_corners=False bilinear, x: (..., h, w) → (..., oh, ow) with scale sh, sw (out/in)."""
    h, w = x.shape[-2:]

    def idx(n_out, n_in, s):
        c = (np.arange(n_out) + 0.5) / s - 0.5
        c = np.maximum(c, 0)
        i0 = np.minimum(np.floor(c).astype(int), n_in - 1)
        i1 = np.minimum(i0 + 1, n_in - 1)
        t = c - i0
        return i0, i1, t

    y0, y1, ty = idx(oh, h, sh)
    x0, x1, tx = idx(ow, w, sw)
    a = x[..., y0, :] * (1 - ty)[:, None] + x[..., y1, :] * ty[:, None]
    return a[..., x0] * (1 - tx) + a[..., x1] * tx


def flr(y, g, sigmas=(6.0, 12.0, 20.0), eps_mul=1e-3, eps_add=1e-2, eps_windows=None, shared_residual=False, shrink=(0.0, 0.0, 0.0), basis="chol", use_f=False, mse_blur=0.0, K=BIAS_DISCOUNT, wpow=1.0, chroma=None, lattice=0, subsets=(), subset_windows=(0, 1, 2)):
    q, h, w = g.shape
    gs = g
    if lattice:
        ys = ((2 * np.arange(lattice) + 1) * h) // (2 * lattice)
        xs = ((2 * np.arange(lattice) + 1) * w) // (2 * lattice)
        gs = g[:, ys][:, :, xs]
    mean = gs.mean(axis=(1, 2), keepdims=True)
    std = np.maximum(gs.std(axis=(1, 2), ddof=1, keepdims=True), 1e-6)
    z = (g - mean) / std
    return fit_moments(moments(y, z), z, sigmas, eps_mul, eps_add, eps_windows, shared_residual, shrink, basis, use_f, mse_blur, K, wpow, chroma, subsets, subset_windows)


def blurred_mean(v, sigma):
    """v (gh × gw) under the window blur of σ pixels, normalised at the edges."""
    return blur(v[None], sigma)[0] / blur(np.ones_like(v)[None], sigma)[0]


def fit_moments(m, z, sigmas=(6.0, 12.0, 20.0), eps_mul=1e-3, eps_add=1e-2, eps_windows=None, shared_residual=False, shrink=(0.0, 0.0, 0.0), basis="chol", use_f=False, mse_blur=0.0, K=BIAS_DISCOUNT, wpow=1.0, chroma=None, subsets=(), subset_windows=(0, 1, 2), frames=None):
    """FLR from the block moments `m` of the normalised guides `z`: blur, solve,
    adaptive blend and apply. `frames` (gh × gw, optional): the frames each
    cell's moments average (tools/temporal_moments.py); each window's variance
    is divided by their window-blurred mean."""
    q, h, w = z.shape
    gh, gw = m.shape[1:]
    shrink = tuple(shrink) + (0.0,) * (len(sigmas) - len(shrink))
    fits, v = [], []
    cands = [(k, sg, tuple(range(q))) for k, sg in enumerate(sigmas)]
    for keep in subsets:
        cands += [(k, sg, keep) for k, sg in enumerate(sigmas) if k in subset_windows]
    for k, sg, keep in cands:
        qq = len(keep)
        pooled = k > 0 and sg >= 1.5 * B
        mm = m if qq == q else sub_moments(m, q, keep)
        ea = eps_windows[k] if eps_windows else eps_add
        if not pooled:
            f = solve(blur(mm, sg), qq, eps_mul, ea, shrink[k], sg, basis=basis)
            vv = variance(f, qq, sg, use_f=use_f)
            if frames is not None:
                vv = vv / np.maximum(blurred_mean(frames, sg), 1.0)
            if LEVERAGE:
                mu_c, cov_c = cell_stats(mm, qq)
                vv = vv / (qq + 1) * LEV_SCALE * (1 + leverage(f["mu"], f["M"], mu_c, cov_c))
            v.append(vv)
            fits.append(f if qq == q else expand(f, q, keep))
            continue
        mp = block_sum(mm, 2)
        f = solve(blur(mp, sg / 2), qq, eps_mul, ea, shrink[k], sg, cell=4 * B * B, basis=basis)
        vp = variance(f, qq, sg, cell=4 * B * B, use_f=use_f)
        if frames is not None:
            vp = vp / np.maximum(blurred_mean(block_sum(frames[None], 2)[0] / 4, sg / 2), 1.0)
        fM, fmu = f["M"], f["mu"]
        f = f if qq == q else expand(f, q, keep)
        pgh, pgw = mp.shape[1:]
        cb = np.concatenate([f["c0"], f["beta"].reshape(pgh, pgw, q * 3), vp[..., None]], -1)
        if LEVERAGE:
            cb = np.concatenate([cb, fmu, fM.reshape(pgh, pgw, qq * qq)], -1)
        cb = np.moveaxis(resize_bilinear(np.moveaxis(cb, -1, 0), gh, gw, 2, 2), 0, -1)
        if LEVERAGE:
            base = 3 + 3 * q + 1
            mu_s, M_s = cb[..., base:base + qq], cb[..., base + qq:].reshape(gh, gw, qq, qq)
            mu_c, cov_c = cell_stats(mm, qq)
            cb[..., base - 1] = cb[..., base - 1] / (qq + 1) * LEV_SCALE * (1 + leverage(mu_s, M_s, mu_c, cov_c))
        fits.append(dict(c0=cb[..., :3], beta=cb[..., 3:3 + 3 * q].reshape(gh, gw, q, 3)))
        v.append(cb[..., 3 + 3 * q])
    if shared_residual:
        a0 = sigmas[0] ** 2 + AREA_BOX * B * B / 12
        for i, (k, sg, keep) in enumerate(cands[1:], 1):
            ak = sg ** 2 + AREA_BOX * (4 if (k > 0 and sg >= 1.5 * B) else 1) * B * B / 12
            v[i] = v[0] * a0 / ak * (len(keep) + 1) / (q + 1)
    sigmas = [c[1] for c in cands]  # the blend below weighs every candidate like a window
    if len(sigmas) == 1:
        c0, beta = fits[0]["c0"], fits[0]["beta"]
    else:
        mse = [v[0]]
        for k in range(1, len(sigmas)):
            seen = np.maximum(v[0] - v[k], 0.0)
            mse.append(np.maximum(gap(fits[k], fits[0]) - K * seen, 0.0) + v[k])
        if mse_blur > 0:
            mse = [blur(x[None], mse_blur * B)[0] / blur(np.ones_like(x)[None], mse_blur * B)[0] for x in mse]
        wts = [1.0 / np.maximum(x, 1e-30) ** wpow for x in mse]
        tot = sum(wts)
        c0 = sum(wk[..., None] * f["c0"] for wk, f in zip(wts, fits)) / tot[..., None]
        beta = sum(wk[..., None, None] * f["beta"] for wk, f in zip(wts, fits)) / tot[..., None, None]
    if chroma is not None:
        # the window's mean colour, c0 + β·μ at window 0's guide mean (a pooled
        # window's fit, interpolated, keeps only c0 and β)
        src = fits[chroma]
        mc = src["c0"] + (src["beta"] * fits[0]["mu"][..., :, None]).sum(-2)
        ratio = mc / np.maximum((mc @ LUMA)[..., None], 1e-12)
        ratio = np.where((mc @ LUMA)[..., None] > 1e-12, ratio, 1.0)
        c0 = (c0 @ LUMA)[..., None] * ratio
        beta = (beta @ LUMA)[..., None] * ratio[..., None, :]
    model = np.concatenate([c0, beta.reshape(gh, gw, q * 3)], -1).astype(np.float32)
    model = resize_bilinear(np.moveaxis(model, -1, 0), h, w, B, B)
    c0 = model[:3]
    beta = model[3:].reshape(q, 3, h, w)
    return np.maximum(c0 + (beta * z[:, None]).sum(0), 0)


def prep(fr):
    noisy = np.nan_to_num(fr["noisy"], nan=0.0, posinf=0.0, neginf=0.0)
    d = fr["depth"]
    g = np.concatenate([fr["normal"], d, fr["ao"]], 0).astype(np.float64)
    return noisy.astype(np.float64), g


def main():
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("frames", nargs="+")
    ap.add_argument("--sigmas", default="6,12,20")
    ap.add_argument("--lattice", type=int, default=0)
    ap.add_argument("--shrink", type=float, default=0.0)
    ap.add_argument("--basis", choices=["chol", "eig"], default="chol")
    ap.add_argument("--shrink-variance", action="store_true")
    ap.add_argument("--mse-blur", type=float, default=0.0)
    ap.add_argument("--weight-power", type=float, default=1.0)
    ap.add_argument("--chroma", type=int, default=None)
    ap.add_argument("--subsets", default="", help="extra candidate guide subsets, e.g. 0123;012 (indices into normal x, y, z, depth, ao)")
    ap.add_argument("--subset-windows", default="0,1,2", help="the windows (indices into --sigmas) fitted with each subset too")
    ap.add_argument("--eps-windows", default="", help="ϵ per window (experiment)")
    ap.add_argument("--area-box", type=float, default=0.0)
    ap.add_argument("--shared-residual", action="store_true")
    ap.add_argument("--leverage", action="store_true")
    ap.add_argument("--ao-demod", default="0.1", help="offset C of the AO demodulation s = sqrt(ao + C), or off")
    a = ap.parse_args()
    global AREA_BOX, LEVERAGE
    AREA_BOX, LEVERAGE = a.area_box, a.leverage
    sigmas = tuple(float(v) for v in a.sigmas.split(","))
    kw = dict(sigmas=sigmas, shrink=(a.shrink,) * len(sigmas), basis=a.basis, use_f=a.shrink_variance,
              mse_blur=a.mse_blur, wpow=a.weight_power, chroma=a.chroma, lattice=a.lattice,
              subsets=[tuple(int(c) for c in t) for t in a.subsets.split(';') if t], subset_windows=tuple(int(x) for x in a.subset_windows.split(',')),
              eps_windows=tuple(float(x) for x in a.eps_windows.split(',')) if a.eps_windows else None, shared_residual=a.shared_residual)
    scores = []
    for f in sorted(sum((glob.glob(p) for p in a.frames), [])):
        fr = load(f)
        y, g = prep(fr)
        s = np.ones_like(y[:1])
        if a.ao_demod != "off":
            ao = np.nan_to_num(fr["ao"][0].astype(np.float64), nan=1.0, posinf=1.0, neginf=1.0)
            s = np.sqrt(np.clip(ao, 0, 1) + float(a.ao_demod))[None]
        scores.append(psnr(flr(y / s, g, **kw) * s, fr))
        print(f"{f}: {scores[-1]:.2f} dB", flush=True)
    print(f"mean of {len(scores)}: {np.mean(scores):.3f} dB")


if __name__ == "__main__":
    main()
