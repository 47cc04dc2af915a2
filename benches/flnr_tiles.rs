//! FLNR's network in tiles: scratch and time per tile size at a frame size.
//!
//! `cargo bench --bench flnr_tiles [-- WIDTH HEIGHT [RUNS]]` (default
//! 1920 1080 3): for tiles of 128, 256, 384, 512, 768 px and the whole frame, the
//! scratch [`Flnr::scratch_len`] asks for and the median time of `RUNS`
//! denoises on one thread.

use lrdenoise::flnr::Flnr;
use lrdenoise::*;
use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let (w, h) = (args.first().copied().unwrap_or(1920), args.get(1).copied().unwrap_or(1080));
    let runs = args.get(2).copied().unwrap_or(3).max(1);
    let n = w * h;
    let blob = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/train/flnr.bin")).expect("train/flnr.bin");
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| (((i / 3) / 97) % 7) as f32 * 0.1 - 0.3).collect();
    let depth: Vec<f32> = (0..n).map(|i| 1.0 + (i % w) as f32 * 1e-2).collect();
    let ao: Vec<f32> = (0..n).map(|i| ((i / w) % 13) as f32 / 13.0).collect();
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
        ao: Some(ImageView::interleaved(&ao, w, h, 1).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mut out = vec![0f32; 3 * n];
    let mut first: Option<Vec<f32>> = None;
    for tile in [128, 256, 384, 512, 768, usize::MAX] {
        let fl = Flnr::new(FlnrConfig { tile, ..FlnrConfig::new(&blob) }, w, h).unwrap();
        let mut scratch = vec![0f32; fl.scratch_len()];
        let mut fs = vec![0f64; fl.flr_scratch_len()];
        let mut times = Vec::new();
        for _ in 0..runs {
            let t = Instant::now();
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            fl.denoise(&frame, &mut scratch, &mut fs, &mut ov).unwrap();
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        let same = first.get_or_insert_with(|| out.clone()).iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits());
        let (nx, ny) = fl.tile_grid();
        let guides = fl.network().out_channels() * n; // the 2·Q' learned guide planes
        println!(
            "{w}x{h} tile {:>5}: {nx}x{ny} tiles, scratch {:.1} M f32 ({:.1} M of them the guide planes), median {:.0} ms, same output as tile 128: {same}",
            if tile == usize::MAX { "frame".to_string() } else { tile.to_string() },
            fl.scratch_len() as f64 / 1e6,
            guides as f64 / 1e6,
            times[times.len() / 2]
        );
    }
}
