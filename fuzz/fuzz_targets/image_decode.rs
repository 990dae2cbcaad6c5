//! Any bytes as an image file (PNG, JPEG, EXR): an error or an image, never a panic.
//! Run: `cargo +nightly fuzz run image_decode`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = btfmrf::btf::io::picture::probe_size(data, "fuzz");
    let _ = btfmrf::btf::io::picture::decode(data, "fuzz");
});
