//! Model files as image sources: [`AnyModel::open`] tells a `.btfm` (MRF) from a `.lpca`
//! model by its first bytes, and [`ModelImages`] / [`LpcaImages`] serve a model's images for
//! any view and light directions as a [`Btf`], so that the BTF writers can export them.

use std::path::Path;

use ndarray::Array3;

use crate::btf::{Btf, BtfError, Direction, DirectionSet, ImageSource};
use crate::lpca::{self, LpcaError, LpcaModel};
use crate::model::{MaterialModel, ModelError, format};
use crate::synthesis::{SynthesisCache, SynthesisOptions};

/// What can go wrong opening a model file or making its images.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The file could not be read, or a BTF of its images could not be made.
    #[error(transparent)]
    Btf(#[from] BtfError),
    /// A `.btfm` model is invalid, or synthesis failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A `.lpca` model is invalid.
    #[error(transparent)]
    Lpca(#[from] LpcaError),
}

/// Bytes at the start of a model file that tell its kind (both formats' magic numbers).
const SNIFF_BYTES: usize = 4;

/// The two model file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelFile {
    /// `.btfm`, an MRF model ([`format`]).
    Btfm,
    /// `.lpca`, a PCA model ([`lpca::format`]).
    Lpca,
}

impl ModelFile {
    /// The format whose magic bytes start `head`; `None` for anything else.
    pub fn sniff(head: &[u8]) -> Option<ModelFile> {
        if lpca::format::is_lpca(head) {
            Some(ModelFile::Lpca)
        } else if head.starts_with(&format::MAGIC) {
            Some(ModelFile::Btfm)
        } else {
            None
        }
    }

    /// The format of the file at `path` by its first bytes; `None` for a folder or another
    /// kind of file.
    ///
    /// # Errors
    /// The file cannot be read.
    pub fn of(path: &Path) -> Result<Option<ModelFile>, BtfError> {
        use std::io::Read;
        if path.is_dir() {
            return Ok(None);
        }
        let mut head = Vec::with_capacity(SNIFF_BYTES);
        std::fs::File::open(path)
            .and_then(|f| f.take(SNIFF_BYTES as u64).read_to_end(&mut head))
            .map_err(|e| BtfError::io(path, e))?;
        Ok(ModelFile::sniff(&head))
    }
}

/// A model file of either kind.
#[derive(Debug)]
pub enum AnyModel {
    /// An MRF model (`.btfm`): synthesizes texture of any size.
    Mrf(Box<MaterialModel>),
    /// A pixelwise PCA model (`.lpca`): rebuilds the measured tile.
    Lpca(Box<LpcaModel>),
}

impl AnyModel {
    /// Reads a model file, its kind told by its magic bytes (the extension is not trusted):
    /// the `.lpca` magic means an LPCA model, anything else is read as a `.btfm` model (whose
    /// reader names a wrong magic).
    ///
    /// # Errors
    /// The file cannot be read, or it is not a valid model of the kind it claims.
    pub fn open(path: &Path) -> Result<Self, SourceError> {
        if ModelFile::of(path)? == Some(ModelFile::Lpca) {
            Ok(AnyModel::Lpca(Box::new(lpca::format::read(path)?)))
        } else {
            Ok(AnyModel::Mrf(Box::new(format::read(path)?)))
        }
    }

    /// The measured view directions the model was fitted on.
    pub fn views(&self) -> &DirectionSet {
        match self {
            AnyModel::Mrf(m) => m.views(),
            AnyModel::Lpca(m) => m.views(),
        }
    }

    /// The measured light directions the model was fitted on.
    pub fn lights(&self) -> &DirectionSet {
        match self {
            AnyModel::Mrf(m) => m.lights(),
            AnyModel::Lpca(m) => m.lights(),
        }
    }
}

/// An MRF model's synthesized images for chosen views and lights, drawing on one synthesis
/// cache (each subspace image is synthesized once, when an image first needs it).
pub struct ModelImages {
    model: MaterialModel,
    cache: SynthesisCache,
    views: DirectionSet,
    lights: DirectionSet,
}

impl ModelImages {
    /// The images of `model` for every pair of `views` x `lights`, synthesized with
    /// `options` (their size, seed and tileability), as a BTF labelled "synthesized".
    ///
    /// # Errors
    /// Invalid synthesis options, or a size that does not fit a BTF.
    pub fn into_btf(
        model: MaterialModel,
        views: DirectionSet,
        lights: DirectionSet,
        options: &SynthesisOptions,
    ) -> Result<Btf, SourceError> {
        let source = ModelImages {
            cache: model.synthesis_cache(options)?,
            model,
            views: views.clone(),
            lights: lights.clone(),
        };
        Ok(Btf::from_source(
            "synthesized",
            views,
            lights,
            u32::try_from(options.cols).map_err(|_| too_big(options.cols))?,
            u32::try_from(options.rows).map_err(|_| too_big(options.rows))?,
            Box::new(source),
        )?)
    }
}

fn too_big(side: usize) -> BtfError {
    BtfError::parameter("size", format!("{side} pixels does not fit an image"))
}

impl ImageSource for ModelImages {
    fn load(&self, view: usize, light: usize) -> Result<Array3<f32>, BtfError> {
        let (v, l) = (self.views.as_slice()[view], self.lights.as_slice()[light]);
        self.model
            .image_from_cache(&self.cache, &v, &l)
            .map_err(|e| failed(self.describe(view, light), &e))
    }

    fn describe(&self, view: usize, light: usize) -> String {
        format!("synthesized image (view {view}, light {light})")
    }
}

/// An LPCA model's images for chosen views and lights, each interpolated from the 3 x 3
/// nearest measured pairs ([`LpcaModel::reconstruct_direction`]).
pub struct LpcaImages {
    model: LpcaModel,
    views: DirectionSet,
    lights: DirectionSet,
}

impl LpcaImages {
    /// The images of `model` for every pair of `views` x `lights`, at the model's measured
    /// size, as a BTF labelled "reconstructed".
    ///
    /// # Errors
    /// A size that does not fit a BTF (never for a fitted or parsed model).
    pub fn into_btf(
        model: LpcaModel,
        views: DirectionSet,
        lights: DirectionSet,
    ) -> Result<Btf, SourceError> {
        let (w, h) = (model.width() as u32, model.height() as u32);
        let source = LpcaImages {
            model,
            views: views.clone(),
            lights: lights.clone(),
        };
        Ok(Btf::from_source(
            "reconstructed",
            views,
            lights,
            w,
            h,
            Box::new(source),
        )?)
    }
}

impl ImageSource for LpcaImages {
    fn load(&self, view: usize, light: usize) -> Result<Array3<f32>, BtfError> {
        let (v, l): (&Direction, &Direction) =
            (&self.views.as_slice()[view], &self.lights.as_slice()[light]);
        self.model
            .reconstruct_direction(v, l)
            .map_err(|e| failed(self.describe(view, light), &e))
    }

    fn describe(&self, view: usize, light: usize) -> String {
        format!("reconstructed image (view {view}, light {light})")
    }
}

/// A model's failure to make one image, as the BTF error its readers expect.
fn failed(file: String, e: &dyn std::fmt::Display) -> BtfError {
    BtfError::Image {
        file,
        reason: e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_kind_is_told_by_the_magic_not_the_extension() {
        let dir = tempfile::tempdir().unwrap();
        let fake = dir.path().join("x.lpca");
        std::fs::write(&fake, b"BTFM and nothing valid").unwrap();
        // Read as a .btfm model (named by the .btfm reader), not as LPCA.
        let e = AnyModel::open(&fake).unwrap_err();
        assert!(matches!(e, SourceError::Model(_)), "{e}");
        std::fs::write(&fake, b"LPCA and nothing valid").unwrap();
        let e = AnyModel::open(&fake).unwrap_err();
        assert!(matches!(e, SourceError::Lpca(_)), "{e}");
        let e = AnyModel::open(&dir.path().join("missing.btfm")).unwrap_err();
        assert!(matches!(e, SourceError::Btf(BtfError::Io { .. })), "{e}");
        assert_eq!(ModelFile::sniff(b"BTFM\x01"), Some(ModelFile::Btfm));
        assert_eq!(ModelFile::sniff(b"LPCA"), Some(ModelFile::Lpca));
        assert_eq!(ModelFile::sniff(b"PK\x03\x04"), None);
        assert_eq!(ModelFile::sniff(b"BT"), None);
        assert_eq!(ModelFile::of(dir.path()).unwrap(), None);
    }
}
