//! The weight blob of FLNR's network: a small, versioned, little-endian
//! format written by `train/unet.py`, parsed and validated without copying.
//!
//! ```text
//! offset  field
//! 0       magic  "LRDN"
//! 4       u32    version (1, 2 or 3)
//! 8       u32    input channels   (1..=128)
//! 12      u32    output channels  (1..=128)
//! 16      u32    levels L         (0..=4)
//! 20      u32    widths c_0..c_L  (L + 1 values, 1..=128 each)
//! ..             the FLR the network was trained with:
//!                version 1: f32 σ (pixels), ε, ϵ (one Gaussian window);
//!                version 2: u32 windows W (1 or 3), f32 σ_1..σ_W (pixels,
//!                increasing; 3 = the adaptive window), f32 ε, ϵ;
//!                version 3: as version 2, then f32 c, the AO demodulation's
//!                offset (0: off; see `FlrConfig::ao_demodulation`)
//! ..      u32    payload length in f16 values
//! ..      f16    payload: for every layer in the order of [`crate::nn`], the
//!                weights [out][in][k][k] then the biases [out]
//! ```
//!
//! Every field is checked: bad magic, version, sizes, lengths or non-finite
//! values give a typed [`Error`], never a panic.

use super::conv::ConvDesc;
use crate::error::Error;
use half::f16;

/// Most U-Net levels a blob may have.
pub const MAX_LEVELS: usize = 4;
const MAGIC: &[u8; 4] = b"LRDN";
/// The newest version written (versions 1 and 2 are still read).
const VERSION: u32 = 3;
const MAX_LAYERS: usize = 4 * MAX_LEVELS + 4;

/// A parsed network: shapes and views into the blob's payload.
#[derive(Clone, Copy, Debug)]
pub struct UNet<'b> {
    in_ch: usize,
    out_ch: usize,
    levels: usize,
    widths: [usize; MAX_LEVELS + 1],
    /// Window σ (pixels) of the FLR trained with the network: `sigmas[..windows]`.
    sigmas: [f32; 3],
    windows: usize,
    /// ε (multiplicative), ϵ (additive).
    eps: [f32; 2],
    /// The AO demodulation's offset c (0: off).
    ao_offset: f32,
    layers: [ConvDesc<'b>; MAX_LAYERS],
    count: usize,
}

struct Reader<'b> {
    b: &'b [u8],
    pos: usize,
}

impl<'b> Reader<'b> {
    fn take(&mut self, n: usize) -> Result<&'b [u8], Error> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.b.len()).ok_or(Error::InvalidConfig("weights: blob truncated"))?;
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, Error> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn f32(&mut self) -> Result<f32, Error> {
        Ok(f32::from_bits(self.u32()?))
    }
}

impl<'b> UNet<'b> {
    /// Parses and validates a blob (see the module docs for the format).
    pub fn parse(blob: &'b [u8]) -> Result<Self, Error> {
        let mut r = Reader { b: blob, pos: 0 };
        if r.take(4)? != MAGIC {
            return Err(Error::InvalidConfig("weights: bad magic (not an lrdenoise network)"));
        }
        let version = r.u32()?;
        if !(1..=VERSION).contains(&version) {
            return Err(Error::InvalidConfig("weights: unsupported version"));
        }
        let in_ch = r.u32()? as usize;
        let out_ch = r.u32()? as usize;
        let levels = r.u32()? as usize;
        if !(1..=128).contains(&in_ch) || !(1..=128).contains(&out_ch) || levels > MAX_LEVELS {
            return Err(Error::InvalidConfig("weights: channels (1..=128) or levels (0..=4) out of range"));
        }
        let mut widths = [0usize; MAX_LEVELS + 1];
        for w in widths.iter_mut().take(levels + 1) {
            *w = r.u32()? as usize;
            if !(1..=128).contains(w) {
                return Err(Error::InvalidConfig("weights: layer width out of range (1..=128)"));
            }
        }
        let windows = if version == 1 { 1 } else { r.u32()? as usize };
        if windows != 1 && windows != 3 {
            return Err(Error::InvalidConfig("weights: FLR windows must be 1 or 3"));
        }
        let mut sigmas = [0f32; 3];
        for s in sigmas.iter_mut().take(windows) {
            *s = r.f32()?;
        }
        let eps = [r.f32()?, r.f32()?];
        if !sigmas[..windows].iter().chain(&eps).all(|v| v.is_finite() && *v > 0.0) {
            return Err(Error::InvalidConfig("weights: FLR parameters must be finite and positive"));
        }
        if sigmas[..windows].windows(2).any(|p| p[0] >= p[1]) {
            return Err(Error::InvalidConfig("weights: FLR window sizes must increase"));
        }
        let ao_offset = if version >= 3 { r.f32()? } else { 0.0 };
        if !(ao_offset.is_finite() && ao_offset >= 0.0) {
            return Err(Error::InvalidConfig("weights: AO demodulation offset must be finite and ≥ 0"));
        }
        let payload_len = r.u32()? as usize;
        let payload = r.take(payload_len.checked_mul(2).ok_or(Error::InvalidConfig("weights: payload length overflows"))?)?;
        if r.pos != blob.len() {
            return Err(Error::InvalidConfig("weights: trailing bytes after the payload"));
        }
        // layer shapes in forward order
        let c = widths;
        let mut shapes = [(0usize, 0usize, 0usize, 0usize); MAX_LAYERS];
        let mut n = 0;
        let mut push = |cin, cout, k, stride| {
            shapes[n] = (cin, cout, k, stride);
            n += 1;
        };
        push(in_ch, c[0], 3, 1);
        push(c[0], c[0], 1, 1);
        for l in 1..=levels {
            push(c[l - 1], c[l], 3, 1);
            push(c[l], c[l], 3, 2);
        }
        for l in (1..=levels).rev() {
            push(c[l] + c[l - 1], c[l - 1], 3, 1);
            push(c[l - 1], c[l - 1], 3, 1);
        }
        push(c[0], c[0], 3, 1);
        push(c[0], out_ch, 1, 1);
        let mut layers = [ConvDesc::EMPTY; MAX_LAYERS];
        let mut off = 0usize;
        for (i, &(cin, cout, k, stride)) in shapes.iter().enumerate().take(n) {
            let len = (cout * cin * k * k + cout) * 2;
            let bytes = payload.get(off..off + len).ok_or(Error::InvalidConfig("weights: payload shorter than the layer shapes"))?;
            off += len;
            layers[i] = ConvDesc { cin, cout, k, stride, params: bytes };
        }
        if off != payload.len() {
            return Err(Error::InvalidConfig("weights: payload longer than the layer shapes"));
        }
        if payload.chunks_exact(2).any(|p| !f16::from_le_bytes([p[0], p[1]]).is_finite()) {
            return Err(Error::InvalidConfig("weights: non-finite weight"));
        }
        Ok(UNet { in_ch, out_ch, levels, widths, sigmas, windows, eps, ao_offset, layers, count: n })
    }

    /// Input channels (1..=128).
    pub fn in_channels(&self) -> usize {
        self.in_ch
    }
    /// Output channels (1..=128).
    pub fn out_channels(&self) -> usize {
        self.out_ch
    }
    /// U-Net levels L (0..=[`MAX_LEVELS`]).
    pub fn levels(&self) -> usize {
        self.levels
    }
    /// Widths `c_0..c_L`.
    pub fn widths(&self) -> &[usize] {
        &self.widths[..=self.levels]
    }
    /// The window sizes σ (pixels) of the FLR trained with the network: one
    /// Gaussian window, or three (the adaptive window).
    pub fn flr_sigmas(&self) -> &[f32] {
        &self.sigmas[..self.windows]
    }
    /// The regularisation trained with the network: ε (multiplicative), ϵ (additive).
    pub fn flr_eps(&self) -> [f32; 2] {
        self.eps
    }
    /// The AO demodulation trained with the network: its offset c, or `None`
    /// (off; always off before version 3).
    pub fn flr_ao_demodulation(&self) -> Option<f32> {
        (self.ao_offset > 0.0).then_some(self.ao_offset)
    }
    /// Number of convolutions.
    pub fn layer_count(&self) -> usize {
        self.count
    }
    pub(crate) fn conv(&self, i: usize) -> Result<ConvDesc<'b>, Error> {
        if i < self.count {
            Ok(self.layers[i])
        } else {
            Err(Error::InvalidTile { index: i, count: self.count })
        }
    }
}
