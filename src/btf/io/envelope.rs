//! The envelope shared by the model files (`.btfm`, `.lpca`): magic, version, flags, payload
//! length, payload, CRC-32 of the payload. Checked here once, before any payload is parsed.
//! The flags field must be zero: no flag is defined in version 1.

/// The payload of `bytes` after checking the envelope; the error says what is wrong (`ext`
/// names the file kind in messages, e.g. ".btfm").
pub(crate) fn open<'a>(
    bytes: &'a [u8],
    magic: [u8; 4],
    ext: &str,
    version: u16,
    max_payload: u32,
) -> Result<&'a [u8], String> {
    open_versions(bytes, magic, ext, version..=version, max_payload).map(|(_, p)| p)
}

/// [`open`] for a reader of several format versions: the version found and the payload.
pub(crate) fn open_versions<'a>(
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
