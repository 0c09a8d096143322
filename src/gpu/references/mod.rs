//! The GPU references (docs/design.md §5): the brute force, exact visibility and its
//! importance-sampled estimator.

pub mod brute_force;
pub mod estimator;
pub mod exact;
pub(crate) mod rounds;
