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

/// The `q` quantile of `values` by nearest rank (the `ceil(q n)`-th
/// smallest); NaN for none. Reorders `values`, in O(n) by selection.
pub fn quantile(values: &mut [f64], q: f64) -> f64 {
    let n = values.len();
    if n == 0 {
        return f64::NAN;
    }
    let at = ((q * n as f64).ceil() as usize).clamp(1, n) - 1;
    *values.select_nth_unstable_by(at, f64::total_cmp).1
}

/// The root of `f`, positive below it and not above it, between `lo` and
/// `hi` (> 0), by bisection in the logarithm (a scale's estimating equation:
/// its root is found to the same relative precision at any magnitude).
pub fn falling_root_in_log(f: impl Fn(f64) -> f64, lo: f64, hi: f64) -> f64 {
    let (mut lo, mut hi) = (lo.ln(), hi.ln());
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if f(mid.exp()) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (0.5 * (lo + hi)).exp()
}

/// The median of the finite values of `values` (NaN for none).
pub fn median_of_finite(values: &[f64]) -> f64 {
    let mut finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    median(&mut finite)
}

/// A track's own scatter (m): the median distance of each point `en[i]` at
/// `t[i]` from a quadratic in time fitted to its neighbours within 4 s
/// (itself left out), `x(t) = a + b (t - t_i) + c (t - t_i)^2` per axis.
/// It needs no model: a model that cannot follow the fixes is measured
/// against something it cannot bend, and a check of the odometer against the
/// GPS track knows how much of the track's length is noise. `None` with
/// fewer than 5 points that have 4 neighbours on both sides.
pub fn track_scatter_m(t: &[f64], en: &[[f64; 2]]) -> Option<f64> {
    const HALF_WINDOW_S: f64 = 4.0;
    let mut distances = Vec::new();
    let mut lo = 0usize;
    for i in 0..t.len() {
        while t[lo] < t[i] - HALF_WINDOW_S {
            lo += 1;
        }
        let mut a = nalgebra::Matrix3::<f64>::zeros();
        let mut b = [nalgebra::Vector3::<f64>::zeros(); 2];
        let (mut n, mut before, mut after) = (0, false, false);
        for k in lo..t.len() {
            if t[k] > t[i] + HALF_WINDOW_S {
                break;
            }
            if k == i {
                continue;
            }
            let dt = t[k] - t[i];
            before |= dt < 0.0;
            after |= dt > 0.0;
            let h = nalgebra::Vector3::new(1.0, dt, dt * dt);
            a += h * h.transpose();
            for (axis, rhs) in b.iter_mut().enumerate() {
                *rhs += h * en[k][axis];
            }
            n += 1;
        }
        if n < 4 || !before || !after {
            continue;
        }
        let Some(inv) = a.try_inverse() else { continue };
        let east = (inv * b[0])[0] - en[i][0];
        let north = (inv * b[1])[0] - en[i][1];
        distances.push(east.hypot(north));
    }
    (distances.len() >= 5).then(|| median(&mut distances))
}

/// Student's t distribution function `P(T <= t)` for `dof` (>= 1) degrees
/// of freedom, in closed form for whole degrees of freedom (Abramowitz and
/// Stegun 26.7.3-4): with `theta = atan(t / sqrt(dof))`,
/// `P(|T| <= t) = 2/pi (theta + sin theta (cos theta + 2/3 cos^3 theta + ...))`
/// for odd `dof` (the sum running to `cos^(dof-2)`, empty for 1) and
/// `sin theta (1 + 1/2 cos^2 theta + 1*3/(2*4) cos^4 theta + ...)` for even.
pub fn student_t_cdf(t: f64, dof: usize) -> f64 {
    let dof = dof.max(1);
    let theta = (t.abs() / (dof as f64).sqrt()).atan();
    let (s, c) = theta.sin_cos();
    let c2 = c * c;
    let within = if dof % 2 == 1 {
        let (mut term, mut sum) = (c, 0.0);
        for k in (1..dof.saturating_sub(1)).step_by(2) {
            sum += term;
            term *= c2 * (k + 1) as f64 / (k + 2) as f64;
        }
        std::f64::consts::FRAC_2_PI * (theta + s * sum)
    } else {
        let (mut term, mut sum) = (1.0, 0.0);
        for k in (0..dof - 1).step_by(2) {
            sum += term;
            term *= c2 * (k + 1) as f64 / (k + 2) as f64;
        }
        s * sum
    };
    let upper = 0.5 * (1.0 - within.clamp(0.0, 1.0));
    if t >= 0.0 { 1.0 - upper } else { upper }
}

/// The `p` quantile (0.5 <= p < 1) of Student's t with `dof` degrees of
/// freedom, by bisection of [`student_t_cdf`].
pub fn student_t_quantile(p: f64, dof: usize) -> f64 {
    let (mut lo, mut hi) = (0.0, 1e6);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if student_t_cdf(mid, dof) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Pearson correlation of two equally long series (`None` if either is constant).
pub fn pearson(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len().min(y.len());
    if n < 3 {
        return None;
    }
    let mx = x[..n].iter().sum::<f64>() / n as f64;
    let my = y[..n].iter().sum::<f64>() / n as f64;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (a, b) = (x[i] - mx, y[i] - my);
        sxy += a * b;
        sxx += a * a;
        syy += b * b;
    }
    (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Textbook quantiles: t(0.975) for 1, 2, 3, 9 and 30 degrees of freedom,
    /// and the distribution function's symmetry.
    #[test]
    fn student_t_matches_its_tables() {
        for (dof, q) in [(1, 12.706), (2, 4.303), (3, 3.182), (9, 2.262), (30, 2.042)] {
            let got = student_t_quantile(0.975, dof);
            assert!((got - q).abs() < 2e-3, "{dof}: {got}");
        }
        assert!((student_t_cdf(-1.3, 4) + student_t_cdf(1.3, 4) - 1.0).abs() < 1e-12);
        assert!((student_t_cdf(0.0, 7) - 0.5).abs() < 1e-12);
    }

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
