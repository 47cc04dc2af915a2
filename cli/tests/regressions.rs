//! Inputs that once crashed a fuzz target (`fuzz/`): each must now give a clean error.

#[test]
fn fuzz_regressions_read_cleanly() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/regressions");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        let bytes = std::fs::read(&p).unwrap();
        let r = lrdenoise_cli::exrio::ExrFrame::read_bytes(&bytes, &p.display().to_string());
        assert!(r.is_err(), "{}: expected a clean error", p.display());
        n += 1;
    }
    assert!(n >= 1);
}

/// A 722-byte file whose header declares ~400 MB of samples (it made the
/// decoder allocate them and the fuzz run exceed its memory limit) is refused
/// from its header, before any sample memory is allocated.
#[test]
fn tiny_file_declaring_a_huge_image_is_refused_early() {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/regressions/exr_tiny_file_huge_window.exr");
    let bytes = std::fs::read(&p).unwrap();
    let e = lrdenoise_cli::exrio::ExrFrame::read_bytes(&bytes, "tiny.exr").unwrap_err();
    assert!(e.contains("bytes of samples"), "{e}");
}
