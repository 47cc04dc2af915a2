// FLR (Fast Local Regression) as WGSL compute shaders: the stages of the CPU
// path (src/flr, src/kernels) in f32. One module, one bind group (bindings 0–7)
// shared by every entry point; run the entry points in this order, each once
// per frame, with the workgroup counts of `lrdenoise::flr::gpu::GpuPlan::passes`:
//
//   reference → moments → finish_stats → blur_rows → blur_cols → solve → apply
//
// With the adaptive window (three windows blended per cell) window 0's
// blurred grid goes to `tmp` instead of `cells`, its solve also writes
// variance estimates, and the other windows and the blend run before apply:
//
//   … moments → [pool] → finish_stats → blur_rows → blur_cols → solve → blur_rows_1 →
//   blur_cols_1 → solve_1 → blur_rows_2 → blur_cols_2 → solve_2 → blend → apply
//
// (`pool` when a window is fitted on the 2×2-pooled grid). Regions of `tmp`
// and `models` are given by `Params::win`. With `Params::without` (the AO
// channel), window 0's solve also fits each cell without that guide, from the
// same Cholesky factor (the guide ordered last: the system without it is the
// leading block), and the blend weighs that fit as a fourth candidate. With
// the firefly clamp (`Params::fireflies`, src/fireflies.rs) `reference` also
// sums the noisy input's 8×8 clamp cells into the start of `tmp`, and
// `moments` derives the thresholds of its block's cells from them and clamps
// the samples it reads.
// Equation numbers are those of the FLR paper's appendix (eqs. 12–23).
// Differences from the CPU path, all from f32 (WGSL has no f64): moments are
// shifted to the frame reference and blurred in f32; the pivot floors are
// scaled for f32's resolution (FLOOR_*). Guide and noisy samples are f32 or
// f16 storage buffers addressed with the same layouts as the CPU's image
// views (element units); the output is f32.

const MAX_Q: u32 = 8u;
const MAX_K: u32 = 73u; // moment count at Q = 8: 1 + 8 + 36 + 3 + 24 + 1
const MAX_ML: u32 = 30u; // model length at Q = 8: 3 + 24 + 3
const WG: u32 = 64u;
const NONE: u32 = 0xffffffffu;
// Relative pivot floors (the CPU's 1e-12 and 1e-15 are below f32 resolution).
const FLOOR_NORMALIZED: f32 = 1e-6;
const FLOOR_TIKHONOV: f32 = 1e-6;

struct Params {
    width: u32,
    height: u32,
    cells_x: u32,
    cells_y: u32,
    block: u32,
    q: u32,
    k: u32,
    ml: u32,
    radius: u32,
    clamp_negative: u32,
    tikhonov: u32,
    // 1: noisy and guides are f16 (two per u32, unpack2x16float); 0: f32
    input_f16: u32,
    eps_mul: f32,
    eps_add: f32,
    eps_tikhonov: f32,
    weight_norm: f32,
    min_weight: f32,
    // noisy and fit-guide resolution (= width, height unless upsampling) and
    // the block size there (block / upsample)
    in_width: u32,
    in_height: u32,
    fit_block: u32,
    // offset, pixel stride, row stride, channel stride (elements)
    noisy: vec4<u32>,
    output: vec4<u32>,
    // one per guide channel: offset, pixel stride, row stride, unused; `guide`
    // at the output resolution (the model is applied to it), `guide_fit` at
    // the noisy resolution (the moments are taken from it; = `guide` unless
    // upsampling or a separate fit set)
    guide: array<vec4<u32>, 8>,
    guide_fit: array<vec4<u32>, 8>,
    // blur taps w[0..=radius], four per vector (window 0)
    taps: array<vec4<f32>, 17>,
    // 1, or 3 with the adaptive window (Blur::Adaptive: three windows blended)
    windows: u32,
    // the 2×2-pooled moment grid in `tmp` (element offset; NONE without) and its size
    pooled_off: u32,
    pooled_x: u32,
    pooled_y: u32,
    win: array<Window, 3>,
    // taps of windows 1 and 2, 17 vectors each
    taps_12: array<vec4<f32>, 34>,
    // FlrConfig::adaptive_without_ao: the guide (AO) window 0 is also fitted
    // without (NONE: off), and where that fit's models and variances go in
    // `models` (on window 0's grid)
    without: u32,
    without_model_off: u32,
    without_var_off: u32,
    // FlrConfig::ao_demodulation: the AO channel (NONE: off) and the offset c
    // of s = sqrt(ao + c); the noisy light is divided by s before the moments,
    // the output multiplied by it
    demod_ao: u32,
    demod_offset: f32,
    // FlrConfig::fireflies: the firefly clamp's factor k (0: off)
    fireflies: f32,
    pad_fireflies0: u32,
    pad_fireflies1: u32,
}

// One window of the fit: its grid, where its blur reads and writes, where its
// models (and, adaptive, its variance estimates) go. Buffers: 0 `cells`, 1 `tmp`.
struct Window {
    cells_x: u32,
    cells_y: u32,
    factor: u32, // block cells per cell side: 1, or 2 (pooled)
    radius: u32,
    src_buf: u32,
    src_off: u32, // the moments its blur reads
    out_buf: u32,
    out_off: u32, // its blurred grid (what its solve reads)
    tmp_off: u32, // its row-blurred grid, in `tmp`
    model_off: u32, // its models, in `models`
    var_off: u32, // its variance estimates, in `models` (NONE: not wanted)
    weight_norm: f32,
    min_weight: f32,
    area: f32, // 4πσ² in input pixels
    pad0: u32,
    pad1: u32,
}

struct Stats {
    reference: array<f32, 8>,
    mean: array<f32, 8>,
    scale: array<f32, 8>,
    nonfinite_noisy: atomic<u32>,
    nonfinite_guides: atomic<u32>,
    fallback_pixels: atomic<u32>,
    empty_blocks: atomic<u32>,
    empty_cells: atomic<u32>,
    dropped_pivots: atomic<u32>,
    clamped_fireflies: atomic<u32>,
}

@group(0) @binding(0) var<uniform> P: Params;
// f32 samples (bit patterns) or f16 pairs, per `input_f16`
@group(0) @binding(1) var<storage, read> noisy: array<u32>;
@group(0) @binding(2) var<storage, read> guides: array<u32>;
@group(0) @binding(3) var<storage, read_write> stats: Stats;
@group(0) @binding(4) var<storage, read_write> cells: array<f32>;
@group(0) @binding(5) var<storage, read_write> tmp: array<f32>;
@group(0) @binding(6) var<storage, read_write> models: array<f32>;
@group(0) @binding(7) var<storage, read_write> output: array<f32>;

// Finite test on the bits: immune to compilers that assume no NaN.
fn finite(v: f32) -> bool {
    return (bitcast<u32>(v) & 0x7f800000u) != 0x7f800000u;
}

// Element `i` of a sample buffer word `w`: f32 bits, or half `i & 1` of an f16 pair.
fn sample(w: u32, i: u32) -> f32 {
    if P.input_f16 != 0u {
        let v = unpack2x16float(w);
        return select(v.x, v.y, (i & 1u) == 1u);
    }
    return bitcast<f32>(w);
}

fn word(i: u32) -> u32 {
    return select(i, i >> 1u, P.input_f16 != 0u);
}

fn guide_at(q: u32, x: u32, y: u32) -> f32 {
    let l = P.guide[q];
    let i = l.x + y * l.z + x * l.y;
    return sample(guides[word(i)], i);
}

fn fit_at(q: u32, x: u32, y: u32) -> f32 {
    let l = P.guide_fit[q];
    let i = l.x + y * l.z + x * l.y;
    return sample(guides[word(i)], i);
}

fn noisy_at(c: u32, x: u32, y: u32) -> f32 {
    let l = P.noisy;
    let i = l.x + y * l.z + x * l.y + c * l.w;
    return sample(noisy[word(i)], i);
}

// The AO demodulation's s = sqrt(clamp(ao, 0, 1) + c) (a non-finite AO counts
// as 1, open), and `v · (1 / s)` or `v · s` clamped to ±f32::MAX so that a
// finite value stays finite: the arithmetic of src/kernels/demodulation.rs.
// (`v` is finite at both call sites: moments stage only valid pixels, apply
// has replaced a non-finite prediction by the fallback already.)
const F32_MAX: f32 = 3.40282347e+38;

fn demod_scale(ao: f32) -> f32 {
    var a = 1.0;
    if finite(ao) {
        a = clamp(ao, 0.0, 1.0);
    }
    return sqrt(a + P.demod_offset);
}

fn demod_divide(v: f32, s: f32) -> f32 {
    return clamp(v * (1.0 / s), -F32_MAX, F32_MAX);
}

fn demod_multiply(v: f32, s: f32) -> f32 {
    return clamp(v * s, -F32_MAX, F32_MAX);
}

// The window the running entry point works on (set first thing by each).
var<private> W: u32;

fn tap(o: u32) -> f32 {
    if W == 0u {
        return P.taps[o / 4u][o % 4u];
    }
    return P.taps_12[(W - 1u) * 17u + o / 4u][o % 4u];
}

fn grid_get(buf: u32, i: u32) -> f32 {
    if buf == 0u {
        return cells[i];
    }
    return tmp[i];
}

fn grid_set(buf: u32, i: u32, v: f32) {
    if buf == 0u {
        cells[i] = v;
    } else {
        tmp[i] = v;
    }
}

// Element `i` of the running window's blurred grid (what its solve reads).
fn blurred(i: u32) -> f32 {
    return grid_get(P.win[W].out_buf, P.win[W].out_off + i);
}

// Cell layout offsets (src/kernels/mod.rs): n, s[Q], S (packed upper), t[3], P[Q][3].
fn off_s() -> u32 { return 1u; }
fn off_ss() -> u32 { return 1u + P.q; }
fn off_t() -> u32 { return 1u + P.q + P.q * (P.q + 1u) / 2u; }
fn off_p() -> u32 { return off_t() + 3u; }
fn off_e() -> u32 { return off_p() + 3u * P.q; }

// ---------------------------------------------------------------------------
// The firefly clamp (src/fireflies.rs): the noisy input is cut into bands of
// FF_CELL rows and each band into cells of FF_CELL × FF_CELL pixels; a cell's
// threshold comes from the cells up to FF_REACH away in its band, and a
// finite sample whose luminance ℓ exceeds its cell's threshold T has its
// three channels scaled by T / ℓ, ahead of everything that reads them.
const FF_CELL: u32 = 8u;
const FF_REACH: u32 = 6u;
// largest luminance a sample adds to its cell's sum (fireflies::LUMA_CAP)
const FF_LUMA_CAP: f32 = 1e30;

// Clamp cells per band.
fn ff_cells() -> u32 {
    return (P.in_width + FF_CELL - 1u) / FF_CELL;
}

fn noisy_rgb(x: u32, y: u32) -> vec3<f32> {
    return vec3<f32>(noisy_at(0u, x, y), noisy_at(1u, x, y), noisy_at(2u, x, y));
}

// Sum, count and maximum of the finite luminances of clamp cell `i` of band
// `band` (negatives as 0, capped at FF_LUMA_CAP; `fireflies::Thresholds`,
// in its own summation order) into tmp[3 · (band · cells + i) ..].
fn firefly_cell(i: u32, band: u32) {
    let n = ff_cells();
    if i >= n || band * FF_CELL >= P.in_height {
        return;
    }
    let x1 = min((i + 1u) * FF_CELL, P.in_width);
    let y1 = min((band + 1u) * FF_CELL, P.in_height);
    var sum = 0.0;
    var count = 0.0;
    var top = 0.0;
    for (var y = band * FF_CELL; y < y1; y++) {
        var row_sum = 0.0;
        var row_count = 0.0;
        for (var x = i * FF_CELL; x < x1; x++) {
            let l = luma3(noisy_rgb(x, y));
            if finite(l) {
                let c = clamp(l, 0.0, FF_LUMA_CAP);
                row_sum += c;
                row_count += 1.0;
                top = max(top, c);
            }
        }
        sum += row_sum;
        count += row_count;
    }
    let o = 3u * (band * n + i);
    tmp[o] = sum;
    tmp[o + 1u] = count;
    tmp[o + 2u] = top;
}

// Threshold of clamp cell `i` of band `band` (`fireflies::Thresholds::finish`,
// in f32): k · max(third largest cell maximum, mean ℓ of the cells but the
// one with the largest sum) over cells i − FF_REACH ..= i + FF_REACH; inf()
// where no finite sample lies outside that cell. The mean sums the other
// cells rather than subtracting the top one from the total, so that an
// outlier's sum does not swamp the rest in f32.
fn firefly_threshold(i: u32, band: u32) -> f32 {
    let n = ff_cells();
    let lo = select(0u, i - FF_REACH, i >= FF_REACH);
    let hi = min(i + FF_REACH + 1u, n);
    let row = 3u * band * n;
    var top = lo;
    var top_sum = -1.0;
    var m = vec3<f32>(0.0); // the three largest cell maxima, largest first
    for (var j = lo; j < hi; j++) {
        let s = tmp[row + 3u * j];
        if s > top_sum {
            top_sum = s;
            top = j;
        }
        let c = tmp[row + 3u * j + 2u];
        if c > m.z {
            m.z = c;
            if m.z > m.y {
                m = m.xzy;
                if m.y > m.x {
                    m = m.yxz;
                }
            }
        }
    }
    var sum = 0.0;
    var count = 0.0;
    for (var j = lo; j < hi; j++) {
        if j != top {
            sum += tmp[row + 3u * j];
            count += tmp[row + 3u * j + 1u];
        }
    }
    if !(count > 0.0) {
        return inf();
    }
    return P.fireflies * max(m.z, sum / count);
}

// Whether the clamp scales a sample of luminance `l` under threshold `t`: a
// finite `l` above a finite `t` (non-finite samples are left to the
// validity test; a non-finite `t` clamps nothing).
fn firefly_clamps(l: f32, t: f32) -> bool {
    return finite(l) && finite(t) && l > t;
}

// ---------------------------------------------------------------------------
// Stage 0: the per-guide frame reference (first finite value among 16 fixed
// sample positions, as `Flr::prepare`) and the report counters reset, by
// invocation 0; with the firefly clamp, also the clamp cells' sums, one
// invocation per cell (x: cell, y: band; `firefly_cell`). Those sums are part
// of the Prepare stage: they read only the noisy input, and `moments` needs
// every cell of a band for its thresholds.
@compute @workgroup_size(64)
fn reference(@builtin(global_invocation_id) gid: vec3<u32>) {
    if P.fireflies > 0.0 {
        firefly_cell(gid.x, gid.y);
    }
    if gid.x != 0u || gid.y != 0u {
        return;
    }
    for (var q = 0u; q < P.q; q++) {
        var r = 0.0;
        var found = false;
        for (var sy = 0u; sy < 4u && !found; sy++) {
            for (var sx = 0u; sx < 4u && !found; sx++) {
                let v = fit_at(q, (2u * sx + 1u) * P.in_width / 8u, (2u * sy + 1u) * P.in_height / 8u);
                if finite(v) {
                    r = v;
                    found = true;
                }
            }
        }
        stats.reference[q] = r;
        stats.mean[q] = 0.0;
        stats.scale[q] = 1.0;
    }
    atomicStore(&stats.nonfinite_noisy, 0u);
    atomicStore(&stats.nonfinite_guides, 0u);
    atomicStore(&stats.fallback_pixels, 0u);
    atomicStore(&stats.empty_blocks, 0u);
    atomicStore(&stats.empty_cells, 0u);
    atomicStore(&stats.dropped_pivots, 0u);
    atomicStore(&stats.clamped_fireflies, 0u);
}

// ---------------------------------------------------------------------------
// Stage 1: moments of one B×B block per workgroup (eq. 12), accumulated
// relative to the block's first valid pixel and shifted to the frame
// reference. The block's pixels are staged in workgroup memory 64 at a time
// as [w, e_0..e_Q, y_0..y_2] (w = 1 valid, 0 excluded; e = g − m − r); then
// invocation j sums moment j (and j + 64) over them: no reduction tree, two
// barriers per 64 pixels. Pixels with a non-finite sample are left out and
// counted. With the firefly clamp the workgroup first computes the
// thresholds of the clamp cells its block covers (one, or 2 × 2 at a block
// of 16 pixels: `ff_t`, inf() without the clamp), counts the samples it
// clamps and stages them clamped.
const PIX: u32 = 13u; // values staged per pixel: w, e[MAX_Q], y[3], luminance
var<workgroup> first_valid: atomic<u32>;
var<workgroup> first_plain: u32;
var<workgroup> pix: array<f32, 832>; // 64 pixels × PIX
var<workgroup> sums: array<f32, 73>;
// thresholds of the block's clamp cells (fit_block ≤ 16: at most 2 × 2)
var<workgroup> ff_t: array<f32, 4>;

// Slot in `ff_t` of the clamp cell of pixel (x, y), in the block at (x0, y0).
fn ff_slot(x: u32, y: u32, x0: u32, y0: u32) -> u32 {
    let nc = max(P.fit_block / FF_CELL, 1u);
    return min((y / FF_CELL - y0 / FF_CELL) * nc + x / FF_CELL - x0 / FF_CELL, 3u);
}

fn pixel_valid(x: u32, y: u32) -> vec2<bool> {
    var ok_noisy = true;
    for (var c = 0u; c < 3u; c++) {
        ok_noisy = ok_noisy && finite(noisy_at(c, x, y));
    }
    var ok_guides = true;
    for (var q = 0u; q < P.q; q++) {
        ok_guides = ok_guides && finite(fit_at(q, x, y));
    }
    return vec2<bool>(ok_noisy, ok_guides);
}

// The two staged values whose product, summed, is moment `m` (cell layout).
fn factors(m: u32) -> vec2<u32> {
    let q = P.q;
    if m == 0u || m >= P.k {
        return vec2<u32>(0u, 0u); // n = Σ w·w
    }
    if m < off_ss() {
        return vec2<u32>(0u, m); // s_a = Σ w·e_a
    }
    if m < off_t() {
        var idx = off_ss();
        for (var a = 0u; a < q; a++) {
            if m < idx + q - a {
                return vec2<u32>(1u + a, 1u + a + (m - idx)); // S_ab
            }
            idx += q - a;
        }
    }
    if m < off_p() {
        return vec2<u32>(0u, 1u + q + (m - off_t())); // t_c = Σ w·y_c
    }
    if m == off_e() {
        return vec2<u32>(4u + q, 4u + q); // e = Σ w·ℓ² (ℓ is 0 where w is)
    }
    let j = m - off_p();
    return vec2<u32>(1u + j / 3u, 1u + q + j % 3u); // P_ac
}

@compute @workgroup_size(64)
fn moments(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let b = P.fit_block;
    let x0 = wg.x * b;
    let y0 = wg.y * b;
    let k = P.k;
    let q = P.q;
    if lid == 0u {
        atomicStore(&first_valid, NONE);
    }
    if lid < 4u {
        let nc = max(b / FF_CELL, 1u);
        let i = x0 / FF_CELL + lid % nc;
        let band = y0 / FF_CELL + lid / nc;
        var t = inf();
        if P.fireflies > 0.0 && lid < nc * nc && i < ff_cells() && band * FF_CELL < P.in_height {
            t = firefly_threshold(i, band);
        }
        ff_t[lid] = t;
    }
    workgroupBarrier();
    for (var i = lid; i < b * b; i += WG) {
        let x = x0 + i % b;
        let y = y0 + i / b;
        if x < P.in_width && y < P.in_height {
            // every sample the clamp scales is counted, valid guides or not (as the CPU's)
            if P.fireflies > 0.0 && firefly_clamps(luma3(noisy_rgb(x, y)), ff_t[ff_slot(x, y, x0, y0)]) {
                atomicAdd(&stats.clamped_fireflies, 1u);
            }
            let ok = pixel_valid(x, y);
            if ok.x && ok.y {
                atomicMin(&first_valid, i);
            } else {
                if !ok.x {
                    atomicAdd(&stats.nonfinite_noisy, 1u);
                }
                if !ok.y {
                    atomicAdd(&stats.nonfinite_guides, 1u);
                }
            }
        }
    }
    workgroupBarrier();
    if lid == 0u {
        first_plain = atomicLoad(&first_valid);
    }
    let first = workgroupUniformLoad(&first_plain);
    let cell = (wg.y * P.cells_x + wg.x) * k;
    if first == NONE {
        for (var m = lid; m < k; m += WG) {
            cells[cell + m] = 0.0;
        }
        if lid == 0u {
            atomicAdd(&stats.empty_blocks, 1u);
        }
        return;
    }
    // block reference r (relative to the frame reference)
    var r: array<f32, 8>;
    for (var a = 0u; a < q; a++) {
        r[a] = fit_at(a, x0 + first % b, y0 + first / b) - stats.reference[a];
    }
    let f0 = factors(lid);
    let f1 = factors(lid + WG);
    var acc0 = 0.0;
    var acc1 = 0.0;
    for (var base = 0u; base < b * b; base += WG) {
        // stage 64 pixels
        let i = base + lid;
        let x = x0 + i % b;
        let y = y0 + i / b;
        let o = lid * PIX;
        for (var v = 0u; v < PIX; v++) {
            pix[o + v] = 0.0;
        }
        if i < b * b && x < P.in_width && y < P.in_height {
            let ok = pixel_valid(x, y);
            if ok.x && ok.y {
                pix[o] = 1.0;
                for (var a = 0u; a < q; a++) {
                    pix[o + 1u + a] = (fit_at(a, x, y) - stats.reference[a]) - r[a];
                }
                var s = 1.0;
                if P.demod_ao != NONE {
                    s = demod_scale(fit_at(P.demod_ao, x, y));
                }
                // the firefly clamp on the raw sample, ahead of the demodulation;
                // `pixel_valid` tested the raw sample, which is what the
                // clamped one is: a finite sample scaled by T / ℓ < 1 stays finite
                var rgb = noisy_rgb(x, y);
                let t = ff_t[ff_slot(x, y, x0, y0)];
                let l_raw = luma3(rgb);
                if firefly_clamps(l_raw, t) {
                    rgb *= t / l_raw;
                }
                for (var c = 0u; c < 3u; c++) {
                    pix[o + 1u + q + c] = demod_divide(rgb[c], s);
                }
                let l = 0.2126 * pix[o + 1u + q] + 0.7152 * pix[o + 2u + q] + 0.0722 * pix[o + 3u + q];
                pix[o + 4u + q] = l;
            }
        }
        workgroupBarrier();
        // moment lid (and lid + 64) over the staged pixels
        for (var p = 0u; p < WG; p++) {
            let pp = p * PIX;
            acc0 += pix[pp + f0.x] * pix[pp + f0.y];
            acc1 += pix[pp + f1.x] * pix[pp + f1.y];
        }
        workgroupBarrier();
    }
    if lid < k {
        sums[lid] = acc0;
    }
    if lid + WG < k {
        sums[lid + WG] = acc1;
    }
    workgroupBarrier();
    // moments about r → about the frame reference (store_shifted), one per invocation
    let n = sums[0];
    for (var m = lid; m < k; m += WG) {
        let f = factors(m);
        var v = sums[m];
        if m == 0u || m >= off_t() && m < off_p() || m == off_e() {
            // n, t and e do not depend on the reference
        } else if m < off_ss() {
            v = sums[m] + n * r[m - 1u];
        } else if m < off_t() {
            let a = f.x - 1u;
            let bb = f.y - 1u;
            v = sums[m] + r[a] * sums[off_s() + bb] + sums[off_s() + a] * r[bb] + n * r[a] * r[bb];
        } else {
            let a = f.x - 1u;
            let c = f.y - 1u - q;
            v = sums[m] + r[a] * sums[off_t() + c];
        }
        cells[cell + m] = v;
    }
}

// ---------------------------------------------------------------------------
// Stage 2: frame mean and standard deviation of each guide (standardisation
// of the normalized solve), from every cell (`Flr::finish_stats`).
var<workgroup> part: array<f32, 1088>; // 64 threads × (1 + 2·MAX_Q)

@compute @workgroup_size(64)
fn finish_stats(@builtin(local_invocation_index) lid: u32) {
    let q = P.q;
    let nv = 1u + 2u * q;
    var acc: array<f32, 17>;
    let ncell = P.cells_x * P.cells_y;
    for (var c = lid; c < ncell; c += WG) {
        let base = c * P.k;
        acc[0] += cells[base];
        var idx = off_ss();
        for (var a = 0u; a < q; a++) {
            acc[1u + a] += cells[base + off_s() + a];
            acc[1u + q + a] += cells[base + idx];
            idx += q - a;
        }
    }
    for (var v = 0u; v < nv; v++) {
        part[v * WG + lid] = acc[v];
    }
    workgroupBarrier();
    if lid == 0u {
        var tot: array<f32, 17>;
        for (var v = 0u; v < nv; v++) {
            for (var i = 0u; i < WG; i++) {
                tot[v] += part[v * WG + i];
            }
        }
        let n = tot[0];
        for (var a = 0u; a < q; a++) {
            var mean = 0.0;
            var variance = 0.0;
            if n > 0.0 {
                mean = tot[1u + a] / n;
                variance = tot[1u + q + a] / n - mean * mean;
            }
            let floor = 1e-6 * abs(stats.reference[a] + mean);
            let sd = max(sqrt(max(variance, 0.0)), floor);
            if finite(mean) {
                stats.mean[a] = mean;
            } else {
                stats.mean[a] = 0.0;
            }
            if finite(sd) && sd > 0.0 {
                stats.scale[a] = sd;
            } else {
                stats.scale[a] = 1.0;
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Stages 3–4: separable blur of the moment grid (zero outside the grid).
// One invocation per (cell, moment): x = cell column × k + moment, y = cell
// row. `blur_rows` / `blur_cols` blur window 0; `_1` and `_2` the adaptive
// window's others, on their grids.
fn blur_rows_at(gid: vec3<u32>) {
    let g = P.win[W];
    let k = P.k;
    let cx = gid.x / k;
    let m = gid.x % k;
    let cy = gid.y;
    if cx >= g.cells_x || cy >= g.cells_y {
        return;
    }
    let row = cy * g.cells_x;
    var acc = tap(0u) * grid_get(g.src_buf, g.src_off + (row + cx) * k + m);
    for (var o = 1u; o <= g.radius; o++) {
        if cx >= o {
            acc += tap(o) * grid_get(g.src_buf, g.src_off + (row + cx - o) * k + m);
        }
        if cx + o < g.cells_x {
            acc += tap(o) * grid_get(g.src_buf, g.src_off + (row + cx + o) * k + m);
        }
    }
    tmp[g.tmp_off + (row + cx) * k + m] = acc;
}

fn blur_cols_at(gid: vec3<u32>) {
    let g = P.win[W];
    let k = P.k;
    let cx = gid.x / k;
    let m = gid.x % k;
    let cy = gid.y;
    if cx >= g.cells_x || cy >= g.cells_y {
        return;
    }
    let t = g.tmp_off;
    var acc = tap(0u) * tmp[t + (cy * g.cells_x + cx) * k + m];
    for (var o = 1u; o <= g.radius; o++) {
        if cy >= o {
            acc += tap(o) * tmp[t + ((cy - o) * g.cells_x + cx) * k + m];
        }
        if cy + o < g.cells_y {
            acc += tap(o) * tmp[t + ((cy + o) * g.cells_x + cx) * k + m];
        }
    }
    grid_set(g.out_buf, g.out_off + (cy * g.cells_x + cx) * k + m, acc);
}

@compute @workgroup_size(64)
fn blur_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 0u;
    blur_rows_at(gid);
}

@compute @workgroup_size(64)
fn blur_cols(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 0u;
    blur_cols_at(gid);
}

@compute @workgroup_size(64)
fn blur_rows_1(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 1u;
    blur_rows_at(gid);
}

@compute @workgroup_size(64)
fn blur_cols_1(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 1u;
    blur_cols_at(gid);
}

@compute @workgroup_size(64)
fn blur_rows_2(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 2u;
    blur_rows_at(gid);
}

@compute @workgroup_size(64)
fn blur_cols_2(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 2u;
    blur_cols_at(gid);
}

// Adaptive window: sums the block grid 2×2 into the pooled grid in `tmp`
// (`Flr::pool_tile`; a pooled cell is exactly the moments of its 2B × 2B pixels).
@compute @workgroup_size(64)
fn pool(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = P.k;
    let cx = gid.x / k;
    let m = gid.x % k;
    let cy = gid.y;
    if cx >= P.pooled_x || cy >= P.pooled_y {
        return;
    }
    var acc = 0.0;
    for (var y = 2u * cy; y < min(2u * cy + 2u, P.cells_y); y++) {
        for (var x = 2u * cx; x < min(2u * cx + 2u, P.cells_x); x++) {
            acc += cells[(y * P.cells_x + x) * k + m];
        }
    }
    tmp[P.pooled_off + (cy * P.pooled_x + cx) * k + m] = acc;
}

// ---------------------------------------------------------------------------
// Stage 5: one cell per invocation → its affine model (src/kernels/solve.rs).
// Model: intercept c0[3], coefficients c[q][3] on d = g − m, local mean μ_y[3].

// Cholesky with a relative pivot floor; dropped pivots get a zero inverse.
// Returns the number of dropped pivots. `a` is (n × n) in a 9 × 9 array.
fn cholesky(a: ptr<function, array<array<f32, 9>, 9>>, inv: ptr<function, array<f32, 9>>, n: u32, rel_floor: f32) -> u32 {
    var maxdiag = 0.0;
    for (var i = 0u; i < n; i++) {
        maxdiag = max(maxdiag, abs((*a)[i][i]));
    }
    let floor = max(maxdiag * rel_floor, 1.17549435e-38);
    var dropped = 0u;
    for (var j = 0u; j < n; j++) {
        var d = (*a)[j][j];
        for (var p = 0u; p < j; p++) {
            d -= (*a)[j][p] * (*a)[j][p];
        }
        if !(d > floor) || !finite(d) {
            dropped++;
            (*a)[j][j] = 0.0;
            (*inv)[j] = 0.0;
            for (var i = j + 1u; i < n; i++) {
                (*a)[i][j] = 0.0;
            }
            continue;
        }
        let l = sqrt(d);
        let il = 1.0 / l;
        (*a)[j][j] = l;
        (*inv)[j] = il;
        for (var i = j + 1u; i < n; i++) {
            var s = (*a)[i][j];
            for (var p = 0u; p < j; p++) {
                s -= (*a)[i][p] * (*a)[j][p];
            }
            (*a)[i][j] = s * il;
        }
    }
    return dropped;
}

// L Lᵀ x = b for 3 right-hand sides (rows of `b`), in place.
fn substitute(l: ptr<function, array<array<f32, 9>, 9>>, inv: ptr<function, array<f32, 9>>, b: ptr<function, array<vec3<f32>, 9>>, n: u32) {
    for (var i = 0u; i < n; i++) {
        var s = (*b)[i];
        for (var p = 0u; p < i; p++) {
            s -= (*l)[i][p] * (*b)[p];
        }
        (*b)[i] = s * (*inv)[i];
    }
    for (var ii = 0u; ii < n; ii++) {
        let i = n - 1u - ii;
        var s = (*b)[i];
        for (var p = i + 1u; p < n; p++) {
            s -= (*l)[p][i] * (*b)[p];
        }
        (*b)[i] = s * (*inv)[i];
    }
}

fn vec_finite(v: vec3<f32>) -> bool {
    return finite(v.x) && finite(v.y) && finite(v.z);
}

fn solve_at(gid: vec3<u32>) {
    let g = P.win[W];
    let cx = gid.x;
    let cy = gid.y;
    if cx >= g.cells_x || cy >= g.cells_y {
        return;
    }
    let q = P.q;
    let cell = (cy * g.cells_x + cx) * P.k;
    let model = g.model_off + (cy * g.cells_x + cx) * P.ml;
    let n = blurred(cell);
    if !(n > g.min_weight) || !finite(n) {
        for (var j = 0u; j < P.ml; j++) {
            models[model + j] = 0.0;
        }
        if g.var_off != NONE {
            models[g.var_off + cy * g.cells_x + cx] = inf();
        }
        if W == 0u && P.without != NONE {
            for (var j = 0u; j < P.ml; j++) {
                models[P.without_model_off + (cy * g.cells_x + cx) * P.ml + j] = 0.0;
            }
            models[P.without_var_off + cy * g.cells_x + cx] = inf();
        }
        atomicAdd(&stats.empty_cells, 1u);
        return;
    }
    let s = off_s();
    let ss = off_ss();
    let t = off_t();
    let p = off_p();
    let inv_n = 1.0 / n;
    let muy = vec3<f32>(blurred(cell + t), blurred(cell + t + 1u), blurred(cell + t + 2u)) * inv_n;
    var c0 = muy;
    var coef: array<vec3<f32>, 9>;
    // window 0's fit without guide `d` (NONE: none), `c0` and `coef` as the fit's
    let d = select(NONE, P.without, W == 0u);
    var sub_c0 = muy;
    var sub_coef: array<vec3<f32>, 9>;
    var a: array<array<f32, 9>, 9>;
    var inv: array<f32, 9>;
    var dropped = 0u;
    if P.tikhonov == 0u {
        // Normalized-correlation regularized inverse (eqs. 12–23) on standardised guides.
        var mu: array<f32, 8>;
        var muz: array<f32, 8>;
        var inv_scale: array<f32, 8>;
        for (var i = 0u; i < q; i++) {
            inv_scale[i] = 1.0 / stats.scale[i];
            mu[i] = blurred(cell + s + i) * inv_n;
            muz[i] = (mu[i] - stats.mean[i]) * inv_scale[i];
        }
        // guide i at row and column moved(i, d) (d last; the identity without d)
        var idx = ss;
        for (var i = 0u; i < q; i++) {
            for (var j = i; j < q; j++) {
                let w = (blurred(cell + idx) * inv_n - mu[i] * mu[j]) * (inv_scale[i] * inv_scale[j]);
                var v = w + P.eps_mul * muz[i] * muz[j];
                if i == j {
                    v += P.eps_mul * muz[i] * muz[i] + P.eps_add; // eq. 18
                }
                a[moved(i, d, q)][moved(j, d, q)] = v;
                a[moved(j, d, q)][moved(i, d, q)] = v;
                idx++;
            }
        }
        var isig: array<f32, 8>;
        for (var i = 0u; i < q; i++) {
            let ii = moved(i, d, q);
            isig[i] = 1.0 / sqrt(max(a[ii][ii], 1e-30)); // eq. 19
        }
        var bh: array<vec3<f32>, 9>;
        for (var i = 0u; i < q; i++) {
            let ii = moved(i, d, q);
            for (var j = 0u; j < q; j++) {
                let jj = moved(j, d, q);
                a[ii][jj] *= isig[i] * isig[j]; // eq. 20
            }
            a[ii][ii] += P.eps_add; // eq. 22
            let pv = vec3<f32>(blurred(cell + p + 3u * i), blurred(cell + p + 3u * i + 1u), blurred(cell + p + 3u * i + 2u));
            bh[ii] = (pv * inv_n - mu[i] * muy) * (isig[i] * inv_scale[i]); // eq. 21
        }
        dropped = cholesky(&a, &inv, q, FLOOR_NORMALIZED);
        var lead = bh;
        substitute(&a, &inv, &bh, q);
        if d != NONE {
            // the leading block: every guide but d
            substitute(&a, &inv, &lead, q - 1u);
            lead[q - 1u] = vec3<f32>(0.0);
        }
        for (var i = 0u; i < q; i++) {
            let ii = moved(i, d, q);
            let beta = bh[ii] * (isig[i] * inv_scale[i]); // eq. 23
            coef[i] = beta;
            c0 -= beta * mu[i];
            if d != NONE {
                let sub_beta = lead[ii] * (isig[i] * inv_scale[i]);
                sub_coef[i] = sub_beta;
                sub_c0 -= sub_beta * mu[i];
            }
        }
    } else {
        // Tikhonov (eq. 11) on the raw guides: variables [1, g_0 .. g_Q).
        // unknowns: the intercept, then guide i at 1 + moved(i, d)
        let wn = g.weight_norm;
        var b: array<vec3<f32>, 9>;
        a[0][0] = n * wn + P.eps_tikhonov;
        var idx = ss;
        for (var i = 0u; i < q; i++) {
            let ii = 1u + moved(i, d, q);
            let mi = stats.reference[i];
            let s_i = blurred(cell + s + i);
            let raw_s = (s_i + n * mi) * wn;
            a[0][ii] = raw_s;
            a[ii][0] = raw_s;
            for (var j = i; j < q; j++) {
                let jj = 1u + moved(j, d, q);
                let mj = stats.reference[j];
                let raw = blurred(cell + idx) + mi * blurred(cell + s + j) + s_i * mj + n * mi * mj;
                var v = raw * wn;
                if i == j {
                    v += P.eps_tikhonov;
                }
                a[ii][jj] = v;
                a[jj][ii] = v;
                idx++;
            }
        }
        let tv = vec3<f32>(blurred(cell + t), blurred(cell + t + 1u), blurred(cell + t + 2u));
        b[0] = tv * wn;
        for (var i = 0u; i < q; i++) {
            let pv = vec3<f32>(blurred(cell + p + 3u * i), blurred(cell + p + 3u * i + 1u), blurred(cell + p + 3u * i + 2u));
            b[1u + moved(i, d, q)] = (pv + stats.reference[i] * tv) * wn;
        }
        dropped = cholesky(&a, &inv, q + 1u, FLOOR_TIKHONOV);
        var lead = b;
        substitute(&a, &inv, &b, q + 1u);
        if d != NONE {
            substitute(&a, &inv, &lead, q);
            lead[q] = vec3<f32>(0.0);
        }
        c0 = b[0];
        sub_c0 = lead[0];
        for (var i = 0u; i < q; i++) {
            let ii = 1u + moved(i, d, q);
            coef[i] = b[ii];
            c0 += b[ii] * stats.reference[i];
            if d != NONE {
                sub_coef[i] = lead[ii];
                sub_c0 += lead[ii] * stats.reference[i];
            }
        }
    }
    if dropped > 0u {
        atomicAdd(&stats.dropped_pivots, dropped);
    }
    write_model(model, c0, coef, muy);
    if g.var_off != NONE {
        models[g.var_off + cy * g.cells_x + cx] = variance(cell, model, g, f32(q + 1u));
    }
    if d != NONE {
        let sub_model = P.without_model_off + (cy * g.cells_x + cx) * P.ml;
        write_model(sub_model, sub_c0, sub_coef, muy);
        models[P.without_var_off + cy * g.cells_x + cx] = variance(cell, sub_model, g, f32(q));
    }
}

// Guide `i`'s row and column in a system that orders guide `d` last (the
// others keep their order); `i` itself when `d` is NONE.
fn moved(i: u32, d: u32, q: u32) -> u32 {
    if d == NONE || i < d {
        return i;
    }
    if i == d {
        return q - 1u;
    }
    return i - 1u;
}

// One cell's model at `model` (`write_model` of src/kernels/solve): the local
// mean where the fit is not finite.
fn write_model(model: u32, c0: vec3<f32>, coef: array<vec3<f32>, 9>, muy: vec3<f32>) {
    let q = P.q;
    var ok = vec_finite(c0);
    for (var i = 0u; i < q; i++) {
        ok = ok && vec_finite(coef[i]);
    }
    var m = muy;
    if !vec_finite(muy) {
        m = vec3<f32>(0.0);
    }
    for (var j = 0u; j < P.ml; j++) {
        models[model + j] = 0.0;
    }
    if ok {
        for (var c = 0u; c < 3u; c++) {
            models[model + c] = c0[c];
        }
        for (var i = 0u; i < q; i++) {
            for (var c = 0u; c < 3u; c++) {
                models[model + 3u + 3u * i + c] = coef[i][c];
            }
        }
    } else {
        for (var c = 0u; c < 3u; c++) {
            models[model + c] = m[c];
        }
    }
    for (var c = 0u; c < 3u; c++) {
        models[model + 3u + 3u * q + c] = m[c];
    }
}

@compute @workgroup_size(64)
fn solve(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 0u;
    solve_at(gid);
}

@compute @workgroup_size(64)
fn solve_1(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 1u;
    solve_at(gid);
}

@compute @workgroup_size(64)
fn solve_2(@builtin(global_invocation_id) gid: vec3<u32>) {
    W = 2u;
    solve_at(gid);
}

// ---------------------------------------------------------------------------
// Adaptive window (src/flr/adaptive.rs): each window's estimated prediction
// variance, then a per-cell blend of the three windows' models weighted by
// 1 / (bias² + variance). "Infinite" (an empty window) is the INF bit pattern,
// always tested with `finite` and never computed with.

const BIAS_DISCOUNT: f32 = 0.5;

fn inf() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

fn luma3(v: vec3<f32>) -> f32 {
    return 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z;
}

// v_s = r_s · coefficients / N_s of the model just written at `model`
// (`adaptive::variance`; Q + 1 coefficients, Q for the fit without a guide).
fn variance(cell: u32, model: u32, g: Window, coefficients: f32) -> f32 {
    let q = P.q;
    let n = blurred(cell);
    let inv = 1.0 / n;
    let t = off_t();
    let p = off_p();
    let mean = luma3(vec3<f32>(blurred(cell + t), blurred(cell + t + 1u), blurred(cell + t + 2u))) * inv;
    var explained = 0.0;
    for (var a = 0u; a < q; a++) {
        let pa = cell + p + 3u * a;
        let cov = luma3(vec3<f32>(blurred(pa), blurred(pa + 1u), blurred(pa + 2u))) * inv - blurred(cell + off_s() + a) * inv * mean;
        let j = model + 3u + 3u * a;
        explained += luma3(vec3<f32>(models[j], models[j + 1u], models[j + 2u])) * cov;
    }
    let residual = max(blurred(cell + off_e()) * inv - mean * mean - explained, 0.0);
    let samples = max(g.area * min(n * g.weight_norm, 1.0), 1.0);
    let v = residual * coefficients / samples;
    if finite(v) {
        return v;
    }
    return inf();
}

// Block-grid row (or column) `i` on a pooled grid of `n`: two neighbours
// (x, y) with weights (z, w) (`adaptive::pooled_taps`).
fn pooled_taps(i: u32, n: u32) -> vec4<f32> {
    let c = min(i / 2u, max(n, 1u) - 1u);
    if i % 2u == 0u {
        if c == 0u {
            return vec4<f32>(0.0, 0.0, 1.0, 0.0);
        }
        return vec4<f32>(f32(c - 1u), f32(c), 0.25, 0.75);
    }
    if c + 1u >= n {
        return vec4<f32>(f32(c), f32(c), 1.0, 0.0);
    }
    return vec4<f32>(f32(c), f32(c + 1u), 0.75, 0.25);
}

@compute @workgroup_size(64)
fn blend(@builtin(global_invocation_id) gid: vec3<u32>) {
    let cx = gid.x;
    let cy = gid.y;
    if cx >= P.cells_x || cy >= P.cells_y {
        return;
    }
    let q = P.q;
    let ml = P.ml;
    // each window's model and variance at this cell (a pooled window's
    // interpolated bilinearly; an empty neighbour makes the variance INF)
    // (candidate 3: window 0's fit without `Params::without`, when there is one)
    let nc = select(4u, 3u, P.without == NONE);
    var ms: array<array<f32, 30>, 4>;
    var vs: array<f32, 4>;
    if nc == 4u {
        let c = cy * P.cells_x + cx;
        for (var j = 0u; j < ml; j++) {
            ms[3][j] = models[P.without_model_off + c * ml + j];
        }
        vs[3] = models[P.without_var_off + c];
    }
    for (var s = 0u; s < 3u; s++) {
        let g = P.win[s];
        if g.factor == 1u {
            let c = cy * g.cells_x + cx;
            for (var j = 0u; j < ml; j++) {
                ms[s][j] = models[g.model_off + c * ml + j];
            }
            vs[s] = models[g.var_off + c];
            continue;
        }
        let ty = pooled_taps(cy, g.cells_y);
        let tx = pooled_taps(cx, g.cells_x);
        var at: array<u32, 4>;
        var w: array<f32, 4>;
        for (var c = 0u; c < 4u; c++) {
            let yy = select(ty.x, ty.y, c >= 2u);
            let xx = select(tx.x, tx.y, c % 2u == 1u);
            at[c] = u32(yy) * g.cells_x + u32(xx);
            w[c] = select(ty.z, ty.w, c >= 2u) * select(tx.z, tx.w, c % 2u == 1u);
        }
        var v = 0.0;
        var v_finite = true;
        for (var c = 0u; c < 4u; c++) {
            if w[c] != 0.0 {
                let vc = models[g.var_off + at[c]];
                v_finite = v_finite && finite(vc);
                v += w[c] * vc;
            }
        }
        vs[s] = select(inf(), v, v_finite && finite(v));
        for (var j = 0u; j < ml; j++) {
            var m = 0.0;
            for (var c = 0u; c < 4u; c++) {
                m += w[c] * models[g.model_off + at[c] * ml + j];
            }
            ms[s][j] = m;
        }
    }
    // prediction gaps d_s² of windows 1 and 2 against window 0, over window
    // 0's blurred moments (`adaptive::prediction_gaps`)
    W = 0u;
    let cell = (cy * P.cells_x + cx) * P.k;
    let n = blurred(cell);
    var gaps = vec4<f32>(0.0);
    if n > P.win[0].min_weight && finite(n) {
        let inv = 1.0 / n;
        var mu: array<f32, 8>;
        for (var a = 0u; a < q; a++) {
            mu[a] = blurred(cell + off_s() + a) * inv;
        }
        for (var s = 1u; s < nc; s++) {
            var dc: array<f32, 8>;
            var at_mean = luma3(vec3<f32>(ms[s][0] - ms[0][0], ms[s][1] - ms[0][1], ms[s][2] - ms[0][2]));
            for (var a = 0u; a < q; a++) {
                let j = 3u + 3u * a;
                dc[a] = luma3(vec3<f32>(ms[s][j] - ms[0][j], ms[s][j + 1u] - ms[0][j + 1u], ms[s][j + 2u] - ms[0][j + 2u]));
                at_mean += dc[a] * mu[a];
            }
            var spread = 0.0;
            var idx = off_ss();
            for (var a = 0u; a < q; a++) {
                for (var b = a; b < q; b++) {
                    let cov = blurred(cell + idx) * inv - mu[a] * mu[b];
                    spread += select(2.0, 1.0, a == b) * dc[a] * dc[b] * cov;
                    idx++;
                }
            }
            let d2 = at_mean * at_mean + max(spread, 0.0);
            gaps[s] = select(inf(), d2, finite(d2));
        }
    }
    // weights 1 / (b_s² + v_s) (`adaptive::blend`); a larger window next to
    // an empty smallest one is taken at its variance alone
    var w = vec4<f32>(0.0);
    for (var s = 0u; s < nc; s++) {
        var mse = vs[s];
        if s > 0u && finite(vs[s]) && finite(vs[0]) {
            // the variance difference d_s² holds: max(v₀ − v_s, 0)
            var seen = 0.0;
            if vs[0] > vs[s] {
                seen = vs[0] - vs[s];
            }
            if finite(gaps[s]) {
                mse = max(gaps[s] - BIAS_DISCOUNT * seen, 0.0) + vs[s];
            } else {
                mse = inf();
            }
        }
        if finite(mse) {
            w[s] = 1.0 / max(mse, 1e-30);
        }
    }
    let total = w.x + w.y + w.z + w.w;
    let out = (cy * P.cells_x + cx) * ml;
    for (var j = 0u; j < ml; j++) {
        if total > 0.0 && finite(total) {
            var m = w.x * ms[0][j] + w.y * ms[1][j] + w.z * ms[2][j];
            if nc == 4u {
                m += w.w * ms[3][j];
            }
            models[out + j] = m / total;
        } else {
            models[out + j] = ms[1][j];
        }
    }
}

// ---------------------------------------------------------------------------
// Stage 6: bilinear interpolation of the models between cell centres and
// application to each pixel's guides (src/kernels/apply.rs).

// Left cell and weight of pixel coordinate `x` (cell_pos).
fn cell_pos(x: u32, cells: u32) -> vec2<f32> {
    let c = (f32(x) + 0.5) / f32(P.block) - 0.5;
    if c <= 0.0 {
        return vec2<f32>(0.0, 0.0);
    }
    let i = u32(c);
    if i + 1u >= cells {
        return vec2<f32>(f32(cells - 1u), 0.0);
    }
    return vec2<f32>(f32(i), c - f32(i));
}

fn model_at(cx: u32, cy: u32, j: u32) -> f32 {
    return models[(cy * P.cells_x + cx) * P.ml + j];
}

@compute @workgroup_size(8, 8)
fn apply(@builtin(global_invocation_id) gid: vec3<u32>) {
    let x = gid.x;
    let y = gid.y;
    if x >= P.width || y >= P.height {
        return;
    }
    let q = P.q;
    let px = cell_pos(x, P.cells_x);
    let py = cell_pos(y, P.cells_y);
    let i = u32(px.x);
    let j = u32(py.x);
    let i1 = min(i + 1u, P.cells_x - 1u);
    let j1 = min(j + 1u, P.cells_y - 1u);
    // vertical then horizontal, as lerp_rows then apply_row
    var lm: array<f32, 30>;
    for (var m = 0u; m < P.ml; m++) {
        let a0 = model_at(i, j, m);
        let b0 = model_at(i, j1, m);
        let a1 = model_at(i1, j, m);
        let b1 = model_at(i1, j1, m);
        var left = a0;
        var right = a1;
        if py.y != 0.0 {
            left = a0 + (b0 - a0) * py.y;
            right = a1 + (b1 - a1) * py.y;
        }
        if px.y != 0.0 {
            lm[m] = left + (right - left) * px.y;
        } else {
            lm[m] = left;
        }
    }
    var valid = true;
    var d: array<f32, 8>;
    for (var g = 0u; g < q; g++) {
        let v = guide_at(g, x, y);
        valid = valid && finite(v);
        d[g] = v - stats.reference[g];
    }
    if !valid {
        atomicAdd(&stats.fallback_pixels, 1u);
    }
    let l = P.output;
    var s = 1.0;
    if P.demod_ao != NONE {
        s = demod_scale(guide_at(P.demod_ao, x, y));
    }
    for (var c = 0u; c < 3u; c++) {
        var yv = lm[c];
        for (var g = 0u; g < q; g++) {
            yv += lm[3u + 3u * g + c] * d[g];
        }
        if !valid || !finite(yv) {
            yv = lm[3u + 3u * q + c];
        }
        if P.clamp_negative != 0u {
            yv = max(yv, 0.0);
        }
        if P.demod_ao != NONE {
            yv = demod_multiply(yv, s);
        }
        output[l.x + y * l.z + x * l.y + c * l.w] = yv;
    }
}
