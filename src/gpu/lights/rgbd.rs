//! RGB-D frame to VALs (`rgbd.wgsl`, docs/design.md §2 "RGB-D frames"): a depth + colour
//! frame becomes at most one VAL per `grid_step`-pixel cell, appended to a VAL buffer after
//! whatever is already there (the RSM's spot-light VALs). Rust twin:
//! `twin::rgbd::rgbd_vals`, whose module docs state the rules.
//!
//! Three dispatches: `filter_grid` (one thread per grid cell: bilateral depth at each cell's
//! centre pixel into `rgbd.grid_depth`), `main` (one thread per cell: position, normal from the
//! neighbouring cells, footprint area, flux, into the cell's slot of `rgbd.candidates`), then
//! `compact` (one workgroup, `compact_vals.wgsl`: the cells' VALs appended in the twin's cell
//! order, so that a frame's VALs are the same from run to run, order included).

use super::compact::{self, Compact};
use crate::gpu::pass::{Entry, Kernel, PassDesc, Res, buffer, module_from_source, read, read_write};
use crate::gpu::raw::RawVal;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::technique::{Frame, Technique, Vals};
use crate::gpu::timing::{Recorder, Span};
use crate::gpu::{Gpu, GpuError};
use crate::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use crate::twin::rgbd::{MIN_FOOTPRINT_COSINE, grid_size};
use bytemuck::{Pod, Zeroable};
use glam::{Mat4, UVec2};

pub const WGSL: &str = include_str!("rgbd.wgsl");

/// The pass's own WGSL: its constants from Rust, then `rgbd.wgsl` and `compact_vals.wgsl`.
pub fn body() -> String {
    Wgsl::new().f32("MIN_FOOTPRINT_COSINE", MIN_FOOTPRINT_COSINE).include(WGSL).include(compact::WGSL).finish()
}

/// `filter_grid` takes the first three bindings; `main` the frame and the filtered
/// `grid_depth`, writing `candidates`; `compact` the candidates and the VALs.
pub const PASS: PassDesc = PassDesc {
    label: "rgbd",
    bindings: &[
        read("params"),
        read("depth"),
        read_write("grid_depth"),
        read("color"),
        read_write("vals"),
        read_write("val_count"),
        read_write("candidates"),
    ],
    entries: &[
        Entry::first("filter_grid", 3),
        Entry { name: "main", bindings: 7, except: &["depth", "vals", "val_count"] },
        Entry { name: "compact", bindings: 7, except: &["params", "depth", "grid_depth", "color"] },
    ],
    workgroup: crate::gpu::shader::IMAGE_TILE,
    default_source: |textured| PASS.source(&body(), textured),
};

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
    compact: Compact,
    intrinsics: Intrinsics,
    settings: RgbdSettings,
    grid: UVec2,
    params: wgpu::Buffer,
    depth: wgpu::Buffer,
    color: wgpu::Buffer,
    filter_group: wgpu::BindGroup,
    append_group: wgpu::BindGroup,
}

impl RgbdVals {
    /// The pass for frames of `intrinsics`' size, made into VALs with `settings`. The scene only
    /// provides the bind group every pass has at group(1).
    pub fn new(gpu: &Gpu, scene: &GpuScene, intrinsics: Intrinsics, settings: &RgbdSettings) -> Result<Self, GpuError> {
        let module = module_from_source(gpu, PASS.label, PASS.source(&body(), scene.textured()))?;
        let filter = Kernel::build(gpu, scene, &PASS, &module, PASS.entry("filter_grid"), &[], PASS.workgroup)?;
        let append = Kernel::build(gpu, scene, &PASS, &module, PASS.entry("main"), &[], PASS.workgroup)?;
        let pixels = intrinsics.width as usize * intrinsics.height as usize;
        let grid = grid_size(&intrinsics, settings);
        let params = RawRgbdParams::new(&intrinsics, settings, &glam::Affine3A::IDENTITY);
        let params = gpu.storage_buffer("rgbd.params", &[params], wgpu::BufferUsages::empty())?;
        let depth = gpu.storage_buffer_sized::<f32>("rgbd.depth", pixels)?;
        let color = gpu.storage_buffer_sized::<u32>("rgbd.color", pixels)?;
        let grid_depth = gpu.storage_buffer_sized::<f32>("rgbd.grid_depth", (grid.x * grid.y) as usize)?;
        let compact = Compact::new(gpu, scene, &PASS, &module, grid.x * grid.y)?;
        let filter_group =
            filter.bind(gpu, &[buffer("params", &params), buffer("depth", &depth), buffer("grid_depth", &grid_depth)]);
        let append_group = append.bind(
            gpu,
            &[
                buffer("params", &params),
                buffer("grid_depth", &grid_depth),
                buffer("color", &color),
                buffer("candidates", &compact.candidates),
            ],
        );
        Ok(Self {
            filter,
            append,
            compact,
            intrinsics,
            settings: *settings,
            grid,
            params,
            depth,
            color,
            filter_group,
            append_group,
        })
    }

    /// VALs one frame can make at most: the grid's cell count.
    pub fn max_vals(&self) -> u32 {
        self.grid.x * self.grid.y
    }

    /// Write `frame` (its depth, colour and intrinsics) with `camera_to_world` (its pose made
    /// relative to the scene's origin, [`crate::scene::Scene::local_pose`]) for the next
    /// [`Self::append`]. Refuses a frame whose size differs from the pass's.
    pub fn upload(&self, gpu: &Gpu, frame: &RgbdFrame, camera_to_world: &glam::Affine3A) -> Result<(), GpuError> {
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
        let params = RawRgbdParams::new(f, &self.settings, camera_to_world);
        gpu.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        Ok(())
    }

    /// Append the uploaded frame's VALs to `vals` after the `vals.count` already there, never
    /// past `vals.capacity` elements (nor past the buffer's end): VALs beyond it are dropped and
    /// the count ends at `min(count + made, capacity)`. Does not clear the count.
    pub fn append(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        vals: &Vals,
        span: Option<Span<'_>>,
    ) {
        let (val_count, capacity) = (&vals.count, vals.capacity);
        let vals = &vals.buffer;
        let stride = std::mem::size_of::<RawVal>() as u64;
        let capacity = (capacity as u64).min(vals.size() / stride);
        let cells = [self.grid.x, self.grid.y, 1];
        if capacity == 0 {
            // Nothing can be appended (and an empty binding is not allowed): the filter alone
            // carries the span.
            self.filter.dispatch(encoder, &self.filter_group, scene, cells, span.as_ref().map(Span::compute));
            return;
        }
        let vals = Res {
            name: "vals",
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: vals,
                offset: 0,
                size: wgpu::BufferSize::new(capacity * stride),
            }),
        };
        let before = [(&self.filter, &self.filter_group, cells), (&self.append, &self.append_group, cells)];
        self.compact.record_after(gpu, encoder, scene, &before, (vals, val_count), span);
    }
}

impl RgbdVals {
    /// Stage name.
    pub const STAGE: &str = "rgbd_vals";
}

impl Technique for RgbdVals {
    fn stages(&self) -> Vec<&'static str> {
        vec![Self::STAGE]
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        rec.stage(Self::STAGE, |e, s| self.append(gpu, e, frame.scene, frame.vals, s))
    }
}
