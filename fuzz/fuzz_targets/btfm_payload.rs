//! Any bytes as the payload of a `.btfm` file with a valid envelope and checksum, so that the
//! fuzzer reaches the payload parser instead of stopping at the CRC: an error or a model whose
//! encoding is a fixed point of write-read-write, never a panic.
//! Run: `scripts/fuzz btfm_payload` (or `cargo fuzz run btfm_payload`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|payload: &[u8]| {
    // Read as version 1 (the seeds' version) and as the current version, whose payload adds
    // the colour tails.
    for version in [1, btfmrf::model::format::VERSION] {
        let mut file = b"BTFM".to_vec();
        file.extend_from_slice(&version.to_le_bytes());
        file.extend_from_slice(&[0, 0]);
        file.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        file.extend_from_slice(payload);
        file.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
        let path = std::path::Path::new("fuzz.btfm");
        if let Ok(model) = btfmrf::model::format::from_bytes(&file, path) {
            // Not the input's length: an older payload is read and written as the current
            // version, and non-canonical values are normalised.
            let bytes = btfmrf::model::format::to_bytes(&model);
            let again = btfmrf::model::format::from_bytes(&bytes, path)
                .expect("what the writer writes, the reader reads");
            assert_eq!(btfmrf::model::format::to_bytes(&again), bytes);
        }
    }
});
