//! What a fit did to an unstable or invalid estimate (mrf_math.md 2.5, 3.4), as data: the
//! messages shown to users are its `Display`.

/// One repair of a band model estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Repair {
    /// The band has too few sites for any neighbourhood: modelled as white noise.
    TooSmall,
    /// No candidate order could be estimated (singular statistics): white noise.
    Singular,
    /// The best order was unstable; the next-best stable order was used.
    NextStableOrder {
        /// The order of the best score.
        best: u8,
        /// The order used.
        used: u8,
    },
    /// No order was stable; the best one's coefficients were scaled by `factor`.
    Shrunk {
        /// The order shrunk.
        order: u8,
        /// The scale applied to its coefficients, in (0, 1).
        factor: f64,
    },
    /// The GMRF spectrum was not positive; its coefficients were scaled so that its smallest
    /// denominator is the floor.
    SpectrumFloored {
        /// The smallest denominator before.
        min: f64,
        /// The scale applied to the coefficients.
        factor: f64,
    },
    /// The GMRF's variance was too large next to the data's; its coefficients were scaled.
    VarianceShrunk {
        /// The model's variance over the data's, before.
        ratio: f64,
        /// The scale applied to the coefficients.
        factor: f64,
    },
}

impl std::fmt::Display for Repair {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Repair::TooSmall => f.write_str("band too small for any neighbourhood: white noise"),
            Repair::Singular => f.write_str("singular statistics: white noise"),
            Repair::NextStableOrder { best, used } => write!(
                f,
                "order {best} was unstable; used the next-best stable order {used}"
            ),
            Repair::Shrunk { order, factor } => {
                write!(
                    f,
                    "no order was stable; shrank order {order} by {factor:.3}"
                )
            }
            Repair::SpectrumFloored { min, factor } => write!(
                f,
                "spectrum not positive (min {min:.3}); shrank gamma by {factor:.3}"
            ),
            Repair::VarianceShrunk { ratio, factor } => write!(
                f,
                "variance {ratio:.3}x the data's; shrank gamma by {factor:.3}"
            ),
        }
    }
}

impl Repair {
    /// Repairs in the order they were made, as one message (`"; "` between them).
    pub fn joined(repairs: &[Repair]) -> String {
        repairs
            .iter()
            .map(Repair::to_string)
            .collect::<Vec<_>>()
            .join("; ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_are_the_ones_users_saw_before() {
        assert_eq!(
            Repair::Shrunk {
                order: 3,
                factor: 0.51234
            }
            .to_string(),
            "no order was stable; shrank order 3 by 0.512"
        );
        assert_eq!(
            Repair::joined(&[
                Repair::SpectrumFloored {
                    min: -0.25,
                    factor: 0.8
                },
                Repair::VarianceShrunk {
                    ratio: 5.0,
                    factor: 0.9
                }
            ]),
            "spectrum not positive (min -0.250); shrank gamma by 0.800; \
             variance 5.000x the data's; shrank gamma by 0.900"
        );
    }
}
