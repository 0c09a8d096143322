//! Filled in by the accumulation work.
