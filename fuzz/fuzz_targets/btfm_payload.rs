//! Any bytes as the payload of a `.btfm` file with a valid envelope and checksum, so that the
//! fuzzer reaches the payload parser instead of stopping at the CRC.
//! Run: `cargo +nightly fuzz run btfm_payload`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|payload: &[u8]| {
    let mut file = b"BTFM\x01\x00\x00\x00".to_vec();
    file.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    file.extend_from_slice(payload);
    file.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    if let Ok(model) = btfmrf::model::format::from_bytes(&file, std::path::Path::new("fuzz.btfm")) {
        assert_eq!(btfmrf::model::format::to_bytes(&model).len(), file.len());
    }
});
