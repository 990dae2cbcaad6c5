//! Bad input: every case ends with a non-zero exit and one `error:` line naming the file and
//! the problem; never a panic, never a half-written output left behind.

mod common;

use std::path::Path;

use btfmrf::btf::{BtfError, ImageFormat, io};
use common::*;
use ndarray::Array3;

/// A damaged copy of a tiny valid Bonn zip: `edit` rewrites the member list.
fn damaged_zip(dir: &Path, edit: impl FnOnce(&mut Vec<(String, Vec<u8>)>)) -> std::path::PathBuf {
    damaged_zip_of_size(dir, 8, edit)
}

fn damaged_zip_of_size(
    dir: &Path,
    size: u32,
    edit: impl FnOnce(&mut Vec<(String, Vec<u8>)>),
) -> std::path::PathBuf {
    let good = tiny_btf(
        &dir.join("good.zip"),
        size,
        ImageFormat::Jpeg { quality: 90 },
    );
    let mut members = read_zip(&good);
    edit(&mut members);
    let bad = dir.join("bad.zip");
    write_zip(&bad, &members);
    bad
}

/// A zlib CRC-32, for hand-made PNG chunks.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A PNG whose header claims `w` x `h` pixels but holds no pixel data.
fn png_claiming(w: u32, h: u32) -> Vec<u8> {
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        png.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        png.extend_from_slice(&body);
        png.extend_from_slice(&crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    chunk(
        b"IDAT",
        &[0x78, 0x9c, 0x63, 0x00, 0x00, 0x00, 0x01, 0x00, 0x01],
    );
    chunk(b"IEND", &[]);
    png
}

#[test]
fn random_bytes_as_a_zip() {
    let dir = temp();
    let p = dir.path().join("noise.zip");
    let noise: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&p, noise).unwrap();
    let err = fails(&["info", s(&p)]);
    assert!(
        err.contains("noise.zip") && err.contains("not a readable zip"),
        "{err}"
    );
}

#[test]
fn truncated_zip() {
    let dir = temp();
    let good = tiny_btf(&dir.path().join("good.zip"), 8, ImageFormat::Png);
    let bytes = std::fs::read(&good).unwrap();
    let cut = dir.path().join("cut.zip");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let err = fails(&["info", s(&cut)]);
    assert!(err.contains("cut.zip") && err.contains("zip"), "{err}");
}

#[test]
fn corrupt_jpeg_header_inside_a_zip() {
    let dir = temp();
    let bad = damaged_zip(dir.path(), |m| {
        m[100].1 = b"\xff\xd8\xffgarbage that is not a JPEG".to_vec()
    });
    let err = fails(&["info", s(&bad)]);
    assert!(err.contains("bad.zip: 00100 tl"), "names the member: {err}");
    assert!(err.contains("corrupt"), "{err}");
}

#[test]
fn corrupt_jpeg_data_fails_the_conversion_and_leaves_nothing() {
    let dir = temp();
    let bad = damaged_zip_of_size(dir.path(), 64, |m| {
        let len = m[4000].1.len();
        m[4000].1.truncate(len * 2 / 3); // header intact, scan data cut off
    });
    ok(&["info", s(&bad)]); // the layout itself is fine: headers only
    let out = dir.path().join("out.zip");
    let err = fails(&["convert", s(&bad), "--out", s(&out)]);
    assert!(
        err.contains("04000 tl") && err.contains("truncated"),
        "names the member: {err}"
    );
    assert!(!out.exists(), "no output left behind");
    let leftovers: Vec<String> = entries(dir.path())
        .into_iter()
        .filter(|n| n.starts_with(".btfmrf"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

#[test]
fn missing_direction() {
    let dir = temp();
    let bad = damaged_zip(dir.path(), |m| {
        m.remove(82);
    });
    let err = fails(&["info", s(&bad)]);
    assert!(
        err.contains("1 of 6561") && err.contains("missing"),
        "{err}"
    );
    assert!(
        err.contains("tl015 pl000 tv015 pv000"),
        "names the angles: {err}"
    );
}

#[test]
fn duplicate_direction() {
    let dir = temp();
    let bad = damaged_zip(dir.path(), |m| {
        let (name, bytes) = m[7].clone();
        m.push((format!("copy {}", &name[6..]), bytes));
    });
    let err = fails(&["info", s(&bad)]);
    assert!(
        err.contains("duplicate direction") && err.contains("00007 tl"),
        "{err}"
    );
}

#[test]
fn image_name_outside_the_pattern() {
    let dir = temp();
    let bad = damaged_zip(dir.path(), |m| {
        m.push(("holiday.jpg".into(), m[0].1.clone()))
    });
    let err = fails(&["info", s(&bad)]);
    assert!(
        err.contains("holiday.jpg") && err.contains("pattern"),
        "{err}"
    );
}

#[test]
fn mixed_image_sizes() {
    let dir = temp();
    let bigger = io::image::encode(&Array3::zeros((3, 16, 16)), ImageFormat::Png, "x").unwrap();
    let bad = damaged_zip(dir.path(), |m| m[3000].1 = bigger);
    let err = fails(&["info", s(&bad)]);
    assert!(
        err.contains("03000 tl") && err.contains("16x16") && err.contains("8x8"),
        "{err}"
    );
}

#[test]
fn png_header_claiming_100000_squared_is_rejected_before_allocating() {
    let huge = png_claiming(100_000, 100_000);
    let dir = temp();
    let bad = damaged_zip(dir.path(), |m| m[5].1 = huge.clone());
    let err = fails(&["info", s(&bad)]);
    assert!(
        err.contains("00005 tl") && err.contains("100000x100000"),
        "{err}"
    );
    // The same through the library, as a single file.
    let p = dir.path().join("huge.png");
    std::fs::write(&p, &huge).unwrap();
    assert!(matches!(
        io::read_image(&p),
        Err(BtfError::TooLarge { width: 100_000, .. })
    ));
}

#[test]
fn nan_and_inf_in_an_exr() {
    let dir = temp();
    let exr_dir = tiny_btf(&dir.path().join("set"), 8, ImageFormat::Exr);
    let mut poisoned = Array3::<f32>::from_elem((3, 8, 8), 0.5);
    poisoned[[1, 2, 3]] = f32::NAN;
    poisoned[[0, 7, 7]] = f32::INFINITY;
    let victim = entries(&exr_dir)[1234].clone();
    let bytes = io::image::encode(&poisoned, ImageFormat::Exr, "x").unwrap();
    std::fs::write(exr_dir.join(&victim), bytes).unwrap();
    let out = dir.path().join("out.zip");
    let err = fails(&["convert", s(&exr_dir), "--out", s(&out)]);
    assert!(
        err.contains(&victim) && err.contains("NaN or infinite"),
        "{err}"
    );
    assert!(err.contains("x=3, y=2"), "{err}");
    assert!(!out.exists());
}

#[test]
fn rti_lp_naming_a_missing_image() {
    let dir = temp();
    let png = io::image::encode(&Array3::from_elem((3, 4, 4), 0.2), ImageFormat::Png, "x").unwrap();
    std::fs::write(dir.path().join("a.png"), &png).unwrap();
    std::fs::write(
        dir.path().join("dirs.lp"),
        "2\na.png 0 0 1\nb.png 0.5 0 0.8\n",
    )
    .unwrap();
    let err = fails(&["info", s(dir.path())]);
    assert!(err.contains("dirs.lp") && err.contains("'b.png'"), "{err}");
}

#[test]
fn unreadable_paths_and_bad_sizes() {
    let err = fails(&["info", "/nonexistent/btf.zip"]);
    assert!(err.contains("/nonexistent/btf.zip"), "{err}");
    let err = fails(&[
        "generate",
        "knit",
        "--size",
        "8",
        "--out",
        "/nonexistent/dir/x.zip",
    ]);
    assert!(err.contains("/nonexistent/dir"), "{err}");
    let err = fails(&["generate", "knit", "--size", "0", "--out", "x.zip"]);
    assert!(err.contains("--size"), "{err}");
    let dir = temp();
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let err = fails(&["info", s(&empty)]);
    assert!(err.contains("no UBO2003-named images"), "{err}");
}

#[test]
fn existing_output_folder_is_not_overwritten() {
    let dir = temp();
    let zip = tiny_btf(&dir.path().join("a.zip"), 4, ImageFormat::Png);
    let out = dir.path().join("exists");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "mine").unwrap();
    let err = fails(&["convert", s(&zip), "--out", s(&out)]);
    assert!(err.contains("already exists"), "{err}");
    assert_eq!(
        std::fs::read_to_string(out.join("keep.txt")).unwrap(),
        "mine"
    );
}
