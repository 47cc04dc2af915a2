//! WALR's inputs: the frame-wide constants ([`Walr::prepare`]), the
//! octahedral normal features (§5.2) and the first averages `Z_0`
//! ([`Walr::features_rows`]).

use super::store::Store;
use super::{CheckedFrame, Prepared, Report, Storage, Walr, GEO_FIXED, G_INV_SCALE, G_N, G_P, G_VALID, MAX_FEATURES};
use crate::error::Error;
use crate::fireflies;
use crate::kernels::LUMA;

/// Octahedral map of a direction in a local frame whose third axis is the
/// pole (Cigolle et al. 2014), remapped from [−1, 1]² to [0, 1]². Continuous
/// on the hemisphere around the pole; the zero vector maps to the centre.
pub fn octahedral(n: [f32; 3]) -> [f32; 2] {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    if !(l1 > 0.0) || !l1.is_finite() {
        return [0.5, 0.5];
    }
    let (mut x, mut y) = (n[0] / l1, n[1] / l1);
    if n[2] < 0.0 {
        let sx = if x >= 0.0 { 1.0 } else { -1.0 };
        let sy = if y >= 0.0 { 1.0 } else { -1.0 };
        (x, y) = ((1.0 - y.abs()) * sx, (1.0 - x.abs()) * sy);
    }
    [0.5 * x + 0.5, 0.5 * y + 0.5]
}

/// An orthonormal basis `[t, b, v]` with `v` along `pole` (normalised).
pub fn basis(pole: [f32; 3]) -> [[f32; 3]; 3] {
    let l = libm::sqrtf(pole[0] * pole[0] + pole[1] * pole[1] + pole[2] * pole[2]);
    let v = if l > 1e-12 && l.is_finite() { pole.map(|c| c / l) } else { [0.0, 0.0, 1.0] };
    // Frisvad / Duff et al. 2017 branchless basis.
    let s = if v[2] >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (s + v[2]);
    let b = v[0] * v[1] * a;
    let t = [1.0 + s * v[0] * v[0] * a, s * b, -s * v[0]];
    let bb = [b, s + v[1] * v[1] * a, -v[1]];
    [t, bb, v]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Stored light is clamped to ± this many frame means: within f16's range,
/// and a 1e30 firefly cannot swamp its 81×81 window by more than ~9 means.
pub const LIGHT_LIMIT: f32 = 60000.0;

/// The energy plane holds `min(ℓ², ENERGY_MAX) · ENERGY_SCALE` per pixel (ℓ
/// = [`LUMA`]·y in light-scale units): scaled and capped so that f16 storage
/// holds it (a value above 4096 × the frame's mean light only counts as
/// 4096 in the noise estimate).
pub const ENERGY_SCALE: f32 = 1.0 / 256.0;
/// Cap of `ℓ²` in the energy plane (see [`ENERGY_SCALE`]).
pub const ENERGY_MAX: f32 = 16_777_216.0;

/// One pixel's energy-plane value (the scalar form of the lanes' operations).
#[inline(always)]
pub fn energy(y: [f32; 3]) -> f32 {
    let l = y[0] * LUMA[0] + y[1] * LUMA[1] + y[2] * LUMA[2];
    (l * l).min(ENERGY_MAX) * ENERGY_SCALE
}

/// Subsampling step of [`Walr::prepare`] in x and y.
const PREP_STEP: usize = 4;
// the light scale's samples are taken cell by cell of the firefly clamp
const _: () = assert!(fireflies::CELL.is_multiple_of(PREP_STEP));
/// Cells of the firefly clamp that [`Walr::prepare`] and
/// [`Walr::features_rows`] measure at a time ([`ClampWindow`], ≈ 12 KB of
/// stack).
const CLAMP_WINDOW: usize = 64;
/// Their pixels per row.
const CLAMP_SPAN: usize = CLAMP_WINDOW * fireflies::CELL;

/// The planes of a geometry row (from `at`) that hold its noisy light
/// between reading and [`Walr::features_rows`] (pixels `0..w`).
fn light_planes(geo: &mut [f32], at: usize, ps: usize, w: usize) -> Option<[&mut [f32]; 3]> {
    let planes = geo.get_mut(at + G_VALID * ps..at + (G_VALID + 3) * ps)?;
    let (a, rest) = planes.split_at_mut(ps);
    let (b, c) = rest.split_at_mut(ps);
    Some([a.get_mut(..w)?, b.get_mut(..w)?, c.get_mut(..w)?])
}

/// The runs of cells of a band of `n` cells that a [`ClampWindow`] measures
/// in turn: cells `c0..c1`, measured over cells `lo..hi` (their
/// neighbourhoods: [`fireflies::REACH`] more on each side, within the band).
fn clamp_runs(n: usize) -> impl Iterator<Item = (usize, usize, usize, usize)> {
    use fireflies::REACH;
    // cells whose thresholds one window gives (the rest of it is their neighbourhoods)
    const STEP: usize = CLAMP_WINDOW - 2 * REACH;
    (0..n).step_by(STEP).map(move |c0| {
        let c1 = (c0 + STEP).min(n);
        (c0, c1, c0.saturating_sub(REACH), (c1 + REACH).min(n))
    })
}

/// The firefly clamp's thresholds of a run of cells, measured on the stack.
/// A cell's threshold depends only on the cells of its neighbourhood, taken
/// in order ([`crate::fireflies`]): measured over the run and its
/// neighbourhoods alone, as a band of that width, they are the whole band's.
struct ClampWindow {
    work: [f32; fireflies::work_len(CLAMP_SPAN)],
    row: [[f32; CLAMP_SPAN]; 3],
}

impl ClampWindow {
    fn new() -> Self {
        ClampWindow { work: [0.0; fireflies::work_len(CLAMP_SPAN)], row: [[0.0; CLAMP_SPAN]; 3] }
    }

    /// The thresholds of the cells of `rows` (one band) in pixels
    /// `x_lo..x_hi` (at most [`CLAMP_SPAN`]), indexed from cell `x_lo / 8`,
    /// measured on the frame's light as it is.
    fn measure(&mut self, f: &CheckedFrame<'_>, k: f32, rows: core::ops::Range<usize>, (x_lo, x_hi): (usize, usize)) -> Option<&[f32]> {
        let ClampWindow { work, row } = self;
        let width = x_hi.checked_sub(x_lo)?;
        let mut t = fireflies::Thresholds::new(work, width)?;
        let [r, g, b] = row;
        let (r, g, b) = (r.get_mut(..width)?, g.get_mut(..width)?, b.get_mut(..width)?);
        for y in rows {
            f.noisy.read_row_n(y, x_lo, [&mut *r, &mut *g, &mut *b])?;
            t.add_row([r, g, b]);
        }
        Some(t.finish(k))
    }
}

impl Walr {
    /// Guide channel indices: (normal, position, depth, first extra).
    fn channels(&self) -> (usize, usize, Option<usize>, usize) {
        let s = &self.cfg.guides;
        let depth = s.depth.then_some(3);
        let pos = 3 + s.depth as usize;
        (0, pos, depth, pos + 3)
    }

    /// Frame-wide constants: the octahedral pole, the light scale and the
    /// ranges of the extra guides, from every 4th pixel of every 4th row.
    /// `index` seeds the replacement choices. With the firefly clamp
    /// ([`WalrConfig::fireflies`](super::WalrConfig::fireflies)) the light
    /// scale is taken from the clamped light, which costs a pass over it.
    pub fn prepare(&self, f: &CheckedFrame<'_>, index: u32) -> Prepared {
        self.prepare_with(f, index, self.cfg.fireflies)
    }

    /// [`Walr::prepare`] with the firefly clamp `clamp` (the temporal
    /// pipeline's accumulated light is clamped already).
    pub(crate) fn prepare_with(&self, f: &CheckedFrame<'_>, index: u32, clamp: Option<f32>) -> Prepared {
        let (w, h) = (self.width, self.height);
        let (cn, cp, cd, ce) = self.channels();
        let extras = self.m - 3;
        // positions relative to the first finite sample (large offsets cancel)
        let (mut p0, mut psum, mut psq, mut pcount) = (None::<[f64; 3]>, [0f64; 3], 0f64, 0u64);
        let mut nsum = [0f64; 3];
        let (lsum, lcount) = self.light_log_sum(f, clamp);
        let mut ext = [(f32::INFINITY, f32::NEG_INFINITY); MAX_FEATURES - 3];
        let mut row = [0f32; 1];
        let get = |q: usize, x: usize, y: usize, row: &mut [f32; 1]| -> Option<f32> {
            f.guides[q].as_ref()?.read_row(y, 0, x, row)?;
            Some(row[0])
        };
        for y in (0..h).step_by(PREP_STEP) {
            for x in (0..w).step_by(PREP_STEP) {
                let n = [0, 1, 2].map(|c| get(cn + c, x, y, &mut row).unwrap_or(f32::NAN));
                if n.iter().all(|v| v.is_finite()) {
                    for c in 0..3 {
                        nsum[c] += n[c] as f64;
                    }
                }
                // the positions' spread: only without depth does anything read it
                let pos = [0, 1, 2].map(|c| if cd.is_none() { get(cp + c, x, y, &mut row) } else { None });
                if let [Some(a), Some(b), Some(c)] = pos.map(|v| v.map(f64::from).filter(|v| v.is_finite())) {
                    let pos = [a, b, c];
                    let r = *p0.get_or_insert(pos);
                    for c in 0..3 {
                        psum[c] += pos[c] - r[c];
                        psq += (pos[c] - r[c]) * (pos[c] - r[c]);
                    }
                    pcount += 1;
                }
                for (e, r) in ext.iter_mut().enumerate().take(extras) {
                    if let Some(v) = get(ce + e, x, y, &mut row).filter(|v| v.is_finite()) {
                        *r = (r.0.min(v), r.1.max(v));
                    }
                }
            }
        }
        let pole = self.cfg.view.unwrap_or(nsum.map(|v| v as f32));
        // the log-average: a 1e30 firefly among the samples barely moves it
        let ls = if lcount > 0 { libm::exp(lsum / lcount as f64) as f32 } else { 1.0 };
        let light_scale = if ls > 1e-30 && ls.is_finite() { ls } else { 1.0 };
        let extra = ext.map(|(lo, hi)| {
            if lo.is_finite() && hi > lo && (hi - lo).is_finite() {
                (lo, 1.0 / (hi - lo))
            } else if lo.is_finite() {
                (lo, 1.0)
            } else {
                (0.0, 1.0)
            }
        });
        let seed = crate::hash::lowbias32(index.wrapping_mul(0x9E37_79B9) ^ 0x5A17_0001);
        // Without depth, distances are relative to the positions' RMS spread
        // about their mean (a stand-in for the camera distance, same units).
        let spread = if pcount > 0 {
            let n = pcount as f64;
            libm::sqrt((psq / n - psum.iter().map(|s| (s / n) * (s / n)).sum::<f64>()).max(0.0)) as f32
        } else {
            1.0
        };
        let distance = if spread > 0.0 && spread.is_finite() && (1.0 / spread).is_finite() { spread } else { 1.0 };
        Prepared { basis: basis(pole), light_scale, extra, seed, distance }
    }

    /// Σ ln|v| and the count of the finite, non-zero noisy values at every
    /// 4th pixel of every 4th row (the light scale's samples), taken band by
    /// band of the firefly clamp (8 rows) and cell by cell (8 columns), each
    /// pixel clamped first with `clamp`. The thresholds of a run of cells come
    /// from their band's rows over those cells and [`fireflies::REACH`] more
    /// on each side, exactly the neighbourhoods the rule reads, so they equal
    /// the whole band's; the run is measured on the stack.
    fn light_log_sum(&self, f: &CheckedFrame<'_>, clamp: Option<f32>) -> (f64, u64) {
        use fireflies::CELL;
        let (w, h) = (self.width, self.height);
        let (mut lsum, mut lcount) = (0f64, 0u64);
        let mut window = clamp.map(|_| ClampWindow::new());
        for band in 0..h.div_ceil(CELL) {
            let rows = band * CELL..((band + 1) * CELL).min(h);
            for (c0, c1, lo, hi) in clamp_runs(fireflies::cells(w)) {
                let x_lo = lo * CELL;
                let th = match (clamp, &mut window) {
                    (Some(k), Some(win)) => win.measure(f, k, rows.clone(), (x_lo, (hi * CELL).min(w))),
                    _ => None,
                };
                for x in (c0 * CELL..(c1 * CELL).min(w)).step_by(CELL) {
                    for y in rows.clone().step_by(PREP_STEP) {
                        for x in (x..(x + CELL).min(w)).step_by(PREP_STEP) {
                            let mut v = [0, 1, 2].map(|c| f.noisy.get(x, y, c).unwrap_or(f32::NAN));
                            if let Some(th) = th {
                                let [r, g, b] = &mut v;
                                let one = core::slice::from_mut;
                                fireflies::clamp_row([one(r), one(g), one(b)], x - x_lo, th);
                            }
                            for v in v.into_iter().filter(|v| v.is_finite() && *v != 0.0) {
                                lsum += libm::log(v.abs() as f64);
                                lcount += 1;
                            }
                        }
                    }
                }
            }
        }
        (lsum, lcount)
    }

    /// Stage 1 on rows `y0..`: geometry planes and `Z_0` (products of the
    /// features with themselves and with the light, sample count 1; 0 for a
    /// NaN/Inf noisy sample, which is thereby excluded). `geo_rows` and
    /// `z_rows` hold the same whole rows of [`super::Parts::geo`] and
    /// [`super::Parts::z`]`[0]`. With the firefly clamp the light is clamped
    /// as it is read: the whole 8-row bands the rows belong to are measured,
    /// rows outside `y0..` included, so any cut into bands of rows gives the
    /// whole frame's result.
    pub fn features_rows(
        &self,
        f: &CheckedFrame<'_>,
        p: &Prepared,
        y0: usize,
        geo_rows: &mut [f32],
        z_rows: &mut [f32],
    ) -> Result<Report, Error> {
        self.features_rows_with(f, p, y0, geo_rows, z_rows, self.cfg.fireflies)
    }

    /// [`Walr::features_rows`] with the firefly clamp `clamp`.
    pub(crate) fn features_rows_with(
        &self,
        f: &CheckedFrame<'_>,
        p: &Prepared,
        y0: usize,
        geo_rows: &mut [f32],
        z_rows: &mut [f32],
        clamp: Option<f32>,
    ) -> Result<Report, Error> {
        let rows = self.check_band(y0, geo_rows.len(), self.geo_row_len())?;
        if z_rows.len() != rows * self.z_row_len() {
            return Err(Error::InvalidTile { index: y0, count: self.height });
        }
        let clamped = match clamp {
            Some(k) => self.clamp_rows(f, k, y0, rows, geo_rows)?,
            None => 0,
        };
        let ready = clamp.is_some();
        let rep = match self.cfg.storage {
            Storage::F32 => self.features_impl::<f32>(f, p, y0, rows, geo_rows, z_rows, ready),
            Storage::F16 => self.features_impl::<u16>(f, p, y0, rows, geo_rows, bytemuck::cast_slice_mut(z_rows), ready),
        }?;
        Ok(Report { clamped_fireflies: clamped, ..rep })
    }

    /// The noisy light of rows `y0..y0 + rows`, clamped ([`crate::fireflies`]),
    /// into the planes of their geometry rows that [`Walr::features_rows`]
    /// reads it from. Each band's thresholds are measured over all of its
    /// rows, those outside the range read from the frame ([`ClampWindow`]).
    /// Returns the count clamped.
    fn clamp_rows(&self, f: &CheckedFrame<'_>, k: f32, y0: usize, rows: usize, geo_rows: &mut [f32]) -> Result<u64, Error> {
        use fireflies::CELL;
        let (w, h, ps, gl) = (self.width, self.height, self.plane_stride(), self.geo_row_len());
        let bad = Error::InvalidTile { index: y0, count: h };
        for r in 0..rows {
            let [a, b, c] = light_planes(geo_rows, r * gl, ps, w).ok_or(bad)?;
            f.noisy.read_row_n(y0 + r, 0, [a, b, c]).ok_or(bad)?;
        }
        let mut window = ClampWindow::new();
        let mut clamped = 0u64;
        let mut s = 0;
        while s < rows {
            let band = (y0 + s) / CELL;
            let band_rows = band * CELL..((band + 1) * CELL).min(h);
            // rows s..e of the range are this band's
            let e = (band_rows.end - y0).min(rows);
            for (c0, c1, lo, hi) in clamp_runs(fireflies::cells(w)) {
                let x_lo = lo * CELL;
                // measured from the frame: the held rows of earlier runs are clamped already
                let th = window.measure(f, k, band_rows.clone(), (x_lo, (hi * CELL).min(w))).ok_or(bad)?;
                let (xa, xb) = (c0 * CELL, (c1 * CELL).min(w));
                for r in s..e {
                    let [a, b, c] = light_planes(geo_rows, r * gl, ps, w).ok_or(bad)?;
                    clamped += fireflies::clamp_row([&mut a[xa..xb], &mut b[xa..xb], &mut c[xa..xb]], xa - x_lo, th) as u64;
                }
            }
            s = e;
        }
        Ok(clamped)
    }

    /// [`Walr::features_rows`] for pixels `x0..x0 + 8` of one row in lanes: the
    /// same operations in the same order as the per-pixel loop (bit-identical).
    /// Returns the counts of non-finite guide and noisy pixels.
    fn features_group8<S: Store>(
        &self,
        p: &Prepared,
        geo: &mut [f32],
        z: &mut [S],
        x0: usize,
        has_depth: bool,
        inv_light: f32,
    ) -> (u32, u32) {
        use wide::f32x8;
        let m = self.m;
        let ps = self.plane_stride();
        let ld = |geo: &[f32], c: usize| <f32 as Store>::load8(geo, c * ps + x0);
        let n = [ld(geo, G_N), ld(geo, G_N + 1), ld(geo, G_N + 2)];
        let pos = [ld(geo, G_P), ld(geo, G_P + 1), ld(geo, G_P + 2)];
        let scale = ld(geo, G_INV_SCALE);
        let rgb = [ld(geo, G_VALID), ld(geo, GEO_FIXED), ld(geo, GEO_FIXED + 1)];
        let mut extra = [f32x8::ZERO; MAX_FEATURES - 3];
        for e in 0..m - 3 {
            extra[e] = ld(geo, GEO_FIXED + 2 + e);
        }
        let mut finite = scale.is_finite();
        for v in n.iter().chain(&pos).chain(&extra[..m - 3]) {
            finite &= v.is_finite();
        }
        let nl = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let mut valid = finite & nl.simd_gt(f32x8::splat(1e-6)) & nl.is_finite();
        if has_depth {
            valid &= scale.simd_gt(f32x8::ZERO);
        }
        let nn = n.map(|c| c / nl);
        let b = p.basis.map(|r| r.map(f32x8::splat));
        let dotv = |a: &[f32x8; 3], b: &[f32x8; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let local = [dotv(&nn, &b[0]), dotv(&nn, &b[1]), dotv(&nn, &b[2])];
        // octahedral map (valid lanes have l1 > 0)
        let l1 = local[0].abs() + local[1].abs() + local[2].abs();
        let (ox, oy) = (local[0] / l1, local[1] / l1);
        let (one, half) = (f32x8::ONE, f32x8::splat(0.5));
        let sx = ox.simd_ge(f32x8::ZERO).select(one, -one);
        let sy = oy.simd_ge(f32x8::ZERO).select(one, -one);
        let lower = local[2].simd_lt(f32x8::ZERO);
        let fx = lower.select((one - oy.abs()) * sx, ox);
        let fy = lower.select((one - ox.abs()) * sy, oy);
        let mut xf = [f32x8::ZERO; MAX_FEATURES];
        xf[0] = one;
        xf[1] = valid.select(half * fx + half, half);
        xf[2] = valid.select(half * fy + half, half);
        for e in 0..m - 3 {
            let v = (extra[e] - f32x8::splat(p.extra[e].0)) * f32x8::splat(p.extra[e].1);
            xf[3 + e] = valid.select(v, f32x8::ZERO);
        }
        let inv_scale = one / scale;
        let st = |geo: &mut [f32], c: usize, v: f32x8| <f32 as Store>::store8(geo, c * ps + x0, v);
        for c in 0..3 {
            st(geo, G_P + c, valid.select(pos[c], f32x8::ZERO));
            st(geo, G_N + c, valid.select(nn[c], f32x8::ZERO));
        }
        st(geo, G_INV_SCALE, valid.select(inv_scale, f32x8::ZERO));
        st(geo, G_VALID, valid.select(one, finite.select(f32x8::ZERO, -one)));
        for j in 1..m {
            st(geo, GEO_FIXED + j - 1, xf[j]);
        }
        let ok = rgb[0].is_finite() & rgb[1].is_finite() & rgb[2].is_finite();
        let lim = f32x8::splat(LIGHT_LIMIT);
        let yv = rgb.map(|v| ok.select((v * f32x8::splat(inv_light)).max(-lim).min(lim), f32x8::ZERO));
        let wgt = ok.select(one, f32x8::ZERO);
        let mut k = 0;
        let mut put = |v: f32x8| {
            S::store8(z, k * ps + x0, v);
            k += 1;
        };
        for q in 1..m {
            put(wgt * xf[q]);
        }
        for a in 1..m {
            for b in a..m {
                put(wgt * xf[a] * xf[b]);
            }
        }
        for c in 0..3 {
            for q in 0..m {
                put(yv[c] * xf[q]);
            }
        }
        if self.blends_adaptively() {
            let l = yv[0] * f32x8::splat(LUMA[0]) + yv[1] * f32x8::splat(LUMA[1]) + yv[2] * f32x8::splat(LUMA[2]);
            put((l * l).fast_min(f32x8::splat(ENERGY_MAX)) * f32x8::splat(ENERGY_SCALE));
        }
        put(wgt);
        (8 - finite.to_bitmask().count_ones(), 8 - ok.to_bitmask().count_ones())
    }

    /// The features of rows `y0..y0 + rows`; with `light_ready` their light
    /// is in their geometry rows already ([`Walr::clamp_rows`]), else it is
    /// read here.
    #[allow(clippy::too_many_arguments)]
    fn features_impl<S: Store>(
        &self,
        f: &CheckedFrame<'_>,
        p: &Prepared,
        y0: usize,
        rows: usize,
        geo_rows: &mut [f32],
        z_rows: &mut [S],
        light_ready: bool,
    ) -> Result<Report, Error> {
        let (w, m) = (self.width, self.m);
        let (cn, cp, cd, ce) = self.channels();
        let gl = self.geo_row_len();
        let ps = self.plane_stride();
        let zl = self.z_row_values();
        let planes = self.planes();
        let bad = Error::InvalidTile { index: y0, count: self.height };
        let mut rep = Report::default();
        let inv_light = 1.0 / p.light_scale;
        for r in 0..rows {
            let y = y0 + r;
            let geo = &mut geo_rows[r * gl..(r + 1) * gl];
            // Raw guides straight into the geometry planes, features after.
            for c in 0..3 {
                let v = f.guides[cn + c].as_ref().ok_or(Error::GuideMismatch)?;
                v.read_row(y, 0, 0, &mut geo[(G_N + c) * ps..(G_N + c) * ps + w]).ok_or(bad)?;
                let v = f.guides[cp + c].as_ref().ok_or(Error::GuideMismatch)?;
                v.read_row(y, 0, 0, &mut geo[(G_P + c) * ps..(G_P + c) * ps + w]).ok_or(bad)?;
            }
            match cd {
                Some(d) => {
                    let v = f.guides[d].as_ref().ok_or(Error::GuideMismatch)?;
                    v.read_row(y, 0, 0, &mut geo[G_INV_SCALE * ps..G_INV_SCALE * ps + w]).ok_or(bad)?;
                }
                None => geo[G_INV_SCALE * ps..G_INV_SCALE * ps + w].fill(p.distance),
            }
            for e in 0..m - 3 {
                let o = (GEO_FIXED + 2 + e) * ps;
                let v = f.guides[ce + e].as_ref().ok_or(Error::GuideMismatch)?;
                v.read_row(y, 0, 0, &mut geo[o..o + w]).ok_or(bad)?;
            }
            if !light_ready {
                // The noisy row goes to planes that are only written per pixel, after reading.
                let (a, rest) = geo[G_VALID * ps..(G_VALID + 3) * ps].split_at_mut(ps);
                let (b, c) = rest.split_at_mut(ps);
                f.noisy.read_row_n(y, 0, [&mut a[..w], &mut b[..w], &mut c[..w]]).ok_or(bad)?;
            }
            let z = &mut z_rows[r * zl..(r + 1) * zl];
            let mut x0 = 0;
            if self.cfg.kernel == crate::isa::Kernel::Simd {
                while x0 + 8 <= w {
                    let (bad_guides, bad_noisy) = self.features_group8(p, geo, z, x0, cd.is_some(), inv_light);
                    rep.nonfinite_guides += bad_guides as u64;
                    rep.nonfinite_noisy += bad_noisy as u64;
                    x0 += 8;
                }
            }
            for x in x0..w {
                let g = |c: usize| geo[c * ps + x];
                let rgb = [g(G_VALID), g(GEO_FIXED), g(GEO_FIXED + 1)];
                let n = [g(G_N), g(G_N + 1), g(G_N + 2)];
                let pos = [g(G_P), g(G_P + 1), g(G_P + 2)];
                let scale = g(G_INV_SCALE);
                let mut extra = [0f32; MAX_FEATURES - 3];
                for e in 0..m - 3 {
                    extra[e] = g(GEO_FIXED + 2 + e);
                }
                let finite =
                    n.iter().chain(&pos).all(|v| v.is_finite()) && scale.is_finite() && extra[..m - 3].iter().all(|v| v.is_finite());
                rep.nonfinite_guides += !finite as u64;
                let nl = libm::sqrtf(dot(n, n));
                let valid = finite && nl > 1e-6 && nl.is_finite() && (cd.is_none() || scale > 0.0);
                let mut x_feat = [0f32; MAX_FEATURES];
                x_feat[0] = 1.0;
                let (nn, pp, inv_scale) = if valid {
                    let nn = n.map(|c| c / nl);
                    let local = [dot(nn, p.basis[0]), dot(nn, p.basis[1]), dot(nn, p.basis[2])];
                    let o = octahedral(local);
                    x_feat[1] = o[0];
                    x_feat[2] = o[1];
                    for e in 0..m - 3 {
                        x_feat[3 + e] = (extra[e] - p.extra[e].0) * p.extra[e].1;
                    }
                    (nn, pos, 1.0 / scale)
                } else {
                    x_feat[1] = 0.5;
                    x_feat[2] = 0.5;
                    ([0.0; 3], [0.0; 3], 0.0)
                };
                let set = |geo: &mut [f32], c: usize, v: f32| geo[c * ps + x] = v;
                for c in 0..3 {
                    set(geo, G_P + c, pp[c]);
                    set(geo, G_N + c, nn[c]);
                }
                set(geo, G_INV_SCALE, inv_scale);
                // 1: geometry; 0: none (sky); −1: unknown (NaN/Inf guides) — see `atrous`
                set(
                    geo,
                    G_VALID,
                    if valid {
                        1.0
                    } else if finite {
                        0.0
                    } else {
                        -1.0
                    },
                );
                for j in 1..m {
                    set(geo, GEO_FIXED + j - 1, x_feat[j]);
                }
                let ok = rgb.iter().all(|v| v.is_finite());
                rep.nonfinite_noisy += !ok as u64;
                let yv = if ok { rgb.map(|v| (v * inv_light).clamp(-LIGHT_LIMIT, LIGHT_LIMIT)) } else { [0.0; 3] };
                let wgt = if ok { 1.0 } else { 0.0 };
                let mut k = 0;
                let mut put = |v: f32| {
                    S::set(z, k * ps + x, v);
                    k += 1;
                };
                for q in 1..m {
                    put(wgt * x_feat[q]);
                }
                for a in 1..m {
                    for b in a..m {
                        put(wgt * x_feat[a] * x_feat[b]);
                    }
                }
                for c in 0..3 {
                    for q in 0..m {
                        put(yv[c] * x_feat[q]);
                    }
                }
                if self.blends_adaptively() {
                    put(energy(yv));
                }
                put(wgt);
                debug_assert_eq!(k, planes);
            }
        }
        Ok(rep)
    }
}
