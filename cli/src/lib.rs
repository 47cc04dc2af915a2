//! Library part of `lrd` (exposed for fuzzing and tests): EXR frame I/O and
//! the quality metrics.
pub mod exrio;
pub mod inject;
pub mod metrics;
