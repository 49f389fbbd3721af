use nalgebra::DMatrix;
fn main() {
    for n in [731usize, 1090] {
        let j = DMatrix::<f64>::from_fn(n + 50, n, |i, k| ((i * 7 + k * 13) % 17) as f64 + if i == k { 10.0 } else { 0.0 });
        let a = j.transpose() * &j;
        let t = std::time::Instant::now();
        let c = a.clone().cholesky().unwrap();
        println!("n {n}: nalgebra cholesky {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
        let _ = c;
    }
}
