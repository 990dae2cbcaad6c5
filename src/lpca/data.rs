//! Arranging a BTF as a matrix of row vectors, streamed image by image.
//!
//! - **BRDF-wise** (Müller et al. 2003, section 3.1): one row per texel holding everything the
//!   texel shows, its apparent BRDF (ABRDF): `n = width * height` rows of
//!   `d = views * lights * 3` values, value `(view * lights + light) * 3 + channel`. For the
//!   Bonn sampling d = 19,683.
//! - **Image-wise** (eigen-textures; the PCA BTF of Koudelka et al., survey section 4.2.2): one
//!   row per image, `views * lights` rows of `3 * height * width` values in the planar image
//!   order `(channel * height + y) * width + x`.
//! - **One view's reflectance fields** (survey section 4.2.1): one row per texel holding what it
//!   shows from one view under every light, `d = lights * 3`, value `light * 3 + channel`.
//!
//! All values are linear RGB f32, as [`Btf::image`] gives them.

use ndarray::Array3;
use rayon::prelude::*;

use super::Method;
use super::error::{LpcaError, Result};
use crate::btf::Btf;
use crate::progress::Progress;

/// How a method arranges a BTF into factorizations (the arrangements above): how many, and
/// the rows and vector length of each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Layout {
    /// Factorizations: 1, or one per view for PCA RF.
    pub parts: usize,
    /// Rows per factorization: texels, or images for PCA BTF.
    pub rows: usize,
    /// Values per row.
    pub dim: usize,
}

impl Layout {
    /// The layout of a `width x height` BTF with `views` and `lights` under `method`.
    pub(crate) fn of(
        method: Method,
        width: usize,
        height: usize,
        views: usize,
        lights: usize,
    ) -> Self {
        let texels = width * height;
        let (parts, rows, dim) = match method {
            Method::Lpca => (1, texels, views * lights * 3),
            Method::PcaBtf => (1, views * lights, 3 * texels),
            Method::PcaRf => (views, texels, lights * 3),
        };
        Self { parts, rows, dim }
    }
}

/// A zeroed `len`-element buffer, or a clear error instead of an abort when memory is short.
pub(crate) fn zeroed(len: usize, what: &str) -> Result<Vec<f32>> {
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| {
        LpcaError::parameter(
            "size",
            format!(
                "{what} needs {:.1} GiB of memory, which is not available",
                len as f64 * 4.0 / (1u64 << 30) as f64
            ),
        )
    })?;
    v.resize(len, 0.0);
    Ok(v)
}

/// The images of one view, all lights, decoded in parallel.
fn view_images(btf: &Btf, view: usize) -> Result<Vec<Array3<f32>>> {
    (0..btf.lights().len())
        .into_par_iter()
        .map(|l| {
            btf.image(view, l)
                .map(|im| im.as_standard_layout().into_owned())
        })
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(LpcaError::from)
}

/// Scatters one view's images into the rows of a texel-major matrix whose rows are `stride`
/// long, starting at column `offset` (value `offset + light * 3 + channel`).
fn scatter_view(images: &[Array3<f32>], rows: &mut [f32], stride: usize, offset: usize) {
    let planes: Vec<&[f32]> = images
        .iter()
        .map(|im| im.as_slice().expect("standard layout"))
        .collect();
    let npx = planes.first().map_or(0, |p| p.len() / 3);
    rows.par_chunks_mut(stride)
        .enumerate()
        .for_each(|(x, row)| {
            for (l, p) in planes.iter().enumerate() {
                let at = offset + l * 3;
                row[at] = p[x];
                row[at + 1] = p[npx + x];
                row[at + 2] = p[2 * npx + x];
            }
        });
}

/// The BRDF-wise matrix (`width * height` rows of `views * lights * 3`), row-major.
///
/// # Errors
/// An unreadable image, or not enough memory for the matrix.
pub fn brdf_matrix(btf: &Btf, progress: &dyn Progress) -> Result<Vec<f32>> {
    let n = btf.width() as usize * btf.height() as usize;
    let (nv, nl) = (btf.views().len(), btf.lights().len());
    let d = nv * nl * 3;
    let mut x = zeroed(n * d, "the BRDF-wise data matrix")?;
    progress.start("reading images", (nv * nl) as u64);
    for v in 0..nv {
        let images = view_images(btf, v)?;
        scatter_view(&images, &mut x, d, v * nl * 3);
        progress.advance(nl as u64);
    }
    progress.finish();
    Ok(x)
}

/// The image-wise matrix (`views * lights` rows of `3 * height * width`), row-major.
///
/// # Errors
/// An unreadable image, or not enough memory for the matrix.
pub fn image_matrix(btf: &Btf, progress: &dyn Progress) -> Result<Vec<f32>> {
    let d = 3 * btf.width() as usize * btf.height() as usize;
    let (nv, nl) = (btf.views().len(), btf.lights().len());
    let mut x = zeroed(nv * nl * d, "the image-wise data matrix")?;
    progress.start("reading images", (nv * nl) as u64);
    for v in 0..nv {
        let rows = &mut x[v * nl * d..(v + 1) * nl * d];
        rows.par_chunks_mut(d)
            .enumerate()
            .try_for_each(|(l, row)| -> Result<()> {
                let im = btf.image(v, l)?;
                row.iter_mut().zip(im.iter()).for_each(|(dst, &s)| *dst = s);
                Ok(())
            })?;
        progress.advance(nl as u64);
    }
    progress.finish();
    Ok(x)
}

/// One view's reflectance fields (`width * height` rows of `lights * 3`), row-major.
///
/// # Errors
/// An unreadable image.
pub fn view_matrix(btf: &Btf, view: usize) -> Result<Vec<f32>> {
    let n = btf.width() as usize * btf.height() as usize;
    let d = btf.lights().len() * 3;
    let mut x = zeroed(n * d, "one view's reflectance fields")?;
    let images = view_images(btf, view)?;
    scatter_view(&images, &mut x, d, 0);
    Ok(x)
}

/// The images of one view back out of a texel-major matrix (rows `stride` long, the view's
/// values starting at column `offset`): `lights` planar `(3, height, width)` images.
pub(crate) fn gather_view(
    rows: &[f32],
    stride: usize,
    offset: usize,
    lights: usize,
    height: usize,
    width: usize,
) -> Vec<Array3<f32>> {
    let npx = height * width;
    let mut planes = vec![vec![0.0f32; 3 * npx]; lights];
    for (x, row) in rows.chunks_exact(stride).enumerate() {
        for (l, p) in planes.iter_mut().enumerate() {
            let at = offset + l * 3;
            p[x] = row[at];
            p[npx + x] = row[at + 1];
            p[2 * npx + x] = row[at + 2];
        }
    }
    planes
        .into_iter()
        .map(|p| Array3::from_shape_vec((3, height, width), p).expect("shape"))
        .collect()
}

/// The images of one view back out of the image-wise matrix ([`image_matrix`]): `lights`
/// planar `(3, height, width)` images.
pub(crate) fn gather_images(
    rows: &[f32],
    view: usize,
    lights: usize,
    height: usize,
    width: usize,
) -> Vec<Array3<f32>> {
    let d = 3 * height * width;
    rows[view * lights * d..(view + 1) * lights * d]
        .chunks_exact(d)
        .map(|row| Array3::from_shape_vec((3, height, width), row.to_vec()).expect("shape"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::DirectionSet;
    use crate::btf::directions::Direction;
    use crate::progress::NoProgress;

    fn small_btf() -> Btf {
        let views =
            DirectionSet::new(vec![Direction::new(0.0, 0.0), Direction::new(30.0, 0.0)]).unwrap();
        let lights = DirectionSet::new(vec![
            Direction::new(0.0, 0.0),
            Direction::new(45.0, 90.0),
            Direction::new(45.0, 180.0),
        ])
        .unwrap();
        let images = (0..6)
            .map(|i| {
                Array3::from_shape_fn((3, 2, 4), |(c, y, x)| {
                    (i * 100 + c * 10 + y * 4 + x) as f32 / 1000.0
                })
            })
            .collect();
        Btf::from_images(views, lights, images).unwrap()
    }

    #[test]
    fn arrangements_put_every_value_where_documented() {
        let btf = small_btf();
        let x = brdf_matrix(&btf, &NoProgress).unwrap();
        let d = 2 * 3 * 3;
        for v in 0..2 {
            for l in 0..3 {
                let im = btf.image(v, l).unwrap();
                for c in 0..3 {
                    for y in 0..2 {
                        for col in 0..4 {
                            let texel = y * 4 + col;
                            assert_eq!(x[texel * d + (v * 3 + l) * 3 + c], im[(c, y, col)]);
                        }
                    }
                }
            }
        }
        let imgs = image_matrix(&btf, &NoProgress).unwrap();
        assert_eq!(imgs[(3 + 2) * 24 + 23], btf.image(1, 2).unwrap()[(2, 1, 3)]);
        let rf = view_matrix(&btf, 1).unwrap();
        assert_eq!(rf[5 * 9 + 2 * 3 + 1], btf.image(1, 2).unwrap()[(1, 1, 1)]);
        let back = gather_view(&x, d, 9, 3, 2, 4);
        assert_eq!(back[2], btf.image(1, 2).unwrap());
        let images = gather_images(&imgs, 1, 3, 2, 4);
        assert_eq!(images[2], btf.image(1, 2).unwrap());
    }
}
