//! The envelope shared by the model files (`.btfm`, `.lpca`): magic, version, flags, payload
//! length, payload, CRC-32 of the payload, all little-endian (docs/FORMAT.md). Written by
//! [`seal`] or [`seal_deflated`] and checked by [`open`] once, before any payload is parsed.
//! One flag is defined, [`DEFLATED`]: the stored payload is a raw deflate stream of the
//! payload the parsers read; any other set flag is refused.

use std::borrow::Cow;
use std::io::{Read, Write};

/// Bytes the envelope adds around a payload: 12 before it, 4 after.
pub const OVERHEAD: usize = 16;

/// The flag saying that the stored payload is deflated (RFC 1951); its checksum is that of
/// the stored bytes.
pub const DEFLATED: u16 = 1;

/// A whole file: the header (`magic`, `version`, no flags, the payload length), the payload
/// and its CRC-32. A payload of 4 GiB or more is marked with the length `u32::MAX`, which no
/// reader's limit admits, rather than a wrapped length.
pub fn seal(magic: [u8; 4], version: u16, payload: &[u8]) -> Vec<u8> {
    sealed(magic, version, 0, payload)
}

/// [`seal`] of `payload` deflated at the best compression, with the [`DEFLATED`] flag.
pub fn seal_deflated(magic: [u8; 4], version: u16, payload: &[u8]) -> Vec<u8> {
    let mut encoder = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
    encoder
        .write_all(payload)
        .and_then(|()| encoder.finish())
        .map(|deflated| sealed(magic, version, DEFLATED, &deflated))
        .expect("deflating into memory cannot fail")
}

fn sealed(magic: [u8; 4], version: u16, flags: u16, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + OVERHEAD);
    out.extend_from_slice(&magic);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&flags.to_le_bytes());
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
) -> Result<Cow<'a, [u8]>, String> {
    open_versions(bytes, magic, ext, version..=version, max_payload).map(|(_, p)| p)
}

/// [`open`] for a reader of several format versions: the version found and the payload
/// (inflated when the file is [`DEFLATED`], to at most `max_payload` bytes).
pub fn open_versions<'a>(
    bytes: &'a [u8],
    magic: [u8; 4],
    ext: &str,
    versions: std::ops::RangeInclusive<u16>,
    max_payload: u32,
) -> Result<(u16, Cow<'a, [u8]>), String> {
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
    // A file with a flag this build does not know was written by a later version whose
    // meaning it cannot know, so it is refused rather than misread.
    let flags = u16::from_le_bytes(field(6, 2)?.try_into().expect("2 bytes"));
    if flags & !DEFLATED != 0 {
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
    if flags & DEFLATED == 0 {
        return Ok((found, Cow::Borrowed(payload)));
    }
    // Inflated into memory that grows with what the stream really holds, never beyond the
    // limit (a small stream that claims to expand to gigabytes stops there).
    let mut inflated = Vec::new();
    flate2::read::DeflateDecoder::new(payload)
        .take(u64::from(max_payload) + 1)
        .read_to_end(&mut inflated)
        .map_err(|e| format!("the deflated payload is corrupt ({e})"))?;
    if inflated.len() > max_payload as usize {
        return Err(format!(
            "the deflated payload inflates beyond the {max_payload}-byte limit"
        ));
    }
    Ok((found, Cow::Owned(inflated)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sealed_payloads_open_and_damage_is_named() {
        let file = seal(*b"TEST", 3, b"payload");
        assert_eq!(file.len(), 7 + OVERHEAD);
        assert_eq!(&*open(&file, *b"TEST", ".test", 3, 64).unwrap(), b"payload");
        let (version, payload) = open_versions(&file, *b"TEST", ".test", 1..=3, 64).unwrap();
        assert_eq!((version, &*payload), (3, &b"payload"[..]));
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
        flagged[6] = 2;
        assert!(err(&flagged).contains("flags"));
        // The deflate flag on a payload that is not a deflate stream.
        flagged[6] = 1;
        assert!(err(&flagged).contains("corrupt"), "{}", err(&flagged));
        let mut long = file.clone();
        long.push(0);
        assert!(err(&long).contains("unexpected"));
        assert!(err(&file[..file.len() - 1]).contains("truncated"));
    }

    #[test]
    fn deflated_payloads_open_to_the_same_bytes_within_the_limit() {
        let payload: Vec<u8> = (0..5000u32).map(|i| (i % 7) as u8).collect();
        let file = seal_deflated(*b"TEST", 3, &payload);
        assert!(file.len() < payload.len() / 4, "{} bytes", file.len());
        assert_eq!(
            &*open(&file, *b"TEST", ".test", 3, 5000).unwrap(),
            &payload[..]
        );
        // A stream that inflates beyond the reader's limit stops at the limit.
        let e = open(&file, *b"TEST", ".test", 3, 4999).unwrap_err();
        assert!(e.contains("beyond the 4999-byte limit"), "{e}");
        // A damaged stream with a matching checksum is named as such.
        let mut broken = file[..OVERHEAD - 4 + 20].to_vec();
        broken[8..12].copy_from_slice(&8u32.to_le_bytes());
        let stream = broken[12..20].to_vec();
        broken.truncate(20);
        broken.extend_from_slice(&crc32fast::hash(&stream).to_le_bytes());
        let e = open(&broken, *b"TEST", ".test", 3, 5000).unwrap_err();
        assert!(e.contains("corrupt"), "{e}");
    }
}
