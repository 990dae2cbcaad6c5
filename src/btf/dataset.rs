//! The [`Btf`] type: view and light direction sets, a spatial size, and images handed out
//! lazily by (view, light) index from some [`ImageSource`].

use ndarray::Array3;

use super::directions::DirectionSet;
use super::error::{BtfError, Result};

/// Where a BTF's images come from: an archive, a folder, a procedural renderer, memory.
///
/// Implementations decode one image per call and keep at most a small cache, so that a
/// measurement of gigabytes is streamed rather than loaded whole.
pub trait ImageSource: Send + Sync {
    /// Loads image (view, light) as planar `(3, height, width)` linear RGB.
    ///
    /// Indices are in range (the [`Btf`] checks them before calling).
    fn load(&self, view: usize, light: usize) -> Result<Array3<f32>>;

    /// A human-readable name of the image (file or archive member), for messages.
    fn describe(&self, view: usize, light: usize) -> String;
}

/// A bidirectional texture function: one image per (view, light) pair, all the same size.
pub struct Btf {
    views: DirectionSet,
    lights: DirectionSet,
    width: u32,
    height: u32,
    label: String,
    warnings: Vec<String>,
    source: Box<dyn ImageSource>,
}

impl std::fmt::Debug for Btf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Btf")
            .field("label", &self.label)
            .field("views", &self.views.len())
            .field("lights", &self.lights.len())
            .field("width", &self.width)
            .field("height", &self.height)
            .finish()
    }
}

impl Btf {
    /// A BTF over any image source.
    ///
    /// # Errors
    /// A zero width or height.
    pub fn from_source(
        label: impl Into<String>,
        views: DirectionSet,
        lights: DirectionSet,
        width: u32,
        height: u32,
        source: Box<dyn ImageSource>,
    ) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(BtfError::parameter(
                "size",
                format!("{width}x{height} has no pixels"),
            ));
        }
        Ok(Self {
            views,
            lights,
            width,
            height,
            label: label.into(),
            warnings: Vec::new(),
            source,
        })
    }

    /// A BTF held in memory: `images[view * lights.len() + light]`, each `(3, h, w)`.
    ///
    /// # Errors
    /// A count that is not views x lights, images of different sizes, non-finite pixels.
    pub fn from_images(
        views: DirectionSet,
        lights: DirectionSet,
        images: Vec<Array3<f32>>,
    ) -> Result<Self> {
        let expected = views.len() * lights.len();
        if images.len() != expected {
            return Err(BtfError::parameter(
                "images",
                format!(
                    "{} images given for {} views x {} lights",
                    images.len(),
                    views.len(),
                    lights.len()
                ),
            ));
        }
        let (c, h, w) = images[0].dim();
        for (i, im) in images.iter().enumerate() {
            let name = format!("image {i}");
            if im.dim() != (3, h, w) || c != 3 {
                let d = im.dim();
                return Err(BtfError::parameter(
                    "images",
                    format!("{name} has shape {d:?}, expected (3, {h}, {w})"),
                ));
            }
            check_finite(im, &name)?;
        }
        let (w32, h32) = (to_u32(w, "width")?, to_u32(h, "height")?);
        let source = MemorySource {
            lights: lights.len(),
            images,
        };
        Self::from_source("in-memory BTF", views, lights, w32, h32, Box::new(source))
    }

    /// The view directions, in index order.
    pub fn views(&self) -> &DirectionSet {
        &self.views
    }

    /// The light directions, in index order.
    pub fn lights(&self) -> &DirectionSet {
        &self.lights
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of images, views x lights.
    pub fn image_count(&self) -> usize {
        self.views.len() * self.lights.len()
    }

    /// Size of the BTF as raw 8-bit RGB: images x width x height x 3 bytes (the numerator of
    /// every compression ratio we report).
    pub fn raw_bytes(&self) -> u64 {
        self.image_count() as u64 * u64::from(self.width) * u64::from(self.height) * 3
    }

    /// Where the BTF came from (a path or a description).
    pub fn label(&self) -> &str {
        &self.label
    }

    /// Oddities of the source that were tolerated (e.g. a `.lp` count that disagrees with its
    /// lines), for the user to see.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The same BTF with these warnings attached.
    pub fn with_warnings(mut self, warnings: Vec<String>) -> Self {
        self.warnings.extend(warnings);
        self
    }

    /// A human-readable name of image (view, light), e.g. the archive member.
    pub fn describe(&self, view: usize, light: usize) -> String {
        self.source.describe(view, light)
    }

    /// Image (view, light) as planar `(3, height, width)` linear RGB, decoded on demand.
    ///
    /// # Errors
    /// Indices out of range, or the image cannot be read or decoded.
    pub fn image(&self, view: usize, light: usize) -> Result<Array3<f32>> {
        if view >= self.views.len() || light >= self.lights.len() {
            return Err(BtfError::parameter(
                "image index",
                format!(
                    "(view {view}, light {light}) is outside {} views x {} lights",
                    self.views.len(),
                    self.lights.len()
                ),
            ));
        }
        let image = self.source.load(view, light)?;
        let (c, h, w) = image.dim();
        if c != 3 || h != self.height as usize || w != self.width as usize {
            return Err(BtfError::SizeMismatch {
                file: self.source.describe(view, light),
                width: self.width,
                height: self.height,
                found_w: w as u32,
                found_h: h as u32,
            });
        }
        Ok(image)
    }
}

fn to_u32(v: usize, name: &'static str) -> Result<u32> {
    u32::try_from(v).map_err(|_| BtfError::parameter(name, format!("{v} is too large")))
}

/// Images kept in memory, view-major.
struct MemorySource {
    lights: usize,
    images: Vec<Array3<f32>>,
}

impl ImageSource for MemorySource {
    fn load(&self, view: usize, light: usize) -> Result<Array3<f32>> {
        Ok(self.images[view * self.lights + light].clone())
    }

    fn describe(&self, view: usize, light: usize) -> String {
        format!("in-memory image (view {view}, light {light})")
    }
}

/// Fails with [`BtfError::NonFinite`] if any sample of a `(c, h, w)` image is NaN or infinite.
pub fn check_finite(image: &Array3<f32>, file: &str) -> Result<()> {
    let (channels, h, w) = image.dim();
    let mut count = 0usize;
    let mut first = None;
    for y in 0..h {
        for x in 0..w {
            for c in 0..channels {
                if !image[[c, y, x]].is_finite() {
                    count += 1;
                    first.get_or_insert((x, y));
                }
            }
        }
    }
    match first {
        None => Ok(()),
        Some((x, y)) => Err(BtfError::NonFinite {
            file: file.to_string(),
            count,
            x,
            y,
        }),
    }
}
