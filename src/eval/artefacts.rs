//! Automatic artefact detectors for synthesized images (issue 13's sweep): seams, Nyquist
//! patterns, edge blow-up, wrong brightness or contrast, off-chroma pixels and popping light
//! sweeps. Each detector reduces a planar `(3, h, w)` linear image to one statistic; the same
//! statistic measured on the material's own photographs (whole and cropped) is the
//! [`Reference`], and a synthesis is flagged when it exceeds that reference by the detector's
//! stated factor ([`Detector::factor`]). Measured images are not free of the patterns (JPEG
//! blocks, an object's outline, a painting's frame), so the limits are relative to what the
//! measurement itself shows rather than absolute.

use ndarray::{Array2, Array3, Axis, s};

use crate::btf::Direction;
use crate::geometry::relight::luminance;

/// The artefact classes of issue 13, one detector each.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Detector {
    /// A line of neighbour differences (a row or column boundary, or the wrap-around of a
    /// tileable image) far above the image's typical line: tile and range-map seams.
    Seam,
    /// Energy at the Nyquist frequency along rows, columns or both, in a 16 x 16 block, as a
    /// share of the block's variance: checkerboards and barcodes.
    Nyquist,
    /// Detail energy in an edge strip against the interior's: edge blow-up.
    Edge,
    /// Mean luminance against the measured image of the same light.
    Mean,
    /// Contrast (luminance std over mean) against the measured image of the same light.
    Contrast,
    /// Share of pixels whose chromaticity lies outside the measured chromaticities.
    Chroma,
    /// Largest frame-to-frame change per degree of a light sweep against the measured images'
    /// change between neighbouring lights: relighting pops.
    Sweep,
}

impl Detector {
    /// Every detector, in report order.
    pub const ALL: [Detector; 7] = [
        Detector::Seam,
        Detector::Nyquist,
        Detector::Edge,
        Detector::Mean,
        Detector::Contrast,
        Detector::Chroma,
        Detector::Sweep,
    ];

    /// The name in reports.
    pub fn name(&self) -> &'static str {
        match self {
            Detector::Seam => "seam",
            Detector::Nyquist => "nyquist",
            Detector::Edge => "edge",
            Detector::Mean => "mean",
            Detector::Contrast => "contrast",
            Detector::Chroma => "chroma",
            Detector::Sweep => "sweep",
        }
    }

    /// How far beyond the measured reference a synthesis may go before it is flagged. Seams,
    /// Nyquist blocks and edge strips: 1.5x the worst measured image (seams) or image or crop (a synthesis of
    /// a stationary model has no reason to exceed the photograph's own structure). Mean and
    /// contrast: 2x the spread of the measured image's own crops around the whole image, in
    /// log ratio. Chroma: 3x the held-out share (each measured light against the others).
    /// Sweep: 2x the largest measured change per degree between neighbouring lights.
    pub fn factor(&self) -> f64 {
        match self {
            Detector::Seam | Detector::Nyquist | Detector::Edge => 1.5,
            Detector::Mean | Detector::Contrast | Detector::Sweep => 2.0,
            Detector::Chroma => 3.0,
        }
    }

    /// The least reference a detector accepts: below it the measured value is noise and the
    /// limit would be meaninglessly strict. Seam 1.5 (a line 1.5x the median line), Nyquist
    /// 0.05 (5% of a block's variance), edge 1.5, mean log 1.15, contrast log 1.25, chroma
    /// 0.2% of the pixels, sweep 0.2% of the mean luminance per degree.
    pub fn floor(&self) -> f64 {
        match self {
            Detector::Seam | Detector::Edge => 1.5,
            Detector::Nyquist => 0.05,
            Detector::Mean => 1.15f64.ln(),
            Detector::Contrast => 1.25f64.ln(),
            Detector::Chroma => 0.002,
            Detector::Sweep => 0.002,
        }
    }

    /// The limit a synthesis' statistic must not exceed, from the measured `reference`.
    pub fn limit(&self, reference: f64) -> f64 {
        self.factor() * reference.max(self.floor())
    }
}

impl std::fmt::Display for Detector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Length of the runs along a boundary line over which neighbour differences are averaged
/// (signed) before their magnitude is taken, pixels.
const SEAM_RUN: usize = 16;

/// Profile of every column boundary (`x` to `x + 1`, and with `wrap` the last column to the
/// first): the mean over runs of `SEAM_RUN` rows of |mean signed neighbour difference in the
/// run|, summed over channels; shape `(w - 1)` or `(w)`. Averaging the signed differences
/// along the line first cancels texture (differences of both signs) and keeps a step between
/// two regions (one sign over the whole run).
fn column_profile(image: &Array3<f32>, wrap: bool) -> Vec<f64> {
    let (c, h, w) = image.dim();
    let boundaries = if wrap { w } else { w.saturating_sub(1) };
    let run = SEAM_RUN.min(h).max(1);
    let runs = h / run;
    (0..boundaries)
        .map(|x| {
            let x1 = (x + 1) % w;
            let mut sum = 0.0;
            for k in 0..c {
                for r in 0..runs {
                    let step: f64 = (r * run..(r + 1) * run)
                        .map(|y| f64::from(image[[k, y, x1]] - image[[k, y, x]]))
                        .sum();
                    sum += step.abs() / run as f64;
                }
            }
            sum / runs.max(1) as f64
        })
        .collect()
}

fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Seam statistic: the largest ratio of a row or column boundary line (its mean step across
/// the line, see `column_profile`) to the median line of the same direction; with `wrap` the
/// wrap-around boundaries of a tileable image are lines too. A straight seam stands out
/// however small the step, because the line averages over the whole side.
pub fn seam(image: &Array3<f32>, wrap: bool) -> f64 {
    let transposed = image.view().permuted_axes([0, 2, 1]).to_owned();
    [
        column_profile(image, wrap),
        column_profile(&transposed, wrap),
    ]
    .iter()
    .filter(|p| p.len() >= 2)
    .map(|p| {
        let m = median(p);
        let top = p.iter().copied().fold(0.0, f64::max);
        if m > 0.0 {
            top / m
        } else if top > 0.0 {
            f64::INFINITY
        } else {
            1.0
        }
    })
    .fold(1.0, f64::max)
}

/// Side of the Nyquist blocks, pixels.
const BLOCK: usize = 16;

/// Starts of `BLOCK`-sized windows along an axis of `n`: every `BLOCK`, plus one flush with
/// the far end (so a pattern in the last few rows or columns fills a whole block).
fn block_starts(n: usize) -> Vec<usize> {
    if n < BLOCK {
        return vec![0];
    }
    let mut starts: Vec<usize> = (0..=n - BLOCK).step_by(BLOCK).collect();
    if starts.last() != Some(&(n - BLOCK)) {
        starts.push(n - BLOCK);
    }
    starts
}

/// Nyquist statistic: over 16 x 16 blocks (8-bit-free: linear values) and the three Nyquist
/// modulations `(-1)^x`, `(-1)^y`, `(-1)^(x+y)`, the largest share of a block's variance
/// (summed over channels) carried by the modulation, `a^2 / (var + eps)` with `a` the block
/// mean of the modulated image. A pure checkerboard or one-pixel barcode gives about 1; white
/// noise about 1/256 per block. `eps` is 1% of the whole image's variance, so nearly flat
/// blocks do not count as patterns.
pub fn nyquist(image: &Array3<f32>) -> f64 {
    let (c, h, w) = image.dim();
    let eps = 0.01
        * (0..c)
            .map(|k| variance(image.index_axis(Axis(0), k).iter().copied()))
            .sum::<f64>()
        + f64::MIN_POSITIVE;
    let mut worst = 0.0f64;
    for &y0 in &block_starts(h) {
        for &x0 in &block_starts(w) {
            let (bh, bw) = (BLOCK.min(h), BLOCK.min(w));
            let mut var = 0.0;
            let mut energy = [0.0f64; 3];
            for k in 0..c {
                let block = image.slice(s![k, y0..y0 + bh, x0..x0 + bw]);
                var += variance(block.iter().copied());
                let mut a = [0.0f64; 3];
                for ((y, x), &v) in block.indexed_iter() {
                    let v = f64::from(v);
                    let (sx, sy) = (sign(x0 + x), sign(y0 + y));
                    a[0] += sx * v;
                    a[1] += sy * v;
                    a[2] += sx * sy * v;
                }
                let n = (bh * bw) as f64;
                for (e, a) in energy.iter_mut().zip(a) {
                    *e += (a / n).powi(2);
                }
            }
            let top = energy.iter().copied().fold(0.0, f64::max);
            worst = worst.max(top / (var + eps));
        }
    }
    worst
}

fn sign(i: usize) -> f64 {
    if i.is_multiple_of(2) { 1.0 } else { -1.0 }
}

fn variance(values: impl Iterator<Item = f32> + Clone) -> f64 {
    let n = values.clone().count().max(1) as f64;
    let mean = values.clone().map(f64::from).sum::<f64>() / n;
    values.map(|v| (f64::from(v) - mean).powi(2)).sum::<f64>() / n
}

/// Detail energy map: squared neighbour differences right and down, summed over channels,
/// shape `(h - 1, w - 1)`.
fn detail(image: &Array3<f32>) -> Array2<f64> {
    let (c, h, w) = image.dim();
    Array2::from_shape_fn((h.saturating_sub(1), w.saturating_sub(1)), |(y, x)| {
        (0..c)
            .map(|k| {
                let v = image[[k, y, x]];
                f64::from((image[[k, y, x + 1]] - v).powi(2) + (image[[k, y + 1, x]] - v).powi(2))
            })
            .sum()
    })
}

/// Edge statistic: the largest mean detail energy (squared neighbour differences) of the
/// four edge strips, each a sixteenth of the side wide (at least 2 pixels), over the mean of
/// the interior (the image less an eighth of the side on every edge). 1 for a homogeneous
/// image; an edge that blows up into stripes or a checkerboard raises it.
pub fn edge(image: &Array3<f32>) -> f64 {
    let d = detail(image);
    let (h, w) = d.dim();
    if h < 16 || w < 16 {
        return 1.0;
    }
    let (sy, sx) = ((h / 16).max(2), (w / 16).max(2));
    let mean = |a: ndarray::ArrayView2<f64>| a.mean().unwrap_or(0.0);
    let interior = mean(d.slice(s![h / 8..h - h / 8, w / 8..w - w / 8]));
    let strips = [
        mean(d.slice(s![..sy, ..])),
        mean(d.slice(s![h - sy.., ..])),
        mean(d.slice(s![.., ..sx])),
        mean(d.slice(s![.., w - sx..])),
    ];
    let top = strips.into_iter().fold(0.0, f64::max);
    if interior > 0.0 {
        top / interior
    } else if top > 0.0 {
        f64::INFINITY
    } else {
        1.0
    }
}

/// Mean luminance and contrast (luminance standard deviation over mean) of an image.
pub fn tone(image: &Array3<f32>) -> (f64, f64) {
    let l = luminance(image);
    let mean = l.mean().unwrap_or(0.0);
    let std = l.std(0.0);
    (mean, if mean > 0.0 { std / mean } else { 0.0 })
}

/// The four corner crops and the centre crop, each half the side: the measured image's own
/// spread, and windows that put the image's interior on a crop's edge.
pub fn crops(image: &Array3<f32>) -> Vec<Array3<f32>> {
    let (_, h, w) = image.dim();
    let (ch, cw) = (h / 2, w / 2);
    if ch < 8 || cw < 8 {
        return Vec::new();
    }
    [
        (0, 0),
        (0, w - cw),
        (h - ch, 0),
        (h - ch, w - cw),
        (h / 4, w / 4),
    ]
    .into_iter()
    .map(|(y, x)| image.slice(s![.., y..y + ch, x..x + cw]).to_owned())
    .collect()
}

/// Bins per chromaticity axis (r and g over r + g + b, each on [0, 1]).
const CHROMA_BINS: usize = 50;

/// Pixels darker than this share of the image's mean luminance carry no usable chromaticity
/// (sensor noise dominates) and are not counted.
const DARK_SHARE: f64 = 0.1;

/// Nor are pixels darker than this linear luminance (10 of 255 sRGB levels): the
/// chromaticity of an 8-bit measurement that dark is quantised in steps of 10% or more.
const DARK_FLOOR: f64 = 0.003;

/// Chromaticity bins of tolerance around the measured support (2 bins: 0.04 in r or g).
const CHROMA_TOLERANCE: isize = 2;

/// The chromaticity bin of each pixel bright enough to count: `Some(bin)` inside the
/// chromaticity triangle, `None` outside it (a negative channel); dark pixels are skipped.
fn chroma_bins(image: &Array3<f32>) -> Vec<Option<usize>> {
    let l = luminance(image);
    let dark = (DARK_SHARE * l.mean().unwrap_or(0.0)).max(DARK_FLOOR);
    let (_, h, w) = image.dim();
    let mut bins = Vec::with_capacity(h * w);
    for y in 0..h {
        for x in 0..w {
            if l[[y, x]] <= dark {
                continue;
            }
            let (r, g, b) = (
                f64::from(image[[0, y, x]]),
                f64::from(image[[1, y, x]]),
                f64::from(image[[2, y, x]]),
            );
            let sum = r + g + b;
            if r < 0.0 || g < 0.0 || b < 0.0 || sum <= 0.0 {
                bins.push(None);
                continue;
            }
            let bin = |v: f64| ((v / sum * CHROMA_BINS as f64) as usize).min(CHROMA_BINS - 1);
            bins.push(Some(bin(r) * CHROMA_BINS + bin(g)));
        }
    }
    bins
}

/// The measured chromaticity distribution: a 50 x 50 histogram of (r, g) over r + g + b of
/// every bright-enough measured pixel (neither below a tenth of its image's mean luminance nor
/// below 10 of 255 sRGB levels).
#[derive(Debug, Clone)]
pub struct ChromaSupport {
    counts: Vec<u64>,
}

impl ChromaSupport {
    /// The histogram of `images`.
    pub fn new<'a>(images: impl IntoIterator<Item = &'a Array3<f32>>) -> Self {
        let mut support = Self {
            counts: vec![0; CHROMA_BINS * CHROMA_BINS],
        };
        for image in images {
            support.add(image, 1);
        }
        support
    }

    fn add(&mut self, image: &Array3<f32>, sign: i64) {
        for bin in chroma_bins(image).into_iter().flatten() {
            self.counts[bin] = self.counts[bin].saturating_add_signed(sign);
        }
    }

    /// Whether a measured pixel lies within `CHROMA_TOLERANCE` bins of bin `(i, j)` in both
    /// coordinates.
    fn supports(&self, bin: usize) -> bool {
        let (i, j) = ((bin / CHROMA_BINS) as isize, (bin % CHROMA_BINS) as isize);
        let n = CHROMA_BINS as isize;
        let t = CHROMA_TOLERANCE;
        (-t..=t).any(|di| {
            (-t..=t).any(|dj| {
                let (a, b) = (i + di, j + dj);
                (0..n).contains(&a) && (0..n).contains(&b) && self.counts[(a * n + b) as usize] > 0
            })
        })
    }

    /// Chroma statistic: the share of `image`'s bright-enough pixels whose chromaticity lies
    /// outside the measured support (a negative channel is always outside).
    pub fn outliers(&self, image: &Array3<f32>) -> f64 {
        let bins = chroma_bins(image);
        let out = bins
            .iter()
            .filter(|b| !b.is_some_and(|b| self.supports(b)))
            .count();
        out as f64 / bins.len().max(1) as f64
    }

    /// The held-out share of each measured image: its outliers against the support of all the
    /// others (`self` must have been built from exactly `images`). The chroma reference.
    pub fn held_out(&self, images: &[&Array3<f32>]) -> Vec<f64> {
        images
            .iter()
            .map(|image| {
                let mut others = self.clone();
                others.add(image, -1);
                others.outliers(image)
            })
            .collect()
    }
}

/// Change between two images of one scene: mean absolute luminance difference over the mean
/// luminance of the two.
pub fn change(a: &Array3<f32>, b: &Array3<f32>) -> f64 {
    let (la, lb) = (luminance(a), luminance(b));
    let mean = 0.5 * (la.mean().unwrap_or(0.0) + lb.mean().unwrap_or(0.0));
    let diff = (&la - &lb).mapv(f64::abs).mean().unwrap_or(0.0);
    if mean > 0.0 { diff / mean } else { 0.0 }
}

/// Angle between two directions, degrees.
pub fn angle_deg(a: &Direction, b: &Direction) -> f64 {
    let (u, v) = (a.vector(), b.vector());
    let dot: f64 = u.iter().zip(v).map(|(p, q)| p * q).sum();
    dot.clamp(-1.0, 1.0).acos().to_degrees()
}

/// Sweep statistic: the largest [`change`] per degree between consecutive `frames` of a light
/// sweep through `lights` (same length).
pub fn sweep(frames: &[Array3<f32>], lights: &[Direction]) -> f64 {
    frames
        .windows(2)
        .zip(lights.windows(2))
        .map(|(f, l)| change(&f[0], &f[1]) / angle_deg(&l[0], &l[1]).max(1e-9))
        .fold(0.0, f64::max)
}

/// The sweep reference: for every measured light, the [`change`] per degree to its nearest
/// measured neighbour; the largest of them.
pub fn measured_sweep(images: &[&Array3<f32>], lights: &[Direction]) -> f64 {
    (0..images.len())
        .filter_map(|i| {
            (0..images.len())
                .filter(|&j| j != i)
                .map(|j| (j, angle_deg(&lights[i], &lights[j])))
                .filter(|&(_, a)| a > 0.5)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(j, a)| change(images[i], images[j]) / a)
        })
        .fold(0.0, f64::max)
}

/// The measured side of every detector, for one material (one real set or built-in material):
/// computed once from its measured images, then used for every synthesis of it.
#[derive(Debug, Clone)]
pub struct Reference {
    /// Worst [`seam`] of a whole measured image (no wrap: measurements do not tile).
    pub seam: f64,
    /// Worst [`nyquist`] of a measured image or crop.
    pub nyquist: f64,
    /// Worst [`edge`] of a measured image or crop.
    pub edge: f64,
    /// The measured chromaticities.
    pub chroma: ChromaSupport,
    /// Worst held-out chroma share of a measured image.
    pub chroma_held_out: f64,
    /// Largest measured change per degree between neighbouring lights.
    pub sweep: f64,
}

impl Reference {
    /// Calibrates on `images` (the measured images, one per light of `lights`). The
    /// structure references (seam, Nyquist, edge) use only the lit images: one whose mean
    /// luminance is below 10 of 255 sRGB levels is quantisation noise, whose lines and blocks
    /// have a median of zero and would make every limit infinite.
    pub fn calibrate(images: &[&Array3<f32>], lights: &[Direction]) -> Self {
        let lit: Vec<&Array3<f32>> = images
            .iter()
            .copied()
            .filter(|i| tone(i).0 >= DARK_FLOOR)
            .collect();
        let lit = if lit.is_empty() { images } else { &lit[..] };
        let mut windows: Vec<Array3<f32>> = Vec::new();
        for image in lit {
            windows.push((*image).clone());
            windows.extend(crops(image));
        }
        let worst = |f: &dyn Fn(&Array3<f32>) -> f64| windows.iter().map(f).fold(0.0, f64::max);
        let chroma = ChromaSupport::new(images.iter().copied());
        let chroma_held_out = chroma.held_out(images).into_iter().fold(0.0, f64::max);
        Self {
            // Whole images only: a half-size crop's lines are half as long, so its seam
            // statistic is noisier than a synthesis of the measured size or larger.
            seam: lit.iter().map(|i| seam(i, false)).fold(0.0, f64::max),
            nyquist: worst(&nyquist),
            edge: worst(&edge),
            chroma,
            chroma_held_out,
            sweep: measured_sweep(images, lights),
        }
    }

    /// Every per-image detector's statistic and limit for a synthesized `image` at a measured
    /// light whose photograph is `measured`; `tileable` adds the wrap-around to the seams.
    pub fn check(
        &self,
        image: &Array3<f32>,
        measured: &Array3<f32>,
        tileable: bool,
    ) -> Vec<Finding> {
        let (mean, contrast) = tone(image);
        let (m_mean, m_contrast) = tone(measured);
        let crop_tones: Vec<(f64, f64)> = crops(measured).iter().map(tone).collect();
        let spread = |pick: fn(&(f64, f64)) -> f64, whole: f64| {
            crop_tones
                .iter()
                .map(|t| log_ratio(pick(t), whole))
                .fold(0.0, f64::max)
        };
        vec![
            Finding::new(Detector::Seam, seam(image, tileable), self.seam),
            Finding::new(Detector::Nyquist, nyquist(image), self.nyquist),
            Finding::new(Detector::Edge, edge(image), self.edge),
            Finding::new(
                Detector::Mean,
                log_ratio(mean, m_mean),
                spread(|t| t.0, m_mean),
            ),
            Finding::new(
                Detector::Contrast,
                log_ratio(contrast, m_contrast),
                spread(|t| t.1, m_contrast),
            ),
            Finding::new(
                Detector::Chroma,
                self.chroma.outliers(image),
                self.chroma_held_out,
            ),
        ]
    }

    /// The sweep detector on synthesized `frames` at `lights`.
    pub fn check_sweep(&self, frames: &[Array3<f32>], lights: &[Direction]) -> Finding {
        Finding::new(Detector::Sweep, sweep(frames, lights), self.sweep)
    }
}

/// `|ln(a / b)|`, infinite where one is zero or negative and the other is not.
fn log_ratio(a: f64, b: f64) -> f64 {
    if a > 0.0 && b > 0.0 {
        (a / b).ln().abs()
    } else if a == b {
        0.0
    } else {
        f64::INFINITY
    }
}

/// One detector's verdict on one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finding {
    /// Which detector.
    pub detector: Detector,
    /// The synthesis' statistic.
    pub value: f64,
    /// The measured reference.
    pub reference: f64,
    /// The limit, [`Detector::limit`] of the reference.
    pub limit: f64,
}

impl Finding {
    fn new(detector: Detector, value: f64, reference: f64) -> Self {
        Self {
            detector,
            value,
            reference,
            limit: detector.limit(reference),
        }
    }

    /// Whether the statistic exceeds its limit (a non-finite statistic always does).
    pub fn flagged(&self) -> bool {
        !self.value.is_finite() || self.value > self.limit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::Btf;
    use crate::btf::synthetic::SyntheticMaterial;

    /// A measured-like image: a built-in material's photograph, 128 x 128.
    fn clean(light: usize) -> Array3<f32> {
        Btf::synthetic(SyntheticMaterial::Sponge, 128, 3)
            .unwrap()
            .image(0, light)
            .unwrap()
    }

    fn reference() -> (Reference, Vec<Array3<f32>>) {
        let btf = Btf::synthetic(SyntheticMaterial::Sponge, 128, 3).unwrap();
        let lights: Vec<usize> = (0..20).collect();
        let images: Vec<Array3<f32>> = lights.iter().map(|&l| btf.image(0, l).unwrap()).collect();
        let dirs: Vec<Direction> = lights
            .iter()
            .map(|&l| *btf.lights().get(l).unwrap())
            .collect();
        let refs: Vec<&Array3<f32>> = images.iter().collect();
        (Reference::calibrate(&refs, &dirs), images)
    }

    fn flagged(findings: &[Finding]) -> Vec<Detector> {
        findings
            .iter()
            .filter(|f| f.flagged())
            .map(|f| f.detector)
            .collect()
    }

    #[test]
    fn a_measured_image_of_another_seed_is_not_flagged() {
        let (reference, _) = reference();
        let other = Btf::synthetic(SyntheticMaterial::Sponge, 128, 9).unwrap();
        for light in [0, 7, 15] {
            let image = other.image(0, light).unwrap();
            let findings = reference.check(&image, &clean(light), false);
            assert!(flagged(&findings).is_empty(), "light {light}: {findings:?}");
        }
    }

    #[test]
    fn a_planted_seam_is_flagged_and_the_wrap_around_counts_only_when_tileable() {
        let (reference, _) = reference();
        let mut image = clean(5);
        image.slice_mut(s![.., .., 64..]).mapv_inplace(|v| v * 1.3);
        assert!(flagged(&reference.check(&image, &clean(5), false)).contains(&Detector::Seam));
        // A straight column step of 30% in an otherwise seamless image.
        let base = clean(5);
        assert!(seam(&image, false) > 1.5 * seam(&base, false));
        // A non-periodic image has a wrap-around seam; a periodic one has none.
        let noise = Array3::from_shape_vec(
            (3, 128, 128),
            crate::mrf::noise::standard_normal(2, 3 * 128 * 128),
        )
        .unwrap();
        let ramp = Array3::from_shape_fn((3, 32, 32), |(_, y, x)| x as f32 + 0.1 * y as f32);
        let (open, wrapped) = (seam(&noise, false), seam(&noise, true));
        assert!(wrapped < 1.2 * open, "{wrapped} {open}");
        assert!(seam(&ramp, true) > 10.0);
        assert!(seam(&ramp, false) < 1.1);
    }

    #[test]
    fn a_checkerboard_and_a_barcode_are_flagged() {
        let (reference, _) = reference();
        let base = clean(5);
        let amp = 0.5 * base.std(0.0);
        let mut board = base.clone();
        board
            .slice_mut(s![.., 80.., 80..])
            .indexed_iter_mut()
            .for_each(|((_, y, x), v)| *v += amp * sign(x + y) as f32);
        let mut barcode = base.clone();
        barcode
            .slice_mut(s![.., .., 112..])
            .indexed_iter_mut()
            .for_each(|((_, _, x), v)| *v += amp * sign(x) as f32);
        for (name, image) in [("checkerboard", &board), ("barcode", &barcode)] {
            let f = flagged(&reference.check(image, &base, false));
            assert!(f.contains(&Detector::Nyquist), "{name}: {f:?}");
        }
        // White noise carries no more than a few per cent of a block at Nyquist.
        let noise = Array3::from_shape_vec(
            (3, 64, 64),
            crate::mrf::noise::standard_normal(4, 3 * 64 * 64),
        )
        .unwrap();
        assert!(nyquist(&noise) < 0.05, "{}", nyquist(&noise));
        assert!(nyquist(&barcode) > 0.15, "{}", nyquist(&barcode));
    }

    #[test]
    fn an_edge_blow_up_is_flagged() {
        let (reference, _) = reference();
        let base = clean(5);
        let mut image = base.clone();
        let noise = crate::mrf::noise::standard_normal(8, 3 * 128 * 10);
        image
            .slice_mut(s![.., .., 118..])
            .iter_mut()
            .zip(noise)
            .for_each(|(v, n)| *v += 0.5 * n);
        let f = flagged(&reference.check(&image, &base, false));
        assert!(f.contains(&Detector::Edge), "{f:?}");
        assert!(edge(&image) > 3.0 * edge(&base));
    }

    #[test]
    fn wrong_brightness_and_a_flat_field_are_flagged() {
        let (reference, _) = reference();
        let base = clean(5);
        let dark = base.mapv(|v| 0.5 * v);
        assert!(flagged(&reference.check(&dark, &base, false)).contains(&Detector::Mean));
        let mean = base.mean().unwrap();
        let flat = base.mapv(|v| mean + 0.1 * (v - mean));
        assert!(flagged(&reference.check(&flat, &base, false)).contains(&Detector::Contrast));
        assert_eq!(tone(&Array3::zeros((3, 4, 4))), (0.0, 0.0));
    }

    #[test]
    fn off_chroma_speckles_are_flagged() {
        let (reference, images) = reference();
        let base = clean(5);
        let mut image = base.clone();
        // Every 50th pixel turns magenta (1% of the image).
        for k in (0..128 * 128).step_by(50) {
            let (y, x) = (k / 128, k % 128);
            let v = image[[1, y, x]];
            image[[0, y, x]] = 2.0 * v;
            image[[1, y, x]] = 0.2 * v;
            image[[2, y, x]] = 2.0 * v;
        }
        let f = flagged(&reference.check(&image, &base, false));
        assert!(f.contains(&Detector::Chroma), "{f:?}");
        // A negative channel is outside any measured support.
        let mut negative = base.clone();
        negative.index_axis_mut(Axis(0), 2).fill(-0.01);
        assert_eq!(reference.chroma.outliers(&negative), 1.0);
        let refs: Vec<&Array3<f32>> = images.iter().collect();
        let held = reference.chroma.held_out(&refs);
        assert!(held.iter().all(|&h| h < 0.01), "{held:?}");
    }

    #[test]
    fn a_pop_in_a_light_sweep_is_flagged() {
        let (reference, _) = reference();
        let btf = Btf::synthetic(SyntheticMaterial::Sponge, 128, 3).unwrap();
        // Lights 1..=8 sit on one ring of the Bonn sampling.
        let lights: Vec<Direction> = (1..=8).map(|l| *btf.lights().get(l).unwrap()).collect();
        let mut frames: Vec<Array3<f32>> = (1..=8).map(|l| btf.image(0, l).unwrap()).collect();
        assert!(!reference.check_sweep(&frames, &lights).flagged());
        frames[4] = frames[4].mapv(|v| 0.3 * v);
        assert!(reference.check_sweep(&frames, &lights).flagged());
    }

    #[test]
    fn an_unlit_measured_image_leaves_the_references_finite() {
        let (_, images) = reference();
        // Nearly black: one quantisation step in one pixel, zero elsewhere.
        let mut black = Array3::<f32>::zeros((3, 128, 128));
        black[[1, 5, 5]] = 0.002;
        let mut refs: Vec<&Array3<f32>> = images.iter().collect();
        refs.push(&black);
        let lights: Vec<Direction> = (0..refs.len())
            .map(|k| Direction::new(10.0 + k as f64, 0.0))
            .collect();
        let r = Reference::calibrate(&refs, &lights);
        assert!(seam(&black, false).is_infinite());
        for v in [r.seam, r.nyquist, r.edge] {
            assert!(v.is_finite() && v < 100.0, "{r:?}");
        }
    }

    #[test]
    fn limits_follow_factor_and_floor() {
        assert_eq!(Detector::Seam.limit(2.0), 3.0);
        assert_eq!(Detector::Seam.limit(0.1), 2.25);
        assert!(Finding::new(Detector::Edge, f64::NAN, 1.0).flagged());
        assert_eq!(log_ratio(0.0, 0.0), 0.0);
        assert!(log_ratio(0.0, 1.0).is_infinite());
        assert!(
            (angle_deg(&Direction::new(0.0, 0.0), &Direction::new(30.0, 10.0)) - 30.0).abs() < 1e-9
        );
    }
}
