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

Robustness rows (docs/DATA.md's outlier protocol): `lrd report ... -o OUT` writes
the stills with each case's outliers to OUT/robustness/CASE/FRAME.exr (the same
files on every run: fixed seed). Score the peers on them, naming the case with
--inject-name (written into each record's `inject` field), and give the records
to the next `lrd report`, which puts them in its robustness table (their clean
column: the records of the plain run on the original stills, no `inject`):

    python3 tools/peers.py data -o peers.json --threads 1
    for c in ff1e-4x1000 ff1e-3x100 nan-inf1e-3; do
        python3 tools/peers.py OUT/robustness/$c --inject-name $c -o OUT/robustness/peers_$c.json --threads 1
    done
    lrd report data/*.exr data/seq_box_7 -o OUT --peers peers.json \
        --peers OUT/robustness/peers_ff1e-4x1000.json --peers OUT/robustness/peers_ff1e-3x100.json \
        --peers OUT/robustness/peers_nan-inf1e-3.json

NaN/Inf in the input are passed to the peers as they are. A peer's output is
scored as it comes out, with lrd's conventions for non-finite values: NaN and
-Inf count as 0 (black), +Inf as the brightest value (white once tone mapped);
rMSE is taken on the same values so that the JSON holds a number. The record's
`nonfinite` field counts the output pixels that were not finite (lrd ignores it),
and a warning names them, as it does an all-zero output (OIDN 2 returns one for
an input with NaN or Inf). A peer that raises on a frame gets no record for it
(a warning says so).
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


def finite(est, what, name):
    """`est` with non-finite values as lrd's metrics see them (NaN, -Inf: 0;
    +Inf: a value that tone maps to 1), and the count of pixels that had one."""
    bad = int(np.count_nonzero(~np.isfinite(est).all(axis=-1)))
    if bad:
        print(f"warning: {name}: {what} output has {bad} non-finite pixel(s), scored as black (NaN, -Inf) or white (+Inf)", file=sys.stderr, flush=True)
    est = np.nan_to_num(est, nan=0.0, posinf=1e30, neginf=0.0)
    if not est.any():
        print(f"warning: {name}: {what} output is all zero (scored as it is)", file=sys.stderr, flush=True)
    return est, bad


def attempt(fn, what, name):
    """fn(), or None with a warning when the peer raises."""
    try:
        return fn()
    except Exception as e:  # a peer refusing NaN/Inf input: no record for this frame
        print(f"warning: {name}: {what} failed ({type(e).__name__}: {e}); no record", file=sys.stderr, flush=True)
        return None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("frames", nargs="+")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0, help="CPU threads (0: all)")
    ap.add_argument("--gf-radius", type=int, default=12)
    ap.add_argument("--gf-eps", type=float, default=1e-3)
    ap.add_argument("--inject-name", default="", metavar="NAME",
                    help="robustness case of the frames (e.g. ff1e-4x1000), written into each record's `inject` field; default: none (the frames as rendered)")
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
        threads = a.threads or os.cpu_count()
        common = {"frame": name, "threads": threads, "width": w, "height": h, "flags": "", "inject": a.inject_name}
        n0 = len(recs)
        with np.errstate(invalid="ignore"):  # 0 albedo x +Inf: NaN, passed on as it is
            col = (alb * noisy).astype(np.float32)
        a32, n32 = alb.astype(np.float32), nrm.astype(np.float32)
        got = attempt(lambda: timed(lambda: pyoidn.denoise(col, a32, n32, hdr=True, clean_aux=True, quality="high"), a.runs), "oidn", name)
        if got is not None:
            out, ms = got
            with np.errstate(invalid="ignore", divide="ignore"):
                est = np.where(alb > 0, np.asarray(out, dtype=np.float64) / np.maximum(alb, 1e-8), 0.0)
            est, bad = finite(est, "oidn", name)
            recs.append({"method": "oidn", "config": "oidn (pyoidn, RT, high)", **common, **scores(est, ref, alb), "ms": ms, "nonfinite": bad})
        src, guide = noisy.astype(np.float32), ((nrm + 1) * 0.5).astype(np.float32)
        got = attempt(lambda: timed(lambda: cv2.ximgproc.guidedFilter(guide, src, a.gf_radius, a.gf_eps), a.runs), "guided filter", name)
        if got is not None:
            gf, ms = got
            est, bad = finite(gf.astype(np.float64), "guided filter", name)
            recs.append({"method": "guided", "config": f"guided filter (normals, r{a.gf_radius}, eps {a.gf_eps})", **common, **scores(est, ref, alb), "ms": ms, "nonfinite": bad})
        print(name, *(f"{r['config']}: {r['psnr']:.2f} dB {r['ms']:.1f} ms" for r in recs[n0:]), sep="\n  ", flush=True)
    with open(a.output, "w") as fo:
        json.dump(recs, fo, indent=1, allow_nan=False)


if __name__ == "__main__":
    main()
