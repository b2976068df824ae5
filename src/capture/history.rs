//! Arm states kept by receive time, so a frame's exposure can be matched to where the arm was.

use hitl_hal::{ArmState, Joints};
use std::collections::VecDeque;

/// The most recent arm states, oldest first.
#[derive(Debug)]
pub struct StateHistory {
    states: VecDeque<ArmState>,
    capacity: usize,
}

impl StateHistory {
    pub fn new(capacity: usize) -> Self {
        Self { states: VecDeque::with_capacity(capacity), capacity: capacity.max(2) }
    }

    pub fn push(&mut self, state: ArmState) {
        if self.states.back().is_some_and(|last| state.received_ns <= last.received_ns) {
            return;
        }
        if self.states.len() == self.capacity {
            self.states.pop_front();
        }
        self.states.push_back(state);
    }

    /// Joints at `t_ns`, linearly interpolated between the two reports around it; the nearest
    /// report when `t_ns` is outside the history; `None` when it is empty.
    pub fn joints_at(&self, t_ns: u64) -> Option<Joints> {
        let after = self.states.iter().position(|s| s.received_ns >= t_ns);
        match after {
            None => self.states.back().map(|s| s.q),
            Some(0) => self.states.front().map(|s| s.q),
            Some(i) => {
                let (a, b) = (&self.states[i - 1], &self.states[i]);
                let span = (b.received_ns - a.received_ns) as f64;
                let w = (t_ns - a.received_ns) as f64 / span;
                Some(std::array::from_fn(|j| a.q[j] + w * (b.q[j] - a.q[j])))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(t: u64, q0: f64) -> ArmState {
        let mut s = ArmState { received_ns: t, ..Default::default() };
        s.q[0] = q0;
        s
    }

    #[test]
    fn interpolates_between_reports_and_clamps_outside() {
        let mut h = StateHistory::new(3);
        assert_eq!(h.joints_at(5), None);
        h.push(state(10, 0.0));
        h.push(state(20, 1.0));
        h.push(state(20, 9.0)); // not newer: ignored
        assert_eq!(h.joints_at(15).map(|q| q[0]), Some(0.5));
        assert_eq!(h.joints_at(5).map(|q| q[0]), Some(0.0));
        assert_eq!(h.joints_at(25).map(|q| q[0]), Some(1.0));
        h.push(state(30, 2.0));
        h.push(state(40, 3.0)); // drops the oldest
        assert_eq!(h.joints_at(10).map(|q| q[0]), Some(1.0));
    }
}
