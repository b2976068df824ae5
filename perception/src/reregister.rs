//! When a backend is sent back to global registration, decided in one place for the live worker
//! and for offline re-runs (`hitl eval --backend`), so both treat the same frames the same way.
//!
//! A backend registers globally on its first frame and whenever it loses track (its own failure
//! detection). [`Reregistering`] additionally resets it after a `Lost` estimate, before every
//! `every_n_frames`-th frame, and after an estimate whose fit residual passes `max_residual_m`
//! (the drift signal: the paper saw tracking drift after 10-15 s and re-registration help).

use crate::estimator::{Estimate, PoseEstimator};
use crate::{PerceptionError, PerceptionFrame};
use std::fmt;

/// Key of the `run` metadata record that holds a live run's policy (JSON), so that an offline
/// re-run of the recording repeats it.
pub const METADATA_KEY: &str = "perception_reregister";

/// When to force a fresh global registration beyond the backend's own.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct ReregisterPolicy {
    /// Reset the tracker before every N-th frame handed to it (None: never).
    pub every_n_frames: Option<u64>,
    /// Reset the tracker after an estimate whose fit residual exceeds this many metres of the
    /// scene the camera sees (lab metres; None: never).
    pub max_residual_m: Option<f64>,
}

/// Why a policy was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolicyError {
    #[error("re-registration every {0} frames: N must be at least 1")]
    ZeroFrames(u64),
    #[error("re-registration residual {0} m: it must be a finite number above 0")]
    BadResidual(f64),
}

impl ReregisterPolicy {
    /// A policy from its two options, each checked (N >= 1; a finite residual > 0).
    pub fn new(
        every_n_frames: Option<u64>,
        max_residual_m: Option<f64>,
    ) -> Result<Self, PolicyError> {
        if let Some(n) = every_n_frames.filter(|&n| n == 0) {
            return Err(PolicyError::ZeroFrames(n));
        }
        if let Some(r) = max_residual_m.filter(|r| !(r.is_finite() && *r > 0.0)) {
            return Err(PolicyError::BadResidual(r));
        }
        Ok(ReregisterPolicy { every_n_frames, max_residual_m })
    }

    /// Whether the frame about to be handed over (0-based count `handed`) starts afresh.
    fn due_before(&self, handed: u64) -> bool {
        self.every_n_frames.is_some_and(|n| n > 0 && handed > 0 && handed.is_multiple_of(n))
    }

    /// Whether this estimate ends the track: lost, or a residual past the drift limit.
    fn due_after(&self, e: &Estimate) -> bool {
        let drift =
            self.max_residual_m.is_some_and(|m| e.residual_m.is_finite() && e.residual_m > m);
        e.pose.is_none() || drift
    }
}

impl fmt::Display for ReregisterPolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("on the first frame and after a lost one")?;
        if let Some(n) = self.every_n_frames {
            write!(f, ", every {n} frames")?;
        }
        if let Some(r) = self.max_residual_m {
            write!(f, ", after a residual above {r} m")?;
        }
        Ok(())
    }
}

/// A backend driven by a [`ReregisterPolicy`].
pub struct Reregistering {
    estimator: Box<dyn PoseEstimator>,
    policy: ReregisterPolicy,
    handed: u64,
}

impl Reregistering {
    pub fn new(estimator: Box<dyn PoseEstimator>, policy: ReregisterPolicy) -> Self {
        Reregistering { estimator, policy, handed: 0 }
    }

    /// The backend's name.
    pub fn name(&self) -> String {
        self.estimator.name()
    }

    /// Estimates one frame, resetting the backend before or after it as the policy says.
    /// Returns the estimate and how many resets it forced (0, 1 or 2).
    pub fn estimate(
        &mut self,
        frame: &PerceptionFrame,
    ) -> (Result<Estimate, PerceptionError>, u32) {
        let mut resets = 0;
        if self.policy.due_before(self.handed) {
            self.estimator.reset();
            resets += 1;
        }
        self.handed += 1;
        let result = self.estimator.estimate(frame);
        if result.as_ref().is_ok_and(|e| self.policy.due_after(e)) {
            self.estimator.reset();
            resets += 1;
        }
        (result, resets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimator::EstimateKind;
    use hitl_hal::Intrinsics;
    use hitl_hal::Pose;
    use std::sync::{Arc, Mutex};

    /// Answers from a script of (residual, lost) per frame and logs every call.
    struct Scripted {
        script: Vec<(f64, bool)>,
        log: Arc<Mutex<Vec<String>>>,
    }

    impl PoseEstimator for Scripted {
        fn name(&self) -> String {
            "scripted".into()
        }
        fn estimate(&mut self, f: &PerceptionFrame) -> Result<Estimate, PerceptionError> {
            self.log.lock().expect("log").push(format!("e{}", f.seq));
            let (residual_m, lost) = self.script[f.seq as usize];
            Ok(if lost {
                Estimate::lost()
            } else {
                Estimate { pose: Some(Pose::identity()), kind: EstimateKind::Tracked, residual_m }
            })
        }
        fn reset(&mut self) {
            self.log.lock().expect("log").push("reset".into());
        }
    }

    fn frame(seq: u64) -> PerceptionFrame {
        PerceptionFrame {
            timestamp_ns: seq,
            seq,
            intrinsics: Intrinsics::pinhole(1, 1, 1.0, 1.0, 0.0, 0.0),
            color: vec![].into(),
            depth_m: vec![1.0].into(),
            mask: None,
        }
    }

    fn run(policy: ReregisterPolicy, script: Vec<(f64, bool)>) -> (Vec<String>, u32) {
        let log = Arc::new(Mutex::new(Vec::new()));
        let n = script.len() as u64;
        let mut driven =
            Reregistering::new(Box::new(Scripted { script, log: log.clone() }), policy);
        let resets = (0..n).map(|s| driven.estimate(&frame(s)).1).sum();
        let calls = log.lock().map(|l| l.clone()).unwrap_or_default();
        (calls, resets)
    }

    #[test]
    fn every_n_frames_resets_before_frames_n_and_2n() {
        let policy = ReregisterPolicy::new(Some(2), None).expect("valid");
        let (calls, resets) = run(policy, vec![(0.001, false); 5]);
        assert_eq!(calls, ["e0", "e1", "reset", "e2", "e3", "reset", "e4"]);
        assert_eq!(resets, 2);
    }

    #[test]
    fn a_lost_frame_and_a_residual_past_the_limit_reset_after_the_frame() {
        let policy = ReregisterPolicy::new(None, Some(0.002)).expect("valid");
        // A residual at the limit is kept; above it, or lost (NaN residual), resets.
        let script = vec![(0.002, false), (0.0021, false), (f64::NAN, true), (0.001, false)];
        let (calls, resets) = run(policy, script);
        assert_eq!(calls, ["e0", "e1", "reset", "e2", "reset", "e3"]);
        assert_eq!(resets, 2);
    }

    #[test]
    fn the_default_policy_resets_only_after_a_lost_frame() {
        let script = vec![(9.0, false), (f64::NAN, true), (9.0, false)];
        let (calls, resets) = run(ReregisterPolicy::default(), script);
        assert_eq!(calls, ["e0", "e1", "reset", "e2"]);
        assert_eq!(resets, 1);
    }

    #[test]
    fn bad_options_are_refused_with_the_value() {
        assert_eq!(ReregisterPolicy::new(Some(0), None), Err(PolicyError::ZeroFrames(0)));
        for r in [0.0, -1.0, f64::INFINITY] {
            let e = ReregisterPolicy::new(None, Some(r)).expect_err("refused");
            assert!(e.to_string().contains(&format!("{r}")), "{e}");
        }
        assert!(ReregisterPolicy::new(None, Some(f64::NAN)).is_err());
        let p = ReregisterPolicy::new(Some(30), Some(0.004)).expect("valid");
        assert_eq!(
            p.to_string(),
            "on the first frame and after a lost one, every 30 frames, after a residual above 0.004 m"
        );
    }
}
