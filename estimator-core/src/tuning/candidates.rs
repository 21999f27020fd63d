//! The methods calibration chooses from, and the order in which it prefers them.
//!
//! ## "Size": the order of preference
//! Calibration takes the first candidate, in this order, that meets the target:
//!
//! 1. **The model: order `n` first.** A data-driven estimator of order `n` assumes the sensor
//!    is an LTI system of order `n` and fits `n + 1` unknowns; that is the model complexity a
//!    reviewer means, and what "model no more than the scene needs" limits. Smaller `n`
//!    first, over every solver and decimation.
//! 2. **Then the solver, cheapest first**, at the same `n`: least squares with a growing
//!    window ([`crate::StepEstimator`], λ = 1); the same with forgetting (λ < 1: one more
//!    tuning parameter, the same cost); bias-compensated least squares (needs the noise
//!    variance from tare, about 3× the cost per row); instrumental variables (about 5×).
//! 3. **Then the decimation, largest first.** `D` is not part of the model: it is how
//!    much data each regression row summarises. The cost per raw sample is one addition
//!    plus one regression update every `D` samples, so a larger `D` is cheaper; it is
//!    preferred only where it still meets the target (a larger `D` also delays the first
//!    estimate: `(2n + 1)·D` samples, which the readout time checks by itself).
//! 4. **Last, the model bank** ([`crate::ModelBank`]): the physical model identified at
//!    calibration (5 states at the reference cell, two identified parameters, the initial
//!    state estimated) run as `K` candidates over the load range. The largest model and the
//!    largest cost (`K` estimators per sample, 21 KB in `f32` for `K = 33`).
//!
//! [`WeighingMethod::size_key`] is this order as a sortable key; [`CandidateGrid::get`]
//! yields candidates in it.

use crate::weighing::{BankCandidate, WeighingMethod};

/// The solver's place in the order of preference at one model order.
fn solver_rank(method: &WeighingMethod) -> u32 {
    match method {
        WeighingMethod::Step { forgetting, .. } if *forgetting == 1.0 => 0,
        WeighingMethod::Step { .. } => 1,
        WeighingMethod::BiasCompensated { .. } => 2,
        WeighingMethod::InstrumentalVariable { .. } => 3,
        WeighingMethod::ModelBank { .. } => 4,
    }
}

impl WeighingMethod {
    /// The order of preference as a key: smaller is preferred (see the module docs):
    /// `(family, order, solver, MAX − D)`, the bank after every data-driven method.
    pub fn size_key(&self) -> (u32, u32, u32, u32) {
        let inverse_decimation = u32::from(u16::MAX - self.decimation());
        match self.order() {
            Some(order) => (
                0,
                order.min(u32::MAX as usize) as u32,
                solver_rank(self),
                inverse_decimation,
            ),
            None => (1, 0, solver_rank(self), inverse_decimation),
        }
    }
}

/// Every candidate calibration may try, generated in the order of preference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CandidateGrid<'a> {
    /// Orders 1..=max_order.
    pub max_order: usize,
    /// Block lengths (any order; tried largest first).
    pub decimations: &'a [u16],
    /// The λ < 1 variant of the least-squares step estimator, as its memory in seconds:
    /// `λ = exp(−D/(f_s·memory))` (the same memory in time at every D). `None`: no variant.
    pub forgetting_memory_s: Option<f64>,
    /// Include bias-compensated least squares.
    pub bias_compensated: bool,
    /// Include instrumental variables.
    pub instrumental_variable: bool,
    /// The bank at the end of the list, if any.
    pub bank: Option<BankCandidate>,
}

/// The decimations of [`CandidateGrid::standard`].
pub const STANDARD_DECIMATIONS: [u16; 8] = [32, 24, 16, 12, 8, 4, 2, 1];

impl CandidateGrid<'static> {
    /// Orders 1–8, D ∈ {32, 24, 16, 12, 8, 4, 2, 1}, λ = 1 and one λ < 1 with a memory of
    /// half the readout time (it discounts the start of the transient, where a model of
    /// too low an order fits worst), bias-compensated and IV, and the reference bank.
    pub fn standard(readout_s: f64) -> Self {
        Self {
            max_order: 8,
            decimations: &STANDARD_DECIMATIONS,
            forgetting_memory_s: Some(0.5 * readout_s),
            bias_compensated: true,
            instrumental_variable: true,
            bank: Some(BankCandidate::REFERENCE),
        }
    }
}

impl CandidateGrid<'_> {
    /// Data-driven candidates at one order.
    fn per_order(&self) -> usize {
        let d = self.decimations.len();
        d * (1
            + usize::from(self.forgetting_memory_s.is_some())
            + usize::from(self.bias_compensated)
            + usize::from(self.instrumental_variable))
    }

    /// Candidates in the grid.
    pub fn len(&self) -> usize {
        self.max_order * self.per_order() + usize::from(self.bank.is_some())
    }

    /// True when the grid holds no candidate.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `index`-th decimation, largest first (ties kept in the given order).
    fn decimation(&self, index: usize) -> u16 {
        // Selection by rank without sorting (the slice is the caller's, fixed memory).
        let mut remaining = index;
        let mut last: Option<(u16, usize)> = None;
        loop {
            // The next value below `last` in (value desc, position asc) order.
            let mut next: Option<(u16, usize)> = None;
            for (position, &d) in self.decimations.iter().enumerate() {
                let after_last = match last {
                    None => true,
                    Some((value, at)) => d < value || (d == value && position > at),
                };
                let better = match next {
                    None => true,
                    Some((value, at)) => d > value || (d == value && position < at),
                };
                if after_last && better {
                    next = Some((d, position));
                }
            }
            match next {
                Some(found) if remaining == 0 => return found.0,
                Some(found) => {
                    last = Some(found);
                    remaining -= 1;
                }
                None => return 0,
            }
        }
    }

    /// The `index`-th candidate in the order of preference, at `sample_rate_hz`.
    pub fn get(&self, index: usize, sample_rate_hz: f64) -> Option<WeighingMethod> {
        let per_order = self.per_order();
        let data_driven = self.max_order * per_order;
        if index >= data_driven {
            return match self.bank {
                Some(bank) if index == data_driven => Some(bank.method()),
                _ => None,
            };
        }
        let order = index / per_order + 1;
        let within = index % per_order;
        let d_count = self.decimations.len();
        let decimation = self.decimation(within % d_count);
        let mut solver = within / d_count;
        if solver == 0 {
            return Some(WeighingMethod::Step {
                order,
                decimation,
                forgetting: 1.0,
            });
        }
        if let Some(memory_s) = self.forgetting_memory_s {
            if solver == 1 {
                let forgetting = libm::exp(-f64::from(decimation) / (sample_rate_hz * memory_s));
                return Some(WeighingMethod::Step {
                    order,
                    decimation,
                    forgetting,
                });
            }
            solver -= 1;
        }
        if self.bias_compensated && solver == 1 {
            return Some(WeighingMethod::BiasCompensated { order, decimation });
        }
        // What remains is the last solver in the list: instrumental variables.
        Some(WeighingMethod::InstrumentalVariable { order, decimation })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_is_generated_in_size_order_and_complete() {
        let grid = CandidateGrid::standard(0.1);
        assert_eq!(grid.len(), 8 * 8 * 4 + 1);
        let mut previous = None;
        for index in 0..grid.len() {
            let method = grid.get(index, 4000.0).unwrap();
            if let Some(previous) = previous {
                let earlier: WeighingMethod = previous;
                assert!(
                    earlier.size_key() < method.size_key(),
                    "{earlier} before {method}"
                );
            }
            previous = Some(method);
        }
        assert_eq!(grid.get(grid.len(), 4000.0), None);
        // The first: the smallest model, the cheapest solver, the largest D.
        assert_eq!(
            grid.get(0, 4000.0),
            Some(WeighingMethod::Step {
                order: 1,
                decimation: 32,
                forgetting: 1.0
            })
        );
        assert!(matches!(
            grid.get(grid.len() - 1, 4000.0),
            Some(WeighingMethod::ModelBank { candidates: 33, .. })
        ));
        // λ < 1 with a memory of 50 ms at D = 32, 4 kHz: exp(−32/200).
        match grid.get(8, 4000.0) {
            Some(WeighingMethod::Step {
                decimation: 32,
                forgetting,
                ..
            }) => assert!((forgetting - libm::exp(-0.16)).abs() < 1e-15),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn decimations_are_taken_largest_first_whatever_the_given_order() {
        let decimations = [4u16, 16, 1, 16, 8];
        let grid = CandidateGrid {
            max_order: 1,
            decimations: &decimations,
            forgetting_memory_s: None,
            bias_compensated: false,
            instrumental_variable: false,
            bank: None,
        };
        let got: [u16; 5] = core::array::from_fn(|i| grid.get(i, 4000.0).unwrap().decimation());
        assert_eq!(got, [16, 16, 8, 4, 1]);
        assert_eq!(grid.get(5, 4000.0), None);
        assert!(!grid.is_empty());
    }
}
