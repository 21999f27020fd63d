//! The input stage every data-driven estimator shares: sample checks, block averaging and
//! the window of differences that forms the Hankel regressor.

use crate::numerics::real::Real;
use crate::reading::InvalidReason;

/// Refuse a sample that is not finite or lies outside `[min, max]`.
#[inline]
pub(crate) fn check_sample<T: Real>(sample: T, min: T, max: T) -> Result<T, InvalidReason> {
    if !sample.is_finite() {
        return Err(InvalidReason::NonFiniteInput);
    }
    if !(sample >= min && sample <= max) {
        return Err(InvalidReason::OutOfRange);
    }
    Ok(sample)
}

/// What the row `[φ, 1]` leaves of its target `x` under the solution `(lead, constant)`:
/// `x − (constant + Σ φ_i·lead_i)`, summed in that order.
#[inline]
pub(crate) fn row_residual<T: Real, const N: usize>(
    x: T,
    phi: &[T; N],
    lead: &[T; N],
    constant: T,
    n: usize,
) -> T {
    let mut prediction = constant;
    for i in 0..n {
        prediction += phi[i] * lead[i];
    }
    x - prediction
}

/// Averages non-overlapping blocks of `D` samples: the anti-alias pre-filter and the
/// decimation of the multi-rate data-driven estimator, in one.
///
/// Why a block mean and not a sharper low-pass:
/// - it keeps the model order: for a step input, the mean of a block of an order-`n` LTI
///   output is a linear function of the state at the block's start and of `u`, so the block
///   means are again the output of an order-`n` LTI system (at rate fs/D) with the same static
///   gain. An IIR anti-alias filter would add its own order to `n`;
/// - it keeps white noise white at the lower rate (non-overlapping blocks), which the
///   least-squares statistics of the method assume; an overlapping FIR would colour it;
/// - it has nulls at multiples of fs/D (D = 80 at 4 kHz nulls 50 Hz mains exactly).
///
/// What "matched to the sensor's bandwidth" means here: the differences Δy must carry the
/// transient above the noise, so D grows until fs/(2D) approaches the sensor's bandwidth,
/// just above the analogue filter's cut-off; the calibration command picks D from recorded
/// drops.
#[derive(Clone, Debug)]
pub(crate) struct Decimator<T> {
    length: u16,
    mean: BlockMean<T>,
    sum: T,
    filled: u16,
}

/// How a block's sum becomes its mean. Each estimator keeps the rule it was validated with,
/// so that its readings stay the same bit for bit.
#[derive(Clone, Copy, Debug)]
enum BlockMean<T> {
    /// Blocks of one sample: the sample itself, not summed.
    Sample,
    /// `sum · (1/D)`: one multiply per block (the estimators').
    Scaled(T),
    /// `sum / D`, summed even for `D = 1` (the covariance reference's and the baselines').
    Divided(T),
}

impl<T: Real> Decimator<T> {
    /// Blocks of one sample: what an estimator not yet configured holds (see
    /// `ModelBank::UNCONFIGURED`; zero bits).
    pub(crate) const PASS_THROUGH: Self = Self {
        length: 0,
        mean: BlockMean::Sample,
        sum: T::ZERO,
        filled: 0,
    };

    /// Block means as `sum · (1/D)`; `D ≤ 1` passes samples through.
    pub(crate) fn new(length: u16) -> Self {
        let mean = if length <= 1 {
            BlockMean::Sample
        } else {
            BlockMean::Scaled(T::ONE / T::from_u32(length as u32))
        };
        Self::with_mean(length, mean)
    }

    /// Block means as `sum / D`, for every `D`.
    pub(crate) fn dividing(length: u16) -> Self {
        Self::with_mean(length, BlockMean::Divided(T::from_u32(length as u32)))
    }

    fn with_mean(length: u16, mean: BlockMean<T>) -> Self {
        Self {
            length,
            mean,
            sum: T::ZERO,
            filled: 0,
        }
    }

    /// The block mean when this sample completes a block.
    #[inline]
    pub(crate) fn push(&mut self, x: T) -> Option<T> {
        if let BlockMean::Sample = self.mean {
            return Some(x);
        }
        self.sum += x;
        self.filled += 1;
        if self.filled < self.length {
            return None;
        }
        let mean = match self.mean {
            BlockMean::Scaled(inv_length) => self.sum * inv_length,
            BlockMean::Divided(length) => self.sum / length,
            BlockMean::Sample => x,
        };
        self.sum = T::ZERO;
        self.filled = 0;
        Some(mean)
    }
}

/// The last `n` differences of order `ORDER` (1: Δx, 2: Δ²x) of a sequence, oldest first.
#[derive(Clone, Debug)]
pub(crate) struct DifferenceWindow<T, const N: usize, const ORDER: usize> {
    /// The last `ORDER` values of the sequence and of its lower differences.
    history: [T; ORDER],
    /// Values pushed so far (saturating).
    seen: u32,
    window: [T; N],
}

impl<T: Real, const N: usize, const ORDER: usize> DifferenceWindow<T, N, ORDER> {
    pub(crate) fn new() -> Self {
        Self {
            history: [T::ZERO; ORDER],
            seen: 0,
            window: [T::ZERO; N],
        }
    }

    /// Push the next value; true once the first `n` differences fill the window.
    #[inline]
    pub(crate) fn push(&mut self, x: T, n: usize) -> bool {
        // history[j] holds the previous j-th difference; walk up the orders.
        let mut difference = x;
        for j in 0..ORDER {
            let previous = self.history[j];
            self.history[j] = difference;
            difference -= previous;
        }
        let seen = self.seen;
        self.seen = seen.saturating_add(1);
        if (seen as usize) < ORDER {
            return false;
        }
        self.window.copy_within(1..n, 0);
        self.window[n - 1] = difference;
        seen as usize >= ORDER + n - 1
    }

    /// The window (its first `n` entries are the active regressor).
    #[inline]
    pub(crate) fn window(&self) -> [T; N] {
        self.window
    }
}
