// The temporal stage (src/temporal.rs) as WGSL compute shaders, in f32 like
// the CPU path. One module, one bind group (bindings 0–8, eight storage
// buffers: WebGPU's default limit per stage), run around FLR's passes each frame, in this order, with the workgroup counts of
// `lrdenoise::temporal::gpu::GpuTemporalPlan::passes`:
//
//   t_cells → t_taps → t_thresholds → t_accumulate → (FLR's passes) → t_resolve
//
// t_cells     the firefly clamp's cell sums of the noisy light (and zeroes the counters)
// t_taps      per pixel: the motion test and the 4 bilinear history taps'
//             tests; counts pixels without history (the camera-cut test)
// t_thresholds the clamp's thresholds, capped by the previous frame's cells
//             (no caps in a cut frame); the next frame's caps into the history
// t_accumulate per pixel: clamps the sample, blends it into the reprojected
//             history (none in a cut frame), writes the record and the
//             accumulated light in place of the noisy light, which FLR then reads
// t_resolve   per pixel: the previous output through the accepted taps,
//             clipped to the fit's 3×3 YCoCg box, blended with the fit
//
// The history is the CPU's (`Reprojection::history_len`), bound as its two
// slots: `hist_in`, the slot the previous frame wrote, and `hist_out`, the
// slot this frame writes (the executor swaps them each frame). A slot holds
// the records of every row (field f of pixel x in row y at
// (y · record + f) · width + x: light 3, history length 1, output 3, the
// rejection guides) and then, per band of 8 rows, the largest luminance the
// clamp kept in each cell and each cell's neighbourhood mean.

const NONE: u32 = 0xffffffffu;
const GUIDE_IN_WORK: u32 = 0x80000000u; // gpu::GUIDE_IN_WORK
const CELL: u32 = 8u; // fireflies::CELL
const REACH: u32 = 6u; // fireflies::REACH
const LUMA_CAP: f32 = 1e30; // fireflies::LUMA_CAP
const LIGHT: u32 = 0u;
const COUNT: u32 = 3u;
const OUTPUT: u32 = 4u;

struct Params {
    width: u32,
    height: u32,
    // clamp cells per band, bands of 8 rows
    nc: u32,
    bands: u32,
    // f32 fields of a pixel's record; the record fields of the normal, the
    // position and the depth (NONE: not in the record)
    record: u32,
    n_at: u32,
    p_at: u32,
    d_at: u32,
    // the element offset of the cells within a slot; 1 when `hist_in` holds
    // a previous frame
    cells_at: u32,
    has_history: u32,
    // element offsets of the normal's x plane, the position's x plane and
    // the depth plane (planes of width · height, NONE: absent): in `guides`,
    // or with GUIDE_IN_WORK set, in `work` (rejection guides FLR does not read)
    g_normal: u32,
    g_position: u32,
    g_depth: u32,
    clamp_negative: u32,
    // the firefly clamp's factor k (0: off) and TemporalConfig's settings
    fireflies: f32,
    firefly_history: f32,
    max_history: f32,
    normal_limit: f32,
    position_limit: f32,
    depth_limit: f32,
    clip_gamma: f32,
    output_alpha: f32,
    // a frame with more pixels without history than this is a camera cut
    cut_limit: u32,
    // largest motion component taken as a motion vector, in pixels
    max_motion: f32,
    // without depth: the squared position limit per squared pixel footprint
    footprint_limit2: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

struct Counters {
    rejected: atomic<u32>,
    invalid_motion: atomic<u32>,
    nonfinite: atomic<u32>,
    clamped: atomic<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
// the noisy light (RGB planes), overwritten with the accumulated light
@group(0) @binding(1) var<storage, read_write> light: array<f32>;
// FLR's guide planes (f32)
@group(0) @binding(2) var<storage, read> guides: array<f32>;
// the history slot the previous frame wrote
@group(0) @binding(3) var<storage, read> hist_in: array<f32>;
// per band and cell: sum, count, largest luminance; then per band and cell the
// threshold; then the reprojected previous output (3 planes, NaN: none); then
// the motion, previous − current position in pixels (2 planes, uploaded)
@group(0) @binding(4) var<storage, read_write> work: array<f32>;
@group(0) @binding(5) var<storage, read_write> counters: Counters;
// FLR's output (RGB planes)
@group(0) @binding(6) var<storage, read> fitted: array<f32>;
// the stage's output (RGB planes)
@group(0) @binding(7) var<storage, read_write> output: array<f32>;
// the history slot this frame writes
@group(0) @binding(8) var<storage, read_write> hist_out: array<f32>;

// Finite test on the bits: immune to compilers that assume no NaN.
fn finite(v: f32) -> bool {
    return (bitcast<u32>(v) & 0x7f800000u) != 0x7f800000u;
}

fn is_nan(v: f32) -> bool {
    let b = bitcast<u32>(v);
    return (b & 0x7f800000u) == 0x7f800000u && (b & 0x007fffffu) != 0u;
}

fn inf() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

fn nan() -> f32 {
    return bitcast<f32>(0x7fc00000u);
}

fn luma(c: vec3<f32>) -> f32 {
    return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
}

fn plane() -> u32 {
    return P.width * P.height;
}

fn light_at(x: u32, y: u32) -> vec3<f32> {
    let i = y * P.width + x;
    let n = plane();
    return vec3<f32>(light[i], light[n + i], light[2u * n + i]);
}

fn guide(base: u32, c: u32, i: u32) -> f32 {
    if (base & GUIDE_IN_WORK) != 0u {
        return work[(base & ~GUIDE_IN_WORK) + c * plane() + i];
    }
    return guides[base + c * plane() + i];
}

// Field `f` of pixel (x, y)'s record in a slot.
fn rec(f: u32, x: u32, y: u32) -> u32 {
    return (y * P.record + f) * P.width + x;
}

fn thresholds_at() -> u32 {
    return 3u * P.nc * P.bands;
}

fn prev_out_at() -> u32 {
    return 4u * P.nc * P.bands;
}

fn motion_at() -> u32 {
    return prev_out_at() + 3u * plane();
}

// The camera-cut test (`Reprojection::is_cut`), after t_taps.
fn is_cut() -> bool {
    return P.has_history != 0u && atomicLoad(&counters.rejected) > P.cut_limit;
}

// ---------------------------------------------------------------------------
// t_cells: per clamp cell of a band, the sum, count and largest luminance of
// its finite samples (negatives as 0, capped), summed as `fireflies::Thresholds`
// does: per column over the rows, then the columns in order.

@compute @workgroup_size(64)
fn t_cells(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x == 0u && gid.y == 0u {
        atomicStore(&counters.rejected, 0u);
        atomicStore(&counters.invalid_motion, 0u);
        atomicStore(&counters.nonfinite, 0u);
        atomicStore(&counters.clamped, 0u);
    }
    let i = gid.x;
    let band = gid.y;
    if P.fireflies == 0.0 || i >= P.nc || band >= P.bands {
        return;
    }
    let y1 = min((band + 1u) * CELL, P.height);
    var sum = 0.0;
    var count = 0.0;
    var top = 0.0;
    for (var lane = 0u; lane < CELL; lane++) {
        let x = i * CELL + lane;
        var s = 0.0;
        var m = 0.0;
        if x < P.width {
            for (var y = band * CELL; y < y1; y++) {
                let l = luma(light_at(x, y));
                if finite(l) {
                    let v = min(max(l, 0.0), LUMA_CAP);
                    s += v;
                    m = max(m, v);
                    count += 1.0;
                }
            }
        }
        sum += s;
        top = max(top, m);
    }
    let o = 3u * (band * P.nc + i);
    work[o] = sum;
    work[o + 1u] = count;
    work[o + 2u] = top;
}

// ---------------------------------------------------------------------------
// t_taps: the history taps of pixel (x, y) as step 1 tests them. Returns the
// weights of the accepted taps (0: rejected) and counts nothing.

struct Taps {
    x0: i32,
    y0: i32,
    w: vec4<f32>,
}

fn motion_ok(x: u32, y: u32) -> bool {
    let i = y * P.width + x;
    let mx = work[motion_at() + i];
    let my = work[motion_at() + plane() + i];
    // false for NaN (compared on the bits' magnitude: no NaN assumptions)
    return finite(mx) && finite(my) && abs(mx) <= P.max_motion && abs(my) <= P.max_motion;
}

fn cur_guide(off: u32, c: u32, x: u32, y: u32) -> f32 {
    return guide(off, c, y * P.width + x);
}

fn cur_position(x: u32, y: u32) -> vec3<f32> {
    return vec3<f32>(cur_guide(P.g_position, 0u, x, y), cur_guide(P.g_position, 1u, x, y), cur_guide(P.g_position, 2u, x, y));
}

// |a − b|², +Inf where that is not finite.
fn distance2(a: vec3<f32>, b: vec3<f32>) -> f32 {
    let e = a - b;
    let d = e.x * e.x + e.y * e.y + e.z * e.z;
    return select(inf(), d, finite(d));
}

// The squared pixel footprint of (x, y) (`temporal::footprint2`): the smaller
// squared distance to the left and right neighbours' positions, of those
// that are finite; 0 without one.
fn footprint2(x: u32, y: u32) -> f32 {
    let p = cur_position(x, y);
    var m = inf();
    if x > 0u {
        m = distance2(cur_position(x - 1u, y), p);
    }
    if x + 1u < P.width {
        m = min(m, distance2(cur_position(x + 1u, y), p));
    }
    return select(0.0, m, finite(m));
}

fn tap_ok(tx: i32, ty: i32, wt: f32, x: u32, y: u32) -> bool {
    if tx < 0 || ty < 0 || tx >= i32(P.width) || ty >= i32(P.height) || !(wt > 0.0) {
        return false;
    }
    let ux = u32(tx);
    let uy = u32(ty);
    var ok = true;
    if P.g_normal != NONE {
        let a = vec3<f32>(cur_guide(P.g_normal, 0u, x, y), cur_guide(P.g_normal, 1u, x, y), cur_guide(P.g_normal, 2u, x, y));
        let b = vec3<f32>(
            hist_in[rec(P.n_at, ux, uy)],
            hist_in[rec(P.n_at + 1u, ux, uy)],
            hist_in[rec(P.n_at + 2u, ux, uy)],
        );
        let d = a.x * b.x + a.y * b.y + a.z * b.z;
        let empty = all(a == vec3<f32>(0.0)) && all(b == vec3<f32>(0.0));
        ok = ok && (d >= P.normal_limit || empty);
    }
    if P.g_position != NONE {
        var plim2 = 0.0;
        if P.g_depth != NONE {
            let plim = P.position_limit * abs(cur_guide(P.g_depth, 0u, x, y));
            plim2 = plim * plim;
        } else {
            plim2 = P.footprint_limit2 * footprint2(x, y);
        }
        var d2 = 0.0;
        for (var c = 0u; c < 3u; c++) {
            let e = hist_in[rec(P.p_at + c, ux, uy)] - cur_guide(P.g_position, c, x, y);
            d2 += e * e;
        }
        ok = ok && d2 <= plim2;
    } else if P.g_depth != NONE {
        let d = cur_guide(P.g_depth, 0u, x, y);
        ok = ok && abs(hist_in[rec(P.d_at, ux, uy)] - d) <= P.depth_limit * abs(d);
    }
    let pl = vec3<f32>(hist_in[rec(LIGHT, ux, uy)], hist_in[rec(LIGHT + 1u, ux, uy)], hist_in[rec(LIGHT + 2u, ux, uy)]);
    let pn = hist_in[rec(COUNT, ux, uy)];
    return ok && finite(pl.x) && finite(pl.y) && finite(pl.z) && finite(pn) && pn >= 0.0;
}

// The 4 taps of (x, y) (`reproject::bilinear_taps`), those rejected at weight 0.
fn taps(x: u32, y: u32) -> Taps {
    let i = y * P.width + x;
    let px = f32(x) + work[motion_at() + i];
    let py = f32(y) + work[motion_at() + plane() + i];
    let fx = floor(px);
    let fy = floor(py);
    let ax = px - fx;
    let ay = py - fy;
    var t: Taps;
    t.x0 = i32(fx);
    t.y0 = i32(fy);
    let w = vec4<f32>((1.0 - ax) * (1.0 - ay), ax * (1.0 - ay), (1.0 - ax) * ay, ax * ay);
    for (var k = 0u; k < 4u; k++) {
        let tx = t.x0 + i32(k & 1u);
        let ty = t.y0 + i32(k >> 1u);
        t.w[k] = select(0.0, w[k], tap_ok(tx, ty, w[k], x, y));
    }
    return t;
}

@compute @workgroup_size(8, 8)
fn t_taps(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y;
    if x >= P.width || y >= P.height || P.has_history == 0u {
        return;
    }
    if !motion_ok(x, y) {
        atomicAdd(&counters.invalid_motion, 1u);
        atomicAdd(&counters.rejected, 1u);
        return;
    }
    let t = taps(x, y);
    if !(t.w.x + t.w.y + t.w.z + t.w.w > 0.0) {
        atomicAdd(&counters.rejected, 1u);
    }
}

// ---------------------------------------------------------------------------
// t_thresholds: cell i of band `band` (`fireflies::Thresholds::finish_capped`
// over padded cells, in its order): k · max(min(third largest cell maximum,
// cap), neighbourhood mean), with the cap from the previous frame's cells
// when the read slot holds a frame and this one is not a cut. Writes the
// threshold (inf: the cell clamps nothing) and, into the write slot, the
// largest luminance the clamp leaves in the cell and the mean term.

fn cell(band: u32, j: i32) -> vec3<f32> {
    if j < 0 || j >= i32(P.nc) {
        return vec3<f32>(0.0);
    }
    let o = 3u * (band * P.nc + u32(j));
    return vec3<f32>(work[o], work[o + 1u], work[o + 2u]);
}

@compute @workgroup_size(64)
fn t_thresholds(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let band = gid.y;
    if i >= P.nc || band >= P.bands {
        return;
    }
    let out_cells = P.cells_at + 2u * band * P.nc;
    if P.fireflies == 0.0 {
        // no clamp, no cap for the next frame
        hist_out[out_cells + i] = inf();
        hist_out[out_cells + P.nc + i] = inf();
        work[thresholds_at() + band * P.nc + i] = inf();
        return;
    }
    var rest_sum = 0.0;
    var rest_count = 0.0;
    var top = -1.0;
    var top_count = 0.0;
    var best = vec3<f32>(0.0);
    for (var d = 0i; d <= 2i * i32(REACH); d++) {
        let c = cell(band, i32(i) - i32(REACH) + d);
        if c.x > top {
            rest_sum += max(top, 0.0);
            rest_count += top_count;
            top = c.x;
            top_count = c.y;
        } else {
            rest_sum += c.x;
            rest_count += c.y;
        }
        var m = c.z;
        for (var k = 0u; k < 3u; k++) {
            let hi = max(best[k], m);
            m = min(best[k], m);
            best[k] = hi;
        }
    }
    var mean = inf();
    if rest_count > 0.0 {
        mean = rest_sum / rest_count;
    }
    var cap = inf();
    var before = inf();
    if P.has_history != 0u && !is_cut() && P.firefly_history > 0.0 {
        let in_cells = P.cells_at + 2u * band * P.nc;
        let lo = select(0u, i - REACH, i >= REACH);
        let hi = min(i + REACH + 1u, P.nc);
        var near = 0.0;
        for (var j = lo; j < hi; j++) {
            near = max(near, hist_in[in_cells + j]);
        }
        cap = P.firefly_history * near;
        before = hist_in[in_cells + P.nc + i];
    }
    let brighter = mean > before;
    var limit = select(cap, cap * (mean / before), brighter);
    if brighter && before <= 0.0 {
        limit = inf();
    }
    if is_nan(limit) {
        limit = inf();
    }
    let t = P.fireflies * max(min(best.z, limit), mean);
    let own = cell(band, i32(i)).z;
    hist_out[out_cells + P.nc + i] = mean;
    hist_out[out_cells + i] = min(own, t);
    work[thresholds_at() + band * P.nc + i] = select(t, inf(), own <= t && own < LUMA_CAP);
}

// ---------------------------------------------------------------------------
// t_accumulate: step 1 for pixel (x, y) (`Reprojection::accumulate_pixel`).

@compute @workgroup_size(8, 8)
fn t_accumulate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y;
    if x >= P.width || y >= P.height {
        return;
    }
    let n = plane();
    let i = y * P.width + x;
    let raw = light_at(x, y);
    var cur = raw;
    var kept = 1.0;
    if P.fireflies != 0.0 {
        let t = work[thresholds_at() + (y / CELL) * P.nc + x / CELL];
        let l = luma(raw);
        if l > t && finite(l) {
            cur = raw * (t / l);
            atomicAdd(&counters.clamped, 1u);
        }
        // fireflies::kept
        let lc = luma(cur);
        if l > lc && finite(l) && lc >= 0.0 {
            kept = clamp(lc / l, 0.0, 1.0);
        }
    }
    let cur_ok = finite(cur.x) && finite(cur.y) && finite(cur.z);
    if !cur_ok {
        atomicAdd(&counters.nonfinite, 1u);
    }
    // the current guides into the record
    if P.g_normal != NONE {
        for (var c = 0u; c < 3u; c++) {
            hist_out[rec(P.n_at + c, x, y)] = guide(P.g_normal, c, i);
        }
    }
    if P.g_position != NONE {
        for (var c = 0u; c < 3u; c++) {
            hist_out[rec(P.p_at + c, x, y)] = guide(P.g_position, c, i);
        }
    }
    if P.g_depth != NONE {
        hist_out[rec(P.d_at, x, y)] = guide(P.g_depth, 0u, i);
    }
    var tw = 0.0;
    var hn = 0.0;
    var prev = vec3<f32>(0.0);
    var ow = 0.0;
    var po = vec3<f32>(0.0);
    if P.has_history != 0u && !is_cut() && motion_ok(x, y) {
        let t = taps(x, y);
            for (var k = 0u; k < 4u; k++) {
            let wt = t.w[k];
            if wt > 0.0 {
                let tx = u32(t.x0 + i32(k & 1u));
                let ty = u32(t.y0 + i32(k >> 1u));
                tw += wt;
                hn += wt * hist_in[rec(COUNT, tx, ty)];
                for (var c = 0u; c < 3u; c++) {
                    prev[c] += wt * hist_in[rec(LIGHT + c, tx, ty)];
                }
                let o = vec3<f32>(hist_in[rec(OUTPUT, tx, ty)], hist_in[rec(OUTPUT + 1u, tx, ty)], hist_in[rec(OUTPUT + 2u, tx, ty)]);
                if finite(o.x) && finite(o.y) && finite(o.z) {
                    ow += wt;
                    po += wt * o;
                }
            }
        }
    }
    var acc = cur;
    var count = max(kept, 1e-3);
    if tw > 0.0 {
        let hist = hn / tw;
        let inv = 1.0 / tw;
        let p = prev * inv;
        if cur_ok {
            count = min(hist + kept, P.max_history);
            var a = 1.0;
            if count > 0.0 {
                a = max(kept / count, kept / P.max_history);
            }
            acc = p + a * (cur - p);
        } else {
            // a NaN/Inf sample is bridged with the history
            acc = p;
            count = hist;
        }
    }
    for (var c = 0u; c < 3u; c++) {
        hist_out[rec(LIGHT + c, x, y)] = acc[c];
        light[c * n + i] = acc[c];
    }
    hist_out[rec(COUNT, x, y)] = count;
    var pv = vec3<f32>(nan());
    if ow > 0.0 {
        pv = po * (1.0 / ow);
    }
    for (var c = 0u; c < 3u; c++) {
        work[prev_out_at() + c * n + i] = pv[c];
    }
}

// ---------------------------------------------------------------------------
// t_resolve: step 3 for pixel (x, y) (`Reprojection::resolve_pixel`).

fn ycocg(c: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(c.x + 2.0 * c.y + c.z, 2.0 * c.x - 2.0 * c.z, -c.x + 2.0 * c.y - c.z);
}

fn rgb(c: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(0.25 * (c.x + c.y - c.z), 0.25 * (c.x + c.z), 0.25 * (c.x - c.y - c.z));
}

fn fitted_at(x: u32, y: u32) -> vec3<f32> {
    let i = y * P.width + x;
    let n = plane();
    return vec3<f32>(fitted[i], fitted[n + i], fitted[2u * n + i]);
}

@compute @workgroup_size(8, 8)
fn t_resolve(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y;
    if x >= P.width || y >= P.height {
        return;
    }
    let n = plane();
    let i = y * P.width + x;
    let cur = fitted_at(x, y);
    var res = cur;
    let pv = vec3<f32>(work[prev_out_at() + i], work[prev_out_at() + n + i], work[prev_out_at() + 2u * n + i]);
    let blend = P.has_history != 0u && !is_cut() && P.output_alpha < 1.0;
    if blend && !is_nan(pv.x) {
        let ya = select(0u, y - 1u, y > 0u);
        let yb = min(y + 2u, P.height);
        let xa = select(0u, x - 1u, x > 0u);
        let xb = min(x + 2u, P.width);
        var s1 = vec3<f32>(0.0);
        var s2 = vec3<f32>(0.0);
        for (var yy = ya; yy < yb; yy++) {
            // the horizontal 3-sum of the row (zeros past the edges), then down the rows
            var r1 = vec3<f32>(0.0);
            var r2 = vec3<f32>(0.0);
            for (var xx = xa; xx < xb; xx++) {
                let c = ycocg(fitted_at(xx, yy));
                r1 += c;
                r2 += c * c;
            }
            s1 += r1;
            s2 += r2;
        }
        let inv = 1.0 / f32((yb - ya) * (xb - xa));
        let p = ycocg(pv);
        var clipped = vec3<f32>(0.0);
        for (var c = 0u; c < 3u; c++) {
            let mu = s1[c] * inv;
            let vr = s2[c] * inv - mu * mu;
            let sd = sqrt(select(0.0, vr, vr > 0.0));
            let lo = mu - P.clip_gamma * sd;
            let hi = mu + P.clip_gamma * sd;
            let v = select(lo, p[c], p[c] >= lo);
            clipped[c] = select(hi, v, v <= hi);
        }
        let hn = hist_out[rec(COUNT, x, y)];
        var a = 1.0;
        if hn > 0.0 {
            a = min(max(1.0 / hn, P.output_alpha), 1.0);
        }
        let old = rgb(clipped);
        res = old + a * (cur - old);
    }
    for (var c = 0u; c < 3u; c++) {
        var v = res[c];
        if P.clamp_negative != 0u && !(v > 0.0) {
            v = 0.0;
        }
        if !finite(v) {
            v = 0.0;
        }
        hist_out[rec(OUTPUT + c, x, y)] = v;
        output[c * n + i] = v;
    }
}
