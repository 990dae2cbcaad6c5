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
    let bigger = io::picture::encode(&Array3::zeros((3, 16, 16)), ImageFormat::Png, "x").unwrap();
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
    let bytes = io::picture::encode(&poisoned, ImageFormat::Exr, "x").unwrap();
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
    let png =
        io::picture::encode(&Array3::from_elem((3, 4, 4), 0.2), ImageFormat::Png, "x").unwrap();
    std::fs::write(dir.path().join("a.png"), &png).unwrap();
    std::fs::write(
        dir.path().join("dirs.lp"),
        "2\na.png 0 0 1\nb.png 0.5 0 0.8\n",
    )
    .unwrap();
    let err = fails(&["info", s(dir.path())]);
    assert!(err.contains("dirs.lp") && err.contains("'b.png'"), "{err}");
}

/// An RTI zip: its `.lp` member names images relative to its folder in the archive; a
/// missing member or two `.lp` members are one error line each.
#[test]
fn rti_zips_read_and_their_mistakes_are_named() {
    let dir = temp();
    let png =
        io::picture::encode(&Array3::from_elem((3, 4, 4), 0.2), ImageFormat::Png, "x").unwrap();
    let lp = b"2\na.png 0 0 1\nb.png 0.6 0 0.8\n".to_vec();
    let member = |name: &str, bytes: &[u8]| (name.to_string(), bytes.to_vec());
    let good = dir.path().join("good.zip");
    write_zip(
        &good,
        &[
            member("set/a.png", &png),
            member("set/b.png", &png),
            member("set/dirs.lp", &lp),
        ],
    );
    let info: serde_json::Value = serde_json::from_str(&ok(&["info", s(&good), "--json"])).unwrap();
    assert_eq!(
        (info["views"].clone(), info["lights"].clone()),
        (1.into(), 2.into())
    );
    let missing = dir.path().join("missing.zip");
    write_zip(&missing, &[member("a.png", &png), member("dirs.lp", &lp)]);
    let err = fails(&["info", s(&missing)]);
    assert!(err.contains("dirs.lp") && err.contains("'b.png'"), "{err}");
    let two = dir.path().join("two.zip");
    write_zip(
        &two,
        &[
            member("a.png", &png),
            member("x.lp", &lp),
            member("y.lp", &lp),
        ],
    );
    let err = fails(&["info", s(&two)]);
    assert!(err.contains("several .lp members"), "{err}");
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

// ---- Issue 12: hostile and unlucky input ----

/// A small committed model (its pyramid has more than one level).
fn golden_model() -> std::path::PathBuf {
    common::repo().join("tests/golden/sponge64.btfm")
}

/// A zip of `members` written with deflate (so that long runs of zeros stay small).
fn write_deflated_zip(path: &Path, members: &[(String, Vec<u8>)]) {
    use std::io::Write;
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .large_file(true);
    for (name, bytes) in members {
        zip.start_file(name.as_str(), options).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap();
}

fn png(side: usize) -> Vec<u8> {
    io::picture::encode(
        &Array3::from_elem((3, side, side), 0.2),
        ImageFormat::Png,
        "x",
    )
    .unwrap()
}

/// Defect 1: a size below the pyramid's was an index out of bounds (exit 101).
#[test]
fn synthesis_smaller_than_the_pyramid_is_refused() {
    let model = btfmrf::model::format::read(&golden_model()).unwrap();
    let least = model.min_synthesis_side();
    // Three levels: the coarsest band halves the side twice.
    assert_eq!((model.levels(), least), (3, 4));
    let dir = temp();
    let out = dir.path().join("x.png");
    for size in [
        "1",
        &(least - 1).to_string(),
        &format!("{}x{}", least, least - 1),
    ] {
        let err = fails(&[
            "synthesize",
            s(&golden_model()),
            "--size",
            size,
            "--view",
            "0,0",
            "--light",
            "45,90",
            "--out",
            s(&out),
        ]);
        assert!(
            err.contains("--size") && err.contains(&format!("at least {least}")),
            "{err}"
        );
    }
    assert!(!out.exists());
    // The smallest allowed size works, tileable or not.
    let o = btfmrf::synthesis::SynthesisOptions {
        rows: least,
        cols: least,
        seed: 1,
        tileable: true,
    };
    let dir0 = btfmrf::btf::Direction::new(0.0, 0.0);
    assert!(model.synthesize_image(&dir0, &dir0, &o).is_ok());
}

/// The header of a `.lpca` file (LPCA method, one view, one light, one component) around
/// `payload_tail`, with a valid checksum.
fn lpca_file(side: u32, tail: &[u8]) -> Vec<u8> {
    let mut p = vec![0u8]; // method: LPCA
    p.extend_from_slice(&side.to_le_bytes());
    p.extend_from_slice(&side.to_le_bytes());
    p.extend_from_slice(&1u16.to_le_bytes()); // components
    for _ in 0..2 {
        p.extend_from_slice(&1u16.to_le_bytes()); // one direction
        p.extend_from_slice(&[0; 8]);
    }
    p.extend_from_slice(tail);
    let mut f = b"LPCA\x01\x00\x00\x00".to_vec();
    f.extend_from_slice(&(p.len() as u32).to_le_bytes());
    f.extend_from_slice(&p);
    f.extend_from_slice(&crc32(&p).to_le_bytes());
    f
}

/// Defect 2: a small `.lpca` claiming a 16384^2 model; the weights are checked before anything
/// of that size is allocated. (`crates/cli/tests/limits.rs` measures the allocation itself.)
#[test]
fn lpca_claiming_a_huge_model_is_refused() {
    // One cluster: 3 means, 3 eigenvector values, then weights that are not there.
    let mut tail = 1u16.to_le_bytes().to_vec();
    tail.extend_from_slice(&[0; 12]);
    let bytes = lpca_file(16384, &tail);
    let err = btfmrf::lpca::format::from_bytes(&bytes, Path::new("x.lpca"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("weights") && err.contains("exceed the file"),
        "{err}"
    );
}

/// `n` members with distinct views and lights (so a table of every pair would be n^2).
pub fn members_with_distinct_directions(n: usize, content: &[u8]) -> Vec<(String, Vec<u8>)> {
    (0..n)
        .map(|i| {
            let (t, p) = (1 + i % 89, (i / 89) % 360);
            let name = format!("{i:05} tl{t:03} pl{p:03} tv{t:03} pv{p:03}.png");
            (name, content.to_vec())
        })
        .collect()
}

/// Defect 3: thousands of members named with distinct views and lights; the layout check is
/// linear (a map of the pairs present), and says how many pairs are missing.
#[test]
fn many_members_with_distinct_directions_fail_fast() {
    let dir = temp();
    let zip = dir.path().join("many.zip");
    write_zip(&zip, &members_with_distinct_directions(3000, b""));
    let Err(err) = btfmrf::btf::Btf::open(&zip) else {
        panic!("an incomplete layout must be refused");
    };
    let err = err.to_string();
    assert!(
        err.contains(
            "8997000 of 9000000 (view, light) images missing, e.g. tl001 pl001 tv001 pv000"
        ),
        "{err}"
    );
}

/// A baseline JPEG of `side`^2 whose frame header is then rewritten to claim `claim`^2.
fn jpeg_claiming(side: usize, claim: u16) -> Vec<u8> {
    let mut jpeg = io::picture::encode(
        &Array3::from_elem((3, side, side), 0.4),
        ImageFormat::Jpeg { quality: 90 },
        "x",
    )
    .unwrap();
    let sof = jpeg
        .windows(2)
        .position(|w| w == [0xff, 0xc0])
        .expect("a baseline frame header");
    jpeg[sof + 5..sof + 7].copy_from_slice(&claim.to_be_bytes());
    jpeg[sof + 7..sof + 9].copy_from_slice(&claim.to_be_bytes());
    jpeg
}

/// Defect 4: a whole 16^2 JPEG (end marker included) whose header claims 2048^2 decoded to a
/// grey 2048^2 image; it is too small to hold that many pixels.
#[test]
fn small_jpeg_claiming_a_large_image_is_refused() {
    for claim in [2048, 16384] {
        let jpeg = jpeg_claiming(16, claim);
        assert!(jpeg.ends_with(&[0xff, 0xd9]));
        let err = io::picture::decode(&jpeg, "x.jpg").unwrap_err().to_string();
        assert!(
            err.contains("truncated JPEG") && err.contains("cannot hold"),
            "{err}"
        );
    }
    // The same file with its true size decodes.
    assert!(io::picture::decode(&jpeg_claiming(16, 16), "x.jpg").is_ok());
}

/// Defect 5: a 4x4 PNG followed by 64 MiB of zeros (compressed to a few kilobytes) was read
/// whole, once per thread; now a member is read only up to what its declared size can need.
#[test]
fn padded_member_is_refused_at_the_bound_of_its_image_size() {
    let dir = temp();
    let mut padded = png(4);
    padded.resize(padded.len() + (64 << 20), 0);
    let mut members: Vec<(String, Vec<u8>)> = (0..4)
        .map(|l| {
            (
                format!("{l:05} tl{:03} pl000 tv000 pv000.png", 15 * l),
                png(4),
            )
        })
        .collect();
    members[2].1 = padded;
    let zip = dir.path().join("padded.zip");
    write_deflated_zip(&zip, &members);
    assert!(std::fs::metadata(&zip).unwrap().len() < 1 << 20);
    let out = dir.path().join("out.zip");
    let err = fails(&["convert", s(&zip), "--out", s(&out)]);
    assert!(
        err.contains("00002 tl030") && err.contains("limit"),
        "{err}"
    );
    assert!(!out.exists());
}

/// Defect 7: `lpca` on more than 65,535 lights wrote a file its own reader rejected.
#[test]
fn lpca_refuses_more_lights_than_its_format_holds() {
    use btfmrf::btf::{Btf, BtfError, Direction, DirectionSet, ImageSource};
    struct Flat;
    impl ImageSource for Flat {
        fn load(&self, _: usize, _: usize) -> Result<Array3<f32>, BtfError> {
            Ok(Array3::from_elem((3, 1, 1), 0.5))
        }
        fn describe(&self, v: usize, l: usize) -> String {
            format!("flat {v} {l}")
        }
    }
    let lights = (0..65_536)
        .map(|i| Direction::new(f64::from(i % 90), f64::from(i / 90)))
        .collect();
    let btf = Btf::from_source(
        "flat",
        DirectionSet::zenith(),
        DirectionSet::new(lights).unwrap(),
        1,
        1,
        Box::new(Flat),
    )
    .unwrap();
    let options = btfmrf::lpca::LpcaOptions {
        clusters: 1,
        components: 1,
        ..Default::default()
    };
    let Err(err) = btfmrf::lpca::LpcaModel::fit(&btf, &options, &btfmrf::progress::NoProgress)
    else {
        panic!("more lights than the format holds must be refused");
    };
    let err = err.to_string();
    assert!(
        err.contains("65536 lights") && err.contains("at most 65535"),
        "{err}"
    );
}

/// Defect 7: `--clusters` above the format's limit is blamed on `--clusters`.
#[test]
fn too_many_clusters_blames_clusters() {
    let dir = temp();
    let zip = tiny_btf(&dir.path().join("a.zip"), 4, ImageFormat::Png);
    let out = dir.path().join("x.lpca");
    let err = fails(&["lpca", s(&zip), "--clusters", "100000", "--out", s(&out)]);
    assert!(
        err.contains("--clusters") && !err.contains("--components"),
        "{err}"
    );
    assert!(!out.exists());
}

/// An RTI folder `set/` with one image inside and `secret.png` beside it; `dirs.lp` lists
/// `listed` (with a light straight above).
fn rti_set(dir: &Path, listed: &str) -> std::path::PathBuf {
    let set = dir.join("set");
    std::fs::create_dir_all(&set).unwrap();
    std::fs::write(set.join("a.png"), png(4)).unwrap();
    std::fs::write(dir.join("secret.png"), png(4)).unwrap();
    std::fs::write(
        set.join("dirs.lp"),
        format!("2\na.png 0 0 1\n{listed} 0.6 0 0.8\n"),
    )
    .unwrap();
    set
}

/// Defect 7: images a `dirs.lp` names must stay inside the set's folder (`../x`, absolute
/// paths and links out are refused), unless BTFMRF_ALLOW_OUTSIDE=1; UBO folders agree.
#[test]
fn lp_files_cannot_reach_outside_their_folder() {
    let dir = temp();
    let secret = dir.path().join("secret.png");
    for listed in ["../secret.png", s(&secret)] {
        let set = rti_set(dir.path(), listed);
        let err = fails(&["info", s(&set)]);
        assert!(err.contains("must stay inside"), "{listed}: {err}");
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_btfmrf"))
            .args(["info", s(&set)])
            .env("BTFMRF_ALLOW_OUTSIDE", "1")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // A link inside the folder pointing out of it.
    let set = rti_set(dir.path(), "b.png");
    std::os::unix::fs::symlink(&secret, set.join("b.png")).unwrap();
    let err = fails(&["info", s(&set)]);
    assert!(err.contains("'b.png' lies outside"), "{err}");
    // A link that stays inside is an ordinary image.
    std::fs::remove_file(set.join("b.png")).unwrap();
    std::os::unix::fs::symlink(set.join("a.png"), set.join("b.png")).unwrap();
    ok(&["info", s(&set)]);
    // The UBO folder reader applies the same rule.
    let ubo = dir.path().join("ubo");
    std::fs::create_dir(&ubo).unwrap();
    std::fs::write(ubo.join("0 tl000 pl000 tv000 pv000.png"), png(4)).unwrap();
    std::os::unix::fs::symlink(&secret, ubo.join("1 tl015 pl000 tv000 pv000.png")).unwrap();
    let err = fails(&["info", s(&ubo)]);
    assert!(err.contains("lies outside"), "{err}");
}

/// Defect 8: names and contents are echoed with control characters escaped, so a member name
/// cannot forge a second terminal line or colour it.
#[test]
fn control_characters_in_names_are_escaped() {
    let dir = temp();
    let zip = dir.path().join("names.zip");
    write_zip(
        &zip,
        &[("x\u{1b}[2K\nerror: all fine tl000.png".to_string(), png(4))],
    );
    let err = fails(&["info", s(&zip)]);
    assert!(err.contains("\\u{1b}[2K\\nerror: all fine"), "{err}");
}

/// Defect 8: an I/O error printed its cause twice (the message and its source).
#[test]
fn io_errors_name_their_cause_once() {
    let err = fails(&["info", "/nonexistent/btf.zip"]);
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
}

/// Defect 8: a UTF-8 byte-order mark starts many real `.lp` files.
#[test]
fn byte_order_mark_in_dirs_lp_is_skipped() {
    let dir = temp();
    let set = rti_set(dir.path(), "a.png");
    let text = std::fs::read_to_string(set.join("dirs.lp")).unwrap();
    std::fs::write(set.join("dirs.lp"), format!("\u{feff}{text}")).unwrap();
    let info = ok(&["info", s(&set), "--json"]);
    assert!(info.contains("\"lights\":2"), "{info}");
}

/// Defect 8: `--out x.jpeg` is an image (it silently became a folder); an image extension we
/// do not write is refused instead.
#[test]
fn synthesize_output_extensions() {
    let dir = temp();
    let args = |out: &Path| {
        [
            "synthesize".to_string(),
            s(&golden_model()).to_string(),
            "--size".into(),
            "32".into(),
            "--view".into(),
            "0,0".into(),
            "--light".into(),
            "45,90".into(),
            "--out".into(),
            s(out).to_string(),
        ]
    };
    let jpeg = dir.path().join("x.jpeg");
    let a = args(&jpeg);
    ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(jpeg.is_file(), "a file, not a folder");
    assert!(io::read_image(&jpeg).is_ok());
    let tiff = dir.path().join("x.tiff");
    let a = args(&tiff);
    let err = fails(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(err.contains(".tiff images are not supported"), "{err}");
    assert!(!tiff.exists());
}

/// Defect 8: the `.btfm` envelope's flags other than the deflate flag must be zero (a later
/// version's file is refused, not misread); files written so far still load.
#[test]
fn unknown_model_flags_are_refused() {
    let good = std::fs::read(golden_model()).unwrap();
    assert!(btfmrf::model::format::from_bytes(&good, Path::new("g.btfm")).is_ok());
    for models in std::fs::read_dir(common::repo().join("models")).unwrap() {
        let p = models.unwrap().path();
        if p.extension().is_some_and(|e| e == "btfm") {
            btfmrf::model::format::read(&p).unwrap();
        }
    }
    let mut flagged = good.clone();
    flagged[6] = 2;
    let err = btfmrf::model::format::from_bytes(&flagged, Path::new("f.btfm"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("unknown flags 0x0002"), "{err}");
    let lpca = {
        let mut f = lpca_file(1, &[]);
        f[7] = 0x80;
        f
    };
    let err = btfmrf::lpca::format::from_bytes(&lpca, Path::new("f.lpca"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("unknown flags 0x8000"), "{err}");
}

/// Defect 8: out-of-range angles in a UBO name (tl095, pv400 read as pv040) are an error.
#[test]
fn out_of_range_angles_in_names_are_refused() {
    for (name, field) in [
        ("0 tl095 pl000 tv000 pv000.png", "tl095"),
        ("0 tl015 pl000 tv015 pv400.png", "pv400"),
    ] {
        let dir = temp();
        let zip = dir.path().join("a.zip");
        write_zip(&zip, &[(name.to_string(), png(4))]);
        let err = fails(&["info", s(&zip)]);
        assert!(err.contains(field) && err.contains("out of range"), "{err}");
    }
}
