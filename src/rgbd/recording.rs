//! Filled in by the recording work.
