//! RGB-D frame to VALs (`shaders/rgbd.wgsl`, DESIGN.md §2 "RGB-D frames"): a depth + colour
//! frame becomes at most one VAL per `grid_step`-pixel cell, appended to a VAL buffer after
//! whatever is already there (the RSM's spot-light VALs). Rust twin:
//! `reference::rgbd::rgbd_vals`, whose module docs state the rules.
//!
//! Two dispatches, one thread per grid cell: `filter_grid` (bilateral depth at each cell's
//! centre pixel into `rgbd.grid_depth`), then `main` (position, normal from the neighbouring
//! cells, footprint area, flux; `atomicAdd` append).

use super::kernel::{self, Kernel, Slot, groups};
use super::raw::RawVal;
use super::scene::GpuScene;
use super::timing::Span;
use super::{Gpu, GpuError};
use crate::reference::rgbd::{MIN_FOOTPRINT_COSINE, grid_size};
use crate::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, UVec2};

pub const WGSL: &str = include_str!("../../shaders/rgbd.wgsl");

/// The pass's full WGSL: its constants from Rust, then `shaders/rgbd.wgsl`.
pub fn source() -> String {
    format!("const MIN_FOOTPRINT_COSINE: f32 = {MIN_FOOTPRINT_COSINE:e};\n{WGSL}")
}

/// WGSL `Intrinsics`: the domain struct is laid out for the GPU already.
pub type RawIntrinsics = Intrinsics;

/// WGSL `RgbdSettings`: the domain struct is laid out for the GPU already.
pub type RawRgbdSettings = RgbdSettings;

/// WGSL `RgbdParams`: one frame's constants.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct RawRgbdParams {
    /// Camera-to-world in optical axes, column-major.
    pub camera_to_world: [[f32; 4]; 4],
    pub intrinsics: RawIntrinsics,
    pub settings: RawRgbdSettings,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

impl RawRgbdParams {
    pub fn new(intrinsics: &Intrinsics, settings: &RgbdSettings, camera_to_world: &glam::Affine3A) -> Self {
        Self {
            camera_to_world: Mat4::from(*camera_to_world).to_cols_array_2d(),
            intrinsics: *intrinsics,
            settings: *settings,
            ..bytemuck::Zeroable::zeroed()
        }
    }
}

/// The RGB-D VAL pass for frames of one size: owns the frame's buffers on the GPU.
pub struct RgbdVals {
    filter: Kernel,
    append: Kernel,
    intrinsics: Intrinsics,
    settings: RgbdSettings,
    grid: UVec2,
    params: wgpu::Buffer,
    depth: wgpu::Buffer,
    color: wgpu::Buffer,
    grid_depth: wgpu::Buffer,
    filter_group: wgpu::BindGroup,
    scene_group: wgpu::BindGroup,
}

impl RgbdVals {
    /// The pass for frames of `intrinsics`' size, made into VALs with `settings`. The scene only
    /// provides the bind group every pass has at group(1).
    pub fn new(gpu: &Gpu, scene: &GpuScene, intrinsics: Intrinsics, settings: &RgbdSettings) -> Result<Self, GpuError> {
        let module = kernel::module(gpu, scene, "rgbd", &source())?;
        let filter_slots = [Slot::Storage, Slot::Storage, Slot::StorageReadWrite];
        let filter = Kernel::new(gpu, &scene.layout, &module, "rgbd.filter_grid", "filter_grid", &filter_slots)?;
        let append_slots = [
            Slot::Storage,
            Slot::Storage,
            Slot::StorageReadWrite,
            Slot::Storage,
            Slot::StorageReadWrite,
            Slot::StorageReadWrite,
        ];
        let append = Kernel::new(gpu, &scene.layout, &module, "rgbd.main", "main", &append_slots)?;
        let pixels = intrinsics.width as usize * intrinsics.height as usize;
        let grid = grid_size(&intrinsics, settings);
        let params = RawRgbdParams::new(&intrinsics, settings, &glam::Affine3A::IDENTITY);
        let params = gpu.storage_buffer("rgbd.params", &[params], wgpu::BufferUsages::empty())?;
        let depth = gpu.storage_buffer_sized::<f32>("rgbd.depth", pixels)?;
        let color = gpu.storage_buffer_sized::<u32>("rgbd.color", pixels)?;
        let grid_depth = gpu.storage_buffer_sized::<f32>("rgbd.grid_depth", (grid.x * grid.y) as usize)?;
        let filter_group =
            filter.bind(gpu, &[params.as_entire_binding(), depth.as_entire_binding(), grid_depth.as_entire_binding()]);
        Ok(Self {
            filter,
            append,
            intrinsics,
            settings: *settings,
            grid,
            params,
            depth,
            color,
            grid_depth,
            filter_group,
            scene_group: scene.bind_group.clone(),
        })
    }

    /// VALs one frame can make at most: the grid's cell count.
    pub fn max_vals(&self) -> u32 {
        self.grid.x * self.grid.y
    }

    /// Write `frame` (its depth, colour, pose and intrinsics) for the next [`Self::record`].
    /// Refuses a frame whose size differs from the pass's.
    pub fn upload(&self, gpu: &Gpu, frame: &RgbdFrame) -> Result<(), GpuError> {
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let f = &frame.intrinsics;
        if (f.width, f.height) != (w, h) {
            return Err(GpuError::FrameMismatch(format!(
                "the RGB-D pass takes {w}x{h} frames, this one is {}x{}",
                f.width, f.height
            )));
        }
        let pixels = w as usize * h as usize;
        if frame.depth.len() != pixels || frame.color.len() != pixels {
            return Err(GpuError::FrameMismatch(format!(
                "a {w}x{h} frame needs {pixels} depth and colour pixels, got {} and {}",
                frame.depth.len(),
                frame.color.len()
            )));
        }
        if pixels > 0 {
            let color: Vec<u32> = frame.color.iter().map(|c| u32::from_le_bytes([c[0], c[1], c[2], 255])).collect();
            gpu.queue.write_buffer(&self.depth, 0, bytemuck::cast_slice(&frame.depth));
            gpu.queue.write_buffer(&self.color, 0, bytemuck::cast_slice(&color));
        }
        let params = RawRgbdParams::new(f, &self.settings, &frame.camera_to_world);
        gpu.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        Ok(())
    }

    /// Append the uploaded frame's VALs to `vals` (`array<Val>`) after the `val_count` (one
    /// `u32`) already there, never past `capacity` elements (nor past the buffer's end): VALs
    /// beyond it are dropped and `val_count` ends at `min(val_count + made, capacity)`. Does not
    /// clear `val_count`.
    pub fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        vals: &wgpu::Buffer,
        val_count: &wgpu::Buffer,
        capacity: u32,
        span: Option<Span<'_>>,
    ) {
        let stride = std::mem::size_of::<RawVal>() as u64;
        let capacity = (capacity as u64).min(vals.size() / stride);
        let workgroups = [groups(self.grid.x, 8), groups(self.grid.y, 8), 1];
        let writes = span.as_ref().map(Span::compute);
        if capacity == 0 {
            // Nothing can be appended (and an empty binding is not allowed): the filter alone
            // carries the span.
            self.filter.dispatch(encoder, &self.filter_group, &self.scene_group, workgroups, writes);
            return;
        }
        let (first, second) = match writes {
            Some(w) => (
                Some(wgpu::ComputePassTimestampWrites { end_of_pass_write_index: None, ..w.clone() }),
                Some(wgpu::ComputePassTimestampWrites { beginning_of_pass_write_index: None, ..w }),
            ),
            None => (None, None),
        };
        self.filter.dispatch(encoder, &self.filter_group, &self.scene_group, workgroups, first);
        let group = self.append.bind(
            gpu,
            &[
                self.params.as_entire_binding(),
                self.depth.as_entire_binding(),
                self.grid_depth.as_entire_binding(),
                self.color.as_entire_binding(),
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: vals,
                    offset: 0,
                    size: wgpu::BufferSize::new(capacity * stride),
                }),
                val_count.as_entire_binding(),
            ],
        );
        self.append.dispatch(encoder, &group, &self.scene_group, workgroups, second);
    }
}
