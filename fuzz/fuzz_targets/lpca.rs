//! Any bytes as the payload of a `.lpca` file with a valid envelope and checksum (so that the
//! fuzzer reaches the payload parser): an error or a model whose encoding is a fixed point of
//! write-read-write, never a panic or an allocation beyond a small multiple of the input.
//! Run: `scripts/fuzz lpca` (or `cargo fuzz run lpca`).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|payload: &[u8]| {
    let mut file = b"LPCA\x01\x00\x00\x00".to_vec();
    file.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    file.extend_from_slice(payload);
    file.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    if let Ok(model) = btfmrf::lpca::format::from_bytes(&file, std::path::Path::new("fuzz.lpca")) {
        // Not the input's bytes: non-canonical direction angles are accepted and normalised.
        let bytes = btfmrf::lpca::format::to_bytes(&model);
        let again = btfmrf::lpca::format::from_bytes(&bytes, std::path::Path::new("fuzz.lpca"))
            .expect("what the writer writes, the reader reads");
        assert_eq!(btfmrf::lpca::format::to_bytes(&again), bytes);
    }
});
