//! Markov random field models of single bands: the 2D causal autoregressive model, the
//! Gaussian MRF and the 3D causal autoregressive model, with their estimators, stability checks
//! and synthesizers, behind one trait ([`BandModel`]) and one registry (`band_models!` below).

use ndarray::{Array3, ArrayView3};

use crate::model::format::{Parse, Reader, Writer};

pub mod neighbourhood;
pub mod noise;
mod repair;
mod spectrum;
mod torus;

pub use repair::Repair;

/// One band model family (mrf_math.md secs. 2-4): its fit, the noise its synthesis consumes,
/// the synthesis from that noise, and its record in the model file. Every family is used
/// through this trait only; `band_models!` registers it.
pub trait BandModel: Clone + std::fmt::Debug + PartialEq + Send + Sync + Sized + 'static {
    /// The name on the command line and in reports.
    const NAME: &'static str;
    /// Planes modelled together: 1 (one model per KL factor) or 3 (the colour channels
    /// jointly, which needs no KL decorrelation).
    const PLANES: usize;

    /// Fits a band of shape `(PLANES, rows, cols)`: the neighbourhood order up to `max_order`
    /// (clamped to what the family supports), the parameters, and any repair.
    fn fit(band: ArrayView3<f64>, max_order: usize) -> Fit<Self>;

    /// How many unit Gaussian values [`BandModel::synthesize_from`] consumes for a
    /// `rows` x `cols` sample (the margin of a larger field included where it is cut from one).
    fn noise_len(rows: usize, cols: usize, tileable: bool) -> usize;

    /// A sample of shape `(PLANES, rows, cols)` driven by unit Gaussian `noise` of at least
    /// [`BandModel::noise_len`] values. `tileable` asks for an exact sample on the torus (it
    /// wraps seamlessly); a family that always samples the torus ignores it.
    ///
    /// # Panics
    /// If `noise` is shorter than [`BandModel::noise_len`].
    fn synthesize_from(
        &self,
        rows: usize,
        cols: usize,
        noise: &[f32],
        tileable: bool,
    ) -> Array3<f64>;

    /// The model's value per plane when every sample it makes is that constant (no noise
    /// variance: a flat band, such as a grey image's chroma factors), so a synthesis can skip
    /// drawing noise and solving; `None` otherwise.
    fn flat_means(&self) -> Option<Vec<f64>>;

    /// [`BandModel::synthesize_from`] with the noise drawn from `seed`: the same seed and size
    /// give every model of the family the same noise (coherent subspaces).
    fn synthesize(&self, rows: usize, cols: usize, seed: u64, tileable: bool) -> Array3<f64> {
        let noise = noise::standard_normal(seed, Self::noise_len(rows, cols, tileable));
        self.synthesize_from(rows, cols, &noise, tileable)
    }

    /// Appends the model's record to a model file payload (docs/FORMAT.md, band records).
    fn write(&self, w: &mut Writer);

    /// Reads a record written by [`BandModel::write`], checking every value's range.
    ///
    /// # Errors
    /// A truncated record or an out-of-range value, as a message.
    fn read(r: &mut Reader) -> Parse<Self>;
}

/// The band models of one subspace image, finest level first: per level, one model per KL
/// factor (`PLANES` = 1) or one joint model (`PLANES` = 3). Built only with that shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Levels<M> {
    levels: Vec<Vec<M>>,
}

impl<M: BandModel> Levels<M> {
    /// Models per level: the three factor planes divided among models of `PLANES` planes.
    pub const PER_LEVEL: usize = 3 / M::PLANES;

    /// The level models, finest first; `None` without levels or when a level does not hold
    /// exactly [`Levels::PER_LEVEL`] models.
    pub fn new(levels: Vec<Vec<M>>) -> Option<Self> {
        let shaped = !levels.is_empty() && levels.iter().all(|l| l.len() == Self::PER_LEVEL);
        shaped.then_some(Self { levels })
    }

    /// The level models, finest first, each [`Levels::PER_LEVEL`] long.
    pub fn levels(&self) -> &[Vec<M>] {
        &self.levels
    }
}

/// Something done with the band model type of a [`ModelKind`] (fitting a new model, reading
/// one): the one place where a kind becomes a type.
pub trait KindVisitor {
    /// What the visit returns.
    type Output;
    /// Runs with `M`, the kind's band model.
    fn visit<M: BandModel>(self) -> Self::Output
    where
        Levels<M>: Into<AnyLevels>;
}

/// Something done with a subspace's [`Levels`] whatever their band model (synthesis, writing).
pub trait LevelsVisitor {
    /// What the visit returns.
    type Output;
    /// Runs with the levels.
    fn visit<M: BandModel>(self, levels: &Levels<M>) -> Self::Output;
}

/// Registers the band model families: defines [`ModelKind`] (one variant per family, in file
/// code order), [`AnyLevels`] (a subspace's levels of any one family, so a level of another
/// family cannot be put beside them) and the two dispatch points, [`ModelKind::visit`] and
/// [`AnyLevels::visit`]. Adding a family is a file with its [`BandModel`] implementation and
/// one line here, appended (the position is the family's code in model files).
macro_rules! band_models {
    ($($(#[$doc:meta])* $kind:ident: $module:ident :: $model:ident,)*) => {
        $(pub mod $module; pub use $module::$model;)*

        /// Which MRF family models the bands.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
        pub enum ModelKind {
            $($(#[$doc])* $kind,)*
        }

        impl ModelKind {
            /// Every kind, in file-code order.
            pub const ALL: [ModelKind; [$(stringify!($kind)),*].len()] = [$(ModelKind::$kind,)*];

            /// Runs `visitor` with the kind's band model type.
            pub fn visit<V: KindVisitor>(self, visitor: V) -> V::Output {
                match self {
                    $(ModelKind::$kind => visitor.visit::<$model>(),)*
                }
            }

            /// The name on the command line and in reports.
            pub fn name(&self) -> &'static str {
                match self {
                    $(ModelKind::$kind => <$model as BandModel>::NAME,)*
                }
            }
        }

        /// The level models of one subspace image, of one family.
        #[derive(Debug, Clone, PartialEq)]
        pub enum AnyLevels {
            $(#[doc = concat!("Levels of [`", stringify!($model), "`].")] $kind(Levels<$model>),)*
        }

        impl AnyLevels {
            /// The family of the levels.
            pub fn kind(&self) -> ModelKind {
                match self {
                    $(AnyLevels::$kind(_) => ModelKind::$kind,)*
                }
            }

            /// Runs `visitor` with the levels.
            pub fn visit<V: LevelsVisitor>(&self, visitor: V) -> V::Output {
                match self {
                    $(AnyLevels::$kind(levels) => visitor.visit(levels),)*
                }
            }
        }

        $(impl From<Levels<$model>> for AnyLevels {
            fn from(levels: Levels<$model>) -> Self {
                AnyLevels::$kind(levels)
            }
        })*
    };
}

band_models! {
    /// Gaussian MRF per KL factor and pyramid level (exactly tileable synthesis by FFT).
    Gmrf: gmrf::GmrfModel,
    /// 2D causal autoregressive model per KL factor and pyramid level.
    Car2d: car2d::Car2dModel,
    /// 3D causal autoregressive model per pyramid level on the colour channels jointly.
    Car3d: car3d::Car3dModel,
}

impl AnyLevels {
    /// Number of pyramid levels.
    pub fn len(&self) -> usize {
        struct Count;
        impl LevelsVisitor for Count {
            type Output = usize;
            fn visit<M: BandModel>(self, levels: &Levels<M>) -> usize {
                levels.levels().len()
            }
        }
        self.visit(Count)
    }

    /// Always false: levels are built non-empty (for clippy's `len_without_is_empty`).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl ModelKind {
    /// The family's code in model files: its position in [`ModelKind::ALL`].
    pub fn code(self) -> u8 {
        Self::ALL
            .iter()
            .position(|&k| k == self)
            .expect("every kind is listed") as u8
    }

    /// The kind of file code `code`, if there is one.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(usize::from(code)).copied()
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// True when a band's variance is nothing but rounding noise next to its level (or is not a
/// number): such a band is stored as a constant, not modelled (mrf_math.md sec. 7, first row).
pub(crate) fn is_flat(mean_magnitude: f64, var: f64) -> bool {
    let scale = mean_magnitude.max(var.sqrt()).max(1e-300);
    !var.is_finite() || var <= 1e-20 * scale * scale || var < 1e-30
}

/// A fitted band model, the score of every candidate neighbourhood, and the repairs made.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit<M> {
    /// The chosen (and possibly repaired) model.
    pub model: M,
    /// (order, score) of every candidate evaluated (D for the CAR models, higher is better;
    /// a BIC-like value for the GMRF, lower is better).
    pub candidates: Vec<(u8, f64)>,
    /// How an unstable or invalid estimate was repaired, in order; empty when it was not.
    pub repairs: Vec<Repair>,
}

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
                repairs: vec![Repair::Singular],
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
            repairs: vec![Repair::Shrunk { order, factor: lo }],
        };
    };
    let (order, model) = sorted.into_iter().nth(pick).expect("position found");
    let repairs = if pick > 0 {
        vec![Repair::NextStableOrder {
            best: best_order,
            used: order,
        }]
    } else {
        Vec::new()
    };
    Fit {
        model,
        candidates,
        repairs,
    }
}

/// The record of a one-plane model (GMRF, 2D CAR): order, mean, noise variance, coefficients.
pub(crate) fn write_plane_record(w: &mut Writer, order: u8, mean: f64, sigma2: f64, gamma: &[f64]) {
    w.u8(order);
    w.f32(mean);
    w.f32(sigma2);
    w.f32s(gamma);
}

/// Reads [`write_plane_record`]'s record as (order, mean, noise variance, coefficients).
pub(crate) fn read_plane_record(r: &mut Reader) -> Parse<(u8, f64, f64, Vec<f64>)> {
    let order = r.u8_at_most(neighbourhood::MAX_ORDER, "neighbourhood order")?;
    let (mean, sigma2) = (r.f32()?, r.f32()?);
    if sigma2 < 0.0 {
        return Err(format!("negative noise variance {sigma2}"));
    }
    let gamma = r.f32s(neighbourhood::causal(usize::from(order)).len())?;
    Ok((order, mean, sigma2, gamma))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_hold_one_model_per_group_of_planes() {
        let flat = Car2dModel::constant(0.0);
        assert!(Levels::new(vec![vec![flat.clone(); 3]; 2]).is_some());
        assert!(Levels::new(vec![vec![flat.clone(); 3], vec![flat.clone(); 2]]).is_none());
        assert!(Levels::<Car2dModel>::new(Vec::new()).is_none());
        let joint = Car3dModel::fit(Array3::zeros((3, 4, 4)).view(), 1).model;
        assert!(Levels::new(vec![vec![joint.clone()]]).is_some());
        assert!(Levels::new(vec![vec![joint; 3]]).is_none());
    }

    /// The flat shortcut against the model's own synthesis: the same values at every site.
    fn flat_means_are_what_it_synthesizes<M: BandModel>(band: Array3<f64>) {
        let model = M::fit(band.view(), 2).model;
        let means = model.flat_means().expect("a flat band fits a flat model");
        for tileable in [false, true] {
            let sample = model.synthesize(9, 13, 5, tileable);
            for (p, plane) in sample.outer_iter().enumerate() {
                assert!(plane.iter().all(|&v| v == means[p]), "{} {p}", M::NAME);
            }
        }
        let textured = band.mapv(|v| v * 2.0)
            + Array3::from_shape_fn(band.dim(), |(p, y, x)| {
                ((p * 5 + y * 3 + x * 7) % 11) as f64
            });
        assert!(
            M::fit(textured.view(), 2).model.flat_means().is_none(),
            "{}",
            M::NAME
        );
    }

    #[test]
    fn a_flat_band_synthesizes_its_means_without_noise() {
        let band = |planes: usize| {
            Array3::from_shape_fn((planes, 12, 12), |(p, _, _)| [2.5, -1.0, 0.25][p])
        };
        flat_means_are_what_it_synthesizes::<Car2dModel>(band(1));
        flat_means_are_what_it_synthesizes::<GmrfModel>(band(1));
        flat_means_are_what_it_synthesizes::<Car3dModel>(band(3));
    }

    #[test]
    fn kinds_have_distinct_names_and_codes_in_registration_order() {
        for (i, kind) in ModelKind::ALL.into_iter().enumerate() {
            assert_eq!(usize::from(kind.code()), i);
            assert_eq!(ModelKind::from_code(kind.code()), Some(kind));
        }
        assert_eq!(ModelKind::from_code(ModelKind::ALL.len() as u8), None);
        let names: Vec<&str> = ModelKind::ALL.iter().map(ModelKind::name).collect();
        // The file codes of existing kinds never change (docs/FORMAT.md).
        assert_eq!(names, ["gmrf", "2dcar", "3dcar"]);
    }
}
