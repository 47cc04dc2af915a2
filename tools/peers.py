#!/usr/bin/env python3
"""Time and score peer denoisers on frames, writing records in the schema of
`lrd eval --json`, for `lrd report --peers FILE.json`.

    pip install pyoidn opencv-contrib-python-headless scikit-image flip-evaluator OpenEXR
    python3 tools/peers.py FRAME_OR_DIR... -o peers.json [--threads N]

Peers (scored with tools/metrics_reference.py, the same protocol as `lrd`):
- oidn: Intel Open Image Denoise (pyoidn, CPU, RT filter, quality high) on the
  albedo-modulated noisy colour, albedo and normal auxiliaries, hdr, clean_aux.
- guided: OpenCV's guided filter (cv2.ximgproc.guidedFilter) on the
  demodulated noisy light with the normals as guide.
Time: median of --runs runs after a warm-up, the denoiser call only.
OIDN uses all cores (OMP/TBB); pin with --threads (sets the thread count through
taskset/OMP env for this process) so rows compare at the same thread count.
"""
import argparse, glob, json, os, sys, time

sys.path.insert(0, os.path.dirname(__file__))
import numpy as np
from metrics_reference import layer, scores


def frames(args):
    out = []
    for a in args:
        out += sorted(glob.glob(os.path.join(a, "*.exr"))) if os.path.isdir(a) else [a]
    return out


def timed(fn, runs):
    fn()
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        r = fn()
        ts.append((time.perf_counter() - t) * 1e3)
    return r, float(np.median(ts))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("frames", nargs="+")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0, help="CPU threads (0: all)")
    ap.add_argument("--gf-radius", type=int, default=12)
    ap.add_argument("--gf-eps", type=float, default=1e-3)
    a = ap.parse_args()
    if a.threads:
        os.sched_setaffinity(0, set(range(a.threads)))
    import pyoidn
    import cv2
    recs = []
    for f in frames(a.frames):
        name = os.path.splitext(os.path.basename(f))[0]
        ref, alb, noisy = layer(f, "reference"), layer(f, "albedo"), layer(f, "noisy")
        nrm = layer(f, "normal")
        h, w = noisy.shape[:2]
        col = (alb * noisy).astype(np.float32)
        a32, n32 = alb.astype(np.float32), nrm.astype(np.float32)
        out, ms = timed(lambda: pyoidn.denoise(col, a32, n32, hdr=True, clean_aux=True, quality="high"), a.runs)
        est = np.where(alb > 0, np.asarray(out, dtype=np.float64) / np.maximum(alb, 1e-8), 0.0)
        threads = a.threads or os.cpu_count()
        recs.append({"method": "oidn", "config": "oidn (pyoidn, RT, high)", "frame": name, **scores(est, ref, alb), "ms": ms, "threads": threads, "width": w, "height": h, "flags": ""})
        src, guide = noisy.astype(np.float32), ((nrm + 1) * 0.5).astype(np.float32)
        gf, ms = timed(lambda: cv2.ximgproc.guidedFilter(guide, src, a.gf_radius, a.gf_eps), a.runs)
        recs.append({"method": "guided", "config": f"guided filter (normals, r{a.gf_radius}, eps {a.gf_eps})", "frame": name, **scores(gf.astype(np.float64), ref, alb), "ms": ms, "threads": threads, "width": w, "height": h, "flags": ""})
        print(name, *(f"{r['config']}: {r['psnr']:.2f} dB {r['ms']:.1f} ms" for r in recs[-2:]), sep="\n  ", flush=True)
    with open(a.output, "w") as fo:
        json.dump(recs, fo, indent=1)


if __name__ == "__main__":
    main()
