//! Reading and writing frames in the layout of `docs/DATA.md`: one
//! multi-layer EXR, channels named `layer.component`, half or float.

use exr::prelude::{read, AnyChannel, AnyChannels, Encoding, FlatSamples, Image, LayerAttributes, ReadChannels, ReadLayers, WritableImage};
use std::collections::BTreeMap;
use std::path::Path;
use std::result::Result;

/// One layer: its component names (e.g. R, G, B) and a plane per component.
#[derive(Clone, Debug)]
pub struct Layer {
    pub comps: Vec<String>,
    pub planes: Vec<Vec<f32>>,
}

impl Layer {
    /// Interleaved copy of the first `n` components (missing ones are 0).
    pub fn interleaved(&self, n: usize) -> Vec<f32> {
        let len = self.planes[0].len();
        let mut out = vec![0f32; len * n];
        for (c, p) in self.planes.iter().take(n).enumerate() {
            for (i, v) in p.iter().enumerate() {
                out[i * n + c] = *v;
            }
        }
        out
    }
}

/// A frame: size and named layers.
#[derive(Clone, Debug)]
pub struct ExrFrame {
    pub width: usize,
    pub height: usize,
    pub layers: BTreeMap<String, Layer>,
}

/// Most samples (pixels × channels, all parts) a frame may declare: 2^28, i.e.
/// 16K×16K with one channel or 8K×4K with 8 channels.
pub const MAX_SAMPLES: usize = 1 << 28;

/// Most bytes of samples a file may declare per byte of file. Deflate (ZIP)
/// cannot exceed ~1032:1, RLE 64:1, PIZ, PXR24 and B44 less; 2^14 leaves a
/// 16× margin (lossy DWA on a nearly flat image is the one case that could
/// come near it). A tiny file declaring hundreds of MB (a corrupt or hostile
/// header) is refused before the decoder allocates them; the fuzz target's
/// inputs (≤ 4 KB) can then declare at most 64 MB.
pub const MAX_EXPANSION: usize = 1 << 14;

const ORDER: [&str; 8] = ["R", "G", "B", "X", "Y", "Z", "A", "W"];

fn comp_rank(c: &str) -> usize {
    ORDER.iter().position(|o| o.eq_ignore_ascii_case(c)).unwrap_or(ORDER.len())
}

impl ExrFrame {
    /// Reads every channel of the first (largest) image part.
    pub fn read(path: &Path) -> Result<Self, String> {
        let name = path.display();
        if !path.exists() {
            return Err(format!("{name}: no such file"));
        }
        let bytes = std::fs::read(path).map_err(|e| format!("{name}: {e}"))?;
        Self::read_bytes(&bytes, &name.to_string())
    }

    /// Reads a frame from EXR bytes; `name` is used in error messages.
    pub fn read_bytes(bytes: &[u8], name: &str) -> Result<Self, String> {
        // Headers first: refuse absurd declared sizes before any pixel memory is
        // allocated (a corrupt or hostile header must not exhaust memory).
        let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
            .map_err(|e| format!("{name}: not a readable OpenEXR file ({e})"))?;
        let mut declared_bytes = 0usize;
        for h in meta.headers.iter() {
            let samples = h.layer_size.0.checked_mul(h.layer_size.1).and_then(|n| n.checked_mul(h.channels.list.len().max(1)));
            if samples.is_none_or(|n| n > MAX_SAMPLES) {
                return Err(format!(
                    "{name}: declared image too large ({}x{} with {} channels)",
                    h.layer_size.0,
                    h.layer_size.1,
                    h.channels.list.len()
                ));
            }
            let pixels = h.layer_size.0 * h.layer_size.1;
            for c in h.channels.list.iter() {
                declared_bytes = declared_bytes.saturating_add(pixels.saturating_mul(c.sample_type.bytes_per_sample()));
            }
        }
        if declared_bytes > bytes.len().saturating_mul(MAX_EXPANSION).max(1 << 20) {
            return Err(format!(
                "{name}: the header declares {declared_bytes} bytes of samples, more than a {}-byte file can hold",
                bytes.len()
            ));
        }
        let img = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            .map_err(|e| format!("{name}: not a readable OpenEXR file ({e})"))?;
        let mut layers: BTreeMap<String, Layer> = BTreeMap::new();
        let (mut width, mut height) = (0, 0);
        for (li, part) in img.layer_data.iter().enumerate() {
            let size = part.size;
            if size.0.checked_mul(size.1).is_none_or(|n| n > 1 << 28) {
                return Err(format!("{name}: image too large ({}x{})", size.0, size.1));
            }
            if li == 0 {
                width = size.0;
                height = size.1;
            } else if (size.0, size.1) != (width, height) {
                return Err(format!("{name}: image parts have different sizes"));
            }
            let prefix = part.attributes.layer_name.as_ref().map(|t| t.to_string());
            for ch in &part.channel_data.list {
                let full = ch.name.to_string();
                let full = match &prefix {
                    Some(p) if !full.contains('.') => format!("{p}.{full}"),
                    _ => full,
                };
                let (layer, comp) = match full.rsplit_once('.') {
                    Some((l, c)) => (l.to_string(), c.to_string()),
                    None => (String::new(), full.clone()), // un-layered RGB: the "" layer
                };
                let plane: Vec<f32> = ch.sample_data.values_as_f32().collect();
                if plane.len() != width * height {
                    return Err(format!("{name}: channel '{full}' has {} samples, expected {}", plane.len(), width * height));
                }
                let e = layers.entry(layer).or_insert(Layer { comps: vec![], planes: vec![] });
                e.comps.push(comp);
                e.planes.push(plane);
            }
        }
        for l in layers.values_mut() {
            let mut idx: Vec<usize> = (0..l.comps.len()).collect();
            idx.sort_by_key(|&i| (comp_rank(&l.comps[i]), l.comps[i].clone()));
            l.comps = idx.iter().map(|&i| l.comps[i].clone()).collect();
            l.planes = idx.iter().map(|&i| std::mem::take(&mut l.planes[i])).collect();
        }
        if width == 0 || height == 0 {
            return Err(format!("{name}: empty image"));
        }
        Ok(ExrFrame { width, height, layers })
    }

    /// The layer, checked to have at least `comps` components.
    pub fn layer(&self, name: &str, comps: usize, file: &Path) -> Result<&Layer, String> {
        let l = self.layers.get(name).ok_or_else(|| {
            let have: Vec<&str> = self.layers.keys().map(|s| s.as_str()).collect();
            format!("{}: missing layer '{name}' (has: {})", file.display(), have.join(", "))
        })?;
        if l.planes.len() < comps {
            return Err(format!("{}: layer '{name}' has {} channels, needs {comps}", file.display(), l.planes.len()));
        }
        Ok(l)
    }

    pub fn has(&self, name: &str) -> bool {
        self.layers.contains_key(name)
    }

    /// Writes the given layers (half floats, except `position`, `depth`,
    /// `motion`, `denoised` and `noisy`, which stay f32: the injected outliers
    /// of the robustness protocol can exceed half's range of 65504), ZIP compressed.
    pub fn write(path: &Path, width: usize, height: usize, layers: &[(&str, &Layer)]) -> Result<(), String> {
        let mut chans: Vec<AnyChannel<FlatSamples>> = vec![];
        for (lname, l) in layers {
            let full = matches!(*lname, "position" | "depth" | "denoised" | "motion" | "noisy");
            for (c, p) in l.comps.iter().zip(&l.planes) {
                let name = if lname.is_empty() { c.clone() } else { format!("{lname}.{c}") };
                let samples =
                    if full { FlatSamples::F32(p.clone()) } else { FlatSamples::F16(p.iter().map(|v| half::f16::from_f32(*v)).collect()) };
                chans.push(AnyChannel::new(name.as_str(), samples));
            }
        }
        let channels = AnyChannels::sort(chans.into());
        let layer = exr::image::Layer::new((width, height), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, channels);
        let img = Image::from_layer(layer);
        img.write().to_file(path).map_err(|e| format!("{}: cannot write ({e})", path.display()))
    }
}
