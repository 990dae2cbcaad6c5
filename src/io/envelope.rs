//! The envelope shared by the model files (`.btfm`, `.lpca`): magic, version, flags, payload
//! length, payload, CRC-32 of the payload, all little-endian (docs/FORMAT.md). Written by
//! [`seal`] and checked by [`open`] once, before any payload is parsed. The flags field must be
//! zero: no flag is defined in version 1.

/// Bytes the envelope adds around a payload: 12 before it, 4 after.
pub const OVERHEAD: usize = 16;

/// A whole file: the header (`magic`, `version`, no flags, the payload length), the payload
/// and its CRC-32. A payload of 4 GiB or more is marked with the length `u32::MAX`, which no
/// reader's limit admits, rather than a wrapped length.
pub fn seal(magic: [u8; 4], version: u16, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + OVERHEAD);
    out.extend_from_slice(&magic);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    let len = u32::try_from(payload.len()).unwrap_or(u32::MAX);
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(payload);
    out.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    out
}

/// The payload of `bytes` after checking the envelope; the error says what is wrong (`ext`
/// names the file kind in messages, e.g. ".btfm").
pub fn open<'a>(
    bytes: &'a [u8],
    magic: [u8; 4],
    ext: &str,
    version: u16,
    max_payload: u32,
) -> Result<&'a [u8], String> {
    open_versions(bytes, magic, ext, version..=version, max_payload).map(|(_, p)| p)
}

/// [`open`] for a reader of several format versions: the version found and the payload.
pub fn open_versions<'a>(
    bytes: &'a [u8],
    magic: [u8; 4],
    ext: &str,
    versions: std::ops::RangeInclusive<u16>,
    max_payload: u32,
) -> Result<(u16, &'a [u8]), String> {
    if bytes.len() < 4 {
        return Err(format!("not a {ext} model (too short)"));
    }
    if bytes[..4] != magic {
        return Err(format!("not a {ext} model (wrong magic bytes)"));
    }
    let field = |at: usize, n: usize| -> Result<&'a [u8], String> {
        bytes
            .get(at..at + n)
            .ok_or_else(|| format!("truncated at byte {at} (wanted {n} more)"))
    };
    let found = u16::from_le_bytes(field(4, 2)?.try_into().expect("2 bytes"));
    if !versions.contains(&found) {
        let known = if versions.start() == versions.end() {
            format!("version {}", versions.start())
        } else {
            format!("versions {}-{}", versions.start(), versions.end())
        };
        return Err(format!("format version {found}; this build reads {known}"));
    }
    // No flag is defined yet: a file with any set was written by a later version whose
    // meaning this build cannot know, so it is refused rather than misread.
    let flags = u16::from_le_bytes(field(6, 2)?.try_into().expect("2 bytes"));
    if flags != 0 {
        return Err(format!(
            "unknown flags {flags:#06x} in the header (written by a newer version?)"
        ));
    }
    let len = u32::from_le_bytes(field(8, 4)?.try_into().expect("4 bytes"));
    if len > max_payload {
        return Err(format!(
            "payload of {len} bytes exceeds the {max_payload}-byte limit"
        ));
    }
    let payload = field(12, len as usize)?;
    let crc = u32::from_le_bytes(field(12 + len as usize, 4)?.try_into().expect("4 bytes"));
    if crc != crc32fast::hash(payload) {
        return Err("checksum mismatch: the file is corrupt".into());
    }
    let end = 16 + len as usize;
    if bytes.len() != end {
        return Err(format!(
            "{} unexpected bytes after the checksum",
            bytes.len() - end
        ));
    }
    Ok((found, payload))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sealed_payloads_open_and_damage_is_named() {
        let file = seal(*b"TEST", 3, b"payload");
        assert_eq!(file.len(), 7 + OVERHEAD);
        assert_eq!(open(&file, *b"TEST", ".test", 3, 64).unwrap(), b"payload");
        assert_eq!(
            open_versions(&file, *b"TEST", ".test", 1..=3, 64).unwrap(),
            (3, &b"payload"[..])
        );
        let err = |bytes: &[u8]| open(bytes, *b"TEST", ".test", 3, 64).unwrap_err();
        assert!(err(&file[..3]).contains("too short"));
        assert!(err(b"NOPE\x03\x00").contains("magic"));
        assert!(
            open(&file, *b"TEST", ".test", 2, 64)
                .unwrap_err()
                .contains("version 2")
        );
        assert!(
            open(&file, *b"TEST", ".test", 3, 6)
                .unwrap_err()
                .contains("limit")
        );
        let mut flipped = file.clone();
        flipped[14] ^= 1;
        assert!(err(&flipped).contains("checksum"));
        let mut flagged = file.clone();
        flagged[6] = 1;
        assert!(err(&flagged).contains("flags"));
        let mut long = file.clone();
        long.push(0);
        assert!(err(&long).contains("unexpected"));
        assert!(err(&file[..file.len() - 1]).contains("truncated"));
    }
}
