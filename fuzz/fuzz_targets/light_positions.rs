//! Any text as an RTI `.lp` light-position file: an error or a parse, never a panic.
//! Run: `cargo +nightly fuzz run light_positions`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(lp) = btfmrf::btf::io::rti::parse_lp(&text, std::path::Path::new("fuzz.lp")) {
        assert_eq!(lp.images.len(), lp.directions.len());
        assert!(
            lp.directions
                .iter()
                .all(|d| d.iter().all(|c| c.is_finite()))
        );
    }
});
