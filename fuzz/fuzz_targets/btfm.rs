//! Any bytes as a `.btfm` model file: an error or a model, never a panic or a huge allocation.
//! Run: `cargo +nightly fuzz run btfm` (from the repository root).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(model) = btfmrf::model::format::from_bytes(data, std::path::Path::new("fuzz.btfm")) {
        // A model that parses must also serialise back to the same bytes.
        assert_eq!(btfmrf::model::format::to_bytes(&model), data);
    }
});
