//! The benchmarks' load: one busy thread per core while a measurement runs, half streaming
//! through a frame-sized buffer (as the recorder does), half doing dense floating point (as
//! perception does). One definition, so every "under load" figure in the README means the same.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Run `f` with every core busy (when `load`), and stop the busy threads when it returns.
pub fn under_load<T>(load: bool, f: impl FnOnce() -> T) -> T {
    if !load {
        return f();
    }
    let stop = Arc::new(AtomicBool::new(false));
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let threads: Vec<_> = (0..cores)
        .map(|i| {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || {
                let mut buf = vec![0u8; 8 << 20];
                let mut x = 1.0f64;
                while !stop.load(Ordering::Relaxed) {
                    if i % 2 == 0 {
                        // Recorder-like: stream through a frame-sized buffer.
                        for (k, b) in buf.iter_mut().enumerate() {
                            *b = b.wrapping_mul(31).wrapping_add(k as u8);
                        }
                    } else {
                        // Perception-like: dense floating point.
                        for k in 0..200_000 {
                            x = (x * 1.000001 + f64::from(k)).sqrt();
                        }
                    }
                    std::hint::black_box((&buf, x));
                }
            })
        })
        .collect();
    let out = f();
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        let _ = t.join();
    }
    out
}
