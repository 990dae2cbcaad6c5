//! The wgpu renderer: a [`MaterialModel`](btfmrf::model::MaterialModel) on a mesh, by bump or
//! displacement mapping (seed 001, sec. 5.3), headless to an image or in a window.
//!
//! Per fragment, the view and light directions are taken into the surface's tangent frame, each
//! is interpolated from its 3 nearest measured directions (barycentric weights, exactly as
//! [`DirectionSet::interpolate`](btfmrf::btf::DirectionSet::interpolate) does on the CPU), and
//! the 9 (view, light) pairs pick their clusters' synthesized subspace images from a tileable
//! texture array. The blend is relit by the range map's normals like
//! [`bump_relight`](btfmrf::synthesis::bump_relight): `max(0, n . l) / mean(max(0, n . l))`.
//! Displacement mapping also moves the vertices of a finely tessellated mesh along the normal
//! by the range map.
//!
//! Only what a scene needs is modelled: [`plan::ScenePlan`] finds the clusters that the
//! visible surface touches and the texture resolution of its screen footprint, and only those
//! subspace images are synthesized.
//!
//! An LPCA model ([`btfmrf::lpca::LpcaModel`], Müller et al. 2003) renders through its own
//! pipeline, [`Mapping::Lpca`] ([`lpca`]): every fragment decodes its texel's 3 x 3 nearest
//! measured (view, light) pairs from the cluster's eigen-ABRDFs and the texel's weights,
//! with the same direction tables, so nothing is synthesized.
//!
//! Layout: [`context`] (device, headless or for a window), [`mesh`] (meshes with tangent
//! frames, OBJ), [`scene`] (camera and light), [`lut`] (direction and shading lookup tables,
//! CPU mirrors of the shader), [`plan`], [`pipeline`] (shaders, GPU material resources, one
//! render pipeline per [`Mapping`]), [`headless`] (render to an image), [`viewer`] (winit).

pub mod context;
pub mod headless;
pub mod lpca;
pub mod lut;
pub mod mesh;
pub mod pipeline;
pub mod plan;
pub mod scene;
pub mod viewer;

use std::path::PathBuf;

pub use context::GpuContext;
pub use headless::{RenderOutput, Renderer};
pub use mesh::{Mesh, MeshKind};
pub use scene::{Camera, Light, Scene};

use btfmrf::model::ModelError;

/// Result alias for the render area.
pub type Result<T, E = RenderError> = std::result::Result<T, E>;

/// The largest rendered image side and texture side, pixels.
pub const MAX_RENDER_SIDE: u32 = 8192;

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
    /// The model and the requested pipeline do not go together.
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

/// How the material is put on the mesh: one render pipeline each.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mapping {
    /// MRF subspace images blended per fragment, relit by the range map's normals.
    Bump,
    /// As [`Mapping::Bump`], on a tessellated mesh displaced along the normal by the range map.
    Displacement,
    /// One subspace image as a plain texture, no view or light dependence: the baseline cost
    /// of texturing the same mesh (benchmarks).
    Plain,
    /// An LPCA model ([`btfmrf::lpca::LpcaModel`]) decoded per fragment: cluster mean plus
    /// weighted eigen-ABRDFs of the 3 x 3 nearest measured (view, light) pairs.
    Lpca,
}

impl Mapping {
    /// Every mapping.
    pub const ALL: [Mapping; 4] = [
        Mapping::Bump,
        Mapping::Displacement,
        Mapping::Plain,
        Mapping::Lpca,
    ];

    /// The name on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Mapping::Bump => "bump",
            Mapping::Displacement => "displacement",
            Mapping::Plain => "plain",
            Mapping::Lpca => "lpca",
        }
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
                    format!("'{s}' is not bump, displacement, plain or lpca"),
                )
            })
    }
}

impl std::fmt::Display for Mapping {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
