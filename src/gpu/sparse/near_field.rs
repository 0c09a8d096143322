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
//! Interleaved (`settings.sparse.near_field_interleave`, the block side N > 1), each pixel of
//! an N x N block sums one of N² subsets of the near VALs, and a filter over the block that
//! keeps to the pixel's surface adds them up again (`near_field_filter.wgsl`, twin
//! `twin::near_field::filter`): 1/N² of the per-pixel work.
//!
//! Two stages: `near_field_grid` (the vertices' centres, then count, scan, scatter) and
//! `near_field` (per pixel, in VAL ranges on CPU adapters, like the brute force:
//! [`Kernels::val_ranges`]; then the filter).

use std::sync::Mutex;

use super::interpolate;
use crate::gpu::pass::{
    Entry, Kernel, Kernels, PassDesc, Res, buffer, module_from_source, read, read_write, texture, view,
};
use crate::gpu::raw::RawVal;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::shader::{IMAGE_TILE, WORKGROUP_SIZE};
use crate::gpu::technique::Frame;
use crate::gpu::timing::{Recorder, Span};
use crate::gpu::{Gpu, GpuError};
use crate::twin::near_field::slot_count;

pub const WGSL: &str = include_str!("near_field.wgsl");
pub const GRID_WGSL: &str = include_str!("near_field_grid.wgsl");
pub const SHADE_WGSL: &str = include_str!("near_field_shade.wgsl");
pub const FILTER_WGSL: &str = include_str!("near_field_filter.wgsl");
pub const WINDOW_WGSL: &str = include_str!("near_field_window.wgsl");

/// The grid's stage.
pub const GRID_STAGE: &str = "near_field_grid";
/// The per-pixel stage.
pub const SHADE_STAGE: &str = "near_field";

/// The constants every pass shares, then `near_field.wgsl`: the radius (m), the grid's cell
/// (twice the radius), the interleaving block's side and its subsets (side²).
pub fn head(radius: f32, side: u32) -> String {
    let cell = crate::twin::near_field::cell_size(radius);
    Wgsl::new()
        .f32("NEAR_FIELD_RADIUS", radius)
        .f32("NEAR_FIELD_CELL", cell)
        .u32("NEAR_FIELD_SIDE", side)
        .u32("NEAR_FIELD_SUBSETS", side * side)
        .include(WGSL)
        .finish()
}

/// The per-pixel pass's constants and body: [`head`], the close grid's radius and cell
/// (`twin::near_field::close_radius`; 0 and unused when not interleaved), then
/// `near_field_shade.wgsl`.
fn shade_body(radius: f32, side: u32) -> String {
    let close = crate::twin::near_field::close_radius(radius, side);
    let cell = if close > 0.0 { crate::twin::near_field::cell_size(close) } else { 1.0 };
    Wgsl::new()
        .include(&head(radius, side))
        .f32("NEAR_FIELD_CLOSE_RADIUS", close)
        .f32("NEAR_FIELD_CLOSE_CELL", cell)
        .include(WINDOW_WGSL)
        .include(SHADE_WGSL)
        .finish()
}

/// The filter's constants and body: [`head`], `near_field_window.wgsl`, `near_field_filter.wgsl`.
fn filter_body(radius: f32, side: u32) -> String {
    Wgsl::new().include(&head(radius, side)).include(WINDOW_WGSL).include(FILTER_WGSL).finish()
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
    default_source: |textured| GRID.source(&Wgsl::new().include(&head(0.25, 4)).include(GRID_WGSL).finish(), textured),
};

/// One invocation per pixel: the near VALs' light added to `indirect`, or, interleaved, their
/// terms and the pixel's surface point into `near_light` and `near_surface` for the filter.
pub const SHADE: PassDesc = PassDesc {
    label: SHADE_STAGE,
    bindings: &[
        texture("visibility"),
        read_write("near_light"),
        read("grid_counts"),
        read("grid_starts"),
        read("grid_vals"),
        read("vertex_centres"),
        read("close_counts"),
        read("close_starts"),
        read("close_vals"),
        read_write("indirect"),
        read_write("near_surface"),
    ],
    entries: &[
        Entry::first("main", 11),
        Entry::first("main_glossy", 11),
        Entry { name: "main_redo", bindings: 11, except: &["close_counts", "close_starts", "close_vals"] },
        Entry { name: "main_redo_glossy", bindings: 11, except: &["close_counts", "close_starts", "close_vals"] },
    ],
    workgroup: IMAGE_TILE,
    default_source: |textured| SHADE.source(&shade_body(0.25, 4), textured),
};

/// One invocation per pixel: the block's terms filtered, through the pixel's material, added to
/// `indirect` (the second part of the `near_field` stage).
pub const FILTER: PassDesc = PassDesc {
    label: "near_field_filter",
    bindings: &[texture("visibility"), read_write("indirect"), read("near_light"), read("near_surface")],
    entries: &[Entry::first("main", 4), Entry::first("main_glossy", 4)],
    workgroup: IMAGE_TILE,
    default_source: |textured| FILTER.source(&filter_body(0.25, 4), textured),
};

/// The grid's buffers, sized for a VAL capacity.
struct GridBuffers {
    /// `array<u32>`, one per slot (a cell bucket's subset): VALs in it (atomic while counting).
    counts: wgpu::Buffer,
    /// `array<u32>`, one per slot: where its VALs start in `vals`.
    starts: wgpu::Buffer,
    /// `array<u32>`, one per VAL: its place in its slot.
    slots: wgpu::Buffer,
    /// `array<Val>`: the frame's VALs in slot order.
    vals: wgpu::Buffer,
    /// VALs the buffers hold.
    capacity: u32,
}

impl GridBuffers {
    fn new(gpu: &Gpu, capacity: u32, subsets: u32) -> Result<Self, GpuError> {
        let buckets = slot_count(capacity, subsets) as usize;
        Ok(Self {
            counts: gpu.storage_buffer_sized::<u32>("near_field_grid.counts", buckets)?,
            starts: gpu.storage_buffer_sized::<u32>("near_field_grid.starts", buckets)?,
            slots: gpu.storage_buffer_sized::<u32>("near_field_grid.slots", capacity as usize)?,
            vals: gpu.storage_buffer_sized::<RawVal>("near_field_grid.vals", capacity as usize)?,
            capacity,
        })
    }
}

/// The interleaved pass's per-pixel buffers.
struct PixelBuffers {
    light: wgpu::Buffer,
    surface: wgpu::Buffer,
}

/// A grid's count, scan and scatter kernels and its buffers.
struct Grid {
    count: Kernel,
    scan: Kernel,
    scatter: Kernel,
    buffers: GridBuffers,
    /// VAL subsets per cell bucket.
    subsets: u32,
}

impl Grid {
    /// The grid of cells twice `radius` wide, `side²` subsets per cell, each split into
    /// `twin::near_field::COLUMNS` columns along x.
    fn new(gpu: &Gpu, scene: &GpuScene, radius: f32, side: u32) -> Result<Self, GpuError> {
        let source =
            GRID.source(&Wgsl::new().include(&head(radius, side)).include(GRID_WGSL).finish(), scene.textured());
        let module = module_from_source(gpu, GRID.label, source)?;
        let kernel = |name: &str| Kernel::build(gpu, scene, &GRID, &module, GRID.entry(name), &[], GRID.workgroup);
        let subsets = side * side;
        Ok(Self {
            count: kernel("grid_count")?,
            scan: kernel("grid_scan")?,
            scatter: kernel("grid_scatter")?,
            buffers: GridBuffers::new(gpu, 1, subsets)?,
            subsets,
        })
    }

    fn fit(&mut self, gpu: &Gpu, max_vals: u32) -> Result<(), GpuError> {
        if max_vals > self.buffers.capacity {
            self.buffers = GridBuffers::new(gpu, max_vals, self.subsets)?;
        }
        Ok(())
    }

    /// Sort the frame's VALs into the grid: parts `first..first + 3` of the stage's `parts`.
    fn record(
        &self,
        gpu: &Gpu,
        e: &mut wgpu::CommandEncoder,
        frame: &Frame<'_>,
        parts: (usize, usize),
        s: Option<Span<'_>>,
    ) {
        let (scene, g) = (frame.scene, &self.buffers);
        let (vals, val_count) = (|| buffer("vals", &frame.vals.buffer), || buffer("val_count", &frame.vals.count));
        let (counts, starts) = (|| buffer("grid_counts", &g.counts), || buffer("grid_starts", &g.starts));
        let slots = || buffer("val_slots", &g.slots);
        let count = self.count.bind(gpu, &[vals(), val_count(), counts(), starts(), slots()]);
        let scan = self.scan.bind(gpu, &[counts(), starts()]);
        let scatter = self.scatter.bind(gpu, &[vals(), val_count(), starts(), slots(), buffer("grid_vals", &g.vals)]);
        let n = frame.vals.capacity.min(g.capacity);
        let part = |i| s.as_ref().and_then(|s| s.compute_part(parts.0 + i, parts.1));
        e.clear_buffer(&g.counts, 0, None);
        self.count.dispatch(e, &count, scene, [n, 1, 1], part(0));
        self.scan.dispatch(e, &scan, scene, [WORKGROUP_SIZE, 1, 1], part(1));
        self.scatter.dispatch(e, &scatter, scene, [n, 1, 1], part(2));
    }
}

/// The near field's kernels and grid.
pub struct NearField {
    /// `interpolate.wgsl`'s `centres`.
    centres: Kernel,
    /// `array<vec4<f32>>`, one per vertex: its near-field centre.
    vertex_centres: wgpu::Buffer,
    shade: Kernels,
    /// Interleaved only: the filter, then every near VAL at the pixels it leaves
    /// (`main_redo`); not built otherwise (the shade then adds its light itself).
    interleaved: Option<(Kernels, Kernels)>,
    grid: Grid,
    /// Interleaved only: the close grid (`twin::near_field::close_radius`).
    close: Option<Grid>,
    /// The interleaving block's side.
    side: u32,
    /// Interleaved: `near_light` and `near_surface` (`array<vec4<f32>>`, two per pixel each:
    /// `near_field_shade.wgsl`), for the last frame's pixel count, reallocated when the camera's
    /// size changes (two bindings, so that each stays within the device's largest storage
    /// binding up to twice as many pixels). Not interleaved: one element each, unused.
    pixels: Mutex<Option<(u32, PixelBuffers)>>,
}

impl NearField {
    /// The near field at `radius` (m, > 0), interleaved over blocks `side` pixels wide (1: not
    /// interleaved), for a scene that is `glossy` or not, whose interpolation pass is
    /// `interpolate_body` ([`interpolate::body`]: the centres weigh the sparse points as it
    /// does).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        glossy: bool,
        (radius, side): (f32, u32),
        interpolate_pass: &'static PassDesc,
        interpolate_body: &str,
    ) -> Result<Self, GpuError> {
        let textured = scene.textured();
        let desc = interpolate_pass;
        let module = module_from_source(gpu, desc.label, desc.source(interpolate_body, textured))?;
        let centres = Kernel::build(gpu, scene, desc, &module, desc.entry("centres"), &[], desc.workgroup)?;
        let vertices = scene.flat.vertices.len().max(1);
        let source = SHADE.source(&shade_body(radius, side), textured);
        // One loop iteration per near VAL (the weight and the bucket loops are a few more).
        let shade = Kernels::val_ranges(gpu, scene, &SHADE, source, SHADE.lobe_entry(glossy), SHADE.workgroup, 1)?;
        let interleaved = (side > 1)
            .then(|| -> Result<_, GpuError> {
                let filter = Kernels::lobes(gpu, scene, &FILTER, &filter_body(radius, side), glossy)?;
                let redo_entry = SHADE.entry(if glossy { "main_redo_glossy" } else { "main_redo" });
                let source = SHADE.source(&shade_body(radius, side), textured);
                let redo = Kernels::val_ranges(gpu, scene, &SHADE, source, redo_entry, SHADE.workgroup, 1)?;
                Ok((filter, redo))
            })
            .transpose()?;
        Ok(Self {
            centres,
            vertex_centres: gpu.storage_buffer_sized::<[f32; 4]>("near_field.vertex_centres", vertices)?,
            shade,
            interleaved,
            grid: Grid::new(gpu, scene, radius, side)?,
            close: (side > 1)
                .then(|| Grid::new(gpu, scene, crate::twin::near_field::close_radius(radius, side), 1))
                .transpose()?,
            side,
            pixels: Mutex::new(None),
        })
    }

    /// Cover frames of up to `max_vals` VALs.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        self.grid.fit(gpu, max_vals)?;
        if let Some(close) = &mut self.close {
            close.fit(gpu, max_vals)?;
        }
        if let Some((_, redo)) = &mut self.interleaved {
            redo.fit(gpu, scene, max_vals)?;
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
        let scene = frame.scene;
        let mut centres = vec![
            buffer("sparse_points", &scene.sparse_points),
            buffer("vertex_neighbours", &scene.vertex_neighbours),
            buffer("vertex_centres", &self.vertex_centres),
        ];
        centres.extend(chosen.into_iter().flat_map(|c| interpolate::adaptive_resources(scene, c)));
        let (vertex_list, vertices) = frame.camera_vertices();
        centres.push(buffer("vertex_list", vertex_list));
        let centres = self.centres.bind(gpu, &centres);
        rec.stage(GRID_STAGE, |e, s| {
            let parts = 4 + 3 * usize::from(self.close.is_some());
            self.centres.dispatch(
                e,
                &centres,
                scene,
                [vertices, 1, 1],
                s.as_ref().and_then(|s| s.compute_part(0, parts)),
            );
            self.grid.record(gpu, e, frame, (1, parts), s);
            if let Some(close) = &self.close {
                close.record(gpu, e, frame, (4, parts), s);
            }
        })?;
        let (g, c) = (&self.grid.buffers, &self.close.as_ref().unwrap_or(&self.grid).buffers);
        let camera = frame.camera;
        let count = if self.interleaved.is_some() { camera.view.width * camera.view.height } else { 0 };
        let mut held = self.pixels.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if held.as_ref().is_none_or(|(n, _)| *n != count) {
            let elements = 2 * count.max(1) as usize;
            let light = gpu.storage_buffer_sized::<[f32; 4]>("near_field.light", elements)?;
            let surface = gpu.storage_buffer_sized::<[f32; 4]>("near_field.surface", elements)?;
            *held = Some((count, PixelBuffers { light, surface }));
        }
        let near = &held.as_ref().expect("allocated above").1;
        let resources = [
            view("visibility", &camera.view.view),
            buffer("near_light", &near.light),
            buffer("grid_counts", &g.counts),
            buffer("grid_starts", &g.starts),
            buffer("grid_vals", &g.vals),
            buffer("vertex_centres", &self.vertex_centres),
            buffer("close_counts", &c.counts),
            buffer("close_starts", &c.starts),
            buffer("close_vals", &c.vals),
            buffer("indirect", &camera.indirect),
            buffer("near_surface", &near.surface),
        ];
        let redo: Vec<Res<'_>> = resources
            .iter()
            .filter(|r| !r.name.starts_with("close_"))
            .map(|r| Res { name: r.name, resource: r.resource.clone() })
            .collect();
        let filter = [
            view("visibility", &camera.view.view),
            buffer("indirect", &camera.indirect),
            buffer("near_light", &near.light),
            buffer("near_surface", &near.surface),
        ];
        let pixels = [camera.view.width, camera.view.height, 1];
        // The shade walks the subsets' sub-images (`near_field_shade.wgsl`'s `pixel_of`).
        let deinterleaved = [0, 1].map(|a| pixels[a].div_ceil(self.side) * self.side);
        let triangles = frame.camera_triangles().0;
        rec.stage(SHADE_STAGE, |e, s| {
            let shade = [deinterleaved[0], deinterleaved[1], 1];
            let Some((filter_kernels, redo_kernels)) = &self.interleaved else {
                self.shade.run_on(gpu, e, triangles, &resources, shade, s);
                return;
            };
            e.clear_buffer(&near.light, 0, None);
            let (first, parts) = (self.shade.len(), self.shade.len() + 1 + redo_kernels.len());
            self.shade.run_on(gpu, e, triangles, &resources, shade, s.map(|s| s.share(0, parts)));
            filter_kernels.run_on(gpu, e, triangles, &filter, pixels, s.map(|s| s.share(first, parts)));
            redo_kernels.run_on(gpu, e, triangles, &redo, pixels, s.map(|s| s.share(first + 1, parts)));
        })
    }
}
