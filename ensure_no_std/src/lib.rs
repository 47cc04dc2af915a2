#![no_std]

use lrdenoise::{Flr, FlrConfig, Frame, GuideSet, Guides, ImageView, ImageViewMut};

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {}
}

/// Denoises a 16×16 constant frame into `out` using `scratch`; returns 0 on success.
#[no_mangle]
pub extern "C" fn ensure_no_std_denoise(out: &mut [f32; 768], scratch: &mut [f64; 65536]) -> i32 {
    static NOISY: [f32; 768] = [0.5; 768];
    static DEPTH: [f32; 256] = [1.0; 256];
    let Ok(flr) = Flr::new(FlrConfig::with_guides(GuideSet { depth: true, ..GuideSet::NONE }), 16, 16) else { return 1 };
    let (Ok(n), Ok(d)) = (ImageView::interleaved(&NOISY, 16, 16, 3), ImageView::interleaved(&DEPTH, 16, 16, 1)) else { return 2 };
    let frame = Frame::new(n, Guides { depth: Some(d), ..Default::default() });
    let Ok(mut o) = ImageViewMut::interleaved(out, 16, 16, 3) else { return 3 };
    match flr.denoise(&frame, scratch, &mut o) {
        Ok(_) => 0,
        Err(_) => 4,
    }
}
