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

/// What the gather sums at each sparse point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GatherLobes {
    /// The diffuse irradiance and its mean VAL position.
    Diffuse,
    /// Also the glossy lobe's sum and its lobe-weighted mean VAL position (what the paper's
    /// glossy point lights are renormalised from: `glossy_interpolation: "lights"`).
    GlossyLights,
    /// Also the glossy lobe's sum, without its mean position (`glossy_interpolation:
    /// "radiance"` interpolates the sum itself): four fewer sums per VAL and point.
    GlossyRadiance,
}

impl GatherLobes {
    pub fn glossy(self) -> bool {
        self != GatherLobes::Diffuse
    }
}

/// The pass's own WGSL: the VAL tiles, `val_visibility` for `groups` groups (or none), the
/// receivers per invocation, whether the glossy mean position is summed, then `gather.wgsl`.
/// `near_radius` (m): the near-field radius whose share the gather leaves out (0: none).
pub fn body(groups: Option<u32>, near_radius: f32, receivers: u32, lobes: GatherLobes) -> String {
    let visibility = group_wgsl(groups, 5);
    let receivers = receivers_wgsl(receivers);
    let glossy_mean = lobes == GatherLobes::GlossyLights;
    format!(
        "{VAL_TILES}\n{visibility}\n{receivers}\nconst NEAR_FIELD_RADIUS: f32 = {near_radius:e};\n\
         const GLOSSY_MEAN: bool = {glossy_mean};\n{WGSL}"
    )
}

/// `RECEIVERS` and `add_to_receivers` (`gather.wgsl`): one VAL added to each of `receivers`
/// sums, one statement per receiver.
fn receivers_wgsl(receivers: u32) -> String {
    let adds: String = (0..receivers)
        .map(|r| {
            format!(
                "    (*sums)[{r}] = add_val((*sums)[{r}], (*receivers)[{r}], first + {r}u, val, val_index, glossy);\n"
            )
        })
        .collect();
    format!(
        "const RECEIVERS: u32 = {receivers}u;\n\
         fn add_to_receivers(sums: ptr<function, array<Sums, RECEIVERS>>, receivers: ptr<function, array<Receiver, RECEIVERS>>, \
         first: u32, val: Val, val_index: u32, glossy: bool) {{\n{adds}}}\n"
    )
}

/// Sparse points per invocation on CPU adapters, measured by the bench's gather variants
/// (README "Gather variants"); GPUs take one, for parallelism (a frame has only thousands of
/// points).
pub const CPU_RECEIVERS: u32 = 8;

/// The most sparse points one invocation may take (the bench's and the tests' range).
pub const MAX_RECEIVERS: u32 = 8;

/// Sparse points per invocation on `gpu`.
pub fn receivers_for(gpu: &Gpu) -> u32 {
    if gpu.is_cpu() { CPU_RECEIVERS } else { 1 }
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
    default_source: |textured| PASS.source(&body(None, 0.0, CPU_RECEIVERS, GatherLobes::GlossyLights), textured),
};

/// The gather of a group visibility mode: [`PASS`] plus the group table.
pub const GROUPED_PASS: PassDesc = PassDesc {
    bindings: BINDINGS,
    entries: &[Entry { name: "main", bindings: 7, except: &["gathered_glossy"] }, Entry::first("main_glossy", 7)],
    default_source: |textured| {
        GROUPED_PASS.source(&body(Some(64), 0.0, CPU_RECEIVERS, GatherLobes::GlossyLights), textured)
    },
    ..PASS
};

pub struct Gather {
    kernels: Kernels,
    /// Sparse points per invocation.
    receivers: u32,
}

impl Gather {
    /// `lobes` says what to sum (a glossy one builds the entry point that also gathers the
    /// Phong lobe); `groups`, the group count of a group visibility mode, the one that reads
    /// its table. `near_radius` (m): leave out each VAL's near-field share at that radius (0:
    /// none).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        lobes: GatherLobes,
        groups: Option<u32>,
        near_radius: f32,
    ) -> Result<Self, GpuError> {
        Self::variant(gpu, scene, lobes, groups, near_radius, TILE_SIZE, receivers_for(gpu))
    }

    /// The pass with `tile_size` VALs per tile and threads per workgroup instead of
    /// [`TILE_SIZE`], and `receivers` (1..=[`MAX_RECEIVERS`]) sparse points per invocation
    /// instead of [`receivers_for`]'s (the bench compares them; the device must allow the
    /// workgroup size).
    pub fn variant(
        gpu: &Gpu,
        scene: &GpuScene,
        lobes: GatherLobes,
        groups: Option<u32>,
        near_radius: f32,
        tile_size: u32,
        receivers: u32,
    ) -> Result<Self, GpuError> {
        assert!((1..=MAX_RECEIVERS).contains(&receivers), "{receivers} receivers per invocation");
        let workgroup = [tile_size, 1, 1];
        let desc = if groups.is_some() { &GROUPED_PASS } else { &PASS };
        let source =
            desc.source_with(&body(groups, near_radius, receivers, lobes), scene.textured(), workgroup, tile_size);
        let entry = desc.lobe_entry(lobes.glossy());
        let kernels = Kernels::val_ranges(gpu, scene, desc, source, entry, workgroup, tile_size)?;
        Ok(Self { kernels, receivers })
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
        let n = scene.flat.sparse_count().div_ceil(self.receivers);
        self.kernels.run(gpu, e, scene, &resources, [n, 1, 1], span);
    }
}
