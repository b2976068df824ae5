//! Run `hitl_record::bench::bench_record` and print its figures (one JSON object).
//! usage: bench_record [SECONDS] [--keep FILE.mcap] [--max|--paced] [--compression none|lz4|zstd:N]
//!        [--threads N]

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let secs = args.get(1).and_then(|s| s.parse::<f64>().ok()).unwrap_or(5.0);
    let mut cfg = hitl_record::RecorderConfig::default();
    if let Some(i) = args.iter().position(|a| a == "--compression") {
        cfg.compression = match args.get(i + 1).map(|s| s.parse()) {
            Some(Ok(c)) => c,
            Some(Err(e)) => {
                eprintln!("{e}");
                std::process::exit(2);
            }
            None => {
                eprintln!("--compression needs none, lz4, zstd or zstd:LEVEL");
                std::process::exit(2);
            }
        };
    }
    if let Some(i) = args.iter().position(|a| a == "--threads") {
        cfg.compression_threads = args.get(i + 1).and_then(|s| s.parse().ok()).unwrap_or(0);
    }
    if args.iter().any(|a| a == "--max") || args.iter().any(|a| a == "--paced") {
        let opts = hitl_record::bench::BenchOptions {
            seconds: secs,
            max_rate: args.iter().any(|a| a == "--max"),
            config: cfg,
            ..Default::default()
        };
        match hitl_record::bench::run_bench(&opts) {
            Ok(v) => println!("{v}"),
            Err(e) => eprintln!("{e}"),
        }
        return;
    }
    if let Some(i) = args.iter().position(|a| a == "--keep") {
        let Some(path) = args.get(i + 1) else {
            eprintln!("--keep needs a file");
            std::process::exit(2);
        };
        let opts = hitl_record::bench::BenchOptions {
            seconds: secs,
            keep: Some(path.into()),
            config: cfg,
            ..Default::default()
        };
        match hitl_record::bench::run_bench(&opts) {
            Ok(v) => println!("{v}"),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
        return;
    }
    println!("{}", hitl_record::bench::bench_record(secs, cfg.compression));
}
