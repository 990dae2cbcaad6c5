//! Any bytes as a `.btfm` model file: an error or a model, never a panic or a huge allocation.
//! Run: `cargo +nightly fuzz run btfm` (from the repository root).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(model) = btfmrf::model::format::from_bytes(data, std::path::Path::new("fuzz.btfm")) {
        // What parses re-encodes to a fixed point: written, read and written again, the same
        // bytes. (Not the input's bytes: older versions and non-canonical angles are accepted
        // and written in today's canonical form.)
        let bytes = btfmrf::model::format::to_bytes(&model);
        let again = btfmrf::model::format::from_bytes(&bytes, std::path::Path::new("fuzz.btfm"))
            .expect("what the writer writes, the reader reads");
        assert_eq!(btfmrf::model::format::to_bytes(&again), bytes);
    }
});
