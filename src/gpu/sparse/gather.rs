//! Gather at sparse points (`gather.wgsl`, docs/design.md §4 step 1). Rust twin:
//! `twin::gather_point`. With a group visibility mode ([`GROUPED_PASS`]) every VAL's
//! contribution is scaled by its group's visibility at the point
//! ([`crate::gpu::visibility::GroupTable`]).
//!
//! On a CPU adapter one invocation may not loop over more than about
//! [`Gpu::CPU_MAX_GATHERED_VALS`] VALs (llvmpipe ends a shader's loops after
//! [`crate::gpu::LLVMPIPE_LOOP_LIMIT`] iterations, silently), so there the VALs are gathered in
//! ranges, one dispatch each, every range merging into the sums of the ones before
//! ([`Kernels::val_ranges`]). GPUs take every VAL in one dispatch, and share each sparse point
//! among [`GPU_LANES`] invocations ([`lanes_for`]).

use crate::gpu::pass::{Binding, Entry, Kernels, PassDesc, buffer, read, read_write, with_lobes};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
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

/// Which sparse points a gather's receiver slots are (`receiver_point` in `gather.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Receivers {
    /// Slot i is point `first + i`, up to `end`: a range of the points gathered every frame
    /// (those before the adaptive candidates, `settings.sparse.adaptive`).
    Span { first: u32, end: u32 },
    /// Slot i is the i-th entry of the frame's list of chosen adaptive candidates
    /// (`adaptive.wgsl`'s `compact`), bound at [`LIST_BINDING`].
    Chosen,
}

/// The binding of the chosen candidates' list; their count is at the next.
pub const LIST_BINDING: u32 = 7;

/// The pass's own WGSL: the VAL tiles, `val_visibility` for `groups` groups (or none), the
/// receivers per invocation, whether the glossy mean position is summed, then `gather.wgsl`.
/// `near_radius` (m): the near-field radius whose share the gather leaves out (0: none).
pub fn body(groups: Option<u32>, near_radius: f32, receivers: u32, lobes: GatherLobes) -> String {
    list_body(groups, near_radius, (receivers, 1), lobes, Receivers::Span { first: 0, end: u32::MAX })
}

/// [`body`] for the receiver slots `slots`, with `(receivers, lanes)`: sparse points per
/// invocation, and invocations per sparse point for the `_lanes` entry points.
pub fn list_body(
    groups: Option<u32>,
    near_radius: f32,
    (receivers, lanes): (u32, u32),
    lobes: GatherLobes,
    slots: Receivers,
) -> String {
    let visibility = group_wgsl(groups, 5);
    let glossy_mean = lobes == GatherLobes::GlossyLights;
    let points = match slots {
        Receivers::Span { first, end } => format!(
            "fn receiver_point(slot: u32) -> u32 {{\n    if slot < min({end}u, frame.sparse_count) - {first}u {{\n        \
             return {first}u + slot;\n    }}\n    return NO_POINT;\n}}\n"
        ),
        Receivers::Chosen => format!(
            "@group(0) @binding({LIST_BINDING}) var<storage, read> receiver_list: array<u32>;\n\
             @group(0) @binding({}) var<storage, read> receiver_count: u32;\n\
             fn receiver_point(slot: u32) -> u32 {{\n    if slot < min(receiver_count, arrayLength(&receiver_list)) {{\n        \
             return receiver_list[slot];\n    }}\n    return NO_POINT;\n}}\n",
            LIST_BINDING + 1
        ),
    };
    Wgsl::new()
        .include(VAL_TILES)
        .include(&visibility)
        .u32("RECEIVERS", receivers)
        .u32("LANES", lanes)
        .include(&add_to_receivers(receivers))
        .include(&points)
        .f32("NEAR_FIELD_RADIUS", near_radius)
        .bool("GLOSSY_MEAN", glossy_mean)
        .include(WGSL)
        .finish()
}

/// `add_to_receivers` (`gather.wgsl`) for `RECEIVERS` = `receivers`: one VAL added to each of
/// the sums, one statement per receiver.
fn add_to_receivers(receivers: u32) -> String {
    let adds: String = (0..receivers)
        .map(|r| format!("    (*sums)[{r}] = add_val((*sums)[{r}], (*receivers)[{r}], val, val_index, glossy);\n"))
        .collect();
    format!(
        "fn add_to_receivers(sums: ptr<function, array<Sums, RECEIVERS>>, receivers: ptr<function, array<Receiver, RECEIVERS>>, \
         val: Val, val_index: u32, glossy: bool) {{\n{adds}}}\n"
    )
}

/// Sparse points per invocation on CPU adapters, measured by the bench's gather variants
/// (docs/measurements/gather-variants.md); GPUs take one, and share it among [`GPU_LANES`]
/// invocations, for parallelism (a frame has only thousands of points).
pub const CPU_RECEIVERS: u32 = 8;

/// The most sparse points one invocation may take (the bench's and the tests' range).
pub const MAX_RECEIVERS: u32 = 8;

/// Sparse points per invocation on `gpu`.
pub fn receivers_for(gpu: &Gpu) -> u32 {
    if gpu.is_cpu() { CPU_RECEIVERS } else { 1 }
}

/// Invocations per sparse point on GPUs (`main_lanes` in `gather.wgsl`): with one each, an
/// H200 gathered 8,192 points at 8·10¹⁰ pairs/s where the brute force's million pixels ran at
/// 5·10¹¹ (docs/measurements/gpu.md), most of its threads idle. Not yet measured on a GPU:
/// the bench's gather variants time 1, 4, 8, 16 and 32 side by side.
pub const GPU_LANES: u32 = 8;

/// The most invocations per sparse point (at most a workgroup).
pub const MAX_LANES: u32 = 64;

/// Invocations per sparse point on `gpu`: CPU adapters take several points per invocation
/// instead ([`receivers_for`]), whose lanes are SIMD lanes already; `gpu.gather_lanes`
/// (`RELUME_GATHER_LANES`) overrides.
pub fn lanes_for(gpu: &Gpu) -> u32 {
    gpu.gather_lanes.unwrap_or(if gpu.is_cpu() { 1 } else { GPU_LANES })
}

/// The bindings of [`CHOSEN_PASS`]; [`GROUPED_PASS`] has the first seven (no list), [`PASS`]
/// the first five (no group table).
const BINDINGS: &[Binding] = &[
    read("sparse_points"),
    read("vals"),
    read("val_count"),
    read_write("gathered_diffuse"),
    read_write("gathered_glossy"),
    read("group_of_val"),
    read("group_visibility"),
    read("receiver_list"),
    read("receiver_count"),
];

/// One invocation per sparse point, `TILE_SIZE` per workgroup (the tile is the workgroup's).
pub const PASS: PassDesc = PassDesc {
    label: "gather",
    bindings: BINDINGS.split_at(5).0,
    entries: &[
        Entry::first("main", 4),
        Entry::first("main_glossy", 5),
        Entry::first("main_lanes", 4),
        Entry::first("main_glossy_lanes", 5),
    ],
    workgroup: [TILE_SIZE, 1, 1],
    default_source: |textured| PASS.source(&body(None, 0.0, CPU_RECEIVERS, GatherLobes::GlossyLights), textured),
};

/// The gather of a group visibility mode: [`PASS`] plus the group table.
pub const GROUPED_PASS: PassDesc = PassDesc {
    bindings: BINDINGS.split_at(7).0,
    entries: &[
        Entry { name: "main", bindings: 7, except: &["gathered_glossy"] },
        Entry::first("main_glossy", 7),
        Entry { name: "main_lanes", bindings: 7, except: &["gathered_glossy"] },
        Entry::first("main_glossy_lanes", 7),
    ],
    default_source: |textured| {
        GROUPED_PASS.source(&body(Some(64), 0.0, CPU_RECEIVERS, GatherLobes::GlossyLights), textured)
    },
    ..PASS
};

/// The gather at the adaptive candidates a frame chose ([`Receivers::Chosen`]), without a
/// group visibility mode.
pub const CHOSEN_PASS: PassDesc = PassDesc {
    label: "adaptive_gather",
    bindings: BINDINGS,
    entries: &[
        Entry { name: "main", bindings: 9, except: &["gathered_glossy", "group_of_val", "group_visibility"] },
        Entry { name: "main_glossy", bindings: 9, except: &["group_of_val", "group_visibility"] },
        Entry { name: "main_lanes", bindings: 9, except: &["gathered_glossy", "group_of_val", "group_visibility"] },
        Entry { name: "main_glossy_lanes", bindings: 9, except: &["group_of_val", "group_visibility"] },
    ],
    default_source: |textured| {
        let body = list_body(None, 0.0, (CPU_RECEIVERS, 1), GatherLobes::GlossyLights, Receivers::Chosen);
        CHOSEN_PASS.source(&body, textured)
    },
    ..PASS
};

/// [`CHOSEN_PASS`] with a group visibility mode's table.
pub const CHOSEN_GROUPED_PASS: PassDesc = PassDesc {
    entries: &[
        Entry { name: "main", bindings: 9, except: &["gathered_glossy"] },
        Entry::first("main_glossy", 9),
        Entry { name: "main_lanes", bindings: 9, except: &["gathered_glossy"] },
        Entry::first("main_glossy_lanes", 9),
    ],
    default_source: |textured| {
        let body = list_body(Some(64), 0.0, (CPU_RECEIVERS, 1), GatherLobes::GlossyLights, Receivers::Chosen);
        CHOSEN_GROUPED_PASS.source(&body, textured)
    },
    ..CHOSEN_PASS
};

pub struct Gather {
    kernels: Kernels,
    /// Sparse points per invocation.
    receivers: u32,
    /// Invocations per sparse point (with one point per invocation).
    lanes: u32,
    /// Which points its slots are.
    slots: Receivers,
    /// Whether it writes the glossy sums (binds them).
    glossy: bool,
}

/// How a gather is built: what it sums ([`Gather::new`]), its tile and points per invocation.
#[derive(Clone, Copy)]
struct Shape {
    lobes: GatherLobes,
    groups: Option<u32>,
    near_radius: f32,
    tile_size: u32,
    receivers: u32,
    lanes: u32,
    slots: Receivers,
}

/// What a gather reads and writes: the scene's sparse points, the frame's VALs, the sums it
/// adds to, and a group visibility mode's table.
#[derive(Clone, Copy)]
pub struct GatherInput<'a> {
    pub scene: &'a GpuScene,
    pub vals: &'a Vals,
    pub gathered: &'a Lobes,
    pub groups: Option<&'a GroupTable<'a>>,
}

/// The chosen adaptive candidates' list and count (`adaptive.wgsl`'s `compact`), and how many
/// slots the list has (the frame's budget).
pub struct ChosenList<'a> {
    pub list: &'a wgpu::Buffer,
    pub count: &'a wgpu::Buffer,
    pub slots: u32,
}

impl Gather {
    /// `lobes` says what to sum (a glossy one builds the entry point that also gathers the
    /// Phong lobe); `groups`, the group count of a group visibility mode, the one that reads
    /// its table. `near_radius` (m): leave out each VAL's near-field share at that radius (0:
    /// none). `slots`: the points it gathers at, a span of those gathered every frame
    /// ([`Gather::record`]) or the adaptive candidates each frame chooses
    /// ([`Gather::record_chosen`]).
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        lobes: GatherLobes,
        groups: Option<u32>,
        near_radius: f32,
        slots: Receivers,
    ) -> Result<Self, GpuError> {
        let mut lanes = lanes_for(gpu);
        // Shared points take one each.
        let receivers = if lanes > 1 { 1 } else { receivers_for(gpu) };
        // Fewer lanes where the scene's points would take the dispatch past the device's
        // workgroups per dimension (one workgroup per TILE_SIZE invocations).
        let points = scene.flat.sparse_points.len() as u64;
        let most = u64::from(gpu.device.limits().max_compute_workgroups_per_dimension);
        while lanes > 1 && (points * u64::from(lanes)).div_ceil(u64::from(TILE_SIZE)) > most {
            lanes /= 2;
        }
        Self::build(gpu, scene, Shape { lobes, groups, near_radius, tile_size: TILE_SIZE, receivers, lanes, slots })
    }

    /// The pass with `tile_size` VALs per tile and threads per workgroup instead of
    /// [`TILE_SIZE`], and `(receivers, lanes)` instead of [`receivers_for`]'s and
    /// [`lanes_for`]'s: 1..=[`MAX_RECEIVERS`] sparse points per invocation, or one point shared
    /// by `lanes` (a divisor of `tile_size`, at most [`MAX_LANES`]) invocations; at every point
    /// gathered every frame, without visibility groups or near field (the bench compares them;
    /// the device must allow the workgroup size).
    pub fn variant(
        gpu: &Gpu,
        scene: &GpuScene,
        lobes: GatherLobes,
        tile_size: u32,
        (receivers, lanes): (u32, u32),
    ) -> Result<Self, GpuError> {
        let slots = Receivers::Span { first: 0, end: scene.flat.base_sparse_count() };
        let shape = Shape { lobes, groups: None, near_radius: 0.0, tile_size, receivers, lanes, slots };
        Self::build(gpu, scene, shape)
    }

    fn build(gpu: &Gpu, scene: &GpuScene, shape: Shape) -> Result<Self, GpuError> {
        let Shape { lobes, groups, near_radius, tile_size, receivers, lanes, slots } = shape;
        assert!((1..=MAX_RECEIVERS).contains(&receivers), "{receivers} receivers per invocation");
        assert!(
            (1..=MAX_LANES).contains(&lanes) && tile_size.is_multiple_of(lanes) && (lanes == 1 || receivers == 1),
            "{lanes} lanes per point ({receivers} points per invocation, tile {tile_size})"
        );
        let workgroup = [tile_size, 1, 1];
        let desc = match (groups.is_some(), slots) {
            (false, Receivers::Span { .. }) => &PASS,
            (true, Receivers::Span { .. }) => &GROUPED_PASS,
            (false, Receivers::Chosen) => &CHOSEN_PASS,
            (true, Receivers::Chosen) => &CHOSEN_GROUPED_PASS,
        };
        let body = list_body(groups, near_radius, (receivers, lanes), lobes, slots);
        let source = desc.source_with(&body, scene.textured(), workgroup, tile_size);
        let entry = match (lobes.glossy(), lanes > 1) {
            (false, false) => desc.entry("main"),
            (true, false) => desc.entry("main_glossy"),
            (false, true) => desc.entry("main_lanes"),
            (true, true) => desc.entry("main_glossy_lanes"),
        };
        let kernels = Kernels::val_ranges(gpu, scene, desc, source, entry, workgroup, tile_size)?;
        Ok(Self { kernels, receivers, lanes, slots, glossy: lobes.glossy() })
    }

    /// Cover frames of up to `max_vals` VALs (see [`Kernels::fit`]).
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32) -> Result<(), GpuError> {
        self.kernels.fit(gpu, scene, max_vals)
    }

    /// Gather `input.vals` at its points (by default every point gathered every frame) into
    /// `input.gathered`, with the input's group visibility when built for a group visibility
    /// mode; timed by `span` (or its share of a stage: [`Span::share`], with [`Gather::parts`]
    /// dispatches).
    pub fn record(&self, gpu: &Gpu, e: &mut wgpu::CommandEncoder, input: &GatherInput<'_>, span: Option<Span<'_>>) {
        let Receivers::Span { first, end } = self.slots else {
            panic!("the chosen candidates' gather needs their list");
        };
        let resources = self.resources(input);
        let n = (end.min(input.scene.flat.base_sparse_count()) - first).div_ceil(self.receivers) * self.lanes;
        self.kernels.run(gpu, e, input.scene, &resources, [n, 1, 1], span);
    }

    /// How many dispatches [`Gather::record`] makes (its VAL ranges).
    pub fn parts(&self) -> usize {
        self.kernels.len()
    }

    /// Gather at the adaptive candidates in `chosen`'s list into their entries of
    /// `input.gathered` (one slot per entry of the budget; slots past the frame's count do
    /// nothing).
    pub fn record_chosen(
        &self,
        gpu: &Gpu,
        e: &mut wgpu::CommandEncoder,
        (input, chosen): (&GatherInput<'_>, &ChosenList<'_>),
        span: Option<Span<'_>>,
    ) {
        assert_eq!(self.slots, Receivers::Chosen, "the gather of the points gathered every frame takes no list");
        let mut resources = self.resources(input);
        resources.extend([buffer("receiver_list", chosen.list), buffer("receiver_count", chosen.count)]);
        let n = chosen.slots.div_ceil(self.receivers) * self.lanes;
        self.kernels.run(gpu, e, input.scene, &resources, [n, 1, 1], span);
    }

    fn resources<'a>(&self, input: &GatherInput<'a>) -> Vec<crate::gpu::pass::Res<'a>> {
        let GatherInput { scene, vals, gathered, groups } = *input;
        let fixed = vec![
            buffer("sparse_points", &scene.sparse_points),
            buffer("vals", &vals.buffer),
            buffer("val_count", &vals.count),
        ];
        let mut resources = if self.glossy {
            with_lobes(fixed, &[(gathered, "gathered_diffuse", "gathered_glossy")])
        } else {
            // The diffuse entry point, also where the scene has glossy sums (for other points).
            let mut fixed = fixed;
            fixed.push(buffer("gathered_diffuse", &gathered.diffuse));
            fixed
        };
        if let Some(g) = groups {
            resources.extend([buffer("group_of_val", g.group_of_val), buffer("group_visibility", g.visibility)]);
        }
        resources
    }
}
