//! WALR (defaults, f32 and f16 storage) on `benches/walr.rs`'s 1920×1080 room,
//! one thread, median of 5 runs, with an output checksum.
use depbench::{checksum, time_runs};
use lrdenoise::walr::{Storage, Walr, WalrConfig};
use lrdenoise::*;
#[path = "../../../../benches/common/room.rs"]
mod room;
use room::room;

fn main() {
    let (w, h) = (1920, 1080);
    let (noisy, normal, position, depth) = room(w, h);
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        depth: Some(ImageView::interleaved(&depth, w, h, 1).unwrap()),
        position: Some(ImageView::interleaved(&position, w, h, 3).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mut out = vec![0f32; 3 * w * h];
    for (name, cfg) in [("f32", WalrConfig::default()), ("f16", WalrConfig { storage: Storage::F16, ..Default::default() })] {
        let wl = Walr::new(cfg, w, h).unwrap();
        let mut scratch = vec![0f32; wl.scratch_len()];
        let (median, _) = time_runs(5, || {
            let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
            wl.denoise(&frame, 1, &mut scratch, &mut ov).unwrap();
        });
        println!("walr {name}: median {median:.1} ms  checksum {}", checksum(&out));
    }
}
