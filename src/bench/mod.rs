//! Benchmarks behind `hitl bench`: each returns one JSON object of figures. The README's figures
//! come from these (with the command that produced them).

pub mod load;
pub mod loop_timing;
pub mod rtf;
