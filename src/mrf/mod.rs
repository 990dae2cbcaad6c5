//! Markov random field models of single bands: the 2D causal autoregressive model and the
//! Gaussian MRF, with their estimators, stability checks and synthesizers.

pub mod car2d;
pub mod car3d;
pub mod gmrf;
pub mod neighbourhood;
pub mod noise;
mod spectrum;
mod torus;

pub use car2d::Car2dModel;
pub use car3d::Car3dModel;
pub use gmrf::GmrfModel;

/// True when a band's variance is nothing but rounding noise next to its level (or is not a
/// number): such a band is stored as a constant, not modelled (mrf_math.md sec. 7, first row).
pub(crate) fn is_flat(mean_magnitude: f64, var: f64) -> bool {
    let scale = mean_magnitude.max(var.sqrt()).max(1e-300);
    !var.is_finite() || var <= 1e-20 * scale * scale || var < 1e-30
}

/// A fitted band model, the score of every candidate neighbourhood, and any repair made.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit<M> {
    /// The chosen (and possibly repaired) model.
    pub model: M,
    /// (order, score) of every candidate evaluated (D for the CAR models, higher is better;
    /// a BIC-like value for the GMRF, lower is better).
    pub candidates: Vec<(u8, f64)>,
    /// How an unstable or invalid estimate was repaired, if it was.
    pub repair: Option<String>,
}

/// The fit of a 2D CAR band.
pub type Car2dFit = Fit<Car2dModel>;
/// The fit of a 3D CAR band.
pub type Car3dFit = Fit<Car3dModel>;
/// The fit of a GMRF band.
pub type GmrfFit = Fit<GmrfModel>;

/// The causal models' repair rule (mrf_math.md 2.5): from candidates sorted best first, the
/// first stable one; if none is, the best one shrunk (`shrunk(model, kappa)` scales its
/// coefficients) by the largest factor found by bisection that makes it stable; with no
/// candidate at all, `fallback`.
pub(crate) fn choose_stable<M>(
    sorted: Vec<(u8, M)>,
    candidates: Vec<(u8, f64)>,
    fallback: M,
    is_stable: impl Fn(&M) -> bool,
    shrunk: impl Fn(&M, f64) -> M,
) -> Fit<M> {
    let best_order = sorted.first().map_or(0, |s| s.0);
    let Some(pick) = sorted.iter().position(|(_, m)| is_stable(m)) else {
        let Some((order, base)) = sorted.into_iter().next() else {
            return Fit {
                model: fallback,
                candidates,
                repair: Some("singular statistics: white noise".into()),
            };
        };
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..30 {
            let mid = 0.5 * (lo + hi);
            if is_stable(&shrunk(&base, mid)) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        return Fit {
            model: shrunk(&base, lo),
            candidates,
            repair: Some(format!(
                "no order was stable; shrank order {order} by {lo:.3}"
            )),
        };
    };
    let (order, model) = sorted.into_iter().nth(pick).expect("position found");
    let repair = (pick > 0).then(|| {
        format!("order {best_order} was unstable; used the next-best stable order {order}")
    });
    Fit {
        model,
        candidates,
        repair,
    }
}
