//! Scatter plots of the benchmark (plotters, drawn into memory and written as PNG): error or
//! the judge's structure distance against model size and against analysis time, one labelled point per method.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

use super::bench::{BenchReport, MethodId, MethodResult};
use super::{EvalError, Result};
use crate::btf::ImageFormat;
use crate::btf::io::picture::encode_rgb8;
use crate::io::write_file_atomic;
use crate::lpca::Method;

/// The embedded font (DejaVu Sans, see assets/fonts/DejaVuSans.LICENSE), so plots have text
/// without system font libraries.
const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
const WIDTH: u32 = 900;
const HEIGHT: u32 = 600;

/// One labelled point.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    /// Text next to the point.
    pub label: String,
    /// Horizontal position (drawn on a log scale).
    pub x: f64,
    /// Vertical position.
    pub y: f64,
    /// Colour group (same method family, same colour).
    pub group: usize,
}

/// Draws labelled points with a logarithmic x axis and writes a `WIDTH x HEIGHT` PNG.
///
/// # Errors
/// Drawing or writing failed, or there are no finite points with x > 0.
pub fn scatter(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    points: &[Point],
) -> Result<()> {
    let fail = |reason: String| EvalError::Plot {
        path: path.to_path_buf(),
        reason,
    };
    let points: Vec<&Point> = points
        .iter()
        .filter(|p| p.x > 0.0 && p.x.is_finite() && p.y.is_finite())
        .collect();
    if points.is_empty() {
        return Err(fail("no finite points to draw".into()));
    }
    register_font();
    let (x0, x1) = decades(points.iter().map(|p| p.x));
    let (y0, y1) = span(points.iter().map(|p| p.y));
    let mut buffer = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (WIDTH, HEIGHT)).into_drawing_area();
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 24))
            .margin(20)
            .margin_right(40)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
            .map_err(|e| fail(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style(("sans-serif", 15))
            .y_labels(8)
            .x_label_formatter(&|x| tick(*x))
            .light_line_style(RGBColor(238, 238, 238))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        chart
            .draw_series(points.iter().enumerate().map(|(i, p)| {
                let colour = Palette99::pick(p.group).to_rgba();
                // Staggered labels, so that close points stay readable.
                let dy = -22 + 15 * (i % 3) as i32;
                EmptyElement::at((p.x, p.y))
                    + Circle::new((0, 0), 6, colour.filled())
                    + Text::new(p.label.clone(), (9, dy), ("sans-serif", 15))
            }))
            .map_err(|e| fail(e.to_string()))?;
        root.present().map_err(|e| fail(e.to_string()))?;
    }
    let file = path.display().to_string();
    let png = encode_rgb8(&buffer, WIDTH, HEIGHT, ImageFormat::Png, &file)?;
    write_file_atomic(path, &png)?;
    Ok(())
}

/// The benchmark's plots, written into `dir`: structure distance against model size and against analysis
/// time for every method, and ΔE against model size for the methods that have one. Returns
/// (title, file name) of each plot written.
///
/// # Errors
/// Drawing or writing a plot failed.
pub fn benchmark_plots(report: &BenchReport, dir: &Path) -> Result<Vec<(String, String)>> {
    let points = |x: fn(&MethodResult) -> f64, y: fn(&MethodResult) -> Option<f64>| {
        report
            .methods
            .iter()
            .filter_map(|m| {
                Some(Point {
                    label: label(m),
                    x: x(m),
                    y: y(m)?,
                    group: group(&m.method),
                })
            })
            .collect::<Vec<_>>()
    };
    let kib = |m: &MethodResult| m.model_bytes as f64 / 1024.0;
    let plots: [(&str, &str, &str, Vec<Point>); 3] = [
        (
            "structure_vs_size.png",
            "Structure distance (judge) against model size (lower is better)",
            "model size, KiB (log)",
            points(kib, |m| Some(m.judge.judgement.structure)),
        ),
        (
            "structure_vs_time.png",
            "Structure distance (judge) against analysis time (lower is better)",
            "analysis time, s (log)",
            points(
                |m| m.analysis_seconds,
                |m| Some(m.judge.judgement.structure),
            ),
        ),
        (
            "delta_e_vs_size.png",
            "Mean CIE76 ΔE against model size (pixelwise methods)",
            "model size, KiB (log)",
            points(kib, |m| m.mean_delta_e),
        ),
    ];
    let mut written = Vec::new();
    for (file, title, x_desc, pts) in plots {
        if pts.is_empty() {
            continue;
        }
        let y_desc = if file.starts_with("delta") {
            "mean ΔE"
        } else {
            "structure distance"
        };
        scatter(&dir.join(file), title, x_desc, y_desc, &pts)?;
        written.push((title.to_string(), file.to_string()));
    }
    Ok(written)
}

/// A point's label: the method and its main parameters (`lpca K=8,C=4`).
fn label(m: &MethodResult) -> String {
    let params: Vec<String> = m
        .method
        .parameters()
        .entries()
        .into_iter()
        .filter_map(|(k, v)| match k {
            "clusters" => Some(format!("K={v}")),
            "components" => Some(format!("C={v}")),
            _ => None,
        })
        .collect();
    if params.is_empty() {
        m.method.name().to_string()
    } else {
        format!("{} {}", m.method.name(), params.join(","))
    }
}

/// MRF models in one colour family, each PCA method in another.
fn group(method: &MethodId) -> usize {
    match method {
        MethodId::Mrf { .. } => 0,
        MethodId::Baseline(b) => match b.method {
            Method::Lpca => 1,
            Method::PcaBtf => 2,
            Method::PcaRf => 3,
        },
    }
}

/// A padded range around the values (never empty).
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    let pad = ((hi - lo) * 0.15).max(hi.abs().max(1.0) * 0.05);
    (lo - pad, hi + pad)
}

/// A log-axis tick without needless decimals (1000, 10, 0.1, 0.01).
fn tick(x: f64) -> String {
    if x >= 1.0 {
        format!("{x:.0}")
    } else {
        format!("{x}")
    }
}

/// The enclosing powers of ten of positive values (at least one decade), so that a log axis
/// always has labelled ticks.
fn decades(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    let lo = 10f64.powf(lo.log10().floor());
    let hi = 10f64.powf(hi.log10().ceil()).max(lo * 10.0);
    (lo, hi)
}

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid (it is part of the build); an error would only mean
        // text-less plots, so it is not worth failing for.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_pad_and_cover_whole_decades() {
        let (lo, hi) = span([2.0].into_iter());
        assert!(lo < 2.0 && hi > 2.0);
        let (lo, hi) = span([1.0, 3.0].into_iter());
        assert!(lo < 1.0 && hi > 3.0);
        assert_eq!(decades([30.0, 38.0].into_iter()), (10.0, 100.0));
        assert_eq!(decades([0.5, 2000.0].into_iter()), (0.1, 10000.0));
    }

    #[test]
    fn scatter_writes_a_png_with_drawn_points() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        let pts = [
            Point {
                label: "a".into(),
                x: 10.0,
                y: 1.0,
                group: 0,
            },
            Point {
                label: "b".into(),
                x: 1000.0,
                y: 2.0,
                group: 1,
            },
        ];
        scatter(&path, "t", "x", "y", &pts).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (WIDTH, HEIGHT));
        let non_white = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
        assert!(non_white > 1000, "only {non_white} drawn pixels");
        // No points: an error, and no file.
        let empty = dir.path().join("e.png");
        assert!(scatter(&empty, "t", "x", "y", &[]).is_err());
        assert!(!empty.exists());
    }
}
