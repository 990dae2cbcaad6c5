//! Procedural reference materials, rendered as BTFs: a periodic height field (meso-geometry)
//! with a spatially varying BRDF, ray-marched for every (view, light) pair with parallax,
//! masking and cast shadows, in the spirit of the Flat-BTF paper's synthetic test data
//! (seed 004, sec. 5). They are the project's built-in inputs, and because their geometry is
//! known ([`GroundTruth`]), later stages (photometric stereo, range maps) can be checked
//! against the truth.
//!
//! Rendering is lazy: an image is shaded when asked for. Per view, the surface point every
//! texel shows is found once (and cached for a few views); per light, a shadow map of the tile
//! is computed once. An image is then a cheap per-texel shading pass.

mod materials;
mod noise;
mod render;

use std::collections::VecDeque;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};

use ndarray::{Array2, Array3};

use super::dataset::{Btf, ImageSource};
use super::directions::DirectionSet;
use super::error::{BtfError, Result};
use super::io::picture::encode_exr_channels;
use materials::{Knit, Leather, Pattern, Sponge, Stones};
use render::{Surface, ViewSample, shade};

/// Smallest accepted tile size, texels.
pub const MIN_SIZE: u32 = 4;
/// Largest accepted tile size, texels (memory grows with size^2 per cached view).
pub const MAX_SIZE: u32 = 2048;

/// The built-in procedural materials.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SyntheticMaterial {
    /// Irregular porous foam: round pores of two sizes, matte yellow.
    Sponge,
    /// A regular plain weave of red and cream threads.
    Knit,
    /// Rounded cobbles of mixed colours in light grout; the deepest relief.
    Stones,
    /// Fine irregular grain with creases; dark brown and glossy; the shallowest relief.
    Leather,
}

impl SyntheticMaterial {
    /// Every material, in a fixed order.
    pub const ALL: [SyntheticMaterial; 4] = [
        SyntheticMaterial::Sponge,
        SyntheticMaterial::Knit,
        SyntheticMaterial::Stones,
        SyntheticMaterial::Leather,
    ];

    /// The material's name on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            SyntheticMaterial::Sponge => "sponge",
            SyntheticMaterial::Knit => "knit",
            SyntheticMaterial::Stones => "stones",
            SyntheticMaterial::Leather => "leather",
        }
    }

    fn pattern(&self, seed: u64) -> Box<dyn Pattern> {
        match self {
            SyntheticMaterial::Sponge => Box::new(Sponge::new(seed)),
            SyntheticMaterial::Knit => Box::new(Knit::new(seed)),
            SyntheticMaterial::Stones => Box::new(Stones::new(seed)),
            SyntheticMaterial::Leather => Box::new(Leather::new(seed)),
        }
    }
}

impl std::str::FromStr for SyntheticMaterial {
    type Err = BtfError;
    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|m| m.name()).collect();
                BtfError::parameter(
                    "material",
                    format!("'{s}' is not one of {}", names.join(", ")),
                )
            })
    }
}

impl std::fmt::Display for SyntheticMaterial {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The geometry and reflectance a synthetic BTF was rendered from.
///
/// Frames: x right and y up in the image, z out of the surface; heights and all lengths in
/// texel units.
#[derive(Debug, Clone)]
pub struct GroundTruth {
    /// Height above the lowest point, texels, shape (h, w).
    pub height: Array2<f32>,
    /// Unit surface normals (x, y, z), shape (3, h, w).
    pub normals: Array3<f32>,
    /// Diffuse albedo, linear RGB, shape (3, h, w).
    pub albedo: Array3<f32>,
    /// Specular strength of the Blinn-Phong lobe, shape (h, w).
    pub specular: Array2<f32>,
    /// Blinn-Phong exponent, shape (h, w).
    pub shininess: Array2<f32>,
}

impl GroundTruth {
    fn from_surface(s: &Surface) -> Self {
        let n = s.n;
        let plane = |f: &dyn Fn(usize) -> f32| Array2::from_shape_fn((n, n), |(i, j)| f(i * n + j));
        Self {
            height: plane(&|k| s.height[k]),
            normals: Array3::from_shape_fn((3, n, n), |(c, i, j)| s.normal[i * n + j][c]),
            albedo: Array3::from_shape_fn((3, n, n), |(c, i, j)| s.albedo[i * n + j][c]),
            specular: plane(&|k| s.specular[k]),
            shininess: plane(&|k| s.shininess[k]),
        }
    }

    /// Writes the truth as EXR files into a new folder `dir`: `height.exr` (channel Y, texels),
    /// `normals.exr` (R, G, B = x, y, z), `albedo.exr` (linear RGB), `specular.exr` (Y = lobe
    /// strength) and `shininess.exr` (Y = exponent). The folder appears only when complete.
    ///
    /// # Errors
    /// `dir` exists already, or cannot be written.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let (h, w) = self.height.dim();
        let flat = |a: ndarray::ArrayView2<f32>| a.iter().copied().collect::<Vec<f32>>();
        let rgb = |a: &Array3<f32>| -> Vec<NamedPlane> {
            ["R", "G", "B"]
                .iter()
                .enumerate()
                .map(|(c, n)| (*n, flat(a.index_axis(ndarray::Axis(0), c))))
                .collect()
        };
        let files: [(&str, Vec<NamedPlane>); 5] = [
            ("height.exr", vec![("Y", flat(self.height.view()))]),
            ("normals.exr", rgb(&self.normals)),
            ("albedo.exr", rgb(&self.albedo)),
            ("specular.exr", vec![("Y", flat(self.specular.view()))]),
            ("shininess.exr", vec![("Y", flat(self.shininess.view()))]),
        ];
        let tmp = crate::io::temp_dir_beside(dir)?;
        for (name, planes) in files {
            let path = tmp.path().join(name);
            let bytes = encode_exr_channels(w, h, planes, &path.display().to_string())?;
            std::fs::write(&path, bytes).map_err(|e| BtfError::io(&path, e))?;
        }
        Ok(crate::io::publish_dir(tmp, dir)?)
    }
}

/// One named float channel of an EXR file, row-major.
type NamedPlane = (&'static str, Vec<f32>);

/// How many views' hit maps are kept (a writer walks view by view, a few threads at a time).
const VIEW_CACHE: usize = 6;

/// A procedural material as an [`ImageSource`] (use [`super::Btf::synthetic`] for the usual
/// Bonn sampling).
pub struct SyntheticBtf {
    label: String,
    view_set: DirectionSet,
    light_set: DirectionSet,
    surface: Surface,
    views: Vec<[f32; 3]>,
    lights: Vec<[f32; 3]>,
    shadows: Vec<OnceLock<Vec<f32>>>,
    view_cache: Mutex<VecDeque<(usize, Arc<Vec<ViewSample>>)>>,
}

fn unit_vectors(set: &DirectionSet) -> Vec<[f32; 3]> {
    set.iter().map(|d| d.vector().map(|c| c as f32)).collect()
}

impl SyntheticBtf {
    /// The material `material` on a `size` x `size` tile in the Bonn sampling.
    ///
    /// # Errors
    /// `size` outside [`MIN_SIZE`]..=[`MAX_SIZE`].
    pub fn new(material: SyntheticMaterial, size: u32, seed: u64) -> Result<Self> {
        Self::with_directions(
            material,
            size,
            seed,
            &DirectionSet::bonn(),
            &DirectionSet::bonn(),
        )
    }

    /// The material rendered for any view and light directions.
    ///
    /// # Errors
    /// `size` outside [`MIN_SIZE`]..=[`MAX_SIZE`].
    pub fn with_directions(
        material: SyntheticMaterial,
        size: u32,
        seed: u64,
        views: &DirectionSet,
        lights: &DirectionSet,
    ) -> Result<Self> {
        if !(MIN_SIZE..=MAX_SIZE).contains(&size) {
            return Err(BtfError::parameter(
                "--size",
                format!("{size} is outside {MIN_SIZE}..={MAX_SIZE} texels"),
            ));
        }
        let surface = Surface::sample(material.pattern(seed).as_ref(), size as usize);
        Ok(Self {
            label: format!("synthetic {material} ({size}x{size}, seed {seed})"),
            view_set: views.clone(),
            light_set: lights.clone(),
            surface,
            views: unit_vectors(views),
            lights: unit_vectors(lights),
            shadows: (0..lights.len()).map(|_| OnceLock::new()).collect(),
            view_cache: Mutex::new(VecDeque::new()),
        })
    }

    /// The material as a [`Btf`] (images rendered on demand).
    pub fn into_btf(self) -> Btf {
        let n = self.surface.n as u32;
        let (label, views, lights) = (
            self.label.clone(),
            self.view_set.clone(),
            self.light_set.clone(),
        );
        Btf::from_source(label, views, lights, n, n, Box::new(self))
            .expect("a synthetic tile has at least MIN_SIZE texels")
    }

    /// The height field, normals and BRDF maps the images are rendered from.
    pub fn ground_truth(&self) -> GroundTruth {
        GroundTruth::from_surface(&self.surface)
    }

    fn view_samples(&self, view: usize) -> Arc<Vec<ViewSample>> {
        let lock = || self.view_cache.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((_, s)) = lock().iter().find(|(v, _)| *v == view) {
            return Arc::clone(s);
        }
        // Computed outside the lock; two threads may race to compute the same view, which
        // costs time but not correctness (the result is deterministic).
        let samples = Arc::new(self.surface.view_samples(self.views[view]));
        let mut cache = lock();
        if !cache.iter().any(|(v, _)| *v == view) {
            cache.push_front((view, Arc::clone(&samples)));
            cache.truncate(VIEW_CACHE);
        }
        samples
    }
}

impl ImageSource for SyntheticBtf {
    fn load(&self, view: usize, light: usize) -> Result<Array3<f32>> {
        let samples = self.view_samples(view);
        let shadow =
            self.shadows[light].get_or_init(|| self.surface.shadow_map(self.lights[light]));
        let n = self.surface.n;
        let pixels = shade(&samples, shadow, n, self.views[view], self.lights[light]);
        Ok(Array3::from_shape_vec((3, n, n), pixels).expect("3 planes of n x n"))
    }

    fn describe(&self, view: usize, light: usize) -> String {
        format!("synthetic image (view {view}, light {light})")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn materials_parse_by_name() {
        for m in SyntheticMaterial::ALL {
            assert_eq!(m.name().parse::<SyntheticMaterial>().unwrap(), m);
        }
        let e = "velvet"
            .parse::<SyntheticMaterial>()
            .unwrap_err()
            .to_string();
        assert!(e.contains("sponge, knit, stones, leather"), "{e}");
    }

    #[test]
    fn sizes_out_of_range_are_rejected() {
        assert!(SyntheticBtf::new(SyntheticMaterial::Knit, 0, 1).is_err());
        assert!(SyntheticBtf::new(SyntheticMaterial::Knit, 3, 1).is_err());
        assert!(SyntheticBtf::new(SyntheticMaterial::Knit, MAX_SIZE + 1, 1).is_err());
    }

    #[test]
    fn rendering_is_deterministic_and_seed_dependent() {
        let a = SyntheticBtf::new(SyntheticMaterial::Stones, 16, 5).unwrap();
        let b = SyntheticBtf::new(SyntheticMaterial::Stones, 16, 5).unwrap();
        let c = SyntheticBtf::new(SyntheticMaterial::Stones, 16, 6).unwrap();
        assert_eq!(a.load(40, 7).unwrap(), b.load(40, 7).unwrap());
        assert_ne!(a.load(40, 7).unwrap(), c.load(40, 7).unwrap());
        // The cache must not change results: ask again after other views.
        let first = a.load(3, 3).unwrap();
        for v in 10..20 {
            a.load(v, 0).unwrap();
        }
        assert_eq!(a.load(3, 3).unwrap(), first);
    }

    #[test]
    fn truth_is_consistent() {
        let s = SyntheticBtf::new(SyntheticMaterial::Sponge, 32, 1).unwrap();
        let t = s.ground_truth();
        assert_eq!(t.height.dim(), (32, 32));
        let (lo, hi) = t
            .height
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &h| (a.min(h), b.max(h)));
        assert_eq!(lo, 0.0);
        assert!((hi - 0.07 * 32.0).abs() < 1e-3, "relief {hi}");
        for i in 0..32 {
            for j in 0..32 {
                let n: f32 = (0..3).map(|c| t.normals[[c, i, j]].powi(2)).sum();
                assert!((n - 1.0).abs() < 1e-4);
                assert!(t.normals[[2, i, j]] > 0.0);
            }
        }
    }
}
