//! A technique prepares its resources for a scene and records its own passes; a frame is the
//! ordered list of the techniques the scene and the request need (the renderer builds
//! it), each pass a stage of the frame's [`Recorder`]: a debug group and a timing span.
//!
//! The techniques (one folder each): the spot light's VALs and its direct light and the
//! RGB-D VALs (`lights/`), the camera's visibility buffer (`raster/`), the sparse method with
//! its visibility mode (`sparse/`, `visibility/`), and the references (`references/`).

use super::raster::VisibilityTarget;
use super::scene::GpuScene;
use super::timing::{Recorder, StageTimings};
use super::{Gpu, GpuError};
use glam::Mat4;

/// The VAL list every light technique appends to and every indirect technique reads.
pub struct Vals {
    /// `array<Val>`.
    pub buffer: wgpu::Buffer,
    /// One `u32`: how many VALs the frame's light techniques appended (readers clamp it to
    /// `capacity`).
    pub count: wgpu::Buffer,
    /// Elements `buffer` holds.
    pub capacity: u32,
}

/// The camera's images of one size: its visibility buffer and the two outputs.
pub struct CameraTarget {
    pub view: VisibilityTarget,
    /// `array<vec4<f32>>`, one per pixel: indirect radiance, alpha = coverage.
    pub indirect: wgpu::Buffer,
    /// `array<vec4<f32>>`, one per pixel: direct radiance, alpha = coverage.
    pub direct: wgpu::Buffer,
}

/// What every technique of one frame sees.
pub struct Frame<'a> {
    pub scene: &'a GpuScene,
    pub vals: &'a Vals,
    pub camera: &'a CameraTarget,
    /// World to the camera's clip space.
    pub camera_to_clip: Mat4,
    /// Whether the camera draws the scene's simplified copy (`GpuScene::camera_lod`, a frame of
    /// the sparse method that asks for it) instead of its own triangles.
    pub camera_lod: bool,
}

impl Frame<'_> {
    /// Group(1) with the triangles the camera draws and its visibility buffer names, and how
    /// many (`GpuScene::camera_triangles`). The camera's raster and every pass that decodes its
    /// visibility buffer (the sparse shade and near field, the direct light) bind this one.
    pub fn camera_triangles(&self) -> (&wgpu::BindGroup, u32) {
        self.scene.camera_triangles(self.camera_lod)
    }

    /// The vertices those triangles use and how many (`GpuScene::camera_vertices`): the
    /// per-vertex interpolation lights only these.
    pub fn camera_vertices(&self) -> (&wgpu::Buffer, u32) {
        self.scene.camera_vertices(self.camera_lod)
    }
}

/// One technique of a frame.
pub trait Technique {
    /// The stages it records, in order: their names in the frame's timings.
    fn stages(&self) -> Vec<&'static str>;

    /// Record its passes, each in a stage of `rec` named as [`Technique::stages`] says.
    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError>;

    /// Work that must follow the frame's submission (the exact reference's further rounds),
    /// its time added to `timings`; returns how many dispatches of the stage it took (0 when
    /// it has none).
    fn finish(&self, _gpu: &Gpu, _frame: &Frame<'_>, _timings: &mut StageTimings) -> Result<u32, GpuError> {
        Ok(0)
    }
}
