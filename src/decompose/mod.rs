//! Decomposition of a BTF into parts the MRF models can handle: clustering of the view x light
//! space into subspace images, KL colour decorrelation, the Gaussian-Laplacian pyramid, and a
//! check that the images are stationary textures at all.

pub mod cluster;
pub mod colour_transfer;
pub mod kl;
pub mod marginals;
pub mod pyramid;
pub mod stationarity;

pub use cluster::{ClusterOptions, SubspaceClustering};
pub use kl::{ColourSpace, KlBasis};
pub use pyramid::{Border, Pyramid};
