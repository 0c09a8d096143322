//! The sparse method's near field (`near_field*.wgsl`): VALs closer to a receiver than the
//! near-field radius light it per pixel instead of through the sparse points, found in a hashed
//! uniform grid rebuilt every frame by a counting sort. The gather leaves their share out
//! ([`super::gather::body`]), so every VAL counts once: `twin::near_field_weight` splits it.
//! Rust twins: `twin::near_field::ValGrid` (the grid and the per-pixel sum),
//! `twin::shade_near_field` (the same sum over every VAL).
//!
//! The share is split at each receiver's *near-field centre*, not at the receiver: a sparse
//! point's centre is itself; a vertex's is the mean of its sparse points' positions weighted as
//! its interpolation weighs them (`interpolate.wgsl`'s `centres`, twin
//! `twin::near_field::vertex_centre`), and a pixel's is its triangle's corners' centres
//! interpolated. A VAL the sparse points behind a pixel left out is then the VAL the pixel adds,
//! also at corners, where all of a pixel's sparse points lie on one side of it.
//!
//! Two stages: `near_field_grid` (the vertices' centres, then count, scan, scatter) and
//! `near_field` (per pixel, in VAL ranges on CPU adapters, like the brute force:
//! [`Kernels::val_ranges`]).

use super::interpolate;
use crate::gpu::pass::{Entry, Kernel, Kernels, PassDesc, buffer, module_from_source, read, read_write, texture, view};
use crate::gpu::raw::RawVal;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
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
    Wgsl::new().f32("NEAR_FIELD_RADIUS", radius).f32("NEAR_FIELD_CELL", cell).include(WGSL).finish()
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
    default_source: |textured| GRID.source(&Wgsl::new().include(&head(0.25)).include(GRID_WGSL).finish(), textured),
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
        read("vertex_centres"),
    ],
    entries: &[Entry::first("main", 6), Entry::first("main_glossy", 6)],
    workgroup: IMAGE_TILE,
    default_source: |textured| SHADE.source(&Wgsl::new().include(&head(0.25)).include(SHADE_WGSL).finish(), textured),
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
    /// `interpolate.wgsl`'s `centres`.
    centres: Kernel,
    /// `array<vec4<f32>>`, one per vertex: its near-field centre.
    vertex_centres: wgpu::Buffer,
    count: Kernel,
    scan: Kernel,
    scatter: Kernel,
    shade: Kernels,
    grid: GridBuffers,
}

impl NearField {
    /// The near field at `radius` (m, > 0) for a scene that is `glossy` or not, whose
    /// interpolation pass is `interpolate_body` ([`interpolate::body`]: the centres weigh the
    /// sparse points as it does).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        glossy: bool,
        radius: f32,
        interpolate_pass: &'static PassDesc,
        interpolate_body: &str,
    ) -> Result<Self, GpuError> {
        let textured = scene.textured();
        let desc = interpolate_pass;
        let module = module_from_source(gpu, desc.label, desc.source(interpolate_body, textured))?;
        let centres = Kernel::build(gpu, scene, desc, &module, desc.entry("centres"), &[], desc.workgroup)?;
        let vertices = scene.flat.vertices.len().max(1);
        let head = head(radius);
        let module = module_from_source(
            gpu,
            GRID.label,
            GRID.source(&Wgsl::new().include(&head).include(GRID_WGSL).finish(), textured),
        )?;
        let kernel = |name: &str| Kernel::build(gpu, scene, &GRID, &module, GRID.entry(name), &[], GRID.workgroup);
        let source = SHADE.source(&Wgsl::new().include(&head).include(SHADE_WGSL).finish(), textured);
        // One loop iteration per near VAL (the weight and the bucket loops are a few more).
        let shade = Kernels::val_ranges(gpu, scene, &SHADE, source, SHADE.lobe_entry(glossy), SHADE.workgroup, 1)?;
        Ok(Self {
            centres,
            vertex_centres: gpu.storage_buffer_sized::<[f32; 4]>("near_field.vertex_centres", vertices)?,
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

    /// Place every vertex's centre and sort the frame's VALs into the grid, then add the near
    /// field to every covered pixel of the camera's `indirect`.
    /// `chosen`: with adaptive candidates, which were chosen this frame (the centres weigh
    /// them as the interpolation does).
    pub fn record(
        &self,
        gpu: &Gpu,
        frame: &Frame<'_>,
        chosen: Option<&wgpu::Buffer>,
        rec: &mut Recorder<'_>,
    ) -> Result<(), GpuError> {
        let (scene, g) = (frame.scene, &self.grid);
        let (vals, val_count) = (|| buffer("vals", &frame.vals.buffer), || buffer("val_count", &frame.vals.count));
        let (counts, starts) = (|| buffer("grid_counts", &g.counts), || buffer("grid_starts", &g.starts));
        let slots = || buffer("val_slots", &g.slots);
        let count = self.count.bind(gpu, &[vals(), val_count(), counts(), starts(), slots()]);
        let scan = self.scan.bind(gpu, &[counts(), starts()]);
        let scatter = self.scatter.bind(gpu, &[vals(), val_count(), starts(), slots(), buffer("grid_vals", &g.vals)]);
        let mut centres = vec![
            buffer("sparse_points", &scene.sparse_points),
            buffer("vertex_neighbours", &scene.vertex_neighbours),
            buffer("vertex_centres", &self.vertex_centres),
        ];
        centres.extend(chosen.into_iter().flat_map(|c| interpolate::adaptive_resources(scene, c)));
        let (vertex_list, vertices) = frame.camera_vertices();
        centres.push(buffer("vertex_list", vertex_list));
        let centres = self.centres.bind(gpu, &centres);
        let n = frame.vals.capacity.min(g.capacity);
        rec.stage(GRID_STAGE, |e, s| {
            e.clear_buffer(&g.counts, 0, None);
            let part = |i| s.as_ref().and_then(|s| s.compute_part(i, 4));
            self.centres.dispatch(e, &centres, scene, [vertices, 1, 1], part(0));
            self.count.dispatch(e, &count, scene, [n, 1, 1], part(1));
            self.scan.dispatch(e, &scan, scene, [WORKGROUP_SIZE, 1, 1], part(2));
            self.scatter.dispatch(e, &scatter, scene, [n, 1, 1], part(3));
        })?;
        let camera = frame.camera;
        let resources = [
            view("visibility", &camera.view.view),
            buffer("indirect", &camera.indirect),
            buffer("grid_counts", &g.counts),
            buffer("grid_starts", &g.starts),
            buffer("grid_vals", &g.vals),
            buffer("vertex_centres", &self.vertex_centres),
        ];
        let pixels = [camera.view.width, camera.view.height, 1];
        rec.stage(SHADE_STAGE, |e, s| self.shade.run_on(gpu, e, frame.camera_triangles().0, &resources, pixels, s))
    }
}
