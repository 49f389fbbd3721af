use std::sync::Arc;
use gyropath::{loading, signals::Signals, model::{Model, ModelSpec}, optimisation::FitStats};
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let sig = Arc::new(Signals::from_log(&loading::load(path).unwrap()).unwrap());
    let m = Model::new(sig.clone(), ModelSpec::default()).unwrap();
    let s = &m.start;
    let f = s.attitude * nalgebra::Vector3::x();
    println!("heading(ENU, deg from east) {:.2}, bias {:?} dps, gain {:.4}, pos {:?}, baro {:.2}", f.y.atan2(f.x).to_degrees(), s.gyro_bias.map(f64::to_degrees), s.odometer_gain, s.position, s.baro_offset);
    let th = m.initial_params();
    println!("{:?}", FitStats::of(&m, &th));
    let tr = m.trajectory(&th);
    for fx in sig.fixes.iter().step_by(60).take(12) {
        println!("t {:7.1} fix {:9.1} {:9.1}  path {:9.1} {:9.1}", fx.t, fx.en[0], fx.en[1], tr.p[fx.row].x, tr.p[fx.row].y);
    }
}
