//! The memory budget: peak-memory estimates of the long commands, pure functions of the sizes and
//! worker threads they are given, checked before any work starts so that a request the machine
//! cannot hold is refused with a size that fits instead of being killed half-way.
//!
//! The constants are measured peaks (resident set, `crates/cli/tests/limits.rs` checks each estimate
//! against a spawned command's measured peak) rounded up: an estimate errs on the large side.

/// Everything that is not proportional to the sizes: the binary, thread stacks, the allocator's
/// arenas, small tables. Bytes (`btfmrf info` on a small BTF peaks at 25 MB).
pub const BASE_BYTES: u64 = 48 << 20;

/// Bytes a synthesized pixel costs once, whatever the number of subspaces: the bands and noise
/// of the subspaces made in parallel, the range map and its normals, the output image.
const SYNTH_PER_PIXEL: u64 = 128;
/// Bytes a synthesized pixel costs per subspace image drawn on: the `(3, rows, cols)` f32
/// image kept in the cache and its share of the working planes.
const SYNTH_PER_PIXEL_SUBSPACE: u64 = 64;
/// Images a BTF writer holds at once (`ubo2003::encode_in_order` encodes 96 at a time), each
/// as f32 (12 bytes a pixel) and encoded (at most 4 bytes a pixel for PNG).
const WRITER_IMAGES: u64 = 96;
const WRITER_PER_PIXEL: u64 = 16;
/// Bytes per pixel each worker thread holds while it relights one image of a synthesized BTF
/// from the cached subspace images: a 256^2 BTF of four views peaked at 136 MB on one thread,
/// 138 MB on two, 161-179 MB on four, 245-267 MB on eight and 381-426 MB on sixteen.
const WRITER_PER_PIXEL_THREAD: u64 = 320;

/// Bytes per measured value (texel x view x light x colour): the analysis streams the images,
/// keeping a little per value (histograms, the frontal view's photometric stereo).
const ANALYZE_PER_VALUE: u64 = 1;
/// Bytes per texel per subspace image: the subspace images and their pyramids and fits.
const ANALYZE_PER_TEXEL_SUBSPACE: u64 = 512;
/// Bytes per worker thread the analysis adds whatever the size: each thread decodes and
/// histograms images in its own allocator arena. A 16^2 BTF of 6561 images peaked at 33 MB
/// on one thread, 43-60 MB on two, 59-83 MB on eight and 76-96 MB on sixteen.
const ANALYZE_PER_THREAD: u64 = 10 << 20;

/// Bytes per measured value an LPCA fit holds: the BTF as f32, the working copy the
/// factorization reads and the reconstruction measured against it (11.4 measured).
const LPCA_PER_VALUE: u64 = 16;
/// Bytes per worker thread an LPCA fit holds whatever the size: the linear algebra's
/// workspaces. A 16^2 BTF of 6561 images peaked at 105-107 MB on one thread, 122-140 MB on
/// two, 159-171 MB on four, 231-237 MB on eight and 311-365 MB on sixteen.
const LPCA_PER_THREAD: u64 = 24 << 20;

/// The GPU driver's own memory (lavapipe, the software Vulkan driver, takes most).
const RENDER_DRIVER_BYTES: u64 = 160 << 20;
/// Bytes per window pixel: render targets, depth, read-back and the output image.
const RENDER_PER_PIXEL: u64 = 256;
/// What each worker thread adds to a render, a fixed part and a part per texel of the tile:
/// its share of the textures made in parallel. A 256^2 window peaked at 216 / 328 MB (one /
/// sixteen threads) with a 256^2 tile, 271 / 434 MB with 512^2 and 460 / 764 MB with 1024^2.
const RENDER_PER_THREAD: u64 = 6 << 20;
const RENDER_PER_TEXEL_THREAD: u64 = 24;

/// Peak bytes of synthesizing `rows` x `cols` images that draw on `subspaces` subspace images.
pub fn synthesis_bytes(rows: usize, cols: usize, subspaces: usize) -> u64 {
    let pixels = rows as u64 * cols as u64;
    BASE_BYTES + pixels * (SYNTH_PER_PIXEL + SYNTH_PER_PIXEL_SUBSPACE * subspaces as u64)
}

/// Peak bytes of synthesizing a BTF of `rows` x `cols` images drawing on `subspaces` subspace
/// images and writing it (zip or folder) on `threads` worker threads ([`worker_threads`]): the
/// synthesis, the images the writer holds and the image each thread is relighting.
pub fn btf_synthesis_bytes(rows: usize, cols: usize, subspaces: usize, threads: usize) -> u64 {
    let pixels = rows as u64 * cols as u64;
    synthesis_bytes(rows, cols, subspaces)
        + pixels * (WRITER_IMAGES * WRITER_PER_PIXEL + threads as u64 * WRITER_PER_PIXEL_THREAD)
}

/// Peak bytes of analysing a `width` x `height` BTF of `images` images into `clusters`
/// subspace images on `threads` worker threads ([`worker_threads`]).
pub fn analysis_bytes(
    width: usize,
    height: usize,
    images: usize,
    clusters: usize,
    threads: usize,
) -> u64 {
    let texels = width as u64 * height as u64;
    BASE_BYTES
        + threads as u64 * ANALYZE_PER_THREAD
        + texels * 3 * images as u64 * ANALYZE_PER_VALUE
        + texels * clusters as u64 * ANALYZE_PER_TEXEL_SUBSPACE
}

/// The worker threads this process's parallel stages run on (rayon's global pool).
pub fn worker_threads() -> usize {
    rayon::current_num_threads()
}

/// Peak bytes of an LPCA fit of a `width` x `height` BTF of `images` images (for PCA RF, one
/// view's images: it holds one view at a time) on `threads` worker threads.
pub fn lpca_bytes(width: usize, height: usize, images: usize, threads: usize) -> u64 {
    BASE_BYTES
        + threads as u64 * LPCA_PER_THREAD
        + width as u64 * height as u64 * 3 * images as u64 * LPCA_PER_VALUE
}

/// Peak bytes of rendering `pixels` window pixels with a `texture` x `texture` texture drawn
/// on `subspaces` subspace images, on `threads` worker threads; count each measured pair the
/// render finishes with its own parts as one more (the ready stones' sphere with a 512^2 tile
/// peaked 107-149 MB higher with its 8 finishes, 51-71 bytes a texel each, and 565-607 MB
/// in all against the 814 MB this estimate gives them on two threads).
/// The textures are synthesized like any image ([`synthesis_bytes`]).
pub fn render_bytes(pixels: usize, texture: usize, subspaces: usize, threads: usize) -> u64 {
    let texels = texture as u64 * texture as u64;
    synthesis_bytes(texture, texture, subspaces)
        + RENDER_DRIVER_BYTES
        + pixels as u64 * RENDER_PER_PIXEL
        + threads as u64 * (RENDER_PER_THREAD + texels * RENDER_PER_TEXEL_THREAD)
}

/// The most subspace images one synthesized (view, light) image draws on: the 3 x 3 measured
/// pairs around it (`MaterialModel::subspace_weights`).
pub const SUBSPACES_PER_IMAGE: usize = 9;

/// Peak bytes of `btfmrf bench` (and of the benchmark inside `btfmrf demo`): the analysis on
/// `threads` worker threads, one `synthesis_side`^2 image, and with `baselines` the LPCA fits,
/// one after the other.
pub fn bench_bytes(
    (width, height, images): (usize, usize, usize),
    clusters: usize,
    synthesis_side: usize,
    baselines: bool,
    threads: usize,
) -> u64 {
    let subspaces = clusters.min(SUBSPACES_PER_IMAGE);
    let mrf = analysis_bytes(width, height, images, clusters, threads).max(synthesis_bytes(
        synthesis_side,
        synthesis_side,
        subspaces,
    ));
    if baselines {
        mrf.max(lpca_bytes(width, height, images, threads))
    } else {
        mrf
    }
}

/// The largest `n` in `1..=max` with `bytes(n) <= budget` (`bytes` growing with `n`), or
/// `None` when even 1 does not fit: the size a refusal suggests.
pub fn largest_fitting(max: usize, budget: u64, bytes: impl Fn(usize) -> u64) -> Option<usize> {
    if max == 0 || bytes(1) > budget {
        return None;
    }
    let (mut lo, mut hi) = (1usize, max); // bytes(lo) fits
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if bytes(mid) <= budget {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    Some(lo)
}

/// A request refused because its estimate exceeds the budget.
#[derive(Debug, thiserror::Error)]
#[error(
    "{what} needs about {} of memory, above the budget of {} ({}); {hint}",
    gib(*need),
    gib(*budget),
    if *from_flag { "--memory-limit" } else { "half this machine's memory; --memory-limit changes it" }
)]
pub struct OverBudget {
    /// The request, e.g. "synthesize --size 8192".
    pub what: String,
    /// The estimate, bytes.
    pub need: u64,
    /// The budget, bytes.
    pub budget: u64,
    /// Whether the budget came from `--memory-limit`.
    pub from_flag: bool,
    /// What would fit, e.g. "--size 4096 fits".
    pub hint: String,
}

fn gib(bytes: u64) -> String {
    format!("{:.2} GiB", bytes as f64 / f64::from(1 << 30))
}

/// How much memory a command may use, bytes, and where that number came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Budget {
    /// Bytes.
    pub bytes: u64,
    /// Whether the user set it (`--memory-limit`) rather than the default.
    pub from_flag: bool,
}

impl Budget {
    /// The user's limit, or half the machine's memory ([`machine_memory`]; 8 GiB when it
    /// cannot be read).
    pub fn new(limit: Option<u64>) -> Self {
        match limit {
            Some(bytes) => Self {
                bytes,
                from_flag: true,
            },
            None => Self {
                bytes: machine_memory().unwrap_or(16 << 30) / 2,
                from_flag: false,
            },
        }
    }

    /// Refuses `need` bytes over the budget; `hint` (called only then) names what would fit.
    ///
    /// # Errors
    /// [`OverBudget`] when `need` exceeds the budget.
    pub fn check(
        &self,
        what: impl Into<String>,
        need: u64,
        hint: impl FnOnce(u64) -> String,
    ) -> Result<(), OverBudget> {
        if need <= self.bytes {
            return Ok(());
        }
        Err(OverBudget {
            what: what.into(),
            need,
            budget: self.bytes,
            from_flag: self.from_flag,
            hint: hint(self.bytes),
        })
    }
}

/// Total memory of this machine, bytes (`MemTotal` in `/proc/meminfo`).
pub fn machine_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    parse_meminfo(&text)
}

fn parse_meminfo(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let mut fields = line.split_whitespace().skip(1);
    let value: u64 = fields.next()?.parse().ok()?;
    match fields.next() {
        Some("kB") => value.checked_mul(1024),
        None => Some(value),
        Some(_) => None,
    }
}

/// Parses a memory size: bytes, or a number with a unit K, M, G or T (powers of 1024, an
/// optional `B` or `iB` after it, any case), e.g. `2G`, `512MiB`, `1.5g`.
///
/// # Errors
/// A message saying what was expected.
pub fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim().to_ascii_lowercase();
    let t = t
        .strip_suffix("ib")
        .or_else(|| t.strip_suffix('b'))
        .unwrap_or(&t);
    let (number, shift) = match t.chars().last() {
        Some('k') => (&t[..t.len() - 1], 10),
        Some('m') => (&t[..t.len() - 1], 20),
        Some('g') => (&t[..t.len() - 1], 30),
        Some('t') => (&t[..t.len() - 1], 40),
        _ => (t, 0),
    };
    let bad = || format!("'{text}' is not a memory size (e.g. 2G, 512M, 1073741824)");
    let value: f64 = number.trim().parse().map_err(|_| bad())?;
    let bytes = value * (1u64 << shift) as f64;
    if !bytes.is_finite() || bytes < 1.0 || bytes >= u64::MAX as f64 {
        return Err(bad());
    }
    Ok(bytes as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_units() {
        assert_eq!(parse_bytes("2G"), Ok(2 << 30));
        assert_eq!(parse_bytes("512MiB"), Ok(512 << 20));
        assert_eq!(parse_bytes("1.5g"), Ok(3 << 29));
        assert_eq!(parse_bytes("4096"), Ok(4096));
        assert_eq!(parse_bytes(" 64 kb "), Ok(64 << 10));
        for bad in ["", "G", "-1G", "0", "two", "1e30T", "nan"] {
            assert!(parse_bytes(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn meminfo_total_is_read_in_bytes() {
        let text = "MemTotal:       24536848 kB\nMemFree:         1000 kB\n";
        assert_eq!(parse_meminfo(text), Some(24_536_848 * 1024));
        assert_eq!(parse_meminfo("MemFree: 1 kB\n"), None);
    }

    #[test]
    fn largest_fitting_is_the_boundary() {
        let bytes = |n: usize| 1000 + 10 * (n as u64) * (n as u64);
        for budget in [1000, 1010, 5000, 1_000_000, u64::MAX] {
            match largest_fitting(8192, budget, bytes) {
                None => assert!(bytes(1) > budget),
                Some(n) => {
                    assert!(bytes(n) <= budget);
                    assert!(n == 8192 || bytes(n + 1) > budget, "{budget}: {n}");
                }
            }
        }
        assert_eq!(largest_fitting(8192, 999, bytes), None);
    }

    #[test]
    fn estimates_grow_with_every_size() {
        assert!(synthesis_bytes(1024, 1024, 1) < synthesis_bytes(2048, 1024, 1));
        assert!(synthesis_bytes(1024, 1024, 1) < synthesis_bytes(1024, 1024, 2));
        assert!(analysis_bytes(64, 64, 81, 20, 2) < analysis_bytes(64, 64, 6561, 20, 2));
        assert!(analysis_bytes(64, 64, 81, 20, 2) < analysis_bytes(64, 64, 81, 40, 2));
        assert!(analysis_bytes(64, 64, 81, 20, 2) < analysis_bytes(64, 64, 81, 20, 16));
        assert!(lpca_bytes(64, 64, 81, 2) < lpca_bytes(128, 64, 81, 2));
        assert!(lpca_bytes(64, 64, 81, 2) < lpca_bytes(64, 64, 81, 16));
        assert!(render_bytes(512 * 512, 1024, 4, 2) < render_bytes(512 * 512, 2048, 4, 2));
        assert!(render_bytes(512 * 512, 1024, 4, 2) < render_bytes(512 * 512, 1024, 4, 16));
        assert!(synthesis_bytes(64, 64, 3) < btf_synthesis_bytes(64, 64, 3, 1));
        assert!(btf_synthesis_bytes(64, 64, 3, 2) < btf_synthesis_bytes(64, 64, 3, 16));
        // The closed form at one point: 8192^2 drawing on one subspace is about 12 GiB.
        let big = synthesis_bytes(8192, 8192, 1);
        assert_eq!(big, BASE_BYTES + 8192 * 8192 * (128 + 64));
    }

    #[test]
    fn a_budget_refuses_with_a_hint() {
        let budget = Budget::new(Some(1 << 30));
        assert!(budget.check("x", 1 << 30, |_| unreachable!()).is_ok());
        let err = budget
            .check("synthesize --size 8192", 2 << 30, |b| {
                let side = largest_fitting(8192, b, |s| synthesis_bytes(s, s, 1)).unwrap();
                format!("--size {side} fits")
            })
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("--memory-limit") && err.contains("--size "),
            "{err}"
        );
        assert!(Budget::new(None).bytes > 0);
    }
}
