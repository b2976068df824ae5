//! Calibration of the testbed (`hitl calibrate`): the AprilGrid board and its drawing
//! ([`board`]), its detection through the AprilTag C library ([`detect`], [`family`]), the robot-world-hand-eye
//! solver with its refinement and uncertainties ([`solve`]), and the views the arm takes of the
//! board ([`views`]).

pub mod board;
pub mod detect;
pub mod family;
pub mod solve;
pub mod views;

pub use board::{Board, BoardError};
pub use detect::{detect, Corner, Detection};
pub use solve::{solve, Acceptance, Solution, SolveError, View};
