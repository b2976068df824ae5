//! Prints the perception benchmarks as JSON until `hitl bench` wires them in:
//! `cargo run --release -p hitl-perception --example perception_bench [W H FRAMES]`.

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    let (w, h, n) = match a.as_slice() {
        [w, h, n] => (*w as u32, *h as u32, *n),
        _ => (320, 256, 60),
    };
    println!("{}", hitl_perception::bench::bench_tracker(w, h, n));
    println!("{}", hitl_perception::bench::bench_accuracy(&[5.0, 10.0, 25.0, 50.0], w, h, n, 0.5));
}
