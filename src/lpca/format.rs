//! The `.lpca` model file: versioned, checksummed, little-endian, decoded with bounded
//! allocations. The layout is documented byte by byte in `docs/FORMAT.md` ("The .lpca model
//! file").
//!
//! Every array is IEEE half precision (the paper's 16-bit floats, section 4.2), so a model of
//! 128 x 128 Bonn data with K = 32, C = 8 is about 11 MB.

use std::path::Path;

use half::f16;

use super::cluster::Factorization;
use super::data::Layout;
use super::error::{LpcaError, Result};
use super::{LpcaModel, Method};
use crate::btf::DirectionSet;
use crate::io::bytes::{Parse, Reader};
use crate::io::envelope;

/// The four bytes every `.lpca` file starts with.
pub const MAGIC: [u8; 4] = *b"LPCA";
/// The format version this library writes and reads.
pub const VERSION: u16 = 1;
/// The largest payload accepted, bytes.
pub const MAX_PAYLOAD: u32 = 1 << 30;
/// The largest width or height accepted, texels.
pub const MAX_SIDE: u32 = 16384;

fn method_code(m: Method) -> u8 {
    match m {
        Method::Lpca => 0,
        Method::PcaBtf => 1,
        Method::PcaRf => 2,
    }
}

/// The payload length, bytes, of a model of this shape with `clusters` clusters per
/// factorization (saturating; compare with [`MAX_PAYLOAD`]).
pub fn payload_len(
    method: Method,
    width: usize,
    height: usize,
    views: usize,
    lights: usize,
    clusters: usize,
    components: usize,
) -> u64 {
    let layout = Layout::of(method, width, height, views, lights);
    let [count, rows, dim, k, c] =
        [layout.parts, layout.rows, layout.dim, clusters, components].map(|v| v as u64);
    let indices = if k > 1 { 2 * rows } else { 0 };
    let part = 2 + 2 * k.saturating_mul(c + 1).saturating_mul(dim) + indices + 2 * rows * c;
    1 + 4 + 4 + 2 + 2 + 8 * views as u64 + 2 + 8 * lights as u64 + count.saturating_mul(part)
}

/// Serialises a model (header, payload, CRC-32 of the payload).
pub fn to_bytes(model: &LpcaModel) -> Vec<u8> {
    let mut p = Vec::new();
    p.push(method_code(model.method()));
    p.extend_from_slice(&(model.width() as u32).to_le_bytes());
    p.extend_from_slice(&(model.height() as u32).to_le_bytes());
    p.extend_from_slice(&(model.components() as u16).to_le_bytes());
    for set in [model.views(), model.lights()] {
        set.write_le(&mut p);
    }
    let halves = |p: &mut Vec<u8>, v: &[f32]| {
        for &x in v {
            p.extend_from_slice(&f16::from_f32(x).to_bits().to_le_bytes());
        }
    };
    for f in model.parts() {
        let (k, c) = (f.clusters(), f.components());
        p.extend_from_slice(&(k as u16).to_le_bytes());
        for j in 0..k {
            halves(&mut p, f.mean(j));
        }
        for j in 0..k {
            for t in 0..c {
                halves(&mut p, f.component(j, t));
            }
        }
        if k > 1 {
            for &a in f.assignment() {
                p.extend_from_slice(&a.to_le_bytes());
            }
        }
        halves(&mut p, f.weights());
    }
    // A payload over the limit (checked by `write` and before fitting) gets a length no
    // reader accepts ([`envelope::seal`]).
    envelope::seal(MAGIC, VERSION, &p)
}

/// Parses a model from bytes; `path` is only used in messages.
///
/// # Errors
/// [`LpcaError::Format`] for a wrong magic, version, size or checksum, a truncated or
/// inconsistent payload, or out-of-range values. Nothing is allocated beyond what the bytes
/// can actually hold.
pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<LpcaModel> {
    parse(bytes).map_err(|reason| LpcaError::Format {
        path: path.to_path_buf(),
        reason,
    })
}

/// Whether `bytes` start like a `.lpca` file.
pub fn is_lpca(bytes: &[u8]) -> bool {
    bytes.starts_with(&MAGIC)
}

fn parse(bytes: &[u8]) -> Parse<LpcaModel> {
    let payload = envelope::open(bytes, MAGIC, ".lpca", VERSION, MAX_PAYLOAD)?;
    let mut r = Reader::new(&payload);
    let method = match r.u8()? {
        0 => Method::Lpca,
        1 => Method::PcaBtf,
        2 => Method::PcaRf,
        m => return Err(format!("unknown method code {m}")),
    };
    let width = r.u32()?;
    let height = r.u32()?;
    if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
        return Err(format!(
            "size {width}x{height} outside 1..={MAX_SIDE} texels a side"
        ));
    }
    let components = usize::from(r.u16()?);
    let views = DirectionSet::read_le(&mut r, "view directions")?;
    let lights = DirectionSet::read_le(&mut r, "light directions")?;
    let (w, h) = (width as usize, height as usize);
    let layout = Layout::of(method, w, h, views.len(), lights.len());
    let (items, dim) = (layout.rows, layout.dim);
    if components == 0 || components > dim {
        return Err(format!(
            "{components} components for vectors of {dim} values"
        ));
    }
    let mut parts = Vec::with_capacity(layout.parts.min(u16::MAX as usize));
    for part in 0..layout.parts {
        let what = |s: &str| format!("part {part}: {s}");
        let clusters = usize::from(r.u16()?);
        if clusters == 0 || clusters > items || (method != Method::Lpca && clusters != 1) {
            return Err(what(&format!(
                "{clusters} clusters for {items} vectors ({} method)",
                method.name()
            )));
        }
        let means = r.halves(clusters.saturating_mul(dim), &what("cluster means"))?;
        let bases = r.halves(
            clusters.saturating_mul(components).saturating_mul(dim),
            &what("eigenvectors"),
        )?;
        let assignment = if clusters > 1 {
            r.u16s(items, &what("cluster indices"))?
        } else {
            // Nothing is allocated for a size the file cannot hold: the weights come next.
            r.ensure(items, 2 * components, &what("weights"))?;
            vec![0; items]
        };
        let weights = r.halves(items.saturating_mul(components), &what("weights"))?;
        let f = Factorization::new(dim, components, means, bases, assignment, weights);
        parts.push(f.map_err(|reason| what(&reason))?);
    }
    r.finish()?;
    LpcaModel::from_parts(method, views, lights, (w, h), parts)
}

/// Writes a model file atomically (a temporary name, then a rename).
///
/// # Errors
/// The destination cannot be written.
pub fn write(model: &LpcaModel, path: &Path) -> Result<()> {
    let bytes = to_bytes(model);
    if bytes.len() - envelope::OVERHEAD > MAX_PAYLOAD as usize {
        return Err(LpcaError::Format {
            path: path.to_path_buf(),
            reason: format!(
                "the model needs {} bytes, above the format's {MAX_PAYLOAD}-byte limit",
                bytes.len()
            ),
        });
    }
    Ok(crate::io::write_file_atomic(path, &bytes)?)
}

/// Reads a model file (at most [`MAX_PAYLOAD`] + 16 bytes are read).
///
/// # Errors
/// The file cannot be read, or is not a valid model.
pub fn read(path: &Path) -> Result<LpcaModel> {
    let limit = u64::from(MAX_PAYLOAD) + envelope::OVERHEAD as u64;
    let bytes = crate::io::read_capped(path, limit)?;
    from_bytes(&bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::Btf;
    use crate::btf::synthetic::SyntheticMaterial;
    use crate::lpca::LpcaOptions;
    use crate::progress::NoProgress;
    use std::sync::OnceLock;

    /// One small fitted model per method (16 x 16 knit), fitted once.
    fn models() -> &'static Vec<LpcaModel> {
        static MODELS: OnceLock<Vec<LpcaModel>> = OnceLock::new();
        MODELS.get_or_init(|| {
            let btf = Btf::synthetic(SyntheticMaterial::Knit, 16, 2).unwrap();
            [Method::Lpca, Method::PcaBtf, Method::PcaRf]
                .into_iter()
                .map(|method| {
                    let options = LpcaOptions {
                        method,
                        clusters: 4,
                        components: 3,
                        max_iterations: 3,
                        evaluate: false,
                        ..LpcaOptions::default()
                    };
                    LpcaModel::fit(&btf, &options, &NoProgress).unwrap().0
                })
                .collect()
        })
    }

    fn parse_err(bytes: &[u8]) -> String {
        match from_bytes(bytes, Path::new("m.lpca")) {
            Err(LpcaError::Format { path, reason }) => {
                assert_eq!(path, Path::new("m.lpca"));
                reason
            }
            other => panic!("expected a format error, got {other:?}"),
        }
    }

    /// A valid file around a changed payload (new length and CRC).
    fn repack(bytes: &[u8], edit: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
        let mut payload = bytes[12..bytes.len() - 4].to_vec();
        edit(&mut payload);
        let mut out = bytes[..8].to_vec();
        out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        out.extend_from_slice(&payload);
        out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        out
    }

    #[test]
    fn every_method_round_trips_exactly() {
        for model in models() {
            let bytes = to_bytes(model);
            let back = from_bytes(&bytes, Path::new("m.lpca")).unwrap();
            assert_eq!(&back, model, "{:?}", model.method());
            assert_eq!(to_bytes(&back), bytes);
            let predicted = payload_len(
                model.method(),
                model.width(),
                model.height(),
                model.views().len(),
                model.lights().len(),
                model.clusters(),
                model.components(),
            );
            assert_eq!(predicted as usize, bytes.len() - 16);
            assert_eq!(
                back.reconstruct(40, 7).unwrap(),
                model.reconstruct(40, 7).unwrap()
            );
        }
    }

    #[test]
    fn truncated_files_are_errors_at_every_length() {
        let bytes = to_bytes(&models()[0]);
        let step = (bytes.len() / 97).max(1);
        for len in (0..bytes.len()).step_by(step) {
            parse_err(&bytes[..len]);
        }
        // Truncated payload with a matching header length and CRC.
        let short = repack(&bytes, |p| p.truncate(p.len() - 3));
        assert!(parse_err(&short).contains("truncated") || parse_err(&short).contains("exceed"));
    }

    #[test]
    fn corrupt_files_are_errors() {
        let bytes = to_bytes(&models()[2]);
        let mut flipped = bytes.clone();
        let mid = flipped.len() / 2;
        flipped[mid] ^= 0x40;
        assert!(parse_err(&flipped).contains("checksum"));
        let mut magic = bytes.clone();
        magic[0] = b'X';
        assert!(parse_err(&magic).contains("magic"));
        let mut version = bytes.clone();
        version[4] = 9;
        assert!(parse_err(&version).contains("version"));
        let mut extra = bytes.clone();
        extra.push(0);
        assert!(parse_err(&extra).contains("unexpected"));
        assert!(parse_err(b"").contains("too short"));
        // A .btfm file is not a .lpca file.
        assert!(parse_err(b"BTFM\x01\x00\x00\x00").contains("magic"));
    }

    #[test]
    fn hostile_counts_are_rejected_before_allocating() {
        let bytes = to_bytes(&models()[0]);
        // Payload: method(1) width(4) height(4) components(2) views(2)...
        let huge_len = {
            let mut b = bytes.clone();
            b[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
            b
        };
        assert!(parse_err(&huge_len).contains("limit"));
        let side = repack(&bytes, |p| p[1..5].copy_from_slice(&u32::MAX.to_le_bytes()));
        assert!(parse_err(&side).contains("outside"));
        // 16384 x 16384 texels: a weights array of 2^28 x C halves that the file cannot hold.
        let big = repack(&bytes, |p| {
            p[1..5].copy_from_slice(&16384u32.to_le_bytes());
            p[5..9].copy_from_slice(&16384u32.to_le_bytes());
        });
        let reason = parse_err(&big);
        assert!(
            reason.contains("exceed the file") || reason.contains("clusters"),
            "{reason}"
        );
        let comps = repack(&bytes, |p| {
            p[9..11].copy_from_slice(&u16::MAX.to_le_bytes())
        });
        assert!(parse_err(&comps).contains("components"));
        let method = repack(&bytes, |p| p[0] = 7);
        assert!(parse_err(&method).contains("method"));
        let views = repack(&bytes, |p| {
            p[11..13].copy_from_slice(&u16::MAX.to_le_bytes())
        });
        parse_err(&views);
        // A cluster count above the texel count.
        let offset = 1 + 4 + 4 + 2 + 2 + 81 * 8 + 2 + 81 * 8;
        let clusters = repack(&bytes, |p| {
            p[offset..offset + 2].copy_from_slice(&u16::MAX.to_le_bytes())
        });
        assert!(parse_err(&clusters).contains("clusters"));
        // A cluster index out of range.
        let model = &models()[0];
        let f = &model.parts()[0];
        let at = offset + 2 + 2 * f.clusters() * (f.components() + 1) * f.dim();
        let index = repack(&bytes, |p| {
            p[at..at + 2].copy_from_slice(&100u16.to_le_bytes())
        });
        assert!(parse_err(&index).contains("cluster index"));
        // A NaN half float.
        let nan = repack(&bytes, |p| {
            p[offset + 2..offset + 4].copy_from_slice(&f16::NAN.to_bits().to_le_bytes())
        });
        assert!(parse_err(&nan).contains("non-finite"));
    }
}
