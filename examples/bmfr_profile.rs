//! Runs the 1080p BMFR fit (or, with `temporal`, the pipeline) in a loop for profiling.
use lrdenoise::*;
fn main() {
    let temporal = std::env::args().any(|a| a == "temporal");
    let (w, h) = (1920, 1080);
    let n = w * h;
    let noisy: Vec<f32> = (0..3 * n).map(|i| ((i * 7919) % 1000) as f32 / 1000.0).collect();
    let normal: Vec<f32> = (0..3 * n).map(|i| (((i / 3) / 97) % 7) as f32 * 0.1 - 0.3).collect();
    let position: Vec<f32> = (0..3 * n).map(|i| ((i / 3) % w) as f32 * 1e-2 + (i % 3) as f32 + ((i / 3 / w) as f32 * 1e-2)).collect();
    let motion = vec![0.25f32; 2 * n];
    let set = GuideSet { normal: true, position: true, ..GuideSet::NONE };
    let guides = Guides {
        normal: Some(ImageView::interleaved(&normal, w, h, 3).unwrap()),
        position: Some(ImageView::interleaved(&position, w, h, 3).unwrap()),
        ..Default::default()
    };
    let frame = Frame::new(ImageView::interleaved(&noisy, w, h, 3).unwrap(), guides);
    let mv = ImageView::interleaved(&motion, w, h, 2).unwrap();
    let b = Bmfr::new(BmfrConfig::with_guides(set), w, h).unwrap();
    let mut out = vec![0f32; 3 * n];
    let mut scratch = vec![0f32; b.temporal_scratch_len()];
    let mut hist = vec![0f32; b.history_len()];
    let mut history = History::new(&mut hist);
    for i in 0..10 {
        let t = std::time::Instant::now();
        let mut ov = ImageViewMut::interleaved(&mut out, w, h, 3).unwrap();
        if temporal {
            b.denoise_temporal(&frame, Some(&mv), &mut history, &mut scratch, &mut ov).unwrap();
        } else {
            b.denoise(&frame, i, &mut scratch, &mut ov).unwrap();
        }
        eprintln!("{:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    }
}
