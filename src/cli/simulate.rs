//! `gyropath simulate`: a simulated ride, its true path and parameters.

use super::*;

#[derive(Debug, Args)]
pub struct SimulateArgs {
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Ride length (s).
    #[arg(long, default_value_t = 600.0)]
    pub duration: f64,
    /// Logging rate (Hz).
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// Hidden effects, comma separated: gyro_scale, gps_lag, mount_misalignment, gyro_bias_channel:temp_c, gps_outliers, speed_lag (with --gnss-speed).
    #[arg(long, default_value = "")]
    pub hidden: String,
    /// Log cumulative distance (odo_m) instead of wheel pulses.
    #[arg(long)]
    pub odometer: bool,
    /// No GPS outages.
    #[arg(long)]
    pub no_outages: bool,
    /// What drives: bicycle (wheel pulses), car (8-20 m/s, lane changes, reversing
    /// out of a parking bay; wheel speed) or robot (0.5-1 m/s, skid-steer shaking, 2.5 Hz GPS).
    #[arg(long, default_value = "bicycle")]
    pub vehicle: String,
    /// Log only the yaw rate (gx_dps and gy_dps written as 0), as a car's yaw-rate sensor.
    #[arg(long)]
    pub yaw_only: bool,
    /// Write the gyro in other axes or units: the mounting that undoes it, e.g.
    /// "x=-z,y=-x,z=y" or "x=y,y=-x,z=z,scale=57.29577951308232" (rad/s).
    #[arg(long)]
    pub gyro_axes: Option<String>,
    /// GPS environment: open sky; urban (street canyons, heavy tails, fixes pulled
    /// to one side, jumps of 10-70 m; logs gps_hacc_m and gps_num_sats); or city
    /// (reflections of 10-75 m that come and go within seconds over a broad
    /// error, a fix in about 55 % of the seconds: calibrated on a real city drive).
    #[arg(long, default_value = "open")]
    pub gps: String,
    /// The gyro bias's random-walk density (deg/s/sqrt(s)); drawn in 0.002-0.004 when not given.
    #[arg(long)]
    pub bias_walk: Option<f64>,
    /// Log the GNSS receiver's ground speed with every fix (gps_speed_mps), the
    /// distance of a ride without a wheel sensor (fit it with --distance gnss).
    #[arg(long)]
    pub gnss_speed: bool,
    /// Where to write the ride log.
    #[arg(long)]
    pub out: PathBuf,
    /// Where to write the true path (t_s,lat_deg,lon_deg,alt_m).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Where to write the true parameters (JSON).
    #[arg(long)]
    pub truth_params: Option<PathBuf>,
}

pub fn simulate(args: &SimulateArgs) -> Result<()> {
    let config = SimConfig {
        seed: args.seed,
        duration_s: args.duration,
        rate_hz: args.rate,
        hidden: split_list(&args.hidden),
        odometer: args.odometer,
        outages: !args.no_outages,
        vehicle: args
            .vehicle
            .parse()
            .map_err(|e| anyhow::anyhow!("--vehicle: {e}"))?,
        yaw_only: args.yaw_only,
        gyro_axes: args
            .gyro_axes
            .as_deref()
            .map(str::parse)
            .transpose()
            .map_err(|e| anyhow::anyhow!("--gyro-axes: {e}"))?,
        gps: args
            .gps
            .parse()
            .map_err(|e| anyhow::anyhow!("--gps: {e}"))?,
        bias_walk_dps_sqrt_s: args.bias_walk,
        gnss_speed: args.gnss_speed,
    };
    let ride = simulation::simulate(&config)?;
    write_atomically(&args.out, None, |w| w.write_all(ride.log_csv.as_bytes()))?;
    if let Some(t) = &args.truth {
        write_atomically(t, None, |w| w.write_all(ride.truth_csv.as_bytes()))?;
    }
    if let Some(t) = &args.truth_params {
        write_atomically(t, None, |w| write_json(w, &ride.truth))?;
    }
    eprintln!(
        "wrote {} ({:.0} s, {:.0} m, hidden: {})",
        args.out.display(),
        ride.truth.duration_s,
        ride.truth.distance_m,
        if config.hidden.is_empty() {
            "none".into()
        } else {
            config.hidden.join(", ")
        }
    );
    Ok(())
}
