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
