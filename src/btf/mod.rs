//! The BTF data model and its sources: directions, the lazy [`Btf`] type, file formats
//! (UBO2003 zip/folder, RTI, EXR) and procedural reference materials.

pub mod dataset;
pub mod directions;
pub mod error;
pub mod io;
pub mod synthetic;

pub use dataset::{Btf, ImageSource};
pub use directions::{Direction, DirectionSet, Weighted};
pub use error::{BtfError, Result};
pub use io::ImageFormat;

use std::path::Path;

/// The constructors that dispatch to a reader or generator live here, above
/// [`dataset`], [`io`] and [`synthetic`], so that those three import one another one way only
/// (`io` and `synthetic` build a [`Btf`]; [`dataset`] knows neither).
impl Btf {
    /// Opens a BTF from disk, recognising the layout:
    /// - a `.zip` archive or a folder of UBO2003-named images (`... tl015 pl060 tv000 pv000.jpg`,
    ///   JPEG, PNG or EXR);
    /// - an RTI folder holding a `.lp` light-position file (one view, N lights), or the `.lp`
    ///   file itself.
    ///
    /// The layout is validated completely (names, directions, image sizes) before this returns;
    /// pixel data is decoded only when [`Btf::image`] asks for it.
    ///
    /// # Errors
    /// Unreadable paths, corrupt archives, bad names, missing or duplicate directions,
    /// mixed or oversized images; each error names the file at fault.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        io::open(path.as_ref())
    }

    /// A procedural material rendered lazily in the Bonn sampling (81 x 81), `size` x `size`
    /// texels, deterministic in `seed`. See [`synthetic`].
    ///
    /// # Errors
    /// `size` outside the accepted range.
    pub fn synthetic(material: synthetic::SyntheticMaterial, size: u32, seed: u64) -> Result<Self> {
        Ok(synthetic::SyntheticBtf::new(material, size, seed)?.into_btf())
    }
}
