//! The re-registration flags shared by `hitl run` (the live perception worker) and
//! `hitl eval --backend` (an offline re-run).

use hitl_perception::{PolicyError, ReregisterPolicy};

/// When the pose estimator goes back to global registration, beyond the first frame and a lost
/// track (docs/perception.md).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ReregisterArgs {
    /// Re-register the pose estimator before every N-th frame (N >= 1). Off by default.
    #[arg(long, value_name = "N")]
    pub reregister_every: Option<u64>,
    /// Re-register after an estimate whose fit residual is above M metres of the lab scene
    /// (ICP: RMS point-to-plane distance of its inliers), a drift signal. Off by default.
    #[arg(long, value_name = "M", allow_negative_numbers = true)]
    pub reregister_residual_m: Option<f64>,
}

impl ReregisterArgs {
    /// Whether either flag was given.
    pub fn given(&self) -> bool {
        self.reregister_every.is_some() || self.reregister_residual_m.is_some()
    }

    /// The policy the flags ask for, checked.
    pub fn policy(&self) -> Result<ReregisterPolicy, PolicyError> {
        ReregisterPolicy::new(self.reregister_every, self.reregister_residual_m)
    }
}
