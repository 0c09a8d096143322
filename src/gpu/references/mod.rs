//! The GPU references (docs/design.md §5): the brute force and exact visibility.

pub mod brute_force;
pub mod exact;
