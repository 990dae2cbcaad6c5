//! The wgpu renderer: a [`MaterialModel`](btfmrf::model::MaterialModel) on a mesh, by bump or
//! displacement mapping (seed 001, sec. 5.3), headless to an image or in a window.
//!
//! Per fragment, the view and light directions are taken into the surface's tangent frame, each
//! is interpolated from its 3 nearest measured directions (barycentric weights, exactly as
//! [`DirectionSet::interpolate`](btfmrf::btf::DirectionSet::interpolate) does on the CPU), and
//! the 9 (view, light) pairs pick their clusters' synthesized subspace images from a tileable
//! texture array. The blend is relit by the range map's normals like
//! [`bump_relight`](btfmrf::synthesis::bump_relight): `max(0, n . l) / mean(max(0, n . l))`,
//! times the cast light of a shadow ray marched over the heights where the map casts shadows.
//! Displacement mapping also moves the vertices of a finely tessellated mesh along the normal
//! by the range map.
//!
//! Only what a scene needs is modelled: [`plan::ScenePlan`] finds the clusters that the
//! visible surface touches and the texture resolution of its screen footprint, and only those
//! subspace images are synthesized.
//!
//! An LPCA model ([`btfmrf::lpca::LpcaModel`], Müller et al. 2003) is another [`Material`]
//! with a pass of its own ([`lpca`]): every fragment decodes its texel's 3 x 3 nearest
//! measured (view, light) pairs from the cluster's eigen-ABRDFs and the texel's weights,
//! with the same direction tables, so nothing is synthesized. The [`Mapping`] (geometry)
//! applies to MRF models only, and the types say so.
//!
//! Layout: [`context`] (device, headless or for a window), [`mesh`] (meshes with tangent
//! frames, OBJ), [`scene`] (camera and light), [`lut`] (direction and shading lookup tables,
//! CPU mirrors of the shader), [`plan`], [`pipeline`] (what every pass shares: uniforms,
//! direction tables, mesh buffers, pipeline construction), one pass per material ([`mrf`]:
//! one pipeline per [`Mapping`]; [`lpca`]), [`frame`] (render targets and readback),
//! [`headless`] (render to an image), [`viewer`] (winit).

pub mod context;
pub mod frame;
pub mod headless;
pub mod lpca;
pub mod lut;
pub mod mesh;
pub mod mrf;
pub mod pipeline;
pub mod plan;
pub mod scene;
pub mod viewer;

use std::path::PathBuf;

pub use context::GpuContext;
pub use headless::{LpcaStats, ModelRenderOptions, MrfStats, RenderOutput, RenderStats, Renderer};
pub use mesh::{Mesh, MeshKind};
pub use scene::{Camera, Light, Scene};

use btfmrf::lpca::LpcaModel;
use btfmrf::model::{MaterialModel, ModelError};

/// Result alias for the render area.
pub type Result<T, E = RenderError> = std::result::Result<T, E>;

/// The largest rendered image side and texture side, pixels.
pub const MAX_RENDER_SIDE: u32 = 8192;

/// The smallest tile side, measured texels per texture repetition (`render --tile`,
/// `view --tile`): below it, the subspace images are too small to hold the material.
pub const MIN_TILE: usize = 32;

/// Checks `tile` (measured texels per texture repetition, the side at which subspace images
/// and range map are synthesized) for `model`: one range for `render` and `view`.
///
/// # Errors
/// A side that is not a power of two within `MIN_TILE.max(model.min_synthesis_side())` and
/// [`MAX_RENDER_SIDE`].
pub fn check_tile(model: &MaterialModel, tile: usize) -> Result<()> {
    let min = model.min_synthesis_side().max(MIN_TILE);
    if !tile.is_power_of_two() || !(min..=MAX_RENDER_SIDE as usize).contains(&tile) {
        return Err(RenderError::parameter(
            "--tile",
            format!("{tile} is not a power of two within {min}..={MAX_RENDER_SIDE}"),
        ));
    }
    Ok(())
}

/// What can go wrong while rendering.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// No GPU adapter (not even a software one such as Mesa lavapipe) could be found.
    #[error(
        "no GPU adapter found ({0}); install a Vulkan driver (on Debian: mesa-vulkan-drivers, see scripts/setup)"
    )]
    NoAdapter(String),
    /// The device could not be created or reported an error.
    #[error("GPU device: {0}")]
    Device(String),
    /// The model could not be read or synthesized.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A mesh file is missing, corrupt or unusable.
    #[error("{}: {reason}", path.display())]
    Mesh {
        /// The mesh file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A caller's argument is out of range (named as on the command line).
    #[error("invalid {name}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Why it is rejected.
        reason: String,
    },
    /// An LPCA model could not be read or is not one this renderer decodes.
    #[error(transparent)]
    Lpca(#[from] btfmrf::lpca::LpcaError),
    /// The model is one this renderer cannot draw (a PCA BTF model, or one beyond the
    /// device's limits).
    #[error("{0}")]
    Unsupported(String),
    /// The window system failed.
    #[error("window: {0}")]
    Window(String),
}

impl RenderError {
    pub(crate) fn parameter(name: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name,
            reason: reason.into(),
        }
    }
}

/// How the MRF material is put on the mesh's geometry: one render pipeline each (see
/// [`mrf::MrfPass`]). An LPCA model has no range map and is drawn on the mesh as it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mapping {
    /// Subspace images blended per fragment, relit by the range map's normals.
    Bump,
    /// As [`Mapping::Bump`], on a tessellated mesh displaced along the normal by the range map.
    Displacement,
    /// One subspace image as a plain texture, no view or light dependence: the baseline cost
    /// of texturing the same mesh (benchmarks).
    Plain,
}

impl Mapping {
    /// Every mapping, in the order of [`Mapping::index`].
    pub const ALL: [Mapping; 3] = [Mapping::Bump, Mapping::Displacement, Mapping::Plain];

    /// The name on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Mapping::Bump => "bump",
            Mapping::Displacement => "displacement",
            Mapping::Plain => "plain",
        }
    }

    /// The position in [`Mapping::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

impl std::str::FromStr for Mapping {
    type Err = RenderError;
    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                RenderError::parameter(
                    "--mapping",
                    format!("'{s}' is not bump, displacement or plain"),
                )
            })
    }
}

impl std::fmt::Display for Mapping {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What decodes the BTF per fragment, with what it needs: the job of
/// [`Renderer::render_material`].
#[derive(Debug, Clone, Copy)]
pub enum Material<'a> {
    /// An MRF model: the subspace images the scene needs are synthesized, then blended.
    Mrf(&'a MaterialModel, ModelRenderOptions),
    /// An LPCA (or PCA RF) model, decoded per fragment; nothing is synthesized.
    Lpca(&'a LpcaModel),
}

/// Every pipeline's WGSL source, named: what the naga validation test checks.
pub fn shader_sources() -> Vec<(&'static str, String)> {
    let mut sources: Vec<_> = Mapping::ALL
        .into_iter()
        .map(|m| (m.name(), mrf::shader_source(m)))
        .collect();
    sources.push(("lpca", lpca::shader_source()));
    sources
}
