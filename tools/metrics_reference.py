#!/usr/bin/env python3
"""Reference implementation of the docs/DATA.md quality protocol with
scikit-image and NVIDIA's flip-evaluator, to cross-check `lrd`'s Rust metrics.

    python3 tools/metrics_reference.py FRAME.exr [DENOISED.exr]

Prints JSON: {"noisy": {psnr, ssim, flip, rmse}, "denoised": {...}} (the latter
only when DENOISED.exr, a file with a `denoised` layer, is given). FLIP is LDR
FLIP on the tone-mapped images quantised to 8 bits, as `lrd` evaluates it.
"""
import json, sys
import numpy as np
import OpenEXR
from skimage.metrics import structural_similarity, peak_signal_noise_ratio
import flip_evaluator as flip


def layer(path, name):
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if name in ch:
            return np.asarray(ch[name].pixels, dtype=np.float64)
        comps = [c for c in ("R", "G", "B", "X", "Y", "Z") if f"{name}.{c}" in ch]
        return np.stack([np.asarray(ch[f"{name}.{c}"].pixels, dtype=np.float64) for c in comps], axis=-1)


def tonemap(x, L):
    v = np.maximum(x, 0) * 0.5 / L
    return (v / (1 + v)) ** (1 / 2.2)


def scores(est, ref, albedo):
    I, R = albedo * est, albedo * ref
    L = np.mean(0.2126 * R[..., 0] + 0.7152 * R[..., 1] + 0.0722 * R[..., 2])
    ti, tr = tonemap(I, L), tonemap(R, L)
    q = lambda a: (np.round(np.clip(a, 0, 1) * 255) / 255).astype(np.float32)
    _, fl, _ = flip.evaluate(q(tr), q(ti), "LDR", applyMagma=False)
    return {
        "psnr": float(peak_signal_noise_ratio(tr, ti, data_range=1.0)),
        "ssim": float(structural_similarity(tr, ti, channel_axis=-1, data_range=1.0)),
        "flip": float(fl),
        "rmse": float(np.mean((I - R) ** 2 / (R ** 2 + 0.01))),
    }


def main():
    frame = sys.argv[1]
    ref, albedo = layer(frame, "reference"), layer(frame, "albedo")
    out = {"noisy": scores(layer(frame, "noisy"), ref, albedo)}
    if len(sys.argv) > 2:
        out["denoised"] = scores(layer(sys.argv[2], "denoised"), ref, albedo)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
