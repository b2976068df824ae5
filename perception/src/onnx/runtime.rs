//! Loading ONNX Runtime once per process (`ort` with `load-dynamic`).

use crate::PerceptionError;
use std::path::PathBuf;
use std::sync::OnceLock;

/// The shared library to load: `ORT_DYLIB_PATH` if set, else the one `make setup` put in
/// `.deps/lib` (the path is fixed at build time).
pub fn dylib_path() -> PathBuf {
    match std::env::var_os("ORT_DYLIB_PATH") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => PathBuf::from(concat!(env!("HITL_DEPS_LIB"), "/libonnxruntime.so")),
    }
}

static ENV: OnceLock<Result<ort::environment::Environment, String>> = OnceLock::new();

/// The process's ONNX Runtime environment (ORT allows one), created on first use.
pub fn environment() -> Result<ort::environment::Environment, PerceptionError> {
    ENV.get_or_init(|| {
        let path = dylib_path();
        if !path.exists() {
            return Err(format!(
                "{} not found (run make setup, or set ORT_DYLIB_PATH)",
                path.display()
            ));
        }
        ort::init_from(&path)
            .map_err(|e| format!("cannot load {}: {e}", path.display()))?
            .with_name("hitl")
            .build()
            .map_err(|e| format!("cannot start ONNX Runtime: {e}"))
    })
    .clone()
    .map_err(PerceptionError::OnnxRuntime)
}
