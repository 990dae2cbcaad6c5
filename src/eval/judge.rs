//! The texture judge (issue 11, item 1; mrf_math.md sec. 6): how far a synthesized image is
//! from the measured material, in structure and in colour, with reference levels made from the
//! measured image itself so that every figure can be read.
//!
//! - **Structure**: statistics in the spirit of Portilla and Simoncelli (2000) on the L* plane,
//!   from an undecimated steerable pyramid ([`OrientedPyramid`], 4 orientations, up to 4
//!   scales): marginal moments of the image and of the low-pass images, band energies,
//!   marginal moments of the bands, autocorrelation of the band magnitudes, cross-orientation
//!   and cross-scale magnitude correlations, autocorrelation of the low-pass images. Each of
//!   these seven groups is compared by its mean absolute difference and the groups are averaged
//!   ([`STRUCTURE_GROUPS`]): the groups beyond the power spectrum (moments, magnitude
//!   correlations) carry as much weight as those a Gaussian noise with the right spectrum
//!   matches, so such a noise does not score like the material.
//! - **Colour**: the CIE Lab marginals compared by exact quantiles (512 levels, no bins):
//!   `colour_lab` is the mean over L*, a*, b* of the mean |quantile difference|, in Lab units;
//!   also the standard deviation and kurtosis of a* and b*, and `colour_coupling`: how far the
//!   mean chroma at each tenth of the lightness is from the reference's (the marginals alone
//!   miss highlights that take the colour of the shadows).
//!
//! Reference levels ([`Yardstick`]): the measured image is cut into two square crops, A (the
//! reference every candidate is compared with) and B (or two samples of the material are given,
//! [`Yardstick::from_samples`]). The levels are B itself (another crop:
//! "the same material"), B's random-phase noise (its exact power spectrum, random phases: what
//! a Gaussian model reaches at best), B pixel-shuffled (exact histogram, no structure), B
//! blurred, and optionally a crop of a different material. A candidate's `structure_vs_crop`
//! and `structure_vs_random_phase` are its structure distance over those two levels.
//!
//! Images are taken as planar `(3, h, w)` linear RGB, brought into [0, 1] as our display does
//! ([`crate::color::fit_to_gamut`]).
//! Band statistics are computed on a mirrored copy (so the borders make no seam) over the
//! image's own pixels.

use ndarray::{Array2, Array3, Axis, Zip, s};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_distr::{Distribution, StandardNormal};
use rustfft::num_complex::Complex64;

use super::pyramid::OrientedPyramid;
use super::{EvalError, Result};
use crate::color::{fit_to_gamut, linear_to_lab};

/// Orientations of the pyramid.
const ORIENTATIONS: usize = 4;
/// The most scales used (fewer on small images: the coarsest must see 8 of its periods).
const MAX_SCALES: usize = 4;
/// Half-width of the lag window of the autocorrelations, in units of the scale's step
/// (Portilla and Simoncelli use 7 x 7 windows).
const LAG: isize = 3;
/// The smallest side the judge accepts, pixels.
pub const MIN_SIDE: usize = 16;
/// Quantile levels of the colour comparison.
const QUANTILES: usize = 512;
/// Standard deviation of the blur of the "blurred" reference level, pixels.
const BLUR_SIGMA: f64 = 2.0;
/// Lightness ranks (equal shares of the pixels) at which the colour coupling compares the mean
/// chroma.
const COUPLING_BINS: usize = 10;

/// Names of the structure statistics' groups, in the order of [`Judgement::groups`].
pub const STRUCTURE_GROUPS: [&str; 7] = [
    "pixel moments",
    "band energies",
    "band moments",
    "magnitude autocorrelation",
    "cross-orientation",
    "cross-scale",
    "low-pass autocorrelation",
];

/// The statistics of one image, computed once and compared many times.
#[derive(Debug, Clone)]
pub struct Signature {
    scales: usize,
    groups: [Vec<f64>; 7],
    lab_sorted: [Vec<f32>; 3],
    chroma_std: [f64; 2],
    chroma_kurtosis: [f64; 2],
    coupling: [f64; COUPLING_BINS],
}

/// How far one image is from another (the second is the reference).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Judgement {
    /// Mean over the seven structure groups of their mean absolute statistic difference
    /// (0 for identical statistics).
    pub structure: f64,
    /// The structure distance of each group ([`STRUCTURE_GROUPS`]).
    pub groups: [f64; 7],
    /// Mean over L*, a*, b* of the mean |quantile difference|, Lab units.
    pub colour_lab: f64,
    /// Mean |quantile difference| of L*, a*, b*, Lab units.
    pub colour_lab_channels: [f64; 3],
    /// Standard deviation of a* and b* of the judged image, Lab units.
    pub chroma_std: [f64; 2],
    /// Kurtosis of a* and b* of the judged image (3 for a Gaussian).
    pub chroma_kurtosis: [f64; 2],
    /// Mean |difference| of the mean chroma `sqrt(a*^2 + b*^2)` of the pixels in each tenth of
    /// the lightness (by rank), Lab units: how colour goes with lightness.
    pub colour_coupling: f64,
}

impl Signature {
    /// The statistics of a planar `(3, h, w)` linear RGB image, with `scales` pyramid scales
    /// (see [`scales_for`]).
    ///
    /// # Errors
    /// The image is smaller than [`MIN_SIDE`] or has no three channels.
    pub fn of(image: &Array3<f32>, scales: usize) -> Result<Self> {
        let (c, h, w) = image.dim();
        if c != 3 || h.min(w) < MIN_SIDE {
            return Err(EvalError::Judge(format!(
                "the judge needs a 3-channel image of at least {MIN_SIDE}x{MIN_SIDE} pixels, \
                 got {c} channels of {w}x{h}"
            )));
        }
        let lab = to_lab(image);
        let lightness = lab.index_axis(Axis(0), 0).to_owned();
        let lab_sorted = std::array::from_fn(|k| {
            let mut v: Vec<f32> = lab.index_axis(Axis(0), k).iter().copied().collect();
            v.sort_by(f32::total_cmp);
            v
        });
        let chroma = |k: usize| moments(lab.index_axis(Axis(0), k + 1).iter().map(|&v| v as f64));
        let (ma, mb) = (chroma(0), chroma(1));
        let coupling = chroma_by_lightness(&lab);
        Ok(Self {
            scales,
            groups: structure_statistics(&lightness.mapv(f64::from), scales),
            lab_sorted,
            chroma_std: [ma.std, mb.std],
            chroma_kurtosis: [ma.kurtosis, mb.kurtosis],
            coupling,
        })
    }

    /// How far `self` (the judged image) is from `reference`.
    ///
    /// # Panics
    /// If the two were computed with different numbers of scales.
    pub fn compare(&self, reference: &Signature) -> Judgement {
        assert_eq!(
            self.scales, reference.scales,
            "signatures of different pyramids"
        );
        let groups: [f64; 7] = std::array::from_fn(|g| {
            let (a, b) = (&self.groups[g], &reference.groups[g]);
            a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len().max(1) as f64
        });
        let colour_lab_channels = std::array::from_fn(|k| {
            quantile_distance(&self.lab_sorted[k], &reference.lab_sorted[k])
        });
        Judgement {
            structure: groups.iter().sum::<f64>() / groups.len() as f64,
            groups,
            colour_lab: colour_lab_channels.iter().sum::<f64>() / 3.0,
            colour_lab_channels,
            chroma_std: self.chroma_std,
            chroma_kurtosis: self.chroma_kurtosis,
            colour_coupling: (self.coupling.iter().zip(&reference.coupling))
                .map(|(a, b)| (a - b).abs())
                .sum::<f64>()
                / COUPLING_BINS as f64,
        }
    }

    /// Standard deviation of a* and b*, Lab units.
    pub fn chroma_std(&self) -> [f64; 2] {
        self.chroma_std
    }

    /// Kurtosis of a* and b*.
    pub fn chroma_kurtosis(&self) -> [f64; 2] {
        self.chroma_kurtosis
    }
}

/// Pyramid scales for images whose smaller side is `side`: the coarsest band's period
/// (`4 * 2^s` pixels) fits at least 8 times.
pub fn scales_for(side: usize) -> usize {
    let mut scales = 1;
    while scales < MAX_SCALES && 32 << scales <= side {
        scales += 1;
    }
    scales
}

/// A candidate's figures against the measured material.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Verdict {
    /// The candidate against the reference crop.
    #[serde(flatten)]
    pub judgement: Judgement,
    /// `structure` over the another-crop level (1 = as close as the same material).
    pub structure_vs_crop: f64,
    /// `structure` over the random-phase level (1 = as close as the best Gaussian noise).
    pub structure_vs_random_phase: f64,
}

impl Verdict {
    /// The field-by-field mean of several verdicts (e.g. over measured (view, light) pairs);
    /// `None` for none.
    pub fn mean(verdicts: &[Verdict]) -> Option<Verdict> {
        let n = verdicts.len() as f64;
        let avg = |f: &dyn Fn(&Verdict) -> f64| verdicts.iter().map(f).sum::<f64>() / n;
        verdicts.first()?;
        Some(Verdict {
            judgement: Judgement {
                structure: avg(&|v| v.judgement.structure),
                groups: std::array::from_fn(|g| avg(&|v| v.judgement.groups[g])),
                colour_lab: avg(&|v| v.judgement.colour_lab),
                colour_lab_channels: std::array::from_fn(|k| {
                    avg(&|v| v.judgement.colour_lab_channels[k])
                }),
                chroma_std: std::array::from_fn(|k| avg(&|v| v.judgement.chroma_std[k])),
                chroma_kurtosis: std::array::from_fn(|k| avg(&|v| v.judgement.chroma_kurtosis[k])),
                colour_coupling: avg(&|v| v.judgement.colour_coupling),
            },
            structure_vs_crop: avg(&|v| v.structure_vs_crop),
            structure_vs_random_phase: avg(&|v| v.structure_vs_random_phase),
        })
    }
}

/// The reference levels: each reference image judged against the reference crop.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Levels {
    /// The reference crop A against itself: its own chroma statistics, zero distances.
    pub measured: Verdict,
    /// Another crop B of the measured image.
    pub crop: Verdict,
    /// B's random-phase noise.
    pub random_phase: Verdict,
    /// B with its pixels shuffled.
    pub shuffled: Verdict,
    /// B blurred (Gaussian, sigma 2 pixels).
    pub blurred: Verdict,
    /// A crop of a different material, where one was given.
    pub other_material: Option<Verdict>,
}

impl Levels {
    /// The levels as (name, verdict) rows, in the order crop, random phase, shuffled, blurred,
    /// other material.
    pub fn rows(&self) -> Vec<(&'static str, Verdict)> {
        let mut rows = vec![
            ("another crop", self.crop),
            ("random phase", self.random_phase),
            ("shuffled", self.shuffled),
            ("blurred", self.blurred),
        ];
        if let Some(other) = self.other_material {
            rows.push(("other material", other));
        }
        rows
    }
}

/// The measured material's reference crop, its levels, and the judge of candidates.
#[derive(Debug, Clone)]
pub struct Yardstick {
    reference: Signature,
    levels: Levels,
}

impl Yardstick {
    /// Cuts `measured` into the reference crop A and another crop B (two squares from
    /// opposite halves along the longer side) and computes the reference levels; `other`
    /// (a different material, any size) adds that level. `seed` drives the random phases and
    /// the shuffle.
    ///
    /// # Errors
    /// A crop would be smaller than [`MIN_SIDE`].
    pub fn new(measured: &Array3<f32>, other: Option<&Array3<f32>>, seed: u64) -> Result<Self> {
        let (a, b) = two_crops(measured)?;
        Self::from_samples(&a, &b, other, seed)
    }

    /// Like [`Yardstick::new`], with the reference A and the other sample B of the same
    /// material given (two crops, two captures, two seeds of a generated material); B and the
    /// other material are cut to A's size where larger.
    ///
    /// # Errors
    /// An image is smaller than [`MIN_SIDE`].
    pub fn from_samples(
        reference: &Array3<f32>,
        another: &Array3<f32>,
        other: Option<&Array3<f32>>,
        seed: u64,
    ) -> Result<Self> {
        let (_, h, w) = reference.dim();
        let scales = scales_for(h.min(w));
        let b = crop(another, h, w);
        let reference = Signature::of(reference, scales)?;
        let level =
            |image: &Array3<f32>| Signature::of(image, scales).map(|s| s.compare(&reference));
        let crop_level = level(&b)?;
        let random_phase = level(&random_phase(&b, seed))?;
        let shuffled = level(&shuffle(&b, seed))?;
        let blurred = level(&blur(&b, BLUR_SIGMA))?;
        let other_material = other.map(|o| level(&crop(o, h, w))).transpose()?;
        let verdict = |j: Judgement| Verdict {
            judgement: j,
            structure_vs_crop: j.structure / crop_level.structure.max(1e-12),
            structure_vs_random_phase: j.structure / random_phase.structure.max(1e-12),
        };
        let levels = Levels {
            measured: verdict(reference.compare(&reference)),
            crop: verdict(crop_level),
            random_phase: verdict(random_phase),
            shuffled: verdict(shuffled),
            blurred: verdict(blurred),
            other_material: other_material.map(verdict),
        };
        Ok(Self { reference, levels })
    }

    /// The reference levels.
    pub fn levels(&self) -> &Levels {
        &self.levels
    }

    /// Judges a candidate image (any size of at least [`MIN_SIDE`]) against the reference crop.
    ///
    /// # Errors
    /// The candidate is too small.
    pub fn judge(&self, candidate: &Array3<f32>) -> Result<Verdict> {
        let j = Signature::of(candidate, self.reference.scales)?.compare(&self.reference);
        Ok(Verdict {
            judgement: j,
            structure_vs_crop: j.structure / self.levels.crop.judgement.structure.max(1e-12),
            structure_vs_random_phase: j.structure
                / self.levels.random_phase.judgement.structure.max(1e-12),
        })
    }
}

/// Two equal squares from the two halves of the longer side (A from the start of the first
/// half, B from the end of the second), as large as the halves allow.
fn two_crops(image: &Array3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
    let (_, h, w) = image.dim();
    let side = if w >= h {
        (w / 2).min(h)
    } else {
        (h / 2).min(w)
    };
    if side < MIN_SIDE {
        return Err(EvalError::Judge(format!(
            "the measured image is {w}x{h}: the judge needs two crops of at least \
             {MIN_SIDE}x{MIN_SIDE}, so at least {}x{MIN_SIDE}",
            2 * MIN_SIDE
        )));
    }
    Ok((
        crop(image, side, side),
        image.slice(s![.., h - side.., w - side..]).to_owned(),
    ))
}

/// The top-left `h x w` window, clipped to the image.
fn crop(image: &Array3<f32>, h: usize, w: usize) -> Array3<f32> {
    let (_, ih, iw) = image.dim();
    image.slice(s![.., ..h.min(ih), ..w.min(iw)]).to_owned()
}

fn to_lab(image: &Array3<f32>) -> Array3<f32> {
    let (_, h, w) = image.dim();
    let mut lab = Array3::zeros((3, h, w));
    for y in 0..h {
        for x in 0..w {
            let v = linear_to_lab(fit_to_gamut([0, 1, 2].map(|k| image[[k, y, x]])));
            for k in 0..3 {
                lab[[k, y, x]] = v[k];
            }
        }
    }
    lab
}

/// The mean chroma `sqrt(a*^2 + b*^2)` of a `(3, h, w)` Lab image's pixels in each of
/// [`COUPLING_BINS`] equal shares of them ranked by L* (ties broken by position).
fn chroma_by_lightness(lab: &Array3<f32>) -> [f64; COUPLING_BINS] {
    let plane = |k: usize| lab.index_axis(Axis(0), k);
    // (L*, chroma) per pixel, sorted by L*.
    let mut pixels: Vec<(f32, f64)> = Zip::from(&plane(0))
        .and(&plane(1))
        .and(&plane(2))
        .map_collect(|&l, &a, &b| (l, f64::from(a).hypot(f64::from(b))))
        .into_iter()
        .collect();
    pixels.sort_by(|p, q| p.0.total_cmp(&q.0));
    let n = pixels.len();
    std::array::from_fn(|bin| {
        let share = &pixels[bin * n / COUPLING_BINS..(bin + 1) * n / COUPLING_BINS];
        let sum: f64 = share.iter().map(|&(_, chroma)| chroma).sum();
        sum / share.len().max(1) as f64
    })
}

/// Mean |difference| of two sorted samples at [`QUANTILES`] evenly spaced probabilities
/// (each quantile an order statistic of its sample).
fn quantile_distance(a: &[f32], b: &[f32]) -> f64 {
    let at = |v: &[f32], q: f64| f64::from(v[((q * v.len() as f64) as usize).min(v.len() - 1)]);
    (0..QUANTILES)
        .map(|i| {
            let q = (i as f64 + 0.5) / QUANTILES as f64;
            (at(a, q) - at(b, q)).abs()
        })
        .sum::<f64>()
        / QUANTILES as f64
}

/// Mean, standard deviation, skewness and kurtosis of a sample.
#[derive(Debug, Clone, Copy)]
struct Moments {
    std: f64,
    skewness: f64,
    kurtosis: f64,
}

fn moments(values: impl Iterator<Item = f64> + Clone) -> Moments {
    let (mut n, mut sum) = (0.0, 0.0);
    for v in values.clone() {
        n += 1.0;
        sum += v;
    }
    let mean = sum / f64::max(n, 1.0);
    let (mut m2, mut m3, mut m4) = (0.0, 0.0, 0.0);
    for v in values {
        let d = v - mean;
        m2 += d * d;
        m3 += d * d * d;
        m4 += d * d * d * d;
    }
    let var = m2 / f64::max(n, 1.0);
    if var <= 1e-20 {
        return Moments {
            std: 0.0,
            skewness: 0.0,
            kurtosis: 3.0,
        };
    }
    Moments {
        std: var.sqrt(),
        skewness: m3 / n / var.powf(1.5),
        kurtosis: m4 / n / (var * var),
    }
}

/// A plane mirrored to twice its size each way: periodic without a seam.
fn mirror(plane: &Array2<f64>) -> Array2<f64> {
    let (h, w) = plane.dim();
    let fold = |i: usize, n: usize| if i < n { i } else { 2 * n - 1 - i };
    Array2::from_shape_fn((2 * h, 2 * w), |(y, x)| plane[[fold(y, h), fold(x, w)]])
}

/// The lags of a half window (one of each +-pair), in units of the scale's step.
fn half_window() -> impl Iterator<Item = (isize, isize)> {
    (0..=LAG).flat_map(|dy| {
        (-LAG..=LAG)
            .filter(move |&dx| dy > 0 || dx > 0)
            .map(move |dx| (dy, dx))
    })
}

/// Correlation coefficients of a periodic `(2h, 2w)` plane with itself at the half window's
/// lags times `step`, over the first `h x w` pixels.
fn autocorrelation(plane: &Array2<f64>, h: usize, w: usize, step: isize, out: &mut Vec<f64>) {
    let (ph, pw) = plane.dim();
    let n = (h * w) as f64;
    let mean = plane.slice(s![..h, ..w]).sum() / n;
    let var = plane
        .slice(s![..h, ..w])
        .iter()
        .map(|v| (v - mean).powi(2))
        .sum::<f64>()
        / n;
    for (dy, dx) in half_window() {
        let mut acc = 0.0;
        for y in 0..h {
            let yy = (y as isize + dy * step).rem_euclid(ph as isize) as usize;
            for x in 0..w {
                let xx = (x as isize + dx * step).rem_euclid(pw as isize) as usize;
                acc += (plane[[y, x]] - mean) * (plane[[yy, xx]] - mean);
            }
        }
        out.push(if var > 1e-20 { acc / n / var } else { 0.0 });
    }
}

/// Pearson correlation of two planes over their first `h x w` pixels.
fn correlation(a: &Array2<f64>, b: &Array2<f64>, h: usize, w: usize) -> f64 {
    let (a, b) = (a.slice(s![..h, ..w]), b.slice(s![..h, ..w]));
    super::correlation(a.iter(), b.iter())
}

/// The seven groups of structure statistics of an L* plane (see the module documentation).
fn structure_statistics(lightness: &Array2<f64>, scales: usize) -> [Vec<f64>; 7] {
    let (h, w) = lightness.dim();
    let pyramid = OrientedPyramid::new(&mirror(lightness), scales, ORIENTATIONS);
    let inside = |p: &Array2<f64>| p.slice(s![..h, ..w]).iter().copied().collect::<Vec<_>>();
    let image = moments(lightness.iter().copied());
    let total_var = image.std.powi(2).max(1e-12);

    let mut pixel = vec![image.skewness, image.kurtosis.ln()];
    let mut lowpass_corr = Vec::new();
    for (s, low) in pyramid.lowpass.iter().enumerate().skip(1) {
        let m = moments(inside(low).into_iter());
        pixel.extend([m.skewness, m.kurtosis.ln()]);
        autocorrelation(low, h, w, 1 << s, &mut lowpass_corr);
    }

    let mut energy = vec![
        0.5 * total_var.ln(),
        (moments(inside(&pyramid.highpass).into_iter()).std.powi(2) / total_var + 1e-12).ln(),
    ];
    let mut band_moments = Vec::new();
    let mut magnitude_corr = Vec::new();
    let magnitudes: Vec<Vec<Array2<f64>>> = pyramid
        .bands
        .iter()
        // |z| as sqrt(re^2 + im^2): the bands are far from overflow, and libm's hypot cost a
        // sixth of an analysis' judging.
        .map(|scale| {
            scale
                .iter()
                .map(|b| b.mapv(|z| z.norm_sqr().sqrt()))
                .collect()
        })
        .collect();
    for (s, scale) in pyramid.bands.iter().enumerate() {
        for (band, magnitude) in scale.iter().zip(&magnitudes[s]) {
            let m = moments(inside(&band.mapv(|c| c.re)).into_iter());
            energy.push((m.std.powi(2) / total_var + 1e-12).ln());
            band_moments.extend([m.skewness, m.kurtosis.ln()]);
            autocorrelation(magnitude, h, w, 1 << s, &mut magnitude_corr);
        }
    }
    let mut cross_orientation = Vec::new();
    let mut cross_scale = Vec::new();
    for (s, scale) in magnitudes.iter().enumerate() {
        for (k, a) in scale.iter().enumerate() {
            for b in &scale[k + 1..] {
                cross_orientation.push(correlation(a, b, h, w));
            }
            if let Some(coarser) = magnitudes.get(s + 1) {
                for b in coarser {
                    cross_scale.push(correlation(a, b, h, w));
                }
            }
        }
    }
    [
        pixel,
        energy,
        band_moments,
        magnitude_corr,
        cross_orientation,
        cross_scale,
        lowpass_corr,
    ]
}

/// Random-phase noise of an image (Galerne, Gousseau and Morel 2011): every channel keeps its
/// Fourier moduli and takes the phases of one seeded white noise (the same for all channels,
/// so the colours stay correlated); the mean is kept.
pub fn random_phase(image: &Array3<f32>, seed: u64) -> Array3<f32> {
    let (c, h, w) = image.dim();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let noise = Array2::from_shape_fn((h, w), |_| StandardNormal.sample(&mut rng));
    let phases = crate::fft::forward(&noise).mapv(|z: Complex64| {
        let n = z.norm();
        if n > 0.0 {
            z / n
        } else {
            Complex64::new(1.0, 0.0)
        }
    });
    let mut out = Array3::zeros((c, h, w));
    for k in 0..c {
        let mut spectrum = crate::fft::forward(&image.index_axis(Axis(0), k).mapv(f64::from));
        let dc = spectrum[[0, 0]];
        spectrum.zip_mut_with(&phases, |x, p| *x = p * x.norm());
        spectrum[[0, 0]] = dc;
        let plane = crate::fft::inverse_real(&spectrum);
        out.index_axis_mut(Axis(0), k)
            .assign(&plane.mapv(|v| v as f32));
    }
    out
}

/// The image with its pixels in a seeded random order (each pixel's colour kept).
pub fn shuffle(image: &Array3<f32>, seed: u64) -> Array3<f32> {
    let (_, h, w) = image.dim();
    let mut order: Vec<usize> = (0..h * w).collect();
    order.shuffle(&mut rand_pcg::Pcg64::seed_from_u64(seed));
    Array3::from_shape_fn(image.dim(), |(c, y, x)| {
        let k = order[y * w + x];
        image[[c, k / w, k % w]]
    })
}

/// Separable Gaussian blur (`sigma` pixels, borders clamped).
pub fn blur(image: &Array3<f32>, sigma: f64) -> Array3<f32> {
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|d| (-(d * d) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let norm: f64 = kernel.iter().sum();
    let (_, h, w) = image.dim();
    let pass = |src: &Array3<f32>, vertical: bool| {
        Array3::from_shape_fn(src.dim(), |(c, y, x)| {
            let mut acc = 0.0;
            for (i, k) in kernel.iter().enumerate() {
                let d = i as isize - radius;
                let (yy, xx) = if vertical {
                    ((y as isize + d).clamp(0, h as isize - 1) as usize, x)
                } else {
                    (y, (x as isize + d).clamp(0, w as isize - 1) as usize)
                };
                acc += k * f64::from(src[[c, yy, xx]]);
            }
            (acc / norm) as f32
        })
    };
    pass(&pass(image, false), true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blobs(h: usize, w: usize, seed: u64) -> Array3<f32> {
        // Sparse bright discs on a dark ground: strongly non-Gaussian structure.
        use rand::RngExt;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let centres: Vec<(f64, f64)> = (0..(h * w) / 150)
            .map(|_| {
                (
                    rng.random::<f64>() * h as f64,
                    rng.random::<f64>() * w as f64,
                )
            })
            .collect();
        let mut plane = Array2::from_elem((h, w), 0.05f32);
        for &(cy, cx) in &centres {
            for y in 0..h {
                for x in 0..w {
                    if (y as f64 - cy).powi(2) + (x as f64 - cx).powi(2) < 9.0 {
                        plane[[y, x]] = 0.6;
                    }
                }
            }
        }
        Array3::from_shape_fn((3, h, w), |(c, y, x)| plane[[y, x]] * [1.0, 0.8, 0.6][c])
    }

    #[test]
    fn the_mean_verdict_averages_every_field() {
        let y = Yardstick::new(&blobs(32, 64, 9), None, 1).unwrap();
        let (a, b) = (y.levels().crop, y.levels().shuffled);
        let m = Verdict::mean(&[a, b]).unwrap();
        let mid = |x: f64, y: f64| (x + y) / 2.0;
        assert!(
            (m.judgement.structure - mid(a.judgement.structure, b.judgement.structure)).abs()
                < 1e-12
        );
        assert!((m.structure_vs_crop - mid(1.0, b.structure_vs_crop)).abs() < 1e-12);
        assert!(
            (m.judgement.chroma_std[1] - mid(a.judgement.chroma_std[1], b.judgement.chroma_std[1]))
                .abs()
                < 1e-12
        );
        assert!(Verdict::mean(&[]).is_none());
    }

    #[test]
    fn scales_grow_with_the_image() {
        assert_eq!(scales_for(16), 1);
        assert_eq!(scales_for(32), 1);
        assert_eq!(scales_for(64), 2);
        assert_eq!(scales_for(96), 2);
        assert_eq!(scales_for(128), 3);
        assert_eq!(scales_for(256), 4);
        assert_eq!(scales_for(4096), 4);
    }

    #[test]
    fn moments_of_known_samples() {
        let m = moments([1.0, 2.0, 3.0, 4.0].into_iter());
        assert!((m.std - 1.25f64.sqrt()).abs() < 1e-12);
        assert!(m.skewness.abs() < 1e-12);
        assert!((m.kurtosis - 1.64).abs() < 1e-12); // (2 * 1.5^4 + 2 * 0.5^4) / 4 / 1.25^2
        let flat = moments([2.0; 5].into_iter());
        assert_eq!((flat.std, flat.kurtosis), (0.0, 3.0));
    }

    #[test]
    fn quantile_distance_is_the_shift_of_a_shifted_sample() {
        let a: Vec<f32> = (0..1000).map(|i| i as f32 / 10.0).collect();
        let b: Vec<f32> = a.iter().map(|v| v + 0.3).collect();
        assert!((quantile_distance(&a, &b) - 0.3).abs() < 1e-4);
        assert_eq!(quantile_distance(&a, &a), 0.0);
    }

    #[test]
    fn random_phase_keeps_the_power_spectrum_and_the_mean() {
        let im = blobs(48, 40, 1);
        let rp = random_phase(&im, 7);
        for k in 0..3 {
            let (a, b) = (
                im.index_axis(Axis(0), k).mapv(f64::from),
                rp.index_axis(Axis(0), k).mapv(f64::from),
            );
            let (fa, fb) = (crate::fft::forward(&a), crate::fft::forward(&b));
            for (x, y) in fa.iter().zip(&fb) {
                assert!((x.norm() - y.norm()).abs() < 1e-3 * (1.0 + x.norm()));
            }
        }
        assert_eq!(rp, random_phase(&im, 7), "same seed, same noise");
        assert_ne!(rp, random_phase(&im, 8));
        assert_ne!(rp, im);
    }

    #[test]
    fn identical_images_are_at_distance_zero_and_the_shift_of_colour_shows() {
        let im = blobs(64, 64, 3);
        let s = Signature::of(&im, 2).unwrap();
        let j = s.compare(&s);
        assert_eq!((j.structure, j.colour_lab), (0.0, 0.0));
        let darker = im.mapv(|v| v * 0.8);
        let d = Signature::of(&darker, 2).unwrap().compare(&s);
        assert!(d.colour_lab_channels[0] > 1.0, "{d:?}");
    }

    #[test]
    fn the_coupling_sees_colour_moved_between_light_and_dark_pixels() {
        // Half the pixels grey, half brown, each half of mixed lightness; with grey and brown
        // traded between the bright and the dark pixels the Lab marginals move a little (the
        // brown's chroma scales with its lightness), how chroma goes with lightness a lot.
        let (h, w) = (32, 64);
        let pixel = |y: usize, x: usize, swap: bool| {
            let bright = (x + y).is_multiple_of(2);
            let grey = bright != swap;
            let v = if bright { 0.6 } else { 0.15 };
            if grey {
                [v, v, v]
            } else {
                [v * 1.3, v, v * 0.6]
            }
        };
        let image =
            |swap: bool| Array3::from_shape_fn((3, h, w), |(c, y, x)| pixel(y, x, swap)[c] as f32);
        let (kept, traded) = (image(false), image(true));
        let s = Signature::of(&kept, 2).unwrap();
        assert_eq!(s.compare(&s).colour_coupling, 0.0);
        let shuffled = Signature::of(&shuffle(&kept, 4), 2).unwrap().compare(&s);
        assert!(shuffled.colour_coupling < 1e-9, "{shuffled:?}");
        let d = Signature::of(&traded, 2).unwrap().compare(&s);
        assert!(d.colour_coupling > 4.0 * d.colour_lab, "{d:?}");
    }

    #[test]
    fn too_small_or_grey_images_are_refused_with_a_clear_error() {
        let small = Array3::<f32>::zeros((3, 12, 100));
        let e = Signature::of(&small, 1).unwrap_err().to_string();
        assert!(e.contains("at least 16x16") && e.contains("100x12"), "{e}");
        let e = Yardstick::new(&Array3::<f32>::zeros((3, 24, 24)), None, 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("two crops"), "{e}");
    }

    /// The ranking the judge exists for, on a synthetic texture whose structure is not
    /// Gaussian: another crop < random phase < shuffled, blurred.
    #[test]
    fn levels_rank_crop_then_random_phase_then_shuffle_and_blur() {
        let im = blobs(64, 128, 5);
        let y = Yardstick::new(&im, None, 2).unwrap();
        let l = y.levels();
        let (c, r) = (
            l.crop.judgement.structure,
            l.random_phase.judgement.structure,
        );
        assert!(c < r, "crop {c} random phase {r}");
        assert!(r < l.shuffled.judgement.structure && r < l.blurred.judgement.structure);
        assert!((l.crop.structure_vs_crop - 1.0).abs() < 1e-12);
        assert_eq!(l.measured.judgement.structure, 0.0);
    }
}
