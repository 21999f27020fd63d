//! A weighing method as one short text: what `host-sim calibrate` writes as `spec` in
//! `weighing.toml` and a board's console takes (`method step:n=5,D=24`), so a method chosen
//! on the host is typed or uploaded verbatim.
//!
//! ```text
//! step:n=5,D=24[,lambda=0.999]        least squares (also bare: n=5,D=24)
//! bc:n=5,D=24                         bias-compensated least squares
//! iv:n=5,D=24                         instrumental variables
//! model:D=8,K=33,span=0.68-1.3        the model bank on the identified model
//! model:D=8,K=65,span=0.68-1.3,interp=5,whiten=32
//!                                     … combined over five candidates, whitened
//! ```
//! `precision=f32` may follow (a board computes in `f32`); `f64` is refused. This is the
//! subset of host-sim's method specs a [`WeighingMethod`] can hold: a key host-sim takes
//! for a study (`delay`, `prior`, `fn_hz`, …) is refused here by name, never ignored.

use core::fmt;

use super::WeighingMethod;
use crate::estimators::model::{Interpolation, WHITENING_ORDER};

/// Why a method spec was refused: the word, and what was expected there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SpecError {
    /// The family before `:` is none of step, bc, iv, model.
    UnknownKind,
    /// A `key=value` whose key the family does not take.
    UnknownKey,
    /// A key given twice.
    RepeatedKey,
    /// A value that is not the key's (a whole number, λ in (0, 1], a span `a-b`, f32).
    BadValue {
        /// The key.
        key: &'static str,
    },
    /// A key the family needs is missing.
    Missing {
        /// The key.
        key: &'static str,
    },
}

impl SpecError {
    /// What was expected, for an answer line.
    pub fn expected(&self) -> &'static str {
        match self {
            SpecError::UnknownKind => "step:, bc:, iv: or model: (step:n=5,D=24)",
            SpecError::UnknownKey | SpecError::RepeatedKey => {
                "n, D and lambda (step), n and D (bc, iv), D, K, span, interp and whiten (model), precision, each once"
            }
            SpecError::BadValue { key: "lambda" } => "lambda in (0, 1]",
            SpecError::BadValue { key: "span" } => "span as two ratios low-high (0.68-1.3)",
            SpecError::BadValue { key: "precision" } => "precision=f32 (the board computes in f32)",
            SpecError::BadValue { key: "interp" } => "interp=3 or interp=5 (candidates combined)",
            SpecError::BadValue { key: "whiten" } => "whiten=0 to whiten=32 (the whitening filter's order)",
            SpecError::BadValue { .. } => "a whole number from 1 (n, D, K)",
            SpecError::Missing { key: "n" } => "the order n (n=5)",
            SpecError::Missing { key: "D" } => "the block length D (D=24)",
            SpecError::Missing { .. } => "K and span for the model bank (K=33,span=0.68-1.3)",
        }
    }
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "expected {}", self.expected())
    }
}

/// The keys a spec's families take (`model`'s `K` and `span` included).
#[derive(Default)]
struct Keys {
    order: Option<usize>,
    decimation: Option<u16>,
    forgetting: Option<f64>,
    candidates: Option<usize>,
    span: Option<(f64, f64)>,
    interpolation: Option<Interpolation>,
    whitening: Option<usize>,
}

impl WeighingMethod {
    /// The method a spec names (the module's grammar), or why not.
    pub fn parse_spec(spec: &str) -> Result<Self, SpecError> {
        let (kind, keys) = match spec.split_once(':') {
            Some((kind, keys)) => (kind, keys),
            // A bare `n=5,D=24` is the step estimator, as in host-sim.
            None if spec.contains('=') => ("step", spec),
            None => (spec, ""),
        };
        let is = |name: &str| kind.eq_ignore_ascii_case(name);
        let family = if is("step") {
            Family::Step
        } else if is("bc") {
            Family::BiasCompensated
        } else if is("iv") {
            Family::InstrumentalVariable
        } else if is("model") {
            Family::ModelBank
        } else {
            return Err(SpecError::UnknownKind);
        };
        let keys = family.keys(keys)?;
        let order = keys.order.ok_or(SpecError::Missing { key: "n" });
        let decimation = keys.decimation.ok_or(SpecError::Missing { key: "D" });
        Ok(match family {
            Family::Step => WeighingMethod::Step {
                order: order?,
                decimation: decimation?,
                forgetting: keys.forgetting.unwrap_or(1.0),
            },
            Family::BiasCompensated => WeighingMethod::BiasCompensated {
                order: order?,
                decimation: decimation?,
            },
            Family::InstrumentalVariable => WeighingMethod::InstrumentalVariable {
                order: order?,
                decimation: decimation?,
            },
            Family::ModelBank => {
                let (ratio_min, ratio_max) = keys.span.ok_or(SpecError::Missing { key: "span" })?;
                WeighingMethod::ModelBank {
                    decimation: decimation?,
                    candidates: keys.candidates.ok_or(SpecError::Missing { key: "K" })?,
                    ratio_min,
                    ratio_max,
                    interpolation: keys.interpolation.unwrap_or_default(),
                    whitening: keys.whitening.unwrap_or(0),
                }
            }
        })
    }

    /// The method as a spec [`Self::parse_spec`] reads back: `step:n=5,D=24`.
    pub fn spec(&self) -> Spec<'_> {
        Spec(self)
    }
}

/// [`WeighingMethod::spec`]'s text.
pub struct Spec<'a>(&'a WeighingMethod);

impl fmt::Display for Spec<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self.0 {
            WeighingMethod::Step {
                order,
                decimation,
                forgetting,
            } => {
                write!(f, "step:n={order},D={decimation}")?;
                if forgetting != 1.0 {
                    write!(f, ",lambda={forgetting}")?;
                }
                Ok(())
            }
            WeighingMethod::BiasCompensated { order, decimation } => {
                write!(f, "bc:n={order},D={decimation}")
            }
            WeighingMethod::InstrumentalVariable { order, decimation } => {
                write!(f, "iv:n={order},D={decimation}")
            }
            WeighingMethod::ModelBank {
                decimation,
                candidates,
                ratio_min,
                ratio_max,
                interpolation,
                whitening,
            } => {
                write!(
                    f,
                    "model:D={decimation},K={candidates},span={ratio_min}-{ratio_max}"
                )?;
                if interpolation != Interpolation::default() {
                    write!(f, ",interp={}", interpolation.points())?;
                }
                if whitening > 0 {
                    write!(f, ",whiten={whitening}")?;
                }
                Ok(())
            }
        }
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Family {
    Step,
    BiasCompensated,
    InstrumentalVariable,
    ModelBank,
}

impl Family {
    /// The `key=value` list after the family, each key once and one the family takes.
    fn keys(self, text: &str) -> Result<Keys, SpecError> {
        let mut keys = Keys::default();
        let mut precision = false;
        for pair in text.split(',').filter(|pair| !pair.trim().is_empty()) {
            let (key, value) = pair.split_once('=').ok_or(SpecError::UnknownKey)?;
            let (key, value) = (key.trim(), value.trim());
            let data_driven = self != Family::ModelBank;
            let repeated = match key {
                "n" if data_driven => keys.order.replace(whole(value, "n")?).is_some(),
                "D" => {
                    let d = u16::try_from(whole(value, "D")?)
                        .map_err(|_| SpecError::BadValue { key: "D" })?;
                    keys.decimation.replace(d).is_some()
                }
                "lambda" if self == Family::Step => {
                    let lambda = value
                        .parse::<f64>()
                        .ok()
                        .filter(|l| *l > 0.0 && *l <= 1.0)
                        .ok_or(SpecError::BadValue { key: "lambda" })?;
                    keys.forgetting.replace(lambda).is_some()
                }
                "K" if !data_driven => keys.candidates.replace(whole(value, "K")?).is_some(),
                "span" if !data_driven => keys.span.replace(span(value)?).is_some(),
                "interp" if !data_driven => {
                    let interpolation = value
                        .parse()
                        .ok()
                        .and_then(Interpolation::with_points)
                        .ok_or(SpecError::BadValue { key: "interp" })?;
                    keys.interpolation.replace(interpolation).is_some()
                }
                "whiten" if !data_driven => {
                    let order = value
                        .parse::<usize>()
                        .ok()
                        .filter(|order| *order <= WHITENING_ORDER)
                        .ok_or(SpecError::BadValue { key: "whiten" })?;
                    keys.whitening.replace(order).is_some()
                }
                "precision" => {
                    if !value.eq_ignore_ascii_case("f32") {
                        return Err(SpecError::BadValue { key: "precision" });
                    }
                    core::mem::replace(&mut precision, true)
                }
                _ => return Err(SpecError::UnknownKey),
            };
            if repeated {
                return Err(SpecError::RepeatedKey);
            }
        }
        Ok(keys)
    }
}

/// A whole number from 1.
fn whole(value: &str, key: &'static str) -> Result<usize, SpecError> {
    value
        .parse::<usize>()
        .ok()
        .filter(|v| *v >= 1)
        .ok_or(SpecError::BadValue { key })
}

/// `low-high`, finite, positive and increasing.
fn span(value: &str) -> Result<(f64, f64), SpecError> {
    let bad = SpecError::BadValue { key: "span" };
    let (low, high) = value.split_once('-').ok_or(bad)?;
    let (low, high) = (
        low.parse::<f64>().map_err(|_| bad)?,
        high.parse::<f64>().map_err(|_| bad)?,
    );
    if low.is_finite() && high.is_finite() && 0.0 < low && low < high {
        Ok((low, high))
    } else {
        Err(bad)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::string::ToString;

    use super::*;
    use crate::weighing::BankCandidate;

    #[test]
    fn every_family_reads_back_as_written() {
        for method in [
            WeighingMethod::Step {
                order: 5,
                decimation: 24,
                forgetting: 1.0,
            },
            WeighingMethod::Step {
                order: 7,
                decimation: 16,
                forgetting: 0.999,
            },
            WeighingMethod::BiasCompensated {
                order: 3,
                decimation: 32,
            },
            WeighingMethod::InstrumentalVariable {
                order: 6,
                decimation: 12,
            },
            BankCandidate::REFERENCE.method(),
            BankCandidate::CALIBRATED_U.method(),
        ] {
            let text = method.spec().to_string();
            assert_eq!(WeighingMethod::parse_spec(&text), Ok(method), "{text}");
        }
        // A bank's options are the defaults unless written, and checked.
        assert_eq!(
            WeighingMethod::parse_spec("model:D=8,K=33,span=0.68-1.3,interp=3,whiten=0"),
            WeighingMethod::parse_spec("model:D=8,K=33,span=0.68-1.3")
        );
        for (spec, key) in [
            ("model:D=8,K=33,span=0.68-1.3,interp=4", "interp"),
            ("model:D=8,K=33,span=0.68-1.3,whiten=33", "whiten"),
        ] {
            assert_eq!(
                WeighingMethod::parse_spec(spec),
                Err(SpecError::BadValue { key }),
                "{spec}"
            );
        }
        assert_eq!(
            WeighingMethod::parse_spec("step:n=5,D=24,whiten=8"),
            Err(SpecError::UnknownKey)
        );
    }

    /// What `host-sim calibrate` writes as `spec` in `weighing.toml` is taken verbatim.
    #[test]
    fn the_calibration_files_spec_is_taken_as_written() {
        assert_eq!(
            WeighingMethod::parse_spec("step:n=5,D=24,precision=f32"),
            Ok(WeighingMethod::Step {
                order: 5,
                decimation: 24,
                forgetting: 1.0
            })
        );
        assert_eq!(
            WeighingMethod::parse_spec("n=7,D=16").map(|m| m.order()),
            Ok(Some(7))
        );
    }

    #[test]
    fn refusals_name_the_key() {
        let refused = |spec: &str| WeighingMethod::parse_spec(spec).unwrap_err();
        assert_eq!(refused("kalman:n=5,D=24"), SpecError::UnknownKind);
        assert_eq!(refused("step"), SpecError::Missing { key: "n" });
        assert_eq!(refused("step:n=5"), SpecError::Missing { key: "D" });
        assert_eq!(refused("step:n=0,D=24"), SpecError::BadValue { key: "n" });
        assert_eq!(
            refused("step:n=5,D=70000"),
            SpecError::BadValue { key: "D" }
        );
        assert_eq!(refused("step:n=5,D=2.5"), SpecError::BadValue { key: "D" });
        assert_eq!(
            refused("step:n=5,D=24,lambda=1.5"),
            SpecError::BadValue { key: "lambda" }
        );
        assert_eq!(
            refused("step:n=5,D=24,precision=f64"),
            SpecError::BadValue { key: "precision" }
        );
        // A key host-sim takes for a study but a board's method cannot hold.
        assert_eq!(refused("iv:n=5,D=24,delay=7"), SpecError::UnknownKey);
        assert_eq!(refused("bc:n=5,D=24,lambda=0.99"), SpecError::UnknownKey);
        assert_eq!(refused("step:n=5,n=6,D=24"), SpecError::RepeatedKey);
        assert_eq!(
            refused("model:D=8,K=33"),
            SpecError::Missing { key: "span" }
        );
        assert_eq!(
            refused("model:D=8,K=33,span=1.3-0.68"),
            SpecError::BadValue { key: "span" }
        );
        assert_eq!(refused("model:n=5,D=8"), SpecError::UnknownKey);
        for error in [
            SpecError::UnknownKind,
            SpecError::Missing { key: "K" },
            SpecError::BadValue { key: "span" },
        ] {
            assert!(!error.expected().is_empty());
        }
    }
}
