//! Gather at sparse points (`gather.wgsl`, DESIGN.md §4 step 1). Rust twin:
//! `twin::gather_point`. With a group visibility mode ([`GROUPED_PASS`]) every VAL's
//! contribution is scaled by its group's visibility at the point
//! ([`crate::gpu::visibility::GroupTable`]).
//!
//! On a CPU adapter one invocation may not loop over more than about
//! [`Gpu::CPU_MAX_GATHERED_VALS`] VALs (llvmpipe ends a shader's loops after
//! [`crate::gpu::LLVMPIPE_LOOP_LIMIT`] iterations, silently), so there the VALs are gathered in
//! ranges, one dispatch each, every range merging into the sums of the ones before
//! ([`Kernels::val_ranges`]). GPUs take every VAL in one dispatch.

use crate::gpu::pass::{Binding, Entry, Kernels, PassDesc, buffer, read, read_write, with_lobes};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::{TILE_SIZE, VAL_TILES};
use crate::gpu::technique::Vals;
use crate::gpu::timing::Span;
use crate::gpu::visibility::{GroupTable, group_wgsl};
use crate::gpu::{Gpu, GpuError, Lobes};

pub const WGSL: &str = include_str!("gather.wgsl");

/// Every VAL reaches every point whole when no group visibility mode runs.
const NO_GROUPS: &str = "fn val_visibility(point: u32, val: u32) -> f32 {\n    return 1.0;\n}\n";

/// The pass's own WGSL: the VAL tiles, `val_visibility` for `groups` groups (or none), then
/// `gather.wgsl`.
/// `near_radius` (m): the near-field radius whose share the gather leaves out (0: none).
pub fn body(groups: Option<u32>, near_radius: f32) -> String {
    let visibility = groups.map_or_else(|| NO_GROUPS.to_owned(), group_wgsl);
    format!("{VAL_TILES}\n{visibility}\nconst NEAR_FIELD_RADIUS: f32 = {near_radius:e};\n{WGSL}")
}

/// The bindings of [`GROUPED_PASS`]; [`PASS`] has the first five (no group table).
const BINDINGS: &[Binding] = &[
    read("sparse_points"),
    read("vals"),
    read("val_count"),
    read_write("gathered_diffuse"),
    read_write("gathered_glossy"),
    read("group_of_val"),
    read("group_visibility"),
];

/// One invocation per sparse point, `TILE_SIZE` per workgroup (the tile is the workgroup's).
pub const PASS: PassDesc = PassDesc {
    label: "gather",
    bindings: BINDINGS.split_at(5).0,
    entries: &[Entry::first("main", 4), Entry::first("main_glossy", 5)],
    workgroup: [TILE_SIZE, 1, 1],
    default_source: |textured| PASS.source(&body(None, 0.0), textured),
};

/// The gather of a group visibility mode: [`PASS`] plus the group table.
pub const GROUPED_PASS: PassDesc = PassDesc {
    bindings: BINDINGS,
    entries: &[Entry { name: "main", bindings: 7, except: &["gathered_glossy"] }, Entry::first("main_glossy", 7)],
    default_source: |textured| GROUPED_PASS.source(&body(Some(64), 0.0), textured),
    ..PASS
};

pub struct Gather {
    kernels: Kernels,
}

impl Gather {
    /// `glossy` builds the entry point that also gathers the Phong lobe; `groups`, the
    /// group count of a group visibility mode, the one that reads its table.
    /// `near_radius` (m): leave out each VAL's near-field share at that radius (0: none).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        glossy: bool,
        groups: Option<u32>,
        near_radius: f32,
    ) -> Result<Self, GpuError> {
        Self::with_tile_size(gpu, scene, glossy, groups, near_radius, TILE_SIZE)
    }

    /// The pass with `tile_size` VALs per tile and threads per workgroup instead of
    /// [`TILE_SIZE`] (the bench compares them; the device must allow the workgroup size).
    pub fn with_tile_size(
        gpu: &Gpu,
        scene: &GpuScene,
        glossy: bool,
        groups: Option<u32>,
        near_radius: f32,
        tile_size: u32,
    ) -> Result<Self, GpuError> {
        let workgroup = [tile_size, 1, 1];
        let desc = if groups.is_some() { &GROUPED_PASS } else { &PASS };
        let source = desc.source_with(&body(groups, near_radius), scene.textured(), workgroup, tile_size);
        let entry = desc.lobe_entry(glossy);
        let kernels = Kernels::val_ranges(gpu, scene, desc, source, entry, workgroup, tile_size)?;
        Ok(Self { kernels })
    }

    /// Cover frames of up to `max_vals` VALs (see [`Kernels::fit`]).
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        self.kernels.fit(gpu, scene, max_vals)
    }

    /// Gather `vals` at every sparse point into `gathered`, with `groups`' visibility when
    /// built for a group visibility mode.
    pub fn record(
        &self,
        gpu: &Gpu,
        e: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        vals: &Vals,
        gathered: &Lobes,
        groups: Option<&GroupTable<'_>>,
        span: Option<Span<'_>>,
    ) {
        let mut resources = with_lobes(
            vec![
                buffer("sparse_points", &scene.sparse_points),
                buffer("vals", &vals.buffer),
                buffer("val_count", &vals.count),
            ],
            &[(gathered, "gathered_diffuse", "gathered_glossy")],
        );
        if let Some(g) = groups {
            resources.extend([buffer("group_of_val", g.group_of_val), buffer("group_visibility", g.visibility)]);
        }
        let n = scene.flat.sparse_count();
        self.kernels.run(gpu, e, scene, &resources, [n, 1, 1], span);
    }
}
