#!/usr/bin/env python3
"""Render frames and sequences in the layout of docs/DATA.md with Mitsuba 3.

Scenes are built procedurally from Mitsuba's shapes; each scene family has a
seed, so the same command always gives the same frames. The train/test split is
by scene family and seed (see SPLIT): FLR defaults are tuned on `train`, figures
are reported on `test`, and `data/` (the bundled samples) comes from `test`.

    pip install mitsuba numpy OpenEXR ; apt-get install libllvm19
    python3 tools/render.py --out frames --split test --size 256x256 --ref-spp 2048
    python3 tools/render.py --out data --sample      # the committed sample set

Layers: noisy (1 spp), noisy4, reference, albedo, normal, depth, position, ao
(plus motion for sequences, and reference_b with --second-reference), half
floats except position and depth (float).
Noisy/reference are *demodulated diffuse indirect* light: at the primary hit a
cosine-weighted direction is sampled and Mitsuba's `path` integrator
(hide_emitters, max_depth 3) is evaluated along it; with the cosine pdf and a
Lambertian BRDF, albedo * mean(L) is the outgoing indirect radiance.
"""
import argparse, math, os, sys, zlib

os.environ.setdefault("DRJIT_LIBLLVM_PATH", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so")
import numpy as np
import mitsuba as mi
import drjit as dr

try:
    mi.set_variant("llvm_ad_rgb")
except Exception:  # no LLVM: 10x slower but works
    mi.set_variant("scalar_rgb")

# family -> seeds; disjoint between splits.
SPLIT = {
    "train": [("box", 1), ("clutter", 1), ("colonnade", 1), ("box", 2), ("clutter", 2), ("room", 1)],
    "test": [("room", 7), ("poles", 7), ("farclutter", 7), ("colonnade", 7), ("box", 7)],
    # Generalization (FLNR): the wide training set spans six families, each seed with its own
    # camera field of view, distance and path depth; the held-out families are never trained
    # or tuned on (gallery: thin slats and textured walls; poles; farclutter far from the origin).
    "wide": [(f, s) for f in ("box", "clutter", "colonnade", "room", "courtyard", "hall") for s in range(11, 19)],
    "heldout-families": [(f, s) for f in ("gallery", "poles", "farclutter") for s in range(31, 35)],
}
# Families whose seeds also draw the camera's field of view and distance and the path depth.
VARIED = ("courtyard", "hall", "gallery")


def diffuse(rgb):
    """A Lambertian BSDF of an RGB albedo, or of a texture dict (`checker`)."""
    if isinstance(rgb, dict):
        return {"type": "diffuse", "reflectance": rgb}
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": [float(c) for c in rgb]}}


def checker(rng, scale, lo=0.2, hi=0.85):
    """A checkerboard albedo of two random colours, `scale` squares per unit of the shape's uv."""
    rgb = lambda: {"type": "rgb", "value": color(rng, lo, hi).tolist()}
    return {"type": "checkerboard", "color0": rgb(), "color1": rgb(), "to_uv": mi.ScalarTransform4f().scale([float(scale), float(scale), 1.0])}


def xform(translate=(0, 0, 0), scale=(1, 1, 1), rotate=None):
    t = mi.ScalarTransform4f().translate(list(map(float, translate)))
    if rotate is not None:
        t = t @ mi.ScalarTransform4f().rotate(rotate[0], rotate[1])
    return t @ mi.ScalarTransform4f().scale(list(map(float, scale)))


def cube(c, s, rgb, rot=None):
    return {"type": "cube", "to_world": xform(c, s, rot), "bsdf": diffuse(rgb)}


def rect(c, s, rgb, rot=None, emit=None):
    d = {"type": "rectangle", "to_world": xform(c, s, rot), "bsdf": diffuse(rgb)}
    if emit is not None:
        d["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": emit}}
    return d


def sphere(c, r, rgb):
    return {"type": "sphere", "center": list(map(float, c)), "radius": float(r), "bsdf": diffuse(rgb)}


def cylinder(p0, p1, r, rgb):
    return {"type": "cylinder", "p0": list(map(float, p0)), "p1": list(map(float, p1)), "radius": float(r), "bsdf": diffuse(rgb)}


def color(rng, lo=0.2, hi=0.85):
    return rng.uniform(lo, hi, 3)


def scene_dict(family, seed):
    """Returns (shapes dict, camera (origin, target, fov), ao distance, offset, scale)."""
    # zlib.crc32, not hash(): Python salts str hashes per process
    # (PYTHONHASHSEED), which made every run build different scenes.
    rng = np.random.default_rng(seed * 1000 + zlib.crc32(family.encode()) % 997)
    S = {}
    off, sc = np.zeros(3), 1.0
    if family in ("room", "box"):
        W = 4.0
        wall = color(rng, 0.5, 0.8)
        S["floor"] = rect((0, 0, 0), (W, W, 1), color(rng, 0.3, 0.7), (( 1, 0, 0), -90))
        S["ceil"] = rect((0, 2 * W, 0), (W, W, 1), wall, ((1, 0, 0), 90))
        S["back"] = rect((0, W, -W), (W, W, 1), wall)
        S["left"] = rect((-W, W, 0), (W, W, 1), (0.7, 0.2, 0.15) if family == "box" else wall, ((0, 1, 0), 90))
        if family == "box":
            S["right"] = rect((W, W, 0), (W, W, 1), (0.15, 0.6, 0.2), ((0, 1, 0), -90))
            S["light"] = rect((0, 2 * W - 0.01, 0), (1.0, 1.0, 1), (0, 0, 0), ((1, 0, 0), 90), emit=[12.0, 11.0, 9.0])
        else:
            # right wall with a window: four panels around an opening; sun through it.
            for k, (cy, cz, sy, sz) in enumerate([(0.6, 0, 0.6, W), (2 * W - 1.2, 0, 1.2, W), (W, -2.5, W, 1.5), (W, 2.5, W, 1.5)]):
                S[f"rw{k}"] = rect((W, cy, cz), (sz, sy, 1), wall, ((0, 1, 0), -90))
            S["sun"] = {"type": "directional", "direction": [-1.0, -0.55, rng.uniform(-0.3, 0.3)], "irradiance": {"type": "rgb", "value": [9.0, 8.0, 6.5]}}
            S["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.05, 0.07, 0.1]}}
        for i in range(int(rng.integers(3, 6))):
            c = (rng.uniform(-2.8, 2.8), 0, rng.uniform(-3, 1.5))
            s = rng.uniform(0.3, 0.9, 3)
            if rng.random() < 0.5:
                S[f"c{i}"] = cube((c[0], s[1], c[2]), s, color(rng), ((0, 1, 0), rng.uniform(0, 90)))
            else:
                r = s[0]
                S[f"s{i}"] = sphere((c[0], r, c[2]), r, color(rng))
        cam = ((rng.uniform(-1, 1), W * 0.9, 2 * W - 0.5), (0, W * 0.6, -W), 65)
        ao = 1.5
    elif family in ("clutter", "farclutter"):
        S["floor"] = rect((0, 0, 0), (12, 12, 1), color(rng, 0.4, 0.7), ((1, 0, 0), -90))
        S["back"] = rect((0, 4, -6), (12, 4, 1), color(rng, 0.4, 0.8))
        S["light"] = rect((1, 6, 0), (2.0, 2.0, 1), (0, 0, 0), ((1, 0, 0), 90), emit=[14.0, 13.0, 12.0])
        S["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.25, 0.3, 0.4]}}
        for i in range(28):
            c = (rng.uniform(-4, 4), 0, rng.uniform(-5, 2))
            s = rng.uniform(0.15, 0.7, 3)
            k = rng.random()
            if k < 0.4:
                S[f"c{i}"] = cube((c[0], s[1], c[2]), s, color(rng), ((0, 1, 0), rng.uniform(0, 90)))
            elif k < 0.75:
                S[f"s{i}"] = sphere((c[0], s[0], c[2]), s[0], color(rng))
            else:
                S[f"y{i}"] = cylinder((c[0], 0, c[2]), (c[0], 2 * s[1] + 0.3, c[2]), 0.5 * s[0], color(rng))
        cam = ((0, 3.0, 6.0), (0, 0.5, -1.5), 60)
        ao = 1.0
        if family == "farclutter":
            off, sc = np.array([1.0e4, -3.0e3, 2.5e4]), 100.0  # far from the origin, centimetres
    elif family == "colonnade":
        S["floor"] = rect((0, 0, 0), (20, 20, 1), color(rng, 0.5, 0.7), ((1, 0, 0), -90))
        S["back"] = rect((0, 5, -4), (20, 5, 1), color(rng, 0.5, 0.8))
        S["roof"] = cube((0, 4.2, -1.5), (12, 0.2, 2.2), color(rng, 0.5, 0.8))
        for i in range(-6, 7):
            S[f"col{i}"] = cylinder((1.6 * i, 0, 0), (1.6 * i, 4.0, 0), 0.3, (0.75, 0.72, 0.68))
        S["sun"] = {"type": "directional", "direction": [rng.uniform(-0.8, 0.8), -0.6, -1.0], "irradiance": {"type": "rgb", "value": [8.0, 7.2, 6.0]}}
        S["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.2, 0.28, 0.45]}}
        cam = ((rng.uniform(-3, 3), 1.7, 7.0), (0, 1.6, -3), 70)
        ao = 1.5
    elif family == "poles":
        S["floor"] = rect((0, 0, 0), (8, 8, 1), (0.6, 0.6, 0.6), ((1, 0, 0), -90))
        S["wall"] = rect((0, 3, -2), (8, 3, 1), (0.8, 0.75, 0.7))
        S["lamp"] = rect((0, 5.0, 1.5), (1.5, 1.5, 1), (0, 0, 0), ((1, 0, 0), 90), emit=[15.0, 14.0, 12.0])
        for i in range(9):
            x = -3 + 0.75 * i
            S[f"p{i}"] = cylinder((x, 0, -0.5 + 0.3 * (i % 3)), (x, 3.5, -0.5 + 0.3 * (i % 3)), 0.02 + 0.01 * (i % 4), color(rng))
        S["sphere"] = sphere((1.5, 0.6, 0.2), 0.6, color(rng))
        S["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.1, 0.1, 0.12]}}
        cam = ((0, 1.8, 5.0), (0, 1.5, -2), 55)
        ao = 1.0
    elif family == "courtyard":
        # open: sun and sky only, a textured ground, low walls, objects of every size
        S["floor"] = rect((0, 0, 0), (15, 15, 1), checker(rng, rng.uniform(4, 30), 0.3, 0.7), ((1, 0, 0), -90))
        for k in range(int(rng.integers(1, 4))):
            S[f"wall{k}"] = cube((rng.uniform(-6, 6), 0.6, rng.uniform(-8, -3)), (rng.uniform(1, 4), 0.6, 0.15), color(rng, 0.4, 0.8), ((0, 1, 0), rng.uniform(-40, 40)))
        for i in range(int(rng.integers(8, 20))):
            c = (rng.uniform(-5, 5), 0, rng.uniform(-7, 2))
            s = rng.uniform(0.1, 1.2, 3)
            k = rng.random()
            alb = checker(rng, rng.uniform(2, 12)) if rng.random() < 0.3 else color(rng)
            if k < 0.35:
                S[f"c{i}"] = cube((c[0], s[1], c[2]), s, alb, ((0, 1, 0), rng.uniform(0, 90)))
            elif k < 0.7:
                S[f"s{i}"] = sphere((c[0], s[0], c[2]), s[0], alb)
            else:
                S[f"y{i}"] = cylinder((c[0], 0, c[2]), (c[0], 3 * s[1] + 0.3, c[2]), 0.15 * s[0] + 0.01, alb)
        elev = rng.uniform(0.2, 1.2)
        S["sun"] = {"type": "directional", "direction": [rng.uniform(-1, 1), -elev, rng.uniform(-1, 0.3)], "irradiance": {"type": "rgb", "value": (rng.uniform(4, 10) * np.array([1.0, 0.92, 0.8])).tolist()}}
        S["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": (rng.uniform(0.1, 0.6) * np.array([0.6, 0.75, 1.0])).tolist()}}
        cam = ((rng.uniform(-3, 3), rng.uniform(0.8, 4.0), rng.uniform(4, 9)), (rng.uniform(-1, 1), 0.6, -2), rng.uniform(35, 85))
        ao = 1.5
    elif family == "hall":
        # closed and large, lit only by small bright emitters; flat walls, curved objects
        W, H = rng.uniform(5, 8), rng.uniform(3, 5)
        wall = color(rng, 0.4, 0.85)
        S["floor"] = rect((0, 0, 0), (W, W, 1), checker(rng, rng.uniform(2, 10), 0.3, 0.7) if rng.random() < 0.5 else color(rng, 0.3, 0.7), ((1, 0, 0), -90))
        S["ceil"] = rect((0, H, 0), (W, W, 1), wall, ((1, 0, 0), 90))
        S["back"] = rect((0, H / 2, -W), (W, H / 2, 1), checker(rng, rng.uniform(1, 6)) if rng.random() < 0.5 else wall)
        S["front"] = rect((0, H / 2, W), (W, H / 2, 1), wall, ((0, 1, 0), 180))
        S["left"] = rect((-W, H / 2, 0), (W, H / 2, 1), color(rng, 0.3, 0.85), ((0, 1, 0), 90))
        S["right"] = rect((W, H / 2, 0), (W, H / 2, 1), color(rng, 0.3, 0.85), ((0, 1, 0), -90))
        for k in range(int(rng.integers(2, 7))):
            p = (rng.uniform(-W + 1, W - 1), rng.uniform(0.5 * H, H - 0.3), rng.uniform(-W + 1, W - 1))
            r = rng.uniform(0.04, 0.2)
            S[f"lamp{k}"] = {"type": "sphere", "center": list(map(float, p)), "radius": float(r), "bsdf": diffuse((0, 0, 0)),
                             "emitter": {"type": "area", "radiance": {"type": "rgb", "value": (rng.uniform(20, 120) * (0.4 / r) ** 2 * np.array([1.0, 0.9, 0.75]) / 16).tolist()}}}
        for i in range(int(rng.integers(4, 12))):
            c = (rng.uniform(-W + 1, W - 1), 0, rng.uniform(-W + 1, W - 2))
            s = rng.uniform(0.2, 1.0, 3)
            if rng.random() < 0.5:
                S[f"s{i}"] = sphere((c[0], s[0], c[2]), s[0], color(rng))
            else:
                S[f"y{i}"] = cylinder((c[0], 0, c[2]), (c[0], 2 * s[1] + 0.2, c[2]), 0.4 * s[0], color(rng))
        cam = ((rng.uniform(-W / 2, W / 2), rng.uniform(1.0, H - 0.5), W - 0.5), (rng.uniform(-1, 1), rng.uniform(0.5, 1.5), -W), rng.uniform(45, 80))
        ao = 1.0
    elif family == "gallery":
        # thin geometry: slatted screens in front of textured walls, an area light and a doorway of sky
        W = 6.0
        S["floor"] = rect((0, 0, 0), (W, W, 1), color(rng, 0.3, 0.7), ((1, 0, 0), -90))
        S["ceil"] = rect((0, 4, 0), (W, W, 1), color(rng, 0.6, 0.85), ((1, 0, 0), 90))
        S["back"] = rect((0, 2, -W), (W, 2, 1), checker(rng, rng.uniform(3, 16)))
        S["left"] = rect((-W, 2, 0), (W, 2, 1), checker(rng, rng.uniform(3, 16)), ((0, 1, 0), 90))
        # the right wall has a doorway (two panels and a lintel) to the sky
        S["rw0"] = rect((W, 2, -3.5), (2.5, 2, 1), color(rng, 0.5, 0.8), ((0, 1, 0), -90))
        S["rw1"] = rect((W, 2, 3.5), (2.5, 2, 1), color(rng, 0.5, 0.8), ((0, 1, 0), -90))
        S["rw2"] = rect((W, 3.5, 0), (1.0, 0.5, 1), color(rng, 0.5, 0.8), ((0, 1, 0), -90))
        S["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": (rng.uniform(0.5, 2.0) * np.array([0.7, 0.8, 1.0])).tolist()}}
        S["light"] = rect((rng.uniform(-2, 2), 3.99, rng.uniform(-3, 0)), (0.8, 0.8, 1), (0, 0, 0), ((1, 0, 0), 90), emit=(rng.uniform(8, 20) * np.array([1.0, 0.95, 0.85])).tolist())
        for k in range(int(rng.integers(2, 4))):
            x0, z0, ang = rng.uniform(-4, 3), rng.uniform(-5, 0), rng.uniform(-30, 30)
            slat = color(rng, 0.3, 0.9)
            for j in range(int(rng.integers(8, 20))):
                S[f"sl{k}_{j}"] = cube((x0 + 0.18 * j, 1.4, z0), (rng.uniform(0.01, 0.04), 1.4, 0.2), slat, ((0, 1, 0), ang))
        for i in range(int(rng.integers(2, 6))):
            c = (rng.uniform(-4, 4), 0, rng.uniform(-4, 2))
            r = rng.uniform(0.2, 0.7)
            S[f"s{i}"] = sphere((c[0], r, c[2]), r, color(rng))
        cam = ((rng.uniform(-2, 2), rng.uniform(1.2, 2.5), W - 0.5), (rng.uniform(-1, 1), 1.4, -W), rng.uniform(50, 90))
        ao = 1.0
    else:
        raise SystemExit(f"unknown scene family {family}")
    return S, cam, ao, off, sc


def max_depth(family, seed):
    """Path depth of the indirect light: 3, or for the VARIED families one of 2..5 drawn from the seed."""
    if family not in VARIED:
        return 3
    return int(np.random.default_rng(seed * 7 + zlib.crc32(family.encode()) % 991).integers(2, 6))


def place(S, cam, off, sc):
    """Applies a world offset/scale (far-from-origin scenes) to shapes and camera."""
    if sc == 1.0 and not off.any():
        return S, cam
    T = mi.ScalarTransform4f().translate(off.tolist()) @ mi.ScalarTransform4f().scale(sc)
    out = {}
    for k, v in S.items():
        v = dict(v)
        if "to_world" in v:
            v["to_world"] = T @ v["to_world"]
        elif v["type"] == "sphere":
            v["center"] = (np.array(v["center"]) * sc + off).tolist(); v["radius"] *= sc
        elif v["type"] == "cylinder":
            v["p0"] = (np.array(v["p0"]) * sc + off).tolist(); v["p1"] = (np.array(v["p1"]) * sc + off).tolist(); v["radius"] *= sc
        out[k] = v
    o, t, fov = cam
    return out, ((np.array(o) * sc + off).tolist(), (np.array(t) * sc + off).tolist(), fov)


def sensor_dict(cam, w, h):
    o, t, fov = cam
    return {"type": "perspective", "fov": float(fov), "to_world": mi.ScalarTransform4f().look_at(origin=list(map(float, o)), target=list(map(float, t)), up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}}}


# Camera motions of a sequence; frame i of n from the scene's camera cam0 (world scale sc).
MOTIONS = ("pan", "orbit", "dolly", "rotate", "cut", "burst", "enter")


def mover_at(i, n, cam0):
    """`enter`: the camera stands still and a sphere moves in from the left edge of the view and
    crosses to past its centre, at 60 % of the distance to the target (in front of the scene).
    Its (centre, radius) at frame i of n."""
    o, t, fov = (np.array(cam0[0], float), np.array(cam0[1], float), cam0[2])
    fwd = (t - o) / np.linalg.norm(t - o)
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    dist = 0.6 * np.linalg.norm(t - o)
    half = dist * math.tan(math.radians(fov) / 2)  # half the view's width at that distance
    r = 0.22 * half
    x = -(half + r) + 1.4 * half * i / max(n - 1, 1)
    up = np.cross(right, fwd)
    return o + dist * fwd + x * right - 0.25 * half * up, r


def camera_at(motion, i, n, cam0, sc):
    o, t, fov = (np.array(cam0[0], float), np.array(cam0[1], float), cam0[2])
    if motion in ("pan", "burst"):  # sideways, 0.08 world units (x sc) a frame
        o = o + np.array([0.08 * i * sc, 0.0, 0.0])
    elif motion == "orbit":  # around the target, 2.5 degrees a frame
        a = math.radians(2.5 * i)
        v = o - t
        o = t + np.array([v[0] * math.cos(a) + v[2] * math.sin(a), v[1], -v[0] * math.sin(a) + v[2] * math.cos(a)])
    elif motion == "dolly":  # toward the target, 3 % of the distance a frame
        o = o + (t - o) * 0.03 * i
    elif motion == "rotate":  # the camera turns in place, 3 degrees a frame (about 12 px at 256 wide)
        a = math.radians(3.0 * i)
        v = t - o
        t = o + np.array([v[0] * math.cos(a) + v[2] * math.sin(a), v[1], -v[0] * math.sin(a) + v[2] * math.cos(a)])
    elif motion == "enter":  # a still camera; a sphere moves in (`mover_at`)
        pass
    elif motion == "cut":  # a pan that cuts, half way, to a camera mirrored across the target and lower
        if i >= n // 2:
            v = o - t
            o = t + np.array([-v[0] - 0.5 * v[2], 0.7 * v[1], 0.8 * v[2]]) + np.array([0.08 * (i - n // 2) * sc, 0.0, 0.0])
        else:
            o = o + np.array([0.08 * i * sc, 0.0, 0.0])
    return (o.tolist(), t.tolist(), fov)


def inject(noisy, p, k, seed):
    """The outlier protocol of docs/DATA.md, in place: each pixel with probability p set to k x the mean luminance."""
    lum = float((0.2126 * noisy[..., 0] + 0.7152 * noisy[..., 1] + 0.0722 * noisy[..., 2]).mean())
    hit = np.random.default_rng(seed).random(noisy.shape[:2]) < p
    noisy[hit] = k * lum


def render_frame(scene, sensor, prev_sensor, w, h, spps, ref_spp, ao_dist, ao_rays=64, seed=0, second_reference=False, depth=3, jitter=False, mover=None):
    """The layers of one frame. `depth`: the path integrator's max_depth; `jitter`: the guides
    (and the primary hit every light layer starts from) through a random point of each pixel,
    as a 1-spp G-buffer gives, instead of its centre. `mover`: (centre, radius, step) of a
    sphere in the scene that moved by `step` since the previous frame, so that the motion of
    the pixels that see it follows the sphere, not only the camera."""
    integ = mi.load_dict({"type": "path", "max_depth": int(depth), "hide_emitters": True})
    n = w * h
    idx = dr.arange(mi.UInt32, n)
    if jitter:
        j = np.random.default_rng(seed + 4243).random((2, n))
        px = mi.Float(idx % w) + mi.Float(j[0])
        py = mi.Float(idx // w) + mi.Float(j[1])
    else:
        px = mi.Float(idx % w) + 0.5
        py = mi.Float(idx // w) + 0.5
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(px / w, py / h), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    valid = si.is_valid()
    out = {}
    albedo = dr.select(valid, si.bsdf().eval_diffuse_reflectance(si), 0.0)
    nrm = dr.select(valid, si.sh_frame.n, 0.0)
    out["albedo"] = np.array(albedo).reshape(3, -1).T if np.array(albedo).shape[0] == 3 else np.array(albedo)
    out["normal"] = np.array(nrm)
    out["position"] = np.array(dr.select(valid, si.p, 0.0))
    out["depth"] = np.array(dr.select(valid, si.t, 0.0))

    def arr3(v):
        a = np.array(v)
        return a.T if a.shape[0] == 3 and a.ndim == 2 else a

    for k in ("albedo", "normal", "position"):
        out[k] = arr3(out[k]).reshape(h, w, 3)
    out["depth"] = out["depth"].reshape(h, w)

    def indirect(spp, sd):
        acc = np.zeros((n, 3))
        chunk = max(1, min(spp, (1 << 22) // n))
        done = 0
        sampler = mi.load_dict({"type": "independent"})
        while done < spp:
            c = min(chunk, spp - done)
            sampler.seed(sd * 7919 + done, n * c)
            rep = dr.arange(mi.UInt32, n * c) // c
            si_r = dr.gather(type(si), si, rep)
            v_r = dr.gather(mi.Bool, valid, rep)
            d_local = mi.warp.square_to_cosine_hemisphere(sampler.next_2d())
            d = si_r.sh_frame.to_world(d_local)
            r2 = si_r.spawn_ray(d)
            L, ok, _ = integ.sample(scene, sampler, r2, None, v_r)
            L = dr.select(v_r & ok, L, 0.0)
            La = arr3(L).reshape(n, c, 3)
            acc += La.sum(axis=1)
            done += c
        return (acc / spp).reshape(h, w, 3)

    for name, spp in spps.items():
        out[name] = indirect(spp, seed + zlib.crc32(name.encode()) % 1000)
    out["reference"] = indirect(ref_spp, seed + 99991)
    if second_reference:
        # the same light from other samples: the reference's own noise (`lrd eval`'s flicker floor)
        out["reference_b"] = indirect(ref_spp, seed + 77773)

    # ambient occlusion: fraction of cosine rays unoccluded within ao_dist
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed + 31337, n * ao_rays)
    rep = dr.arange(mi.UInt32, n * ao_rays) // ao_rays
    si_r = dr.gather(type(si), si, rep)
    v_r = dr.gather(mi.Bool, valid, rep)
    d = si_r.sh_frame.to_world(mi.warp.square_to_cosine_hemisphere(sampler.next_2d()))
    r2 = si_r.spawn_ray(d)
    r2.maxt = ao_dist
    hit = scene.ray_test(r2, v_r)
    open_ = np.array(dr.select(v_r & ~hit, 1.0, 0.0)).reshape(n, ao_rays).mean(axis=1)
    out["ao"] = np.where(np.array(valid), open_, 0.0).reshape(h, w)

    if prev_sensor is not None:
        if mover is not None:
            # a hit on the moving sphere was `step` behind a frame ago
            c, r, step = mover
            p = arr3(si.p).reshape(-1, 3).T
            on = np.array(valid) & (np.abs(np.linalg.norm(p - np.array(c, float)[:, None], axis=0) - r) < 1e-3 * r)
            q = np.where(on[None], p - np.array(step, float)[:, None], p).astype(np.float32)
            si.p = mi.Point3f(mi.Float(q[0]), mi.Float(q[1]), mi.Float(q[2]))
        ds, _ = prev_sensor.sample_direction(si, mi.Point2f(0.5, 0.5), valid)
        uv = np.array(ds.uv)
        uv = (uv.T if uv.ndim == 2 and uv.shape[0] == 2 else uv).reshape(h, w, 2)  # (2, n) -> (h, w, 2)
        cur = np.stack(np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5), axis=-1)
        mo = np.where(np.array(valid).reshape(h, w, 1), uv - cur, 0.0)
        out["motion"] = mo
    return out


def write_exr(path, layers):
    import OpenEXR
    chans = {}
    names = {"albedo": "RGB", "noisy": "RGB", "reference": "RGB", "normal": "XYZ", "position": "XYZ", "motion": "XY", "depth": "Z", "ao": "Y"}
    for layer, a in layers.items():
        comps = names.get(layer, "RGB")
        full = layer in ("position", "depth")  # large values: keep float
        dt = np.float32 if full else np.float16
        if a.ndim == 2:
            a = a[..., None]
        for i, c in enumerate(comps):
            chans[f"{layer}.{c}"] = np.ascontiguousarray(a[..., i].astype(dt))
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(hdr, chans) as f:
        f.write(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--split", choices=list(SPLIT), default="test")
    ap.add_argument("--scenes", help="comma list family:seed (overrides --split)")
    ap.add_argument("--size", default="256x256")
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--seq", type=int, default=0, help="also render a sequence of N frames per scene")
    ap.add_argument("--motion", default="pan", help=f"comma list of motions for --seq (of the camera; enter: of an object): {', '.join(MOTIONS)}")
    ap.add_argument("--seq-only", action="store_true", help="render only the sequences, not the stills")
    ap.add_argument(
        "--second-reference",
        action="store_true",
        help="sequences: also render reference_b, the reference from other samples (lrd eval then reports the flicker the reference's noise adds)",
    )
    ap.add_argument("--sample", action="store_true", help="render the committed data/ sample set")
    ap.add_argument("--noisy-guides", action="store_true", help="guides as a 1-spp renderer has them: a random point of each pixel, AO from 4 rays")
    a = ap.parse_args()
    w, h = map(int, a.size.lower().split("x"))
    scenes = SPLIT[a.split]
    if a.scenes:
        scenes = [(s.split(":")[0], int(s.split(":")[1])) for s in a.scenes.split(",")]
    seq_scenes = []
    if a.sample:
        scenes = [("room", 7), ("poles", 7), ("farclutter", 7), ("colonnade", 7)]
        seq_scenes = [("box", 7)]
        a.seq = 6
    os.makedirs(a.out, exist_ok=True)
    spps = {"noisy": 1, "noisy4": 4}

    def opts(fam, seed):
        return {"depth": max_depth(fam, seed), "jitter": a.noisy_guides, "ao_rays": 4 if a.noisy_guides else 64}
    for fam, seed in ([] if a.seq_only else scenes):
        S, cam, ao, off, sc = scene_dict(fam, seed)
        S, cam = place(S, cam, off, sc)
        scene = mi.load_dict({"type": "scene", **S})
        sensor = mi.load_dict(sensor_dict(cam, w, h))
        lay = render_frame(scene, sensor, None, w, h, spps, a.ref_spp, ao * sc, seed=seed, **opts(fam, seed))
        path = os.path.join(a.out, f"{fam}_{seed}.exr")
        write_exr(path, lay)
        print("wrote", path, flush=True)
    motions = a.motion.split(",")
    for m in motions:
        if m not in MOTIONS:
            raise SystemExit(f"unknown motion {m}; one of {', '.join(MOTIONS)}")
    for fam, seed in seq_scenes or ([(f, s) for f, s in scenes] if a.seq else []):
        S, cam, ao, off, sc = scene_dict(fam, seed)
        S, cam0 = place(S, cam, off, sc)
        scene = mi.load_dict({"type": "scene", **S})
        for motion in motions:
            name = f"seq_{fam}_{seed}" if a.sample else f"seq_{fam}_{seed}_{motion}"
            d = os.path.join(a.out, name)
            os.makedirs(d, exist_ok=True)
            prev = None
            for i in range(a.seq):
                sensor = mi.load_dict(sensor_dict(camera_at(motion, i, a.seq, cam0, sc), w, h))
                frame_scene, mover = scene, None
                if motion == "enter":
                    c, r = mover_at(i, a.seq, cam0)
                    ball = sphere(c, r, (0.75, 0.35, 0.2))
                    frame_scene = mi.load_dict({"type": "scene", **S, "mover": ball})
                    mover = (c, r, c - mover_at(i - 1, a.seq, cam0)[0]) if i > 0 else None
                lay = render_frame(
                    frame_scene, sensor, prev, w, h, spps, a.ref_spp, ao * sc, seed=seed * 100 + i, second_reference=a.second_reference, mover=mover, **opts(fam, seed)
                )
                if motion == "burst" and i == a.seq // 2:
                    inject(lay["noisy"], p=1e-3, k=100.0, seed=seed * 100 + i)
                write_exr(os.path.join(d, f"frame_{i:04d}.exr"), lay)
                print("wrote", d, i, flush=True)
                prev = sensor

if __name__ == "__main__":
    main()
