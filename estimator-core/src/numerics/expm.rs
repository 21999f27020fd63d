//! The matrix exponential of a small fixed-size matrix, for the exact zero-order-hold
//! discretisation of continuous-time sensor models. Scaling and squaring with a truncated
//! Taylor series: the matrix is scaled by 2^-s until its 1-norm is at most 1/4, where 20
//! Taylor terms leave a truncation error below 1e-30 relative, then squared s times.
//! Allocation-free and panic-free; always `f64` (it runs when a model is built, never per
//! sample, so soft-float on the Cortex-M4F costs milliseconds once).
//!
//! One implementation for the whole project: the host simulator discretises its sensor
//! with [`exp`] and the core's parametric load-cell model with [`zoh`].
//! What it must never do: go through transfer-function polynomials (at 4 kHz their
//! coefficients cancel to within rounding), loop on a NaN, or panic.

/// A square matrix, row-major.
pub type Square<const S: usize> = [[f64; S]; S];

fn multiply<const S: usize>(left: &Square<S>, right: &Square<S>) -> Square<S> {
    let mut product = [[0.0; S]; S];
    for row in 0..S {
        for inner in 0..S {
            let factor = left[row][inner];
            if factor == 0.0 {
                continue;
            }
            for col in 0..S {
                product[row][col] += factor * right[inner][col];
            }
        }
    }
    product
}

fn one_norm<const S: usize>(matrix: &Square<S>) -> f64 {
    let mut largest = 0.0_f64;
    for col in 0..S {
        let mut sum = 0.0;
        for row in 0..S {
            sum += libm::fabs(matrix[row][col]);
        }
        largest = largest.max(sum);
    }
    largest
}

/// The largest number of squarings; a norm that needs more is not a sensor at 4 kHz (and a
/// NaN input ends here too instead of looping).
const MAX_SQUARINGS: u32 = 60;
const TAYLOR_TERMS: u32 = 20;

/// `e^matrix`. Entries that are not finite give a matrix of NaN, never a panic.
pub fn exp<const S: usize>(matrix: &Square<S>) -> Square<S> {
    let norm = one_norm(matrix);
    if !norm.is_finite() {
        return [[f64::NAN; S]; S];
    }
    let mut squarings = 0;
    let mut scale = 1.0;
    while norm * scale > 0.25 && squarings < MAX_SQUARINGS {
        scale *= 0.5;
        squarings += 1;
    }
    let mut scaled = *matrix;
    for row in scaled.iter_mut() {
        for entry in row.iter_mut() {
            *entry *= scale;
        }
    }
    // Horner form of the Taylor series: I + X(I + X/2(I + X/3(...))).
    let mut sum = identity::<S>();
    for term in (1..=TAYLOR_TERMS).rev() {
        let mut next = multiply(&scaled, &sum);
        let inverse = 1.0 / term as f64;
        for row in next.iter_mut() {
            for entry in row.iter_mut() {
                *entry *= inverse;
            }
        }
        for diagonal in 0..S {
            next[diagonal][diagonal] += 1.0;
        }
        sum = next;
    }
    for _ in 0..squarings {
        sum = multiply(&sum, &sum);
    }
    sum
}

/// The exact zero-order-hold discretisation of `ẋ = A x + B w` over `period`:
/// `(Φ, Γ)` with `exp([[A, B], [0, 0]]·period) = [[Φ, Γ], [0, I]]`.
///
/// The augmented exponential is computed in its block form, because a const-generic
/// `S + I` square cannot be written on stable Rust: every matrix in the Horner sum and in
/// the squarings has the shape `[[P, Q], [0, I]]`, so only `P` (S×S) and `Q` (S×I) are kept.
/// The scaling, the terms and the order of every sum are those of [`exp`] on the augmented
/// matrix, so both give the same numbers (test `zoh_equals_the_augmented_exponential`).
pub fn zoh<const S: usize, const I: usize>(
    a: &Square<S>,
    b: &[[f64; I]; S],
    period: f64,
) -> (Square<S>, [[f64; I]; S]) {
    // 1-norm of the augmented matrix: the largest column sum over A's and B's columns.
    let mut norm = 0.0_f64;
    for col in 0..S {
        let mut sum = 0.0;
        for row in 0..S {
            sum += libm::fabs(a[row][col] * period);
        }
        norm = norm.max(sum);
    }
    for col in 0..I {
        let mut sum = 0.0;
        for row in 0..S {
            sum += libm::fabs(b[row][col] * period);
        }
        norm = norm.max(sum);
    }
    if !norm.is_finite() {
        return ([[f64::NAN; S]; S], [[f64::NAN; I]; S]);
    }
    let mut squarings = 0;
    let mut scale = 1.0;
    while norm * scale > 0.25 && squarings < MAX_SQUARINGS {
        scale *= 0.5;
        squarings += 1;
    }
    let mut x = [[0.0; S]; S];
    let mut y = [[0.0; I]; S];
    for row in 0..S {
        for col in 0..S {
            x[row][col] = a[row][col] * period * scale;
        }
        for col in 0..I {
            y[row][col] = b[row][col] * period * scale;
        }
    }
    // Horner: [[P, Q], [0, I]] ← I + [[X, Y], [0, 0]]·[[P, Q], [0, I]]/term
    //                          = [[I + X·P/term, (X·Q + Y)/term], [0, I]].
    let mut p = identity::<S>();
    let mut q = [[0.0; I]; S];
    for term in (1..=TAYLOR_TERMS).rev() {
        let mut next_p = multiply(&x, &p);
        let mut next_q = multiply_rect(&x, &q);
        for row in 0..S {
            for col in 0..I {
                next_q[row][col] += y[row][col];
            }
        }
        let inverse = 1.0 / term as f64;
        for row in 0..S {
            for entry in next_p[row].iter_mut() {
                *entry *= inverse;
            }
            for entry in next_q[row].iter_mut() {
                *entry *= inverse;
            }
            next_p[row][row] += 1.0;
        }
        p = next_p;
        q = next_q;
    }
    // [[P, Q], [0, I]]² = [[P², P·Q + Q], [0, I]].
    for _ in 0..squarings {
        let mut next_q = multiply_rect(&p, &q);
        for row in 0..S {
            for col in 0..I {
                next_q[row][col] += q[row][col];
            }
        }
        p = multiply(&p, &p);
        q = next_q;
    }
    (p, q)
}

/// `left · right` for a square `left` and an S×I `right`, summed in the order of [`multiply`].
fn multiply_rect<const S: usize, const I: usize>(
    left: &Square<S>,
    right: &[[f64; I]; S],
) -> [[f64; I]; S] {
    let mut product = [[0.0; I]; S];
    for row in 0..S {
        for inner in 0..S {
            let factor = left[row][inner];
            if factor == 0.0 {
                continue;
            }
            for col in 0..I {
                product[row][col] += factor * right[inner][col];
            }
        }
    }
    product
}

/// The identity matrix.
pub fn identity<const S: usize>() -> Square<S> {
    let mut matrix = [[0.0; S]; S];
    for diagonal in 0..S {
        matrix[diagonal][diagonal] = 1.0;
    }
    matrix
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_generator_gives_cos_and_sin() {
        // e^[[0, w], [-w, 0]] is a rotation by w; a large w exercises the squaring.
        for w in [0.1, 1.0, 7.5, 40.0] {
            let e = exp(&[[0.0, w], [-w, 0.0]]);
            let (s, c) = (libm::sin(w), libm::cos(w));
            for (got, want) in [(e[0][0], c), (e[0][1], s), (e[1][0], -s), (e[1][1], c)] {
                assert!(
                    (got - want).abs() < 1e-12 * (1.0 + w),
                    "w={w}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn nilpotent_block_is_exact_integral() {
        // e^[[a, 1], [0, 0]] = [[e^a, (e^a - 1)/a], [0, 1]]: the ZOH input column.
        let a = -3.0;
        let e = exp(&[[a, 1.0], [0.0, 0.0]]);
        assert!((e[0][0] - libm::exp(a)).abs() < 1e-15);
        assert!((e[0][1] - (libm::exp(a) - 1.0) / a).abs() < 1e-15);
        assert_eq!(e[1], [0.0, 1.0]);
    }

    #[test]
    fn zoh_equals_the_augmented_exponential() {
        // A 3-state stiff-ish system with two inputs, at a period that needs squarings.
        let a = [[-2.0, 1.0, 0.0], [-40.0, -0.5, 3.0], [5.0, 0.0, -70.0]];
        let b = [[0.0, 1.0], [40.0, 0.0], [0.0, 70.0]];
        let period = 0.05;
        let mut augmented = [[0.0; 5]; 5];
        for row in 0..3 {
            for col in 0..3 {
                augmented[row][col] = a[row][col] * period;
            }
            for col in 0..2 {
                augmented[row][3 + col] = b[row][col] * period;
            }
        }
        let e = exp(&augmented);
        let (phi, gamma) = zoh(&a, &b, period);
        for row in 0..3 {
            for col in 0..3 {
                let want = e[row][col];
                assert!((phi[row][col] - want).abs() <= 1e-14 * (1.0 + want.abs()));
            }
            for col in 0..2 {
                let want = e[row][3 + col];
                assert!((gamma[row][col] - want).abs() <= 1e-14 * (1.0 + want.abs()));
            }
        }
        let (phi, _) = zoh(&[[f64::INFINITY]], &[[1.0]], 1.0);
        assert!(phi[0][0].is_nan());
    }

    #[test]
    fn non_finite_input_gives_nan_not_a_hang() {
        let e = exp(&[[f64::NAN, 0.0], [0.0, 1.0]]);
        assert!(e[0][0].is_nan());
    }
}
