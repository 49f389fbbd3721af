//! Residuals at the GPS rows, in the frame of the vehicle's travel.
//!
//! A residual is measurement minus model, `r = z - p` (m). Horizontally it is
//! split along the model's direction of travel `h` (the forward axis rotated
//! by `q_t`, projected on the ground and normalised) and across it:
//!
//! ```text
//! along = r . h          (+: the fix is ahead of the path)
//! cross = r . (up x h)   (+: the fix is to the left of the path)
//! ```
//!
//! A GPS latency shows up in `along` (proportional to speed), a heading or
//! scale-factor error in `cross` (growing through turns), a barometer drift in
//! the vertical residual.

use nalgebra::Vector3;

use crate::model::{Model, PathAt};

/// The residual of one GPS fix.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FixResidual {
    /// Log time (s).
    pub t: f64,
    pub row: usize,
    /// East and north components (m), fix minus path.
    pub east: f64,
    pub north: f64,
    pub along: f64,
    pub cross: f64,
    /// Vertical reference minus path up (m): barometer plus offset if the log has
    /// one, else GPS altitude; `None` if the fix has neither.
    pub up: Option<f64>,
    /// Model speed at the fix (m/s), for relating residuals to motion.
    pub speed: f64,
}

impl FixResidual {
    pub fn horizontal(&self) -> f64 {
        self.east.hypot(self.north)
    }
}

/// Residuals of every GPS fix for parameters `theta` and their path `traj`
/// (pass `model.trajectory(theta)`, or `model.sparse_path(theta,
/// model.residual_rows(theta))` where the full path is too big to hold; it is
/// taken to avoid a second sweep when the caller has it already).
pub fn fix_residuals(model: &Model, theta: &[f64], traj: &impl PathAt) -> Vec<FixResidual> {
    let sig = &model.signals;
    let misfit = model.misfits(theta, traj);
    let (axis, _) = model.forward_axis(theta);
    let obs = &model.observations;
    let mut out = Vec::with_capacity(sig.fixes.len());
    let mut k = 0;
    for fix in &sig.fixes {
        // The observations of this fix (they are stored fix by fix).
        let (mut en, mut up_gps, mut up_baro) = ([0.0; 2], None, None);
        while k < obs.len() && obs[k].row == fix.row {
            let o = &obs[k];
            match (o.axis, o.baro) {
                (2, true) => up_baro = Some(-misfit[k]),
                (2, false) => up_gps = Some(-misfit[k]),
                (a, _) => en[a] = -misfit[k],
            }
            k += 1;
        }
        let f = traj.q_at(fix.row) * axis;
        let h = Vector3::new(f.x, f.y, 0.0);
        let h = if h.norm() > 1e-9 {
            h.normalize()
        } else {
            Vector3::x()
        };
        let [e, n] = en;
        let j = fix.row.max(1);
        let speed = if sig.dt[j] > 0.0 {
            traj.d_at(j) / sig.dt[j]
        } else {
            0.0
        };
        out.push(FixResidual {
            t: fix.t,
            row: fix.row,
            east: e,
            north: n,
            along: e * h.x + n * h.y,
            cross: -e * h.y + n * h.x,
            up: up_baro.or(up_gps),
            speed,
        });
    }
    out
}

/// RMS of along-track, cross-track and vertical residuals.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ResidualRms {
    pub along_m: f64,
    pub cross_m: f64,
    pub up_m: Option<f64>,
    pub fixes: usize,
}

impl ResidualRms {
    pub fn of(res: &[FixResidual]) -> Self {
        let n = res.len();
        if n == 0 {
            return Self::default();
        }
        let ms = |f: &dyn Fn(&FixResidual) -> f64| res.iter().map(|r| f(r).powi(2)).sum::<f64>();
        let ups: Vec<f64> = res.iter().filter_map(|r| r.up).collect();
        Self {
            along_m: (ms(&|r| r.along) / n as f64).sqrt(),
            cross_m: (ms(&|r| r.cross) / n as f64).sqrt(),
            up_m: (!ups.is_empty())
                .then(|| (ups.iter().map(|u| u * u).sum::<f64>() / ups.len() as f64).sqrt()),
            fixes: n,
        }
    }
}

/// RMS per minute of ride: `(start of the minute in log time, rms)`.
pub fn rms_per_minute(res: &[FixResidual]) -> Vec<(f64, ResidualRms)> {
    let Some(first) = res.first() else {
        return Vec::new();
    };
    let t0 = first.t;
    let mut out = Vec::new();
    let mut start = 0;
    while start < res.len() {
        let minute = ((res[start].t - t0) / 60.0).floor();
        let end = res[start..]
            .iter()
            .position(|r| ((r.t - t0) / 60.0).floor() != minute)
            .map_or(res.len(), |k| start + k);
        out.push((t0 + 60.0 * minute, ResidualRms::of(&res[start..end])));
        start = end;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelSpec;
    use crate::optimisation::{FitSettings, Reconstruction};
    use std::sync::Arc;

    #[test]
    fn along_and_cross_split_the_horizontal_residual() {
        let sig = Arc::new(crate::testing::winding_signals(300.0, 100.0));
        let model = Model::new(sig, ModelSpec::default()).expect("model");
        let theta = model.initial_params();
        let traj = model.trajectory(&theta);
        let res = fix_residuals(&model, &theta, &traj);
        assert_eq!(res.len(), model.signals.fixes.len());
        for r in &res {
            let h2 = r.east.powi(2) + r.north.powi(2);
            assert!((r.along.powi(2) + r.cross.powi(2) - h2).abs() < 1e-9 * (1.0 + h2));
        }
    }

    /// A view's snapshot keeps only the rows it reads: the residuals (here with
    /// a GPS lag, which interpolates between rows) are those of the full path.
    #[test]
    fn a_sparse_path_gives_the_full_paths_residuals() {
        let sig = Arc::new(crate::testing::simulated_signals(4, 240.0, &["gps_lag"]));
        let spec = ModelSpec {
            effects: vec!["paper".into(), "gps_lag".into()],
            ..ModelSpec::default()
        };
        let model = Model::new(sig, spec).expect("model");
        let mut theta = model.initial_params();
        let lag = model
            .range(model.effect_index("gps_lag").expect("lag"))
            .start;
        theta[lag] = 0.63;
        let full = fix_residuals(&model, &theta, &model.trajectory(&theta));
        let rows = model.residual_rows(&theta);
        assert!(rows.len() < model.signals.len() / 20, "{} rows", rows.len());
        let sparse = fix_residuals(&model, &theta, &model.sparse_path(&theta, rows));
        assert_eq!(full, sparse);
    }

    #[test]
    fn a_fit_leaves_small_residuals_with_no_along_track_bias() {
        let sig = Arc::new(crate::testing::simulated_signals(2, 300.0, &[]));
        let mut fit = Reconstruction::new(sig, FitSettings::default()).expect("fit");
        fit.run(&mut |_: &Reconstruction, _: &crate::optimisation::IterationReport| {});
        let res = fix_residuals(fit.model(), fit.params(), &fit.trajectory());
        let rms = ResidualRms::of(&res);
        assert!(rms.along_m < 4.0 && rms.cross_m < 4.0, "{rms:?}");
        let mean_along = res.iter().map(|r| r.along).sum::<f64>() / res.len() as f64;
        assert!(
            mean_along.abs() < 0.5,
            "mean along-track residual {mean_along}"
        );
        let minutes = rms_per_minute(&res);
        assert!(
            (5..=6).contains(&minutes.len()),
            "{} minutes",
            minutes.len()
        );
        assert_eq!(
            minutes.iter().map(|(_, r)| r.fixes).sum::<usize>(),
            res.len()
        );
    }
}
