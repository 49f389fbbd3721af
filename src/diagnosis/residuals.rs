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
    /// Along- and cross-track residuals normalised by the fit's noise model:
    /// the whitened east and north innovations `-e'` (see `model::noise`:
    /// fix minus path in sigmas of what the model expects at this fix given
    /// the one before), turned into the direction of travel like `along` and
    /// `cross`. Under a right model they are independent N(0, 1) (a rotation
    /// keeps that): about 4.6 % beyond 2.
    pub normalised: [f64; 2],
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
        let (mut en, mut white, mut up_gps, mut up_baro) = ([0.0; 2], [0.0; 2], None, None);
        while k < obs.len() && obs[k].row == fix.row {
            let o = &obs[k];
            let m = misfit[k];
            match (o.axis, o.baro) {
                (2, true) => up_baro = Some(-m.metres),
                (2, false) => up_gps = Some(-m.metres),
                (a, _) => {
                    en[a] = -m.metres;
                    white[a] = -m.white;
                }
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
            normalised: [
                white[0] * h.x + white[1] * h.y,
                -white[0] * h.y + white[1] * h.x,
            ],
        });
    }
    out
}

/// How the normalised residuals compare with what the noise model expects
/// (independent, unit variance): their RMS (1 expected) and the share of
/// components beyond 2 (4.6 % expected). Much more says the noise is set too
/// tight or an effect is missing; much less, too loose.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct NormalisedSpread {
    pub rms: f64,
    pub beyond_2: f64,
}

impl NormalisedSpread {
    /// Share of N(0, 1) draws beyond +-2.
    pub const EXPECTED_BEYOND_2: f64 = 0.0455;

    pub fn of(res: &[FixResidual]) -> Self {
        let v: Vec<f64> = res
            .iter()
            .flat_map(|r| r.normalised)
            .filter(|x| x.is_finite())
            .collect();
        if v.is_empty() {
            return Self::default();
        }
        let n = v.len() as f64;
        Self {
            rms: (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
            beyond_2: v.iter().filter(|x| x.abs() > 2.0).count() as f64 / n,
        }
    }
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

    /// With independent fixes a normalised residual is the residual over the
    /// fix's sigma; under the noise the fit estimates from the ride the
    /// normalised residuals spread as N(0, 1) does, and under a GPS sigma
    /// set four times too tight they spread about four times wider.
    #[test]
    fn normalised_residuals_are_residuals_in_sigmas_of_the_noise_model() {
        let sig = Arc::new(crate::testing::simulated_signals(3, 600.0, &[]));
        let model = Model::new(sig.clone(), ModelSpec::default()).expect("model");
        let theta = model.initial_params();
        let res = fix_residuals(&model, &theta, &model.trajectory(&theta));
        let sigma = model.spec.sigma_horizontal_m;
        assert!(sig.fixes.iter().all(|f| f.hacc.is_none()));
        assert_eq!(model.spec.gps_tau_s, None);
        for r in &res {
            assert!((r.normalised[0] - r.along / sigma).abs() < 1e-9 * (1.0 + r.along.abs()));
            assert!((r.normalised[1] - r.cross / sigma).abs() < 1e-9 * (1.0 + r.cross.abs()));
        }
        let mut fit = Reconstruction::new(sig.clone(), FitSettings::default()).expect("fit");
        fit.finish();
        let spread =
            NormalisedSpread::of(&fix_residuals(fit.model(), fit.params(), &fit.trajectory()));
        eprintln!("estimated noise: {spread:?}");
        assert!((0.85..1.15).contains(&spread.rms), "{spread:?}");
        assert!((0.02..0.08).contains(&spread.beyond_2), "{spread:?}");
        let mut tight = FitSettings {
            auto_noise: crate::optimisation::AutoNoise::OFF,
            ..FitSettings::default()
        };
        tight.model.sigma_horizontal_m = 0.25 * fit.model().spec.sigma_horizontal_m;
        tight.model.gps_tau_s = fit.model().spec.gps_tau_s;
        let mut fit = Reconstruction::new(sig, tight).expect("fit");
        fit.finish();
        let spread =
            NormalisedSpread::of(&fix_residuals(fit.model(), fit.params(), &fit.trajectory()));
        eprintln!("sigma 4x too tight: {spread:?}");
        assert!(spread.rms > 2.5 && spread.beyond_2 > 0.3, "{spread:?}");
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
