//! Image strips: per frame, the images and their FLIP error maps side by side,
//! each panel captioned.

use super::plot::err;
use super::register_font;
use crate::evaluate::{FrameImages, Panel};
use plotters::prelude::*;
use std::path::Path;

fn magma(v: f32) -> [u8; 3] {
    // a short piecewise-linear magma-like ramp
    let stops = [(0.0, [0, 0, 4]), (0.25, [81, 18, 124]), (0.5, [183, 55, 121]), (0.75, [252, 137, 97]), (1.0, [252, 253, 191])];
    let v = v.clamp(0.0, 1.0);
    for w in stops.windows(2) {
        let ((a, ca), (b, cb)) = (w[0], w[1]);
        if v <= b {
            let t = (v - a) / (b - a);
            return [0, 1, 2].map(|i| (ca[i] as f32 + t * (cb[i] as f32 - ca[i] as f32)) as u8);
        }
    }
    [252, 253, 191]
}

/// Height of the caption band above the images and above the FLIP maps.
const TOP_BAND: u32 = 50;
const MID_BAND: u32 = 22;

/// One PNG per frame: the images (tone mapped) with a caption band above
/// (configuration, PSNR), then their FLIP error maps (caption: mean FLIP);
/// the last column is the reference, with the FLIP colour scale under it.
/// `keep`: the configurations to show (every one when `None`), in the order
/// given.
pub fn strips(dir: &Path, frames: &[FrameImages], keep: Option<&[String]>) -> Result<Vec<String>, String> {
    register_font();
    let mut names = vec![];
    for f in frames {
        let shown: Vec<&Panel> = match keep {
            Some(k) => k.iter().filter_map(|c| f.rows.iter().find(|p| &p.config == c)).collect(),
            None => f.rows.iter().collect(),
        };
        let cols = shown.len() as u32 + 1;
        let (w, h) = (f.w as u32, f.h as u32);
        let (width, height) = (w * cols, TOP_BAND + h + MID_BAND + h);
        let mut img = image::RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
        let mut put = |col: u32, top: u32, rgb: &dyn Fn(usize) -> [u8; 3]| {
            for y in 0..h {
                for x in 0..w {
                    img.put_pixel(col * w + x, top + y, image::Rgb(rgb((y * w + x) as usize)));
                }
            }
        };
        let to8 = |v: &[f32], i: usize| [0, 1, 2].map(|k| (v[3 * i + k].clamp(0.0, 1.0) * 255.0).round() as u8);
        for (c, p) in shown.iter().enumerate() {
            put(c as u32, TOP_BAND, &|i| to8(&p.tm, i));
            put(c as u32, TOP_BAND + h + MID_BAND, &|i| magma(p.fmap[i]));
        }
        put(cols - 1, TOP_BAND, &|i| to8(&f.reference_tm, i));
        let mut raw = img.into_raw();
        {
            let area = BitMapBackend::with_buffer(&mut raw, (width, height)).into_drawing_area();
            let big = ("sans-serif", 14).into_font();
            let small = ("sans-serif", 12).into_font().color(&RGBColor(70, 70, 70));
            let text =
                |s: &str, x: u32, y: u32, font: &TextStyle| area.draw(&Text::new(s.to_string(), (x as i32 + 6, y as i32), font.clone()));
            for (c, p) in shown.iter().enumerate() {
                let x = c as u32 * w;
                let (method, rest) = p.config.split_once(' ').unwrap_or((p.config.as_str(), ""));
                text(method, x, 4, &big.clone().into()).map_err(err)?;
                text(rest, x, 20, &small.clone()).map_err(err)?;
                let q = if p.method == "noisy" { format!("PSNR {:.2} dB (the input)", p.psnr) } else { format!("PSNR {:.2} dB", p.psnr) };
                text(&q, x, 34, &small.clone()).map_err(err)?;
                text(&format!("FLIP {:.3}", p.flip), x, TOP_BAND + h + 4, &small.clone()).map_err(err)?;
            }
            let x = (cols - 1) * w;
            text("reference", x, 4, &big.clone().into()).map_err(err)?;
            text(&f.frame, x, 20, &small.clone()).map_err(err)?;
            text("FLIP error scale", x, TOP_BAND + h + 4, &small.clone()).map_err(err)?;
            // the colour scale of the FLIP maps, 0 (left) to 1 (right)
            let (bx, by, bw, bh) = (x + 16, TOP_BAND + h + MID_BAND + h / 3, w.saturating_sub(32).max(2), 24u32);
            for i in 0..bw {
                let [r, g, b] = magma(i as f32 / (bw - 1) as f32);
                let x0 = bx as i32 + i as i32;
                area.draw(&Rectangle::new([(x0, by as i32), (x0 + 1, (by + bh) as i32)], RGBColor(r, g, b).filled())).map_err(err)?;
            }
            text("0", bx - 6, by + bh + 4, &small.clone()).map_err(err)?;
            text("1", bx + bw - 10, by + bh + 4, &small.clone()).map_err(err)?;
            text("no error → large error", bx - 6, by + bh + 20, &small.clone()).map_err(err)?;
            area.present().map_err(err)?;
        }
        let img = image::RgbImage::from_raw(width, height, raw).ok_or("strip: bad buffer size")?;
        let name = format!("strip_{}.png", f.frame);
        img.save(dir.join(&name)).map_err(|e| format!("{}: {e}", dir.join(&name).display()))?;
        names.push(name);
    }
    Ok(names)
}
