//! `gyro_bias_segments`: a gyro bias per time segment (3 parameters per
//! segment, rad/s, shown in deg/s), on top of the constant `gyro_bias`.
//!
//! Step `j` belongs to segment `s(j) = floor((t_mid,j - t_0) / T)` and
//! `omega_j = omega_j^in - b_{s(j)}` (paper: the bias varies per segment of
//! `T` seconds, default 5). Optional random-walk prior between neighbours:
//! residuals `(b_s - b_{s-1}) / (sigma_w sqrt(T))` for a bias random walk of
//! density `sigma_w` (rad/s/sqrt(s)); without it (`None`) the model is the paper's.
//!
//! The roll and pitch offsets are also held near the constant bias, as
//! `gyro_bias` holds its own near the level guess: `b_{0,a} ~ N(0, 0.3 deg/s)`
//! for `a = x, y` (the walk starts at the constant bias), and every segment's
//! under the paper's independent segments. Their common level is otherwise a
//! flat direction wherever the vehicle barely turns: a roll-axis bias moves
//! nothing on a straight. On a 10 s hand-held GoPro clip it drifted to
//! -15.6 deg/s (1-sigma 9.9) with no change in the path.

use std::sync::Arc;

use nalgebra::Vector3;

use super::gyro_bias::{DEG_PER_RAD, LEVEL_SIGMA};
use super::{Effect, GyroPartials, ParamInfo, PriorRows, Role};
use crate::contract::{ModelError, ModelSpec, StartGuess};
use crate::signals::Signals;

#[derive(Clone, Debug)]
pub struct GyroBiasSegments {
    segment_s: f64,
    /// Segment of each step (index = row), shared by reweighted copies.
    segment_of: Arc<[u32]>,
    /// Segment boundaries in log time, `n + 1` values.
    edges: Vec<f64>,
    /// `1 / (sigma_w sqrt(T))`, or 0 without a prior.
    prior_weight: f64,
    /// First and last step of each segment (inclusive); empty segments get `None`.
    steps: Vec<Option<(usize, usize)>>,
    /// Heading only: the roll and pitch biases are not fitted (their rates are zero).
    planar: bool,
}

impl GyroBiasSegments {
    /// Segments of `segment_s` seconds over the ride; `bias_walk_dps_sqrt_s` is
    /// the random-walk density of the prior in deg/s/sqrt(s) (`None`: no prior).
    pub fn new(
        signals: &Signals,
        segment_s: f64,
        bias_walk_dps_sqrt_s: Option<f64>,
    ) -> Result<Self, ModelError> {
        if !(segment_s.is_finite() && segment_s >= 0.05) {
            return Err(ModelError::Setting(format!(
                "segment length must be at least 0.05 s, got {segment_s}"
            )));
        }
        check_walk(bias_walk_dps_sqrt_s)?;
        let t0 = signals.t[0];
        let duration = signals.duration();
        let n = ((duration / segment_s).ceil() as usize).max(1);
        let segment_of: Arc<[u32]> = (0..signals.len())
            .map(|j| {
                let mid = if j == 0 {
                    signals.t[0]
                } else {
                    0.5 * (signals.t[j] + signals.t[j - 1])
                };
                (((mid - t0) / segment_s).floor() as usize).min(n - 1) as u32
            })
            .collect();
        let mut edges: Vec<f64> = (0..n).map(|s| t0 + s as f64 * segment_s).collect();
        edges.push(t0 + duration);
        let mut steps: Vec<Option<(usize, usize)>> = vec![None; n];
        for (j, &s) in segment_of.iter().enumerate().skip(1) {
            let e = &mut steps[s as usize];
            *e = Some(e.map_or((j, j), |(a, _)| (a, j)));
        }
        Ok(Self {
            segment_s,
            segment_of,
            edges,
            prior_weight: prior_weight(segment_s, bias_walk_dps_sqrt_s),
            steps,
            planar: signals.attitude.is_planar(),
        })
    }

    pub fn n_segments(&self) -> usize {
        self.edges.len() - 1
    }

    pub fn segment_s(&self) -> f64 {
        self.segment_s
    }

    /// Segment index of step `j`.
    pub fn segment_of(&self, j: usize) -> usize {
        self.segment_of[j] as usize
    }

    /// How many segments (from the first) carry a level row on roll and
    /// pitch: the first under a walk, all without one, none when planar.
    fn level_segments(&self) -> usize {
        match (self.planar, self.prior_weight > 0.0) {
            (true, _) => 0,
            (false, true) => 1,
            (false, false) => self.n_segments(),
        }
    }
}

/// A bias walk is a positive density (deg/s/sqrt(s)), or none.
fn check_walk(bias_walk_dps_sqrt_s: Option<f64>) -> Result<(), ModelError> {
    match bias_walk_dps_sqrt_s {
        Some(w) if !(w.is_finite() && w > 0.0) => Err(ModelError::Setting(format!(
            "bias random walk must be a positive number of deg/s/sqrt(s), got {w}"
        ))),
        _ => Ok(()),
    }
}

/// The prior rows' weight `1 / (sigma_w sqrt(T))` of segments `T` long
/// under a walk `sigma_w` (deg/s/sqrt(s)); 0 without a prior.
fn prior_weight(segment_s: f64, bias_walk_dps_sqrt_s: Option<f64>) -> f64 {
    bias_walk_dps_sqrt_s.map_or(0.0, |w| 1.0 / (w / DEG_PER_RAD * segment_s.sqrt()))
}

impl Effect for GyroBiasSegments {
    fn id(&self) -> String {
        "gyro_bias_segments".into()
    }

    fn params(&self) -> Vec<ParamInfo> {
        (0..self.n_segments())
            .flat_map(|s| {
                ["x", "y", "z"]
                    .into_iter()
                    .map(move |a| ParamInfo::new(format!("bias_{a}[{s}]"), "deg/s", DEG_PER_RAD))
            })
            .collect()
    }

    fn n_params(&self) -> usize {
        3 * self.n_segments()
    }

    fn role(&self) -> Role {
        Role::Segments
    }

    fn fixed(&self, i: usize) -> bool {
        self.planar && i % 3 != 2
    }

    fn initial(&self, _guess: &StartGuess) -> Vec<f64> {
        vec![0.0; self.n_params()]
    }

    fn acts_on_gyro(&self) -> bool {
        true
    }

    #[inline]
    fn gyro(&self, p: &[f64], j: usize, omega: Vector3<f64>) -> Vector3<f64> {
        let s = 3 * self.segment_of[j] as usize;
        omega - Vector3::new(p[s], p[s + 1], p[s + 2])
    }

    #[inline]
    fn gyro_partials(&self, _p: &[f64], j: usize, _omega: &Vector3<f64>) -> GyroPartials {
        GyroPartials::bias(3 * self.segment_of[j] as usize)
    }

    fn gyro_batch(&self, p: &[f64], first: usize, rates: &mut [Vector3<f64>]) {
        for (w, &s) in rates.iter_mut().zip(&self.segment_of[first..]) {
            let s = 3 * s as usize;
            *w -= Vector3::new(p[s], p[s + 1], p[s + 2]);
        }
    }

    fn gyro_backward_reads_input(&self) -> bool {
        false
    }

    fn gyro_backward(
        &self,
        _p: &[f64],
        _omega_in: &[Vector3<f64>],
        grad: &mut [Vector3<f64>],
        grad_p: &mut [f64],
    ) {
        for (g, &s) in grad.iter().zip(self.segment_of.iter()).skip(1) {
            let s = 3 * s as usize;
            grad_p[s] -= g.x;
            grad_p[s + 1] -= g.y;
            grad_p[s + 2] -= g.z;
        }
    }

    /// Same segments, the prior of `spec`'s walk: the per-row table is shared.
    fn reweighted(&self, spec: &ModelSpec) -> Option<Box<dyn Effect>> {
        let walk = spec.bias_walk_dps_sqrt_s;
        // An invalid walk is left to the fresh build, which says why.
        (spec.segment_s == self.segment_s && check_walk(walk).is_ok()).then(|| {
            Box::new(Self {
                prior_weight: prior_weight(self.segment_s, walk),
                ..self.clone()
            }) as Box<dyn Effect>
        })
    }

    fn n_prior(&self) -> usize {
        let walk = if self.prior_weight > 0.0 {
            3 * (self.n_segments() - 1)
        } else {
            0
        };
        walk + 2 * self.level_segments()
    }

    /// Walk rows `w (b_s - b_{s-1})`, then level rows `b_{s,a} / 0.3 deg/s`.
    fn prior(&self, p: &[f64], out: &mut PriorRows) {
        if self.prior_weight > 0.0 {
            let w = self.prior_weight;
            for s in 1..self.n_segments() {
                for a in 0..3 {
                    let row = out.residuals.len();
                    out.residuals.push(w * (p[3 * s + a] - p[3 * (s - 1) + a]));
                    out.entries.push((row, 3 * s + a, w));
                    out.entries.push((row, 3 * (s - 1) + a, -w));
                }
            }
        }
        for s in 0..self.level_segments() {
            for a in 0..2 {
                let row = out.residuals.len();
                out.residuals.push(p[3 * s + a] / LEVEL_SIGMA);
                out.entries.push((row, 3 * s + a, 1.0 / LEVEL_SIGMA));
            }
        }
    }

    fn param_steps(&self, i: usize) -> Option<(usize, usize)> {
        // A segment with no step (shorter than a sample) acts nowhere: step range past the end.
        Some(self.steps[i / 3].unwrap_or((usize::MAX, usize::MAX)))
    }

    fn segment_edges(&self) -> Option<&[f64]> {
        Some(&self.edges)
    }

    /// Time-weighted mean of the other segmentation's piecewise-constant bias
    /// over each of this one's segments.
    fn carry_over(&self, other: &dyn Effect, other_p: &[f64]) -> Option<Vec<f64>> {
        let old = other.segment_edges()?;
        if other.id() != self.id() || other_p.len() != 3 * (old.len() - 1) {
            return None;
        }
        let mut out = vec![0.0; self.n_params()];
        for s in 0..self.n_segments() {
            let (a, b) = (self.edges[s], self.edges[s + 1]);
            let mut total = 0.0;
            let mut acc = [0.0; 3];
            for k in 0..old.len() - 1 {
                let overlap = b.min(old[k + 1]) - a.max(old[k]);
                if overlap > 0.0 {
                    total += overlap;
                    for (ax, v) in acc.iter_mut().enumerate() {
                        *v += overlap * other_p[3 * k + ax];
                    }
                }
            }
            if total > 0.0 {
                for ax in 0..3 {
                    out[3 * s + ax] = acc[ax] / total;
                }
            }
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::winding_signals;

    #[test]
    fn segments_cover_the_ride_and_partials_are_right() {
        let sig = winding_signals(12.0, 100.0);
        let e = GyroBiasSegments::new(&sig, 5.0, None).unwrap();
        assert_eq!(e.n_segments(), 3);
        assert_eq!(e.segment_of(1), 0);
        assert_eq!(e.segment_of(sig.len() - 1), 2);
        let p: Vec<f64> = (0..9).map(|i| i as f64 * 0.01).collect();
        crate::effects::testing::check_gyro_partials(&e, &p, 700, Vector3::new(0.1, 0.2, 0.3));
        crate::effects::testing::check_batches(&e, &p, sig.len());
    }

    #[test]
    fn resegmenting_keeps_the_bias_profile() {
        let sig = winding_signals(20.0, 100.0);
        let five = GyroBiasSegments::new(&sig, 5.0, None).unwrap();
        let p5: Vec<f64> = (0..12).map(|i| (i / 3) as f64).collect(); // 0,1,2,3 per segment
        let ten = GyroBiasSegments::new(&sig, 10.0, None).unwrap();
        let p10 = ten.carry_over(&five, &p5).unwrap();
        assert_eq!(p10, vec![0.5, 0.5, 0.5, 2.5, 2.5, 2.5]);
        let back = five.carry_over(&ten, &p10).unwrap();
        assert_eq!(back[0], 0.5);
        assert_eq!(back[9], 2.5);
    }

    #[test]
    fn prior_rows_are_neighbour_differences() {
        let sig = winding_signals(10.0, 100.0);
        let e = GyroBiasSegments::new(&sig, 5.0, Some(0.01)).unwrap();
        let mut rows = PriorRows::default();
        e.prior(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], &mut rows);
        assert_eq!(rows.residuals.len(), e.n_prior());
        let w = 1.0 / (0.01 / DEG_PER_RAD * 5f64.sqrt());
        assert!((rows.residuals[0] - w).abs() < 1e-9);
    }

    /// Roll and pitch offsets are held near the constant bias: the first
    /// segment's under a walk, every segment's without one, none when planar.
    #[test]
    fn level_rows_hold_roll_and_pitch_near_the_constant_bias() {
        let sig = winding_signals(12.0, 100.0);
        let p: Vec<f64> = (0..9).map(|i| i as f64 * 0.001).collect();
        for (walk, levelled) in [(Some(0.01), 1), (None, 3)] {
            let mut e = GyroBiasSegments::new(&sig, 5.0, walk).unwrap();
            e.planar = false;
            let mut rows = PriorRows::default();
            e.prior(&p, &mut rows);
            assert_eq!(rows.residuals.len(), e.n_prior());
            let level = &rows.residuals[rows.residuals.len() - 2 * levelled..];
            for s in 0..levelled {
                for a in 0..2 {
                    let want = p[3 * s + a] / LEVEL_SIGMA;
                    assert!((level[2 * s + a] - want).abs() < 1e-12);
                }
            }
            e.planar = true;
            let walk_rows = if walk.is_some() { 6 } else { 0 };
            assert_eq!(e.n_prior(), walk_rows);
        }
    }
}
