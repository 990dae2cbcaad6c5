//! Any bytes as the payload of a `.btfm` file with a valid envelope and checksum, so that the
//! fuzzer reaches the payload parser instead of stopping at the CRC: an error or a model whose
//! encoding is a fixed point of write-read-write, never a panic.
//! Run: `scripts/fuzz btfm_payload` (or `cargo fuzz run btfm_payload`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|payload: &[u8]| {
    let mut file = b"BTFM\x01\x00\x00\x00".to_vec();
    file.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    file.extend_from_slice(payload);
    file.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    let path = std::path::Path::new("fuzz.btfm");
    if let Ok(model) = btfmrf::model::format::from_bytes(&file, path) {
        // Not the input's length: a version 1 payload is read and written as version 2 (the
        // colour space and band tables added), and non-canonical values are normalised.
        let bytes = btfmrf::model::format::to_bytes(&model);
        let again = btfmrf::model::format::from_bytes(&bytes, path)
            .expect("what the writer writes, the reader reads");
        assert_eq!(btfmrf::model::format::to_bytes(&again), bytes);
    }
});
