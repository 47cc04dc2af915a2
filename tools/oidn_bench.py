#!/usr/bin/env python3
"""Time OIDN 2 on a synthetic frame, for comparison with `lrd bench` at the
same size and thread count (run both in one sitting: this VM's speed drifts).

    pip install pyoidn
    python3 tools/oidn_bench.py --size 1920x1080 --threads 1 [--runs 3]

OIDN as `tools/peers.py` runs it: `quality="high"`, `hdr`, `clean_aux`, colour
with albedo and normal auxiliaries. Its time hardly depends on the content.
The process is pinned to the first THREADS cores. Prints the median, min and
max of RUNS calls after a warm-up call.
"""
import argparse
import os
import time

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="1920x1080", help="WIDTHxHEIGHT")
    ap.add_argument("--threads", type=int, default=1, help="cores to pin to")
    ap.add_argument("--runs", type=int, default=3, help="timed calls after the warm-up")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.lower().split("x"))
    os.sched_setaffinity(0, set(range(a.threads)))
    import pyoidn

    rng = np.random.default_rng(1)
    col = rng.random((h, w, 3), dtype=np.float32)
    alb = rng.random((h, w, 3), dtype=np.float32)
    nrm = rng.random((h, w, 3), dtype=np.float32) * 2 - 1

    def call():
        pyoidn.denoise(col, alb, nrm, hdr=True, clean_aux=True, quality="high")

    call()
    ts = []
    for _ in range(max(a.runs, 1)):
        t = time.perf_counter()
        call()
        ts.append((time.perf_counter() - t) * 1e3)
    ts.sort()
    print(f"oidn {w}x{h} threads {a.threads}: median {ts[len(ts) // 2]:.1f} ms "
          f"(min {ts[0]:.1f}, max {ts[-1]:.1f}, {len(ts)} runs)")


if __name__ == "__main__":
    main()
