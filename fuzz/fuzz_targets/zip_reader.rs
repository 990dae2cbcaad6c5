//! Any bytes as a BTF zip archive: opening it (names, layout, image headers) and decoding its
//! first image give an error or a result, never a panic, a hang or a huge allocation.
//! Run: `scripts/fuzz zip_reader` (or `cargo fuzz run zip_reader`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir_in(std::env::var_os("BTFMRF_FUZZ_TMP").unwrap_or("/tmp".into()))
        .expect("a temporary folder");
    let path = dir.path().join("fuzz.zip");
    std::fs::write(&path, data).expect("written");
    if let Ok(btf) = btfmrf::btf::Btf::open(&path) {
        assert_eq!(btf.image_count(), btf.views().len() * btf.lights().len());
        let _ = btf.image(0, 0);
    }
});
