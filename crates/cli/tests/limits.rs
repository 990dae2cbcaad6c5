//! Memory and signals: every reader stays within a bound on hostile files (counted in this
//! process, and the real binary run under a 1 GiB address-space limit), interrupts leave no
//! temporaries, and the memory budget refuses what it cannot hold while its estimates bound the
//! measured peaks.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use btfmrf::btf::{Btf, ImageFormat, io};
use common::*;
use ndarray::Array3;

/// Counts the bytes this test process holds, and their peak.
struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = CURRENT.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            let now = CURRENT.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        unsafe { System.dealloc(p, layout) };
        CURRENT.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, layout: Layout, new: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, layout, new) };
        if !q.is_null() {
            if new >= layout.size() {
                let now =
                    CURRENT.fetch_add(new - layout.size(), Ordering::Relaxed) + new - layout.size();
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                CURRENT.fetch_sub(layout.size() - new, Ordering::Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Tests that allocate much in this process take turns, so that a peak is one reader's.
static SERIAL: Mutex<()> = Mutex::new(());

/// The most bytes `f` held at once beyond what was held before it.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = CURRENT.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed).saturating_sub(base))
}

/// A zip of `n` empty members whose views and lights are all distinct.
fn many_members_zip(path: &Path, n: usize) {
    let members: Vec<(String, Vec<u8>)> = (0..n)
        .map(|i| {
            let (t, p) = (1 + i % 89, (i / 89) % 360);
            (
                format!("{i:05} tl{t:03} pl{p:03} tv{t:03} pv{p:03}.png"),
                Vec::new(),
            )
        })
        .collect();
    write_zip(path, &members);
}

/// A 16^2 JPEG whose header claims `claim`^2 pixels.
fn jpeg_claiming(claim: u16) -> Vec<u8> {
    let mut jpeg = io::picture::encode(
        &Array3::from_elem((3, 16, 16), 0.4),
        ImageFormat::Jpeg { quality: 90 },
        "x",
    )
    .unwrap();
    let sof = jpeg.windows(2).position(|w| w == [0xff, 0xc0]).unwrap();
    jpeg[sof + 5..sof + 9].copy_from_slice(&[
        (claim >> 8) as u8,
        claim as u8,
        (claim >> 8) as u8,
        claim as u8,
    ]);
    jpeg
}

/// A `.lpca` file claiming a `side`^2 model whose weights are missing.
fn hollow_lpca(side: u32) -> Vec<u8> {
    let mut p = vec![0u8];
    p.extend_from_slice(&side.to_le_bytes());
    p.extend_from_slice(&side.to_le_bytes());
    p.extend_from_slice(&1u16.to_le_bytes());
    for _ in 0..2 {
        p.extend_from_slice(&1u16.to_le_bytes());
        p.extend_from_slice(&[0; 8]);
    }
    p.extend_from_slice(&1u16.to_le_bytes());
    p.extend_from_slice(&[0; 12]);
    let mut f = b"LPCA\x01\x00\x00\x00".to_vec();
    f.extend_from_slice(&(p.len() as u32).to_le_bytes());
    f.extend_from_slice(&p);
    f.extend_from_slice(&crc32fast::hash(&p).to_le_bytes());
    f
}

/// A zip of four 4x4 PNGs under one view, member 2 padded with `pad` zero bytes (deflated).
fn padded_zip(path: &Path, pad: usize) {
    use std::io::Write;
    let png =
        io::picture::encode(&Array3::from_elem((3, 4, 4), 0.2), ImageFormat::Png, "x").unwrap();
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .large_file(true);
    for l in 0..4 {
        zip.start_file(
            format!("{l:05} tl{:03} pl000 tv000 pv000.png", 15 * l),
            options,
        )
        .unwrap();
        zip.write_all(&png).unwrap();
        if l == 2 {
            zip.write_all(&vec![0u8; pad]).unwrap();
        }
    }
    zip.finish().unwrap();
}

/// Each reader on a hostile file holds at most a small bound (counted allocations): a file's
/// claims are checked against its length before anything of the claimed size is allocated.
#[test]
fn readers_allocate_within_their_bounds() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let dir = temp();
    let mb = 1usize << 20;

    let lpca = hollow_lpca(16384);
    let (r, peak) = peak_of(|| btfmrf::lpca::format::from_bytes(&lpca, Path::new("x.lpca")));
    assert!(r.is_err() && peak < mb, ".lpca: {peak} bytes");

    let zip = dir.path().join("many.zip");
    many_members_zip(&zip, 6000);
    let (r, peak) = peak_of(|| Btf::open(&zip));
    assert!(
        r.is_err() && peak < 32 * mb,
        "6000-member zip: {peak} bytes"
    );

    let jpeg = jpeg_claiming(16384);
    let (r, peak) = peak_of(|| io::picture::decode(&jpeg, "x.jpg"));
    assert!(
        r.is_err() && peak < mb,
        "JPEG claiming 16384^2: {peak} bytes"
    );

    let padded = dir.path().join("padded.zip");
    padded_zip(&padded, 256 << 20);
    let btf = Btf::open(&padded).unwrap(); // headers are fine
    let (r, peak) = peak_of(|| btf.image(0, 2));
    assert!(r.is_err() && peak < 40 * mb, "padded member: {peak} bytes");

    let set = dir.path().join("set");
    std::fs::create_dir(&set).unwrap();
    let lp: String = std::iter::once("1000000\n".to_string())
        .chain((0..100_000).map(|i| format!("../../../../etc/x{i}.png 0 0 1\n")))
        .collect();
    std::fs::write(set.join("dirs.lp"), &lp).unwrap();
    let (r, peak) = peak_of(|| Btf::open(&set));
    assert!(
        r.is_err() && peak < 16 * lp.len(),
        "dirs.lp: {peak} bytes for {}",
        lp.len()
    );
}

/// One GiB of address space for a child process.
const ONE_GIB: u64 = 1 << 30;

/// The binary under an address-space limit: its exit code (`None` when killed by a signal) and
/// stderr.
fn run_limited(args: &[&str], bytes: u64) -> (Option<i32>, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_btfmrf"));
    cmd.args(args);
    unsafe {
        cmd.pre_exec(move || {
            let limit = libc::rlimit {
                rlim_cur: bytes,
                rlim_max: bytes,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let out = cmd.output().expect("the binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The real binary on each hostile file under a 1 GiB address-space limit: one clean error
/// line, never an abort. (A plain command under the same limit works: the allocator copes.)
#[test]
fn the_binary_reads_hostile_files_within_one_gib_of_address_space() {
    let dir = temp();
    let d = |name: &str| dir.path().join(name);
    let good = tiny_btf(&d("good.zip"), 4, ImageFormat::Png);
    let (code, err) = run_limited(&["info", s(&good)], ONE_GIB);
    assert_eq!(code, Some(0), "{err}");

    many_members_zip(&d("many.zip"), 6000);
    padded_zip(&d("padded.zip"), 256 << 20);
    write_zip(
        &d("claim.zip"),
        &[(
            "0 tl000 pl000 tv000 pv000.jpg".to_string(),
            jpeg_claiming(16384),
        )],
    );
    std::fs::write(d("hollow.lpca"), hollow_lpca(16384)).unwrap();
    let mut flagged = std::fs::read(common::repo().join("tests/golden/sponge64.btfm")).unwrap();
    flagged[6] = 2;
    std::fs::write(d("flagged.btfm"), flagged).unwrap();
    let p = |name: &str| s(&d(name)).to_string();
    let cases: [(Vec<String>, &str); 5] = [
        (vec!["info".into(), p("many.zip")], "missing"),
        (
            vec![
                "convert".into(),
                p("padded.zip"),
                "--out".into(),
                p("o.zip"),
            ],
            "limit",
        ),
        (
            vec!["convert".into(), p("claim.zip"), "--out".into(), p("q.zip")],
            "truncated JPEG",
        ),
        (
            vec![
                "synthesize".into(),
                p("hollow.lpca"),
                "--out".into(),
                p("out.png"),
            ],
            "weights",
        ),
        (
            vec![
                "synthesize".into(),
                p("flagged.btfm"),
                "--size".into(),
                "64".into(),
                "--out".into(),
                p("out.png"),
            ],
            "unknown flags",
        ),
    ];
    for (args, expected) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, err) = run_limited(&args, ONE_GIB);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(lines.len(), 1, "{args:?}: {err}");
        assert!(lines[0].contains(expected), "{args:?}: {err}");
    }
}

/// Temporaries (`.btfmrf-partial-*`) in `dir`.
fn partials(dir: &Path) -> Vec<String> {
    entries(dir)
        .into_iter()
        .filter(|n| n.starts_with(".btfmrf-partial-"))
        .collect()
}

/// Starts `generate` into `out`, waits until its temporary exists, sends `signal`, and
/// returns the exit code and stderr.
fn interrupt_generate(out: &Path, signal: i32) -> (Option<i32>, String) {
    let dir = out.parent().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_btfmrf"))
        .args(["generate", "sponge", "--size", "256", "--out", s(out)])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while partials(dir).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no temporary appeared"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "finished before the signal"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(300)); // well into the writing
    unsafe { libc::kill(child.id() as i32, signal) };
    let out = child.wait_with_output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// SIGINT during a zip write and SIGTERM during a folder write: the temporary is removed, the
/// error line says so, and the exit status is 130.
#[test]
fn interrupts_remove_temporaries() {
    for (name, signal) in [("x.zip", libc::SIGINT), ("folder", libc::SIGTERM)] {
        let dir = temp();
        let out = dir.path().join(name);
        let (code, err) = interrupt_generate(&out, signal);
        assert_eq!(code, Some(130), "{name}: {err}");
        assert!(
            err.contains("error: interrupted; removed 1 partial output"),
            "{err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(partials(dir.path()), Vec::<String>::new(), "{name}");
        assert!(!out.exists());
    }
}

/// Exit status, peak resident set (bytes) and stderr of the binary.
fn measured(args: &[&str]) -> (i32, u64, String) {
    let err_file = tempfile::NamedTempFile::new().unwrap();
    #[expect(
        clippy::zombie_processes,
        reason = "reaped by wait4 below, which also reports the peak memory"
    )]
    let child = Command::new(env!("CARGO_BIN_EXE_btfmrf"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(err_file.reopen().unwrap())
        .spawn()
        .unwrap();
    let mut status = 0;
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let pid = unsafe { libc::wait4(child.id() as i32, &mut status, 0, &mut usage) };
    assert_eq!(pid, child.id() as i32);
    let code = if libc::WIFEXITED(status) {
        libc::WEXITSTATUS(status)
    } else {
        -1
    };
    let err = std::fs::read_to_string(err_file.path()).unwrap();
    (code, usage.ru_maxrss as u64 * 1024, err)
}

/// Estimate / measured peak: the estimate must cover the peak and stay within this factor.
const FACTOR: f64 = 3.0;

fn check_estimate(what: &str, estimate: u64, measured: u64) {
    let ratio = estimate as f64 / measured as f64;
    eprintln!("{what}: estimate {estimate}, measured peak {measured}, ratio {ratio:.2}");
    assert!(
        (1.0..=FACTOR).contains(&ratio),
        "{what}: estimate {estimate} vs measured {measured}"
    );
}

/// The synthesis, analysis and LPCA estimates against the peaks measured on the real binary.
#[test]
fn estimates_bound_the_measured_peaks() {
    let dir = temp();
    let model = common::repo().join("tests/golden/sponge64.btfm");
    let m = btfmrf::model::format::read(&model).unwrap();
    let out = dir.path().join("x.png");
    let (view, light) = (
        btfmrf::btf::Direction::new(0.0, 0.0),
        btfmrf::btf::Direction::new(45.0, 90.0),
    );
    let k = m.subspace_weights(&view, &light).unwrap().len();
    // The binary runs on as many worker threads as this process.
    let threads = btfmrf::memory::worker_threads();
    let size = 1024;
    let (code, peak, err) = measured(&[
        "synthesize",
        s(&model),
        "--size",
        &size.to_string(),
        "--view",
        "0,0",
        "--light",
        "45,90",
        "--out",
        s(&out),
    ]);
    assert_eq!(code, 0, "{err}");
    check_estimate(
        "synthesize 1024^2",
        btfmrf::memory::synthesis_bytes(size, size, k),
        peak,
    );

    let zip = tiny_btf(&dir.path().join("t.zip"), 16, ImageFormat::Png);
    let images = 81 * 81;
    let (code, peak, err) = measured(&[
        "analyze",
        s(&zip),
        "--clusters",
        "8",
        "--out",
        s(&dir.path().join("t.btfm")),
    ]);
    assert_eq!(code, 0, "{err}");
    check_estimate(
        "analyze 16^2",
        btfmrf::memory::analysis_bytes(16, 16, images, 8, threads),
        peak,
    );

    let (code, peak, err) = measured(&[
        "synthesize",
        s(&model),
        "--size",
        "256",
        "--view",
        "0,0",
        "--view",
        "15,0",
        "--view",
        "30,0",
        "--view",
        "45,0",
        "--out",
        s(&dir.path().join("all.zip")),
    ]);
    assert_eq!(code, 0, "{err}");
    let all = m.subspaces().len();
    check_estimate(
        "synthesize a 256^2 BTF",
        btfmrf::memory::btf_synthesis_bytes(256, 256, all, threads),
        peak,
    );

    let (code, peak, err) = measured(&[
        "lpca",
        s(&zip),
        "--clusters",
        "4",
        "--components",
        "2",
        "--out",
        s(&dir.path().join("t.lpca")),
    ]);
    assert_eq!(code, 0, "{err}");
    check_estimate(
        "lpca 16^2",
        btfmrf::memory::lpca_bytes(16, 16, images, threads),
        peak,
    );

    // Rendering needs a GPU adapter (lavapipe will do); without one it is skipped.
    let (code, peak, err) = measured(&[
        "render",
        s(&model),
        "--out",
        s(&dir.path().join("r.png")),
        "--tile",
        "512",
        "--size",
        "256",
    ]);
    if code != 0 && err.contains("no GPU adapter") {
        eprintln!("skipping the render estimate: {err}");
        return;
    }
    assert_eq!(code, 0, "{err}");
    check_estimate(
        "render, 512^2 tile",
        btfmrf::memory::render_bytes(256 * 256, 512, all, threads),
        peak,
    );
}

/// Over the budget: exit status 2 and a message naming a size that fits, which then runs
/// within that budget.
#[test]
fn requests_over_the_budget_are_refused_with_a_size_that_fits() {
    let dir = temp();
    let model: PathBuf = common::repo().join("tests/golden/sponge64.btfm");
    let out = dir.path().join("x.png");
    let args = |size: &str| {
        vec![
            "synthesize".to_string(),
            s(&model).into(),
            "--size".into(),
            size.into(),
            "--view".into(),
            "0,0".into(),
            "--light".into(),
            "45,90".into(),
            "--out".into(),
            s(&out).into(),
            "--memory-limit".into(),
            "300M".into(),
        ]
    };
    let a = args("8192");
    let (code, _, err) = measured(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(code, 2, "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("--memory-limit") && !out.exists(), "{err}");
    let fits: usize = err
        .split("--size ")
        .nth(2)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("names a size: {err}"));
    assert!((256..8192).contains(&fits), "{err}");
    let a = args(&fits.to_string());
    let (code, peak, err) = measured(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(code, 0, "{err}");
    assert!(
        peak <= 300 << 20,
        "the suggested size peaked at {peak} bytes"
    );

    // The other commands refuse the same way.
    let zip = tiny_btf(&dir.path().join("t.zip"), 16, ImageFormat::Png);
    for args in [
        vec![
            "analyze",
            s(&zip),
            "--out",
            "never.btfm",
            "--memory-limit",
            "1M",
        ],
        vec![
            "lpca",
            s(&zip),
            "--out",
            "never.lpca",
            "--memory-limit",
            "1M",
        ],
        vec!["bench", s(&zip), "--out", "never", "--memory-limit", "1M"],
        vec!["demo", "--out", "never", "--memory-limit", "1M"],
    ] {
        let (code, _, err) = measured(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(
            err.starts_with("error: ") && err.contains("above the budget"),
            "{err}"
        );
    }
    let (code, _, err) = measured(&["info", s(&zip), "--memory-limit", "lots"]);
    assert_eq!(code, 2, "clap's usage error: {err}");
}

/// A small seeded xorshift generator for the mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One random mutation of `input` (bit flips, interesting bytes and integers, inserted,
/// deleted or repeated runs, a splice with `other`, truncation), as libFuzzer's do.
fn mutate(input: &[u8], other: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(v.len() + 1);
        let last = at.min(v.len().saturating_sub(1));
        match rng.below(8) {
            0 if !v.is_empty() => v[last] ^= 1 << rng.below(8),
            1 if !v.is_empty() => v[last] = [0, 1, 0x7f, 0x80, 0xff][rng.below(5)],
            2 if v.len() >= 4 => {
                let at = at.min(v.len() - 4);
                let x: u32 = [0, 1, u32::MAX, 0x7fff_ffff, 65_535, 65_536, 16_384][rng.below(7)];
                v[at..at + 4].copy_from_slice(&x.to_le_bytes());
            }
            3 => {
                let n = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                v.splice(at..at, bytes);
            }
            4 if !v.is_empty() => {
                let n = 1 + rng.below(16.min(v.len() - at.min(v.len() - 1)));
                let at = at.min(v.len() - 1);
                v.drain(at..(at + n).min(v.len()));
            }
            5 if !v.is_empty() => {
                let at = at.min(v.len() - 1);
                let run = v[at..(at + 1 + rng.below(64)).min(v.len())].to_vec();
                v.splice(at..at, run);
            }
            6 if !other.is_empty() => {
                let from = rng.below(other.len());
                let n = 1 + rng.below(other.len() - from);
                let at = at.min(v.len());
                v.splice(at..at, other[from..from + n].iter().copied());
            }
            _ => v.truncate(at),
        }
    }
    v
}

/// A reader under test: takes any bytes, may fail, must not panic.
type Target = Box<dyn Fn(&[u8])>;

fn envelope(magic: &[u8; 4], payload: &[u8]) -> Vec<u8> {
    let mut f = magic.to_vec();
    f.extend_from_slice(&[1, 0, 0, 0]);
    f.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    f.extend_from_slice(payload);
    f.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    f
}

/// The targets of `fuzz/fuzz_targets/`, run in this process, and their seeds.
fn targets(scratch: &Path) -> Vec<(&'static str, Target, Vec<Vec<u8>>)> {
    let root = common::repo();
    let seeds = |name: &str| -> Vec<Vec<u8>> {
        let mut v: Vec<Vec<u8>> = std::fs::read_dir(root.join("fuzz/seeds").join(name))
            .map(|d| {
                d.map(|e| std::fs::read(e.unwrap().path()).unwrap())
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    };
    let model = std::fs::read(root.join("tests/golden/sponge64.btfm")).unwrap();
    let png =
        io::picture::encode(&Array3::from_elem((3, 4, 4), 0.3), ImageFormat::Png, "x").unwrap();
    let jpeg = io::picture::encode(
        &Array3::from_elem((3, 8, 8), 0.3),
        ImageFormat::Jpeg { quality: 80 },
        "x",
    )
    .unwrap();
    let set = scratch.join("set");
    std::fs::create_dir_all(&set).unwrap();
    std::fs::write(set.join("a.png"), &png).unwrap();
    std::fs::write(set.join("b.png"), &png).unwrap();
    let secret =
        io::picture::encode(&Array3::from_elem((3, 5, 3), 0.3), ImageFormat::Png, "x").unwrap();
    std::fs::write(scratch.join("secret.png"), secret).unwrap();
    let zip_path = scratch.join("fuzz.zip");
    let p = |s: &str| Path::new(s).to_path_buf();
    vec![
        (
            "btfm",
            Box::new(move |d: &[u8]| {
                // What parses re-encodes to a fixed point (older versions and non-canonical
                // values are accepted and written in today's form, so not to the input).
                if let Ok(m) = btfmrf::model::format::from_bytes(d, &p("f.btfm")) {
                    let bytes = btfmrf::model::format::to_bytes(&m);
                    let again = btfmrf::model::format::from_bytes(&bytes, &p("f.btfm")).unwrap();
                    assert_eq!(btfmrf::model::format::to_bytes(&again), bytes);
                }
            }) as Target,
            vec![model.clone()],
        ),
        (
            "btfm_payload",
            Box::new(|d: &[u8]| {
                let file = envelope(b"BTFM", d);
                if let Ok(m) = btfmrf::model::format::from_bytes(&file, Path::new("f")) {
                    let bytes = btfmrf::model::format::to_bytes(&m);
                    let again = btfmrf::model::format::from_bytes(&bytes, Path::new("f")).unwrap();
                    assert_eq!(btfmrf::model::format::to_bytes(&again), bytes);
                }
            }),
            [
                vec![model[12..model.len() - 4].to_vec()],
                seeds("btfm_payload"),
            ]
            .concat(),
        ),
        (
            "lpca",
            Box::new(|d: &[u8]| {
                let file = envelope(b"LPCA", d);
                if let Ok(m) = btfmrf::lpca::format::from_bytes(&file, Path::new("f")) {
                    let bytes = btfmrf::lpca::format::to_bytes(&m);
                    let again = btfmrf::lpca::format::from_bytes(&bytes, Path::new("f")).unwrap();
                    assert_eq!(btfmrf::lpca::format::to_bytes(&again), bytes);
                }
            }),
            seeds("lpca"),
        ),
        (
            "image_decode",
            Box::new(|d: &[u8]| {
                let _ = io::picture::probe_size(d, "f");
                let _ = io::picture::decode(d, "f");
            }),
            vec![png.clone(), jpeg],
        ),
        (
            "light_positions",
            Box::new(|d: &[u8]| {
                let _ = io::rti::parse_lp(&String::from_utf8_lossy(d), Path::new("f.lp"));
            }),
            seeds("folder_lp"),
        ),
        (
            "zip_reader",
            Box::new(move |d: &[u8]| {
                std::fs::write(&zip_path, d).unwrap();
                if let Ok(btf) = Btf::open(&zip_path) {
                    let _ = btf.image(0, 0);
                }
            }),
            seeds("zip_reader"),
        ),
        (
            "folder_lp",
            Box::new(move |d: &[u8]| {
                std::fs::write(set.join("dirs.lp"), d).unwrap();
                if let Ok(btf) = Btf::open(&set) {
                    assert_eq!((btf.width(), btf.height()), (4, 4), "read from outside");
                }
            }),
            seeds("folder_lp"),
        ),
    ]
}

/// The fall-back fuzzer of `scripts/fuzz` (where cargo-fuzz cannot be built): every target
/// for FUZZ_SECONDS (default 60) on seeded mutations of its seeds, each input's allocations
/// held under 2 GB (counted), a panic or a blow-up reported with the input saved to
/// target/fuzz-findings/. Prints the executions per target.
#[test]
#[ignore = "a bounded fuzz run of a minute per target: scripts/fuzz"]
fn mutation_fuzz() {
    let _turn = SERIAL.lock().unwrap_or_else(|p| p.into_inner());
    let seconds: u64 = std::env::var("FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let only = std::env::var("FUZZ_TARGET").ok();
    let scratch = temp();
    let findings_dir = common::repo().join("target/fuzz-findings");
    let mut findings = 0;
    std::panic::set_hook(Box::new(|_| {})); // panics are counted, not printed
    for (name, target, seeds) in targets(scratch.path()) {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let mut corpus = seeds;
        assert!(!corpus.is_empty(), "{name}: no seeds");
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ name.len() as u64);
        let start = Instant::now();
        let (mut runs, mut found) = (0u64, 0u32);
        while start.elapsed() < Duration::from_secs(seconds) {
            let a = rng.below(corpus.len());
            let b = rng.below(corpus.len());
            let input = mutate(&corpus[a], &corpus[b], &mut rng);
            let (outcome, peak) = peak_of(|| {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| target(&input)))
            });
            runs += 1;
            if outcome.is_err() || peak > 2 << 30 {
                found += 1;
                std::fs::create_dir_all(&findings_dir).unwrap();
                std::fs::write(findings_dir.join(format!("{name}-{runs}")), &input).unwrap();
            } else if runs % 64 == 0 && corpus.len() < 256 && input.len() < 1 << 16 {
                corpus.push(input); // keep some variety to mutate further
            }
        }
        findings += found;
        println!("fuzz: {name}: {runs} executions in {seconds} s, {found} finding(s)");
    }
    let _ = std::panic::take_hook();
    assert_eq!(findings, 0, "inputs saved in {}", findings_dir.display());
}
