//! The matrix exponential of a small fixed-size matrix, for the exact zero-order-hold
//! discretisation. Scaling and squaring with a truncated Taylor series: the matrix is scaled
//! by 2^-s until its 1-norm is at most 1/4, where 20 Taylor terms leave a truncation error
//! below 1e-30 relative, then squared s times. Allocation-free and panic-free.

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
    fn non_finite_input_gives_nan_not_a_hang() {
        let e = exp(&[[f64::NAN, 0.0], [0.0, 1.0]]);
        assert!(e[0][0].is_nan());
    }
}
