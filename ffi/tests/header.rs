//! The committed header must be what cbindgen generates from the crate's
//! source (every module of `ffi/src/`).
//! `LRD_BLESS=1 cargo test -p lrdenoise-ffi --test header` rewrites it.

#[test]
fn header_is_current() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let cfg = cbindgen::Config::from_file(format!("{dir}/cbindgen.toml")).expect("cbindgen.toml");
    let mut out = Vec::new();
    cbindgen::Builder::new().with_config(cfg).with_crate(dir).generate().expect("cbindgen failed").write(&mut out);
    let generated = String::from_utf8(out).unwrap();
    let path = format!("{dir}/include/lrdenoise.h");
    if std::env::var("LRD_BLESS").is_ok() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(committed == generated, "ffi/include/lrdenoise.h is out of date: run LRD_BLESS=1 cargo test -p lrdenoise-ffi --test header");
}
