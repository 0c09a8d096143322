//! `#[repr(C)]` twins of the structs in `shader/common.wgsl`. A test parses the WGSL with naga
//! and checks every size and field offset against these.

use crate::twin;
use bytemuck::{Pod, Zeroable};

/// WGSL `Val`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawVal {
    pub position: [f32; 3],
    pub area: f32,
    pub normal: [f32; 3],
    pub _pad0: f32,
    pub flux: [f32; 3],
    pub _pad1: f32,
}

impl From<&twin::Val> for RawVal {
    fn from(v: &twin::Val) -> Self {
        Self {
            position: v.position.into(),
            area: v.area,
            normal: v.normal.into(),
            _pad0: 0.0,
            flux: v.flux.into(),
            _pad1: 0.0,
        }
    }
}

impl From<&RawVal> for twin::Val {
    fn from(v: &RawVal) -> Self {
        Self { position: v.position.into(), normal: v.normal.into(), area: v.area, flux: v.flux.into() }
    }
}

/// WGSL `Vertex` (world space).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawVertex {
    pub position: [f32; 3],
    /// Texture coordinate s (left to right).
    pub s: f32,
    pub normal: [f32; 3],
    /// Texture coordinate t (top to bottom: OBJ's `1 - v`).
    pub t: f32,
}

/// WGSL `Material`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawMaterial {
    pub diffuse: [f32; 3],
    pub exponent: f32,
    pub specular: [f32; 3],
    /// Layer of the scene's texture array, or -1.
    pub diffuse_texture: i32,
}

/// WGSL `SparsePoint` (world space).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawSparsePoint {
    pub position: [f32; 3],
    pub occluder_radius: f32,
    pub normal: [f32; 3],
    pub exponent: f32,
    /// The unit face normal of its triangle, on the side of `normal` (`twin::oriented_face_normal`):
    /// the normal its shadow rays leave along (docs/design.md §3).
    pub geometric: [f32; 3],
    pub pad: f32,
}

/// WGSL `Gathered`: one lobe's gathered irradiance (W/m²) and averaged position (m).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawGathered {
    pub irradiance: [f32; 3],
    /// Sum of the weights behind `position`, kept so VAL ranges gathered apart can merge.
    pub weight: f32,
    pub position: [f32; 3],
    pub _pad1: f32,
    /// Weighted mean of the squared VAL positions, per axis (m²).
    pub second_moment: [f32; 3],
    pub _pad2: f32,
}

/// WGSL `PointLight`: position (m), intensity (W/sr) and bound (W/m², 0 = unbounded).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawPointLight {
    pub position: [f32; 3],
    pub _pad0: f32,
    pub intensity: [f32; 3],
    pub bound: f32,
}

impl From<&RawPointLight> for twin::PointLight {
    fn from(p: &RawPointLight) -> Self {
        Self { position: p.position.into(), intensity: p.intensity.into(), bound: p.bound }
    }
}

impl From<&twin::PointLight> for RawPointLight {
    fn from(p: &twin::PointLight) -> Self {
        Self { position: p.position.into(), _pad0: 0.0, intensity: p.intensity.into(), bound: p.bound }
    }
}

/// WGSL `Frame`: per-frame constants shared by every pass.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RawFrame {
    pub world_to_clip: [[f32; 4]; 4],
    pub light_world_to_clip: [[f32; 4]; 4],
    pub eye: [f32; 3],
    pub width: u32,
    pub light_position: [f32; 3],
    pub height: u32,
    pub light_direction: [f32; 3],
    pub rsm_resolution: u32,
    pub light_intensity: [f32; 3],
    pub light_inner_angle: f32,
    pub light_outer_angle: f32,
    pub sparse_count: u32,
    pub vertex_count: u32,
    pub triangle_count: u32,
}
