//! The sparse method's near field (`near_field*.wgsl`): VALs closer to a receiver than the
//! near-field radius light it per pixel instead of through the sparse points, found in a hashed
//! uniform grid rebuilt every frame by a counting sort. The gather leaves their share out
//! ([`super::gather::body`]), so every VAL counts once: `twin::near_field_weight` splits it.
//! Rust twins: `twin::near_field::ValGrid` (the grid and the per-pixel sum),
//! `twin::shade_near_field` (the same sum over every VAL).
//!
//! Two stages: `near_field_grid` (count, scan, scatter) and `near_field` (per pixel, in VAL
//! ranges on CPU adapters, like the brute force: [`Kernels::val_ranges`]).

use crate::gpu::pass::{Entry, Kernel, Kernels, PassDesc, buffer, module_from_source, read, read_write, texture, view};
use crate::gpu::raw::RawVal;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::{IMAGE_TILE, WORKGROUP_SIZE};
use crate::gpu::technique::Frame;
use crate::gpu::timing::Recorder;
use crate::gpu::{Gpu, GpuError};
use crate::twin::near_field::bucket_count;

pub const WGSL: &str = include_str!("near_field.wgsl");
pub const GRID_WGSL: &str = include_str!("near_field_grid.wgsl");
pub const SHADE_WGSL: &str = include_str!("near_field_shade.wgsl");

/// The grid's stage.
pub const GRID_STAGE: &str = "near_field_grid";
/// The per-pixel stage.
pub const SHADE_STAGE: &str = "near_field";

/// The constants both passes share, then `near_field.wgsl`: the radius (m) and the grid's cell,
/// twice the radius.
pub fn head(radius: f32) -> String {
    let cell = crate::twin::near_field::cell_size(radius);
    format!("const NEAR_FIELD_RADIUS: f32 = {radius:e};\nconst NEAR_FIELD_CELL: f32 = {cell:e};\n{WGSL}")
}

/// The grid: one invocation per VAL for the count and the scatter, one workgroup for the scan.
pub const GRID: PassDesc = PassDesc {
    label: GRID_STAGE,
    bindings: &[
        read("vals"),
        read("val_count"),
        read_write("grid_counts"),
        read_write("grid_starts"),
        read_write("val_slots"),
        read_write("grid_vals"),
    ],
    entries: &[
        Entry::first("grid_count", 5),
        Entry { name: "grid_scan", bindings: 4, except: &["vals", "val_count"] },
        Entry { name: "grid_scatter", bindings: 6, except: &["grid_counts"] },
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| GRID.source(&format!("{}\n{GRID_WGSL}", head(0.25)), textured),
};

/// One invocation per pixel.
pub const SHADE: PassDesc = PassDesc {
    label: SHADE_STAGE,
    bindings: &[
        texture("visibility"),
        read_write("indirect"),
        read("grid_counts"),
        read("grid_starts"),
        read("grid_vals"),
    ],
    entries: &[Entry::first("main", 5), Entry::first("main_glossy", 5)],
    workgroup: IMAGE_TILE,
    default_source: |textured| SHADE.source(&format!("{}\n{SHADE_WGSL}", head(0.25)), textured),
};

/// The grid's buffers, sized for a VAL capacity.
struct GridBuffers {
    /// `array<u32>`, one per bucket: VALs in it (atomic while counting).
    counts: wgpu::Buffer,
    /// `array<u32>`, one per bucket: where its VALs start in `vals`.
    starts: wgpu::Buffer,
    /// `array<u32>`, one per VAL: its place in its bucket.
    slots: wgpu::Buffer,
    /// `array<Val>`: the frame's VALs in bucket order.
    vals: wgpu::Buffer,
    /// VALs the buffers hold.
    capacity: u32,
}

impl GridBuffers {
    fn new(gpu: &Gpu, capacity: u32) -> Result<Self, GpuError> {
        let buckets = bucket_count(capacity) as usize;
        Ok(Self {
            counts: gpu.storage_buffer_sized::<u32>("near_field_grid.counts", buckets)?,
            starts: gpu.storage_buffer_sized::<u32>("near_field_grid.starts", buckets)?,
            slots: gpu.storage_buffer_sized::<u32>("near_field_grid.slots", capacity as usize)?,
            vals: gpu.storage_buffer_sized::<RawVal>("near_field_grid.vals", capacity as usize)?,
            capacity,
        })
    }
}

/// The near field's kernels and grid.
pub struct NearField {
    count: Kernel,
    scan: Kernel,
    scatter: Kernel,
    shade: Kernels,
    grid: GridBuffers,
}

impl NearField {
    /// The near field at `radius` (m, > 0) for a scene that is `glossy` or not.
    pub fn new(gpu: &Gpu, scene: &GpuScene, glossy: bool, radius: f32) -> Result<Self, GpuError> {
        let textured = scene.textured();
        let head = head(radius);
        let module = module_from_source(gpu, GRID.label, GRID.source(&format!("{head}\n{GRID_WGSL}"), textured))?;
        let kernel = |name: &str| Kernel::build(gpu, scene, &GRID, &module, GRID.entry(name), &[], GRID.workgroup);
        let source = SHADE.source(&format!("{head}\n{SHADE_WGSL}"), textured);
        // One loop iteration per near VAL (the weight and the bucket loops are a few more).
        let shade = Kernels::val_ranges(gpu, scene, &SHADE, source, SHADE.lobe_entry(glossy), SHADE.workgroup, 1)?;
        Ok(Self {
            count: kernel("grid_count")?,
            scan: kernel("grid_scan")?,
            scatter: kernel("grid_scatter")?,
            shade,
            grid: GridBuffers::new(gpu, 1)?,
        })
    }

    /// Cover frames of up to `max_vals` VALs.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        if max_vals > self.grid.capacity {
            self.grid = GridBuffers::new(gpu, max_vals)?;
        }
        self.shade.fit(gpu, scene, max_vals)
    }

    pub fn stages(&self) -> [&'static str; 2] {
        [GRID_STAGE, SHADE_STAGE]
    }

    /// Sort the frame's VALs into the grid, then add the near field to every covered pixel of
    /// the camera's `indirect`.
    pub fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let (scene, g) = (frame.scene, &self.grid);
        let (vals, val_count) = (|| buffer("vals", &frame.vals.buffer), || buffer("val_count", &frame.vals.count));
        let (counts, starts) = (|| buffer("grid_counts", &g.counts), || buffer("grid_starts", &g.starts));
        let slots = || buffer("val_slots", &g.slots);
        let count = self.count.bind(gpu, &[vals(), val_count(), counts(), starts(), slots()]);
        let scan = self.scan.bind(gpu, &[counts(), starts()]);
        let scatter = self.scatter.bind(gpu, &[vals(), val_count(), starts(), slots(), buffer("grid_vals", &g.vals)]);
        let n = frame.vals.capacity.min(g.capacity);
        rec.stage(GRID_STAGE, |e, s| {
            e.clear_buffer(&g.counts, 0, None);
            let part = |i| s.as_ref().map(|s| s.compute_part(i, 3));
            self.count.dispatch(e, &count, scene, [n, 1, 1], part(0));
            self.scan.dispatch(e, &scan, scene, [WORKGROUP_SIZE, 1, 1], part(1));
            self.scatter.dispatch(e, &scatter, scene, [n, 1, 1], part(2));
        })?;
        let camera = frame.camera;
        let resources = [
            view("visibility", &camera.view.view),
            buffer("indirect", &camera.indirect),
            buffer("grid_counts", &g.counts),
            buffer("grid_starts", &g.starts),
            buffer("grid_vals", &g.vals),
        ];
        let pixels = [camera.view.width, camera.view.height, 1];
        rec.stage(SHADE_STAGE, |e, s| self.shade.run(gpu, e, scene, &resources, pixels, s))
    }
}
