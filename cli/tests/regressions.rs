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
