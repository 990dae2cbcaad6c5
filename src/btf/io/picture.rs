//! Single images: decoding PNG/JPEG (8-bit sRGB, linearised) and EXR (linear float) into planar
//! `(3, h, w)` arrays, encoding them back, with size limits checked before any pixel is
//! allocated.

use std::io::Cursor;

use exr::prelude::{self as exrp, ReadChannels, ReadLayers, WritableImage};
use image::{ImageReader, Limits};
use ndarray::Array3;
use rayon::prelude::*;

use crate::btf::dataset::check_finite;
use crate::btf::error::{BtfError, Result};
use crate::color::{Srgb8Encoder, fit_to_gamut, srgb_to_linear, srgb8_to_linear_table};

/// The largest accepted image side, in pixels (a header claiming more is rejected unread).
pub const MAX_SIDE: u32 = 16_384;

/// How an image is stored in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8-bit sRGB JPEG (lossy; the Bonn database's format).
    Jpeg {
        /// Encoder quality, 1..=100.
        quality: u8,
    },
    /// 8-bit sRGB PNG (lossless at 8 bits).
    Png,
    /// 32-bit float linear OpenEXR (lossless ZIP compression).
    Exr,
}

impl ImageFormat {
    /// The file extension without a dot.
    pub fn extension(&self) -> &'static str {
        match self {
            ImageFormat::Jpeg { .. } => "jpg",
            ImageFormat::Png => "png",
            ImageFormat::Exr => "exr",
        }
    }

    /// The format for a file name's extension (jpg/jpeg/png/exr, any case).
    pub fn from_name(name: &str) -> Option<Self> {
        let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
        match ext.as_str() {
            "jpg" | "jpeg" => Some(ImageFormat::Jpeg { quality: 90 }),
            "png" => Some(ImageFormat::Png),
            "exr" => Some(ImageFormat::Exr),
            _ => None,
        }
    }
}

const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];

fn is_exr(bytes: &[u8]) -> bool {
    bytes.starts_with(&EXR_MAGIC)
}

/// A decoder's message on one line: some span several, which would break the CLI's one-line
/// errors.
fn one_line(e: impl std::fmt::Display) -> String {
    let text = e.to_string();
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    lines.join("; ")
}

/// The most bytes a file holding a `width` x `height` image may take: 32 bytes a pixel (an
/// uncompressed four-channel float EXR needs 16; JPEG and PNG far less) plus 16 MiB of
/// metadata (ICC profiles, EXIF thumbnails). Readers refuse longer files unread.
pub fn max_file_bytes(width: u32, height: u32) -> u64 {
    32 * u64::from(width) * u64::from(height) + (16 << 20)
}

/// The fewest bytes a Huffman-coded JPEG of `width` x `height` can take: every 8 x 8 block of
/// its full-resolution component needs at least one bit (a one-bit DC code), whatever the
/// sampling or progression. A file far smaller than its header claims is truncated or forged,
/// and is refused before a decoder allocates the claimed size and fills it with grey.
fn min_jpeg_bytes(width: u32, height: u32) -> u64 {
    (u64::from(width.div_ceil(8)) * u64::from(height.div_ceil(8))).div_ceil(8)
}

fn check_side(file: &str, width: u64, height: u64) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(BtfError::image(
            file,
            "image has no pixels (0 width or height)",
        ));
    }
    if width > u64::from(MAX_SIDE) || height > u64::from(MAX_SIDE) {
        return Err(BtfError::TooLarge {
            file: file.to_string(),
            width,
            height,
            limit: MAX_SIDE,
        });
    }
    Ok(())
}

/// A format-sniffing reader; `limited` adds the decoder's own allocation limits (the header
/// probe runs without them so that it can report the size it found).
fn reader<'a>(bytes: &'a [u8], file: &str, limited: bool) -> Result<ImageReader<Cursor<&'a [u8]>>> {
    let mut reader = ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| BtfError::image(file, one_line(e)))?;
    if reader.format().is_none() {
        return Err(BtfError::image(
            file,
            "not a PNG, JPEG or EXR image (unknown signature)",
        ));
    }
    if limited {
        let mut limits = Limits::default();
        limits.max_image_width = Some(MAX_SIDE);
        limits.max_image_height = Some(MAX_SIDE);
        limits.max_alloc = Some(4 * u64::from(MAX_SIDE) * u64::from(MAX_SIDE) * 4);
        reader.limits(limits);
    } else {
        reader.no_limits();
    }
    Ok(reader)
}

/// Width and height from an image's header, without decoding pixels. `bytes` may be just the
/// start of the file, as long as it holds the header.
///
/// # Errors
/// An unknown or corrupt header, or a size of zero or beyond [`MAX_SIDE`].
pub fn probe_size(bytes: &[u8], file: &str) -> Result<(u32, u32)> {
    let (w, h) = if is_exr(bytes) {
        let meta = exrp::MetaData::read_from_buffered(Cursor::new(bytes), false)
            .map_err(|e| BtfError::image(file, format!("corrupt EXR header ({})", one_line(e))))?;
        let header = meta
            .headers
            .first()
            .ok_or_else(|| BtfError::image(file, "EXR file without a layer"))?;
        (
            header.layer_size.width() as u64,
            header.layer_size.height() as u64,
        )
    } else {
        // Header only: no pixel memory is touched here, and check_side below says the size.
        let (w, h) = reader(bytes, file, false)?
            .into_dimensions()
            .map_err(|e| header_error(file, e))?;
        (u64::from(w), u64::from(h))
    };
    check_side(file, w, h)?;
    Ok((w as u32, h as u32))
}

fn header_error(file: &str, e: image::ImageError) -> BtfError {
    match e {
        image::ImageError::Limits(_) => BtfError::image(
            file,
            format!("image header claims a size beyond the {MAX_SIDE}x{MAX_SIDE} limit"),
        ),
        other => BtfError::image(file, format!("corrupt image ({})", one_line(other))),
    }
}

/// Decodes a whole PNG, JPEG or EXR file into planar `(3, h, w)` linear RGB.
///
/// 8- and 16-bit images are sRGB-encoded and are linearised; grey images are replicated to
/// three channels; alpha is dropped. EXR samples must be finite.
///
/// # Errors
/// Corrupt data, oversized images, non-finite EXR samples; the message names `file`.
pub fn decode(bytes: &[u8], file: &str) -> Result<Array3<f32>> {
    if is_exr(bytes) {
        return decode_exr(bytes, file);
    }
    // Size check on the header before the decoder allocates anything.
    let (w, h) = probe_size(bytes, file)?;
    check_jpeg_complete(bytes, file, (w, h))?;
    let img = reader(bytes, file, true)?
        .decode()
        .map_err(|e| BtfError::image(file, format!("corrupt image data ({})", one_line(e))))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut out = Array3::<f32>::zeros((3, h, w));
    let deep = matches!(
        img.color(),
        image::ColorType::L16
            | image::ColorType::La16
            | image::ColorType::Rgb16
            | image::ColorType::Rgba16
    );
    let float = matches!(
        img.color(),
        image::ColorType::Rgb32F | image::ColorType::Rgba32F
    );
    if float {
        let rgb = img.to_rgb32f();
        for (x, y, p) in rgb.enumerate_pixels() {
            for c in 0..3 {
                out[[c, y as usize, x as usize]] = p[c];
            }
        }
        check_finite(&out, file)?;
    } else if deep {
        let rgb = img.to_rgb16();
        for (x, y, p) in rgb.enumerate_pixels() {
            for c in 0..3 {
                out[[c, y as usize, x as usize]] = srgb_to_linear(f32::from(p[c]) / 65535.0);
            }
        }
    } else {
        let lut = srgb8_to_linear_table();
        let rgb = img.to_rgb8();
        for (x, y, p) in rgb.enumerate_pixels() {
            for c in 0..3 {
                out[[c, y as usize, x as usize]] = lut[p[c] as usize];
            }
        }
    }
    Ok(out)
}

/// JPEG decoders fill a truncated scan with grey and report success; we refuse it instead.
/// In entropy-coded data 0xFF is always followed by 0x00 or a restart marker, so an
/// end-of-image marker (FF D9) after the last start-of-scan (FF DA) means the file is whole.
/// A file shorter than [`min_jpeg_bytes`] of its claimed size is refused too.
fn check_jpeg_complete(bytes: &[u8], file: &str, (w, h): (u32, u32)) -> Result<()> {
    if !bytes.starts_with(&[0xff, 0xd8]) {
        return Ok(());
    }
    let least = min_jpeg_bytes(w, h);
    if (bytes.len() as u64) < least {
        return Err(BtfError::image(
            file,
            format!(
                "truncated JPEG: {} bytes cannot hold the {w}x{h} pixels its header claims \
                 (at least {least} bytes)",
                bytes.len()
            ),
        ));
    }
    let last_scan = bytes
        .windows(2)
        .rposition(|w| w == [0xff, 0xda])
        .unwrap_or(0);
    if bytes[last_scan..].windows(2).any(|w| w == [0xff, 0xd9]) {
        Ok(())
    } else {
        Err(BtfError::image(
            file,
            "truncated JPEG (no end-of-image marker after the image data)",
        ))
    }
}

fn decode_exr(bytes: &[u8], file: &str) -> Result<Array3<f32>> {
    probe_size(bytes, file)?;
    let image = exrp::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| BtfError::image(file, format!("corrupt EXR ({})", one_line(e))))?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let find = |names: &[&str]| {
        layer.channel_data.list.iter().find(|ch| {
            let n = ch.name.to_string();
            let last = n.rsplit('.').next().unwrap_or(&n).to_ascii_uppercase();
            names.contains(&last.as_str())
        })
    };
    let channels = match (find(&["R"]), find(&["G"]), find(&["B"]), find(&["Y"])) {
        (Some(r), Some(g), Some(b), _) => [r, g, b],
        (_, _, _, Some(y)) => [y, y, y],
        _ => {
            return Err(BtfError::image(
                file,
                "EXR has neither R, G, B nor Y channels",
            ));
        }
    };
    let mut out = Array3::<f32>::zeros((3, h, w));
    for (c, ch) in channels.iter().enumerate() {
        if ch.sample_data.len() != w * h {
            return Err(BtfError::image(
                file,
                "EXR channel is subsampled (unsupported)",
            ));
        }
        for (dst, v) in out
            .index_axis_mut(ndarray::Axis(0), c)
            .iter_mut()
            .zip(ch.sample_data.values_as_f32())
        {
            *dst = v;
        }
    }
    check_finite(&out, file)?;
    Ok(out)
}

/// Encodes planar `(3, h, w)` linear RGB into file bytes of the given format: EXR keeps the
/// values; 8-bit formats are sRGB-encoded after [`fit_to_gamut`] (over-range pixels scaled
/// down whole, keeping their colour).
///
/// # Errors
/// A wrong shape, or the encoder fails.
pub fn encode(image: &Array3<f32>, format: ImageFormat, file: &str) -> Result<Vec<u8>> {
    let (c, h, w) = image.dim();
    if c != 3 || h == 0 || w == 0 {
        return Err(BtfError::image(
            file,
            format!("cannot encode an image of shape {:?}", image.dim()),
        ));
    }
    match format {
        ImageFormat::Exr => {
            let planes: Vec<(&str, Vec<f32>)> = ["R", "G", "B"]
                .iter()
                .enumerate()
                .map(|(c, n)| {
                    (
                        *n,
                        image
                            .index_axis(ndarray::Axis(0), c)
                            .iter()
                            .copied()
                            .collect(),
                    )
                })
                .collect();
            encode_exr_channels(w, h, planes, file)
        }
        ImageFormat::Jpeg { .. } | ImageFormat::Png => {
            let enc = Srgb8Encoder::new();
            let mut rgb = vec![0u8; w * h * 3];
            // Rows in parallel: the 8-bit encoding of a 1024^2 image took longer than the
            // PNG compression after it.
            rgb.par_chunks_exact_mut(w * 3)
                .enumerate()
                .for_each(|(y, row)| {
                    let planes = [0, 1, 2].map(|c| image.slice(ndarray::s![c, y, ..]));
                    for (x, pixel) in row.chunks_exact_mut(3).enumerate() {
                        let fitted = fit_to_gamut(planes.each_ref().map(|p| p[x]));
                        for (code, v) in pixel.iter_mut().zip(fitted) {
                            *code = enc.encode(v);
                        }
                    }
                });
            encode_rgb8(&rgb, w as u32, h as u32, format, file)
        }
    }
}

/// Encodes interleaved 8-bit sRGB pixels (`w * h * 3` bytes) as JPEG or PNG.
///
/// # Errors
/// EXR requested (use [`encode`]) or the encoder fails.
pub fn encode_rgb8(rgb: &[u8], w: u32, h: u32, format: ImageFormat, file: &str) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut buf = Vec::new();
    let result = match format {
        ImageFormat::Jpeg { quality } => {
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, quality.clamp(1, 100))
                .write_image(rgb, w, h, image::ExtendedColorType::Rgb8)
        }
        ImageFormat::Png => image::codecs::png::PngEncoder::new(&mut buf).write_image(
            rgb,
            w,
            h,
            image::ExtendedColorType::Rgb8,
        ),
        ImageFormat::Exr => {
            return Err(BtfError::image(
                file,
                "8-bit pixels cannot be written as EXR",
            ));
        }
    };
    result.map_err(|e| BtfError::image(file, format!("cannot encode ({})", one_line(e))))?;
    Ok(buf)
}

/// Encodes named float planes (each `w * h` samples, row-major) as one EXR layer.
///
/// # Errors
/// A plane of the wrong length, or the encoder fails.
pub fn encode_exr_channels(
    w: usize,
    h: usize,
    planes: Vec<(&str, Vec<f32>)>,
    file: &str,
) -> Result<Vec<u8>> {
    if let Some((name, _)) = planes.iter().find(|(_, p)| p.len() != w * h) {
        return Err(BtfError::image(
            file,
            format!("channel {name} has the wrong length"),
        ));
    }
    let channels: exrp::SmallVec<[exrp::AnyChannel<exrp::FlatSamples>; 4]> = planes
        .into_iter()
        .map(|(name, data)| exrp::AnyChannel::new(name, exrp::FlatSamples::F32(data)))
        .collect();
    let layer = exrp::Layer::new(
        (w, h),
        exrp::LayerAttributes::default(),
        exrp::Encoding::SMALL_LOSSLESS,
        exrp::AnyChannels::sort(channels),
    );
    let mut buf = Cursor::new(Vec::new());
    exrp::Image::from_layer(layer)
        .write()
        .to_buffered(&mut buf)
        .map_err(|e| BtfError::image(file, format!("cannot encode EXR ({})", one_line(e))))?;
    Ok(buf.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(h: usize, w: usize) -> Array3<f32> {
        Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            (x as f32 / w as f32) * 0.8 + c as f32 * 0.05 + y as f32 * 0.001
        })
    }

    #[test]
    fn png_round_trip_is_within_8_bit_quantisation() {
        let im = gradient(9, 13);
        let bytes = encode(&im, ImageFormat::Png, "t.png").unwrap();
        assert_eq!(probe_size(&bytes, "t.png").unwrap(), (13, 9));
        let back = decode(&bytes, "t.png").unwrap();
        for (a, b) in im.iter().zip(back.iter()) {
            // Half an 8-bit sRGB code is at most 0.0045 in linear light (at the top end).
            assert!((a - b).abs() < 0.0045, "{a} vs {b}");
        }
    }

    #[test]
    fn exr_round_trip_is_exact() {
        let im = gradient(7, 5);
        let bytes = encode(&im, ImageFormat::Exr, "t.exr").unwrap();
        assert_eq!(
            probe_size(&bytes[..bytes.len().min(4096)], "t.exr").unwrap(),
            (5, 7)
        );
        assert_eq!(decode(&bytes, "t.exr").unwrap(), im);
    }

    #[test]
    fn jpeg_round_trip_is_close() {
        let im = gradient(16, 16);
        let bytes = encode(&im, ImageFormat::Jpeg { quality: 95 }, "t.jpg").unwrap();
        let back = decode(&bytes, "t.jpg").unwrap();
        let mean_err: f32 = im
            .iter()
            .zip(back.iter())
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / im.len() as f32;
        assert!(mean_err < 0.01, "{mean_err}");
    }

    #[test]
    fn real_jpegs_are_never_below_the_least_size() {
        // Flat grey at the lowest quality is the smallest a JPEG of a size can be.
        for side in [1, 8, 64, 512, 1024] {
            let flat = Array3::from_elem((3, side, side), 0.5f32);
            let bytes = encode(&flat, ImageFormat::Jpeg { quality: 1 }, "t.jpg").unwrap();
            let least = min_jpeg_bytes(side as u32, side as u32);
            assert!(
                bytes.len() as u64 >= least,
                "{side}: {} < {least}",
                bytes.len()
            );
            assert!(decode(&bytes, "t.jpg").is_ok());
        }
        assert_eq!(min_jpeg_bytes(16384, 16384), 524_288);
        // Both bounds are far apart for real images; the padded-file bound is generous.
        assert!(max_file_bytes(4, 4) > 16 << 20);
    }

    #[test]
    fn decoder_messages_are_one_line() {
        assert_eq!(one_line("bad\n  data\n\nhere "), "bad; data; here");
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(decode(b"definitely not an image", "x.jpg").is_err());
        assert!(decode(&EXR_MAGIC, "x.exr").is_err());
        assert!(decode(&[], "x.png").is_err());
        assert!(probe_size(&[0xff, 0xd8, 0xff], "x.jpg").is_err());
    }

    #[test]
    fn format_from_name() {
        assert_eq!(
            ImageFormat::from_name("a/B.JPEG"),
            Some(ImageFormat::Jpeg { quality: 90 })
        );
        assert_eq!(ImageFormat::from_name("x.exr"), Some(ImageFormat::Exr));
        assert_eq!(ImageFormat::from_name("dirs.lp"), None);
    }
}
