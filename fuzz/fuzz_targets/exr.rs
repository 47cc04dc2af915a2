//! (d) EXR reading in the CLI: arbitrary bytes never panic; a frame that reads
//! has consistent layer sizes.
#![no_main]
use libfuzzer_sys::fuzz_target;
use lrdenoise_cli::exrio::ExrFrame;

fuzz_target!(|d: &[u8]| {
    if let Ok(f) = ExrFrame::read_bytes(d, "fuzz.exr") {
        for l in f.layers.values() {
            assert_eq!(l.comps.len(), l.planes.len());
            for p in &l.planes {
                assert_eq!(p.len(), f.width * f.height);
            }
        }
    }
});
