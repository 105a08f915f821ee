//! The median, 99th percentile and maximum of a set of measurements, as report.json holds them.

use serde::Serialize;

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Quantiles {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
    /// How many finite values they are of.
    pub n: usize,
}

/// The nearest-rank quantiles of the finite values of `v` (NaN when there are none).
pub fn quantiles(v: &[f64]) -> Quantiles {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    s.sort_by(f64::total_cmp);
    let q = |f: f64| s.get(((s.len().saturating_sub(1)) as f64 * f).round() as usize).copied().unwrap_or(f64::NAN);
    Quantiles { p50: q(0.5), p99: q(0.99), max: q(1.0), n: s.len() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_skip_what_is_not_finite() {
        let q = quantiles(&[3.0, f64::NAN, 1.0, 2.0, f64::INFINITY]);
        assert_eq!(q, Quantiles { p50: 2.0, p99: 3.0, max: 3.0, n: 3 });
        let none = quantiles(&[]);
        assert!(none.p50.is_nan() && none.max.is_nan() && none.n == 0);
    }
}
