//! Markov random field models of single bands: the 2D causal autoregressive model and the
//! Gaussian MRF, with their estimators, stability checks and synthesizers.

pub mod car2d;
pub mod car3d;
pub mod gmrf;
pub mod neighbourhood;

pub use car2d::{Car2dFit, Car2dModel};
pub use car3d::{Car3dFit, Car3dModel};
pub use gmrf::{GmrfFit, GmrfModel};
