//! The virtual area light (VAL), the light every technique produces or consumes: a plain data
//! type at the bottom of the crate, so the data modules (e.g. `rgbd::accumulate`) and the CPU
//! twins share it without importing each other. `twin::Val` re-exports it.

use glam::Vec3;

/// One virtual area light: a Lambertian disc.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Val {
    pub position: Vec3,
    /// Unit normal; the disc emits into the half-space it faces.
    pub normal: Vec3,
    /// Disc area (m²).
    pub area: f32,
    /// Emitted flux (W, RGB).
    pub flux: Vec3,
}
