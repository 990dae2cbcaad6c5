//! # btfmrf
//!
//! Measured BTFs (bidirectional texture functions: one image per view/light pair, thousands of
//! them) in, compact Markov-random-field models out, and seamless synthesis of any size back.
//!
//! This crate is the core library, free of UI and GPU dependencies. The renderer is the
//! `btfmrf-render` crate (crates/render) and the `btfmrf` binary a thin command-line shell
//! over both (crates/cli). The data flows one way: source -> [`btf::Btf`] -> analysis -> model
//! -> synthesis -> render.
//!
//! ## Conventions
//!
//! - **Images** are planar `ndarray::Array3<f32>` of shape `(3, height, width)`, channel order
//!   R, G, B, **linear** RGB (sRGB primaries, D65). 8-bit files are sRGB-encoded and are
//!   linearised on read ([`color::srgb_to_linear`]); EXR files are linear already.
//! - **Directions** are given by elevation `theta` (0 = straight up, along the surface normal)
//!   and azimuth `phi` (from the +x axis, counter-clockwise), both in degrees. In the tangent
//!   frame, x points right in the image and y points up in the image (the RTI convention);
//!   see [`btf::directions`].
//! - **Randomness** always comes from an explicit seed; the same seed gives the same bytes.
//!
//! ## Quick start
//!
//! ```no_run
//! use btfmrf::btf::{Btf, synthetic::SyntheticMaterial};
//!
//! // A procedural material in the Bonn sampling (81 views x 81 lights), 64x64 texels.
//! let btf = Btf::synthetic(SyntheticMaterial::Stones, 64, 7).unwrap();
//! let image = btf.image(0, 10).unwrap(); // view 0, light 10: (3, 64, 64) linear RGB
//! assert_eq!(image.dim(), (3, 64, 64));
//! ```
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod analysis;
pub mod btf;
pub mod color;
pub mod decompose;
pub mod eval;
pub mod features;
mod fft;
pub mod geometry;
pub mod io;
pub mod lpca;
pub mod memory;
pub mod model;
pub mod mrf;
pub mod progress;
pub mod source;
pub mod synthesis;
