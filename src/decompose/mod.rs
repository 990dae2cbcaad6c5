//! Decomposition of a BTF into parts the MRF models can handle: clustering of the view x light
//! space into subspace images, KL colour decorrelation, and the Gaussian-Laplacian pyramid.

pub mod cluster;
pub mod kl;
pub mod marginals;
pub mod pyramid;

pub use cluster::{ClusterOptions, SubspaceClustering};
pub use kl::{ColourSpace, KlBasis};
pub use pyramid::{Border, Pyramid};
