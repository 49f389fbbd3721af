//! Order statistics shared by the loaders, the start guess, the noise model
//! and the diagnosis.

/// The sample median of `values`: the middle value, or the mean of the
/// middle two for an even count; NaN for none. Reorders `values`, in O(n) by
/// selection rather than a sort (the start guess takes the median of every
/// gyro sample of a ride: 2 million on a 6-hour one).
pub fn median(values: &mut [f64]) -> f64 {
    let n = values.len();
    if n == 0 {
        return f64::NAN;
    }
    let (lower, &mut middle, _) = values.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        middle
    } else {
        let below = lower.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (below + middle)
    }
}

/// The median of the finite values of `values` (NaN for none).
pub fn median_of_finite(values: &[f64]) -> f64 {
    let mut finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    median(&mut finite)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts_and_of_none() {
        assert_eq!(median(&mut [3.0, -1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&mut [7.0]), 7.0);
        assert!(median(&mut []).is_nan());
        // Agrees with a sort on a scrambled sequence.
        let mut v: Vec<f64> = (0..101).map(|i| ((i * 37) % 101) as f64 * 0.5).collect();
        assert_eq!(median(&mut v), 25.0);
        v.pop();
        let mut sorted = v.clone();
        sorted.sort_by(f64::total_cmp);
        assert_eq!(median(&mut v), 0.5 * (sorted[49] + sorted[50]));
        assert_eq!(median_of_finite(&[f64::NAN, 1.0, f64::INFINITY, 3.0]), 2.0);
        assert!(median_of_finite(&[f64::NAN]).is_nan());
    }
}
