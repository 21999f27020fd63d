//! Student's t quantiles for the few degrees of freedom a noise level measured on the fly
//! rests on, evaluated at compile time into tables (the target has no double-precision
//! FPU, and the series in soft `f64` would cost more than what it scales).

/// The quantile of Student's t with `degrees` degrees of freedom at the probability where
/// the standard normal has its quantile `z`: the Cornish–Fisher series in 1/ν of Abramowitz
/// and Stegun 26.7.5 to its third term. For z = 1.96 it is within 1 % of the tables from
/// ν = 3 (3.159 against 3.182) and 0.1 % from ν = 10; for z = 2.5 within 3 % at ν = 3 (5.25 against 5.41) and
/// 0.3 % from ν = 6. Below ν = 3 the series falls ever further short: callers need more.
pub(crate) const fn t_quantile(z: f64, degrees: f64) -> f64 {
    let v = degrees;
    let z3 = z * z * z;
    let z5 = z3 * z * z;
    let z7 = z5 * z * z;
    z + (z3 + z) / (4.0 * v)
        + (5.0 * z5 + 16.0 * z3 + 3.0 * z) / (96.0 * v * v)
        + (3.0 * z7 + 19.0 * z5 + 17.0 * z3 - 15.0 * z) / (384.0 * v * v * v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quantiles_follow_the_t_tables() {
        // Two-sided 95 %: 3.182 (3), 2.228 (10), 2.042 (30).
        for (degrees, t) in [(3.0, 3.182), (10.0, 2.228), (30.0, 2.042)] {
            let series = t_quantile(1.959_964, degrees);
            assert!((series / t - 1.0).abs() < 0.01, "{degrees}: {series}");
        }
        // One-sided at z = 2.5 (p = 0.99379), by numerical integration of the density:
        // 3.527 (6), 2.867 (14), 2.547 (98); and the normal's own beyond.
        for (degrees, t) in [(6.0, 3.527), (14.0, 2.867), (98.0, 2.547)] {
            let series = t_quantile(2.5, degrees);
            assert!((series / t - 1.0).abs() < 0.003, "{degrees}: {series}");
        }
        assert!((t_quantile(2.5, 1e9) - 2.5).abs() < 1e-6);
    }
}
