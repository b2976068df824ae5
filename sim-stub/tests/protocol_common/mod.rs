//! A first-order test plant for the protocol tests (no physics engine): each joint follows its
//! target with a time constant, and a "wall" on one joint stands for the scene.

use hitl_hal::Joints;
use hitl_sim_stub::plant::{Collision, Plant};

pub struct LagPlant {
    q: Joints,
    qd: Joints,
    target: Joints,
    t: f64,
    tau: f64,
    /// Joint index and angle beyond which the arm touches the wall.
    pub wall: Option<(usize, f64)>,
}

impl LagPlant {
    pub fn new(wall: Option<(usize, f64)>) -> Self {
        Self { q: [0.0; 7], qd: [0.0; 7], target: [0.0; 7], t: 0.0, tau: 0.02, wall }
    }
}

impl Plant for LagPlant {
    fn joints(&self) -> Joints {
        self.q
    }
    fn velocities(&self) -> Joints {
        self.qd
    }
    fn command(&mut self, q: &Joints) {
        self.target = *q;
    }
    fn reset(&mut self, q: &Joints) {
        self.q = *q;
        self.target = *q;
        self.qd = [0.0; 7];
    }
    fn advance(&mut self, dt: f64) {
        let a = 1.0 - (-dt / self.tau).exp();
        for j in 0..7 {
            let mut next = self.q[j] + (self.target[j] - self.q[j]) * a;
            // The wall stops the joint.
            if let Some((wj, limit)) = self.wall {
                if wj == j && next > limit {
                    next = limit;
                }
            }
            self.qd[j] = (next - self.q[j]) / dt;
            self.q[j] = next;
        }
        self.t += dt;
    }
    fn time(&self) -> f64 {
        self.t
    }
    fn collision(&self) -> Option<Collision> {
        let (j, limit) = self.wall?;
        (self.q[j] >= limit - 1e-9)
            .then(|| Collision { arm_part: "link2".into(), other: "enclosure wall".into() })
    }
}
