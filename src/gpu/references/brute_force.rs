//! Brute-force reference (`brute_force.wgsl`, docs/design.md §5). Rust twin:
//! `twin::shade_brute_force`. On CPU adapters the VALs go in ranges, one dispatch each,
//! each adding to the radiance of the ones before ([`Kernels::val_ranges`]).
//!
//! **`brute_force_ism`** (the renderer's `Method::BruteForceIsm`): the same pass with every
//! VAL weighted by its group's imperfect-shadow-map lookup at the pixel, so that the ISMs' own
//! error against exact visibility can be told from the sparse interpolation's. The `ism`
//! mode's machinery as the sparse method runs it (`settings.ism`: VALs drawn by flux, groups,
//! splat, pull-push; [`Clusters`] with [`Receivers::Pixels`]), its stages named
//! `brute_force_ism_*`, its lookup (`brute_force_ism_visibility`,
//! `brute_force_visibility.wgsl`) at every (pixel, group) into a table of pixels x groups
//! (`ism.count` floats per pixel: 64 MiB at 128² with 1,024 maps; larger than the device's
//! largest storage binding is an error naming it), then the brute force reading it
//! (`visibility/group.wgsl`). Rust twin: `twin::shade_brute_force_grouped`.
//!
//! **`brute_force_clusters`** (`Method::BruteForceClusters`): the same with the `clusters`
//! mode's groups and maps (`settings.tuning.clusters`: k-means, rasterised shadow maps, or
//! imperfect ones with `shadow_maps: "ism"`; shadow rays serve sparse points only, so `"rays"`
//! gets rasterised maps here), its stages named `brute_force_clusters_*`: the clusters'
//! visibility looked up where the light lands instead of at the sparse points, so the maps'
//! own error and the sparse sampling's separate. Its clusters (at most 256) are looked up in
//! the brute force's own pass, each invocation every cluster at its pixels before the VALs
//! (`brute_force_lookup.wgsl`, [`Receivers::InPass`]): no table, so any image size fits.

use crate::gpu::pass::{Binding, Entry, Kernels, PassDesc, buffer, depth_texture, read, read_write, texture, view};
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::{IMAGE_TILE, TILE_SIZE, VAL_TILES, WORKGROUP_SIZE, Wgsl};
use crate::gpu::technique::{Frame, Technique};
use crate::gpu::timing::Recorder;
use crate::gpu::visibility::clusters::{self, Clusters, Receivers, SceneScale, StageNames};
use crate::gpu::visibility::{GroupVisibility, VisibilitySettings, group_wgsl, ism};
use crate::gpu::{Gpu, GpuError};
use crate::scene::{ClusterSettings, IsmSettings, Occlusion};

pub const WGSL: &str = include_str!("brute_force.wgsl");
pub const VISIBILITY_WGSL: &str = include_str!("brute_force_visibility.wgsl");
/// `brute_force_clusters`' lookup in its own pass.
pub const LOOKUP_WGSL: &str = include_str!("brute_force_lookup.wgsl");

/// Stage of the lookup at the pixels.
pub const ISM_VISIBILITY_STAGE: &str = "brute_force_ism_visibility";

/// The stages of `brute_force_ism`'s groups and maps (the sparse method's `ism` mode keeps its
/// own names).
pub const ISM_STAGES: StageNames = StageNames {
    clustering: "brute_force_clustering",
    shadow_maps: "brute_force_cluster_shadow_maps",
    ism_sampling: "brute_force_ism_sampling",
    ism_splat: "brute_force_ism_splat",
    ism_pull_push: "brute_force_ism_pull_push",
    cluster_visibility: ISM_VISIBILITY_STAGE,
    ism_visibility: ISM_VISIBILITY_STAGE,
};

/// How the brute force's VALs are seen from the pixels.
#[derive(Clone, Copy, Debug)]
pub enum PixelVisibility<'a> {
    /// Not at all: every VAL reaches every pixel.
    None,
    /// Through a table of pixels x `groups`, filled before the pass (`brute_force_ism`).
    Table { groups: u32 },
    /// Through the clusters' maps, looked up in the pass (`brute_force_clusters`): the lookup's
    /// header ([`Clusters::lookup_header`]) and whether the maps are imperfect.
    InPass { head: &'a str, imperfect: bool },
}

/// `prepare_visibility` and `pixel_val_visibility` through `val_visibility` (no visibility, or
/// the table's entry at the pixel).
const TABLE_HOOK: &str = "fn prepare_visibility(receivers: ptr<function, array<Receiver, PIXELS>>) {}\n\
                          fn pixel_val_visibility(r: Receiver, slot: u32, val: u32) -> f32 {\n    \
                          return val_visibility(r.pixel, val);\n}\n";

/// The pass's own WGSL: the VAL tiles, the pixels' `visibility`, then `brute_force.wgsl`.
pub fn body(visibility: PixelVisibility<'_>, pixels: u32) -> String {
    let visibility = match visibility {
        PixelVisibility::None => group_wgsl(None, 4) + TABLE_HOOK,
        PixelVisibility::Table { groups } => group_wgsl(Some(groups), 4) + TABLE_HOOK,
        PixelVisibility::InPass { head, imperfect } => {
            clusters::lookup_pass_body(head, imperfect, IN_PASS_BINDINGS, &[LOOKUP_WGSL])
        }
    };
    let adds: String = (0..pixels)
        .map(|r| format!("    (*ls)[{r}] = add_val((*ls)[{r}], (*receivers)[{r}], {r}u, val, val_index, glossy);\n"))
        .collect();
    // `add_to_pixels`, unrolled: one statement per pixel.
    let add_to_pixels = format!(
        "fn add_to_pixels(ls: ptr<function, array<vec3<f32>, PIXELS>>, receivers: ptr<function, array<Receiver, PIXELS>>, \
         val: Val, val_index: u32, glossy: bool) {{\n{adds}}}\n"
    );
    Wgsl::new()
        .include(VAL_TILES)
        .include(&visibility)
        .u32("PIXELS", pixels)
        .include(&add_to_pixels)
        .include(WGSL)
        .finish()
}

/// Pixels per invocation on CPU adapters (a row's consecutive pixels share each VAL read from
/// workgroup memory, as the gather's points do: `gather::CPU_RECEIVERS`); GPUs take one.
pub const CPU_PIXELS: u32 = 4;

/// Pixels per invocation on `gpu`.
pub fn pixels_for(gpu: &Gpu) -> u32 {
    if gpu.is_cpu() { CPU_PIXELS } else { 1 }
}

/// The bindings of [`GROUPED_PASS`]; [`PASS`] has the first four.
const BINDINGS: &[Binding] = &[
    texture("visibility"),
    read_write("indirect"),
    read("vals"),
    read("val_count"),
    read("group_of_val"),
    read("group_visibility"),
];

/// One invocation per pixel; a workgroup (`IMAGE_TILE[0]` pixels wide, `TILE_SIZE` in all)
/// streams VALs through workgroup memory in tiles of `TILE_SIZE`.
pub const PASS: PassDesc = PassDesc {
    label: "brute_force",
    bindings: BINDINGS.split_at(4).0,
    entries: &[Entry::first("main", 4), Entry::first("main_glossy", 4)],
    workgroup: [IMAGE_TILE[0], TILE_SIZE / IMAGE_TILE[0], 1],
    default_source: |textured| PASS.source(&body(PixelVisibility::None, CPU_PIXELS), textured),
};

/// `brute_force_ism`'s pass: [`PASS`] plus the group table at the pixels.
pub const GROUPED_PASS: PassDesc = PassDesc {
    bindings: BINDINGS,
    entries: &[Entry::first("main", 6), Entry::first("main_glossy", 6)],
    default_source: |textured| GROUPED_PASS.source(&body(PixelVisibility::Table { groups: 64 }, CPU_PIXELS), textured),
    ..PASS
};

/// The bindings of the clusters and their maps in `brute_force_clusters`' pass, after
/// [`PASS`]'s and `group_of_val`.
const IN_PASS_BINDINGS: [u32; 2] = [5, 6];

/// `brute_force_clusters`' bindings: [`PASS`]'s, each VAL's cluster, the clusters and `maps`.
const fn in_pass_bindings(maps: Binding) -> [Binding; 7] {
    [
        texture("visibility"),
        read_write("indirect"),
        read("vals"),
        read("val_count"),
        read("group_of_val"),
        read("clusters"),
        maps,
    ]
}

/// `brute_force_clusters`' WGSL with the default settings' header, for `imperfect` maps or
/// rasterised ones (the passes' `default_source`).
fn in_pass_default_source(desc: &PassDesc, imperfect: bool, textured: bool) -> String {
    let scale = SceneScale { diagonal: 1.0 };
    let head = match imperfect {
        true => ism::header(&IsmSettings::default(), scale),
        false => clusters::header(&ClusterSettings::default(), scale),
    };
    desc.source(&body(PixelVisibility::InPass { head: &head, imperfect }, CPU_PIXELS), textured)
}

/// `brute_force_clusters`' pass with rasterised maps: [`PASS`] plus each VAL's cluster, the
/// clusters and their maps, looked up in the pass.
pub const IN_PASS_RASTER: PassDesc = PassDesc {
    bindings: &in_pass_bindings(depth_texture("shadow_atlas")),
    entries: &[Entry::first("main", 7), Entry::first("main_glossy", 7)],
    default_source: |textured| in_pass_default_source(&IN_PASS_RASTER, false, textured),
    ..PASS
};

/// `brute_force_clusters`' pass with imperfect maps (`shadow_maps: "ism"`).
pub const IN_PASS_ISM: PassDesc = PassDesc {
    bindings: &in_pass_bindings(read("ism_atlas")),
    default_source: |textured| in_pass_default_source(&IN_PASS_ISM, true, textured),
    ..IN_PASS_RASTER
};

/// The stages of `brute_force_clusters`' groups and maps (imperfect ones with
/// `shadow_maps: "ism"`); the lookup is in the brute force's own stage.
pub const CLUSTERS_STAGES: StageNames = StageNames {
    clustering: "brute_force_clusters_clustering",
    shadow_maps: "brute_force_clusters_shadow_maps",
    ism_sampling: "brute_force_clusters_ism_sampling",
    ism_splat: "brute_force_clusters_ism_splat",
    ism_pull_push: "brute_force_clusters_ism_pull_push",
    cluster_visibility: "brute_force",
    ism_visibility: "brute_force",
};

/// The lookup at the pixels, reading imperfect shadow maps.
pub const ISM_VISIBILITY: PassDesc = PassDesc {
    label: ISM_VISIBILITY_STAGE,
    bindings: &[texture("visibility"), read("clusters"), read("ism_atlas"), read_write("group_visibility")],
    entries: &[Entry::first("main", 4)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        let head = ism::header(&IsmSettings::default(), SceneScale { diagonal: 1.0 });
        ISM_VISIBILITY.source(&visibility_body(&head), textured)
    },
};

/// The lookup pass's WGSL after `head`, reading imperfect maps.
fn visibility_body(head: &str) -> String {
    clusters::lookup_pass_body(head, true, [1, 2], &[VISIBILITY_WGSL])
}

/// The lookup pass at the pixels and its WGSL after `head` ([`Clusters`] with
/// [`Receivers::Pixels`] builds it); imperfect maps only (`brute_force_clusters` looks its
/// maps up in its own pass).
pub fn visibility_pass(head: &str, imperfect: bool) -> (&'static PassDesc, String) {
    assert!(imperfect, "brute_force_ism's table holds imperfect shadow maps' lookups");
    (&ISM_VISIBILITY, visibility_body(head))
}

pub struct BruteForce {
    kernels: Kernels,
    /// `brute_force_ism` and `brute_force_clusters`: the groups and their maps, looked up at
    /// the pixels.
    groups: Option<Clusters>,
    /// Pixels of a row per invocation.
    pixels: u32,
}

impl BruteForce {
    /// The brute force; with `groups` (its mode `ism` or `clusters`), `brute_force_ism` or
    /// `brute_force_clusters` with those settings.
    pub fn new(
        gpu: &Gpu,
        scene: &GpuScene,
        glossy: bool,
        groups: Option<&VisibilitySettings>,
    ) -> Result<Self, GpuError> {
        let groups = match groups {
            // The imperfect maps' groups (up to 1,024) through a table; the clusters (up to 256)
            // looked up in the pass.
            Some(v) if v.mode == Occlusion::Ism => {
                Clusters::for_receivers(gpu, scene, v, Receivers::Pixels, ISM_STAGES)?
            }
            Some(v) => Clusters::for_receivers(gpu, scene, v, Receivers::InPass, CLUSTERS_STAGES)?,
            None => None,
        };
        let (desc, visibility) = match &groups {
            None => (&PASS, PixelVisibility::None),
            Some(g) => match g.imperfect_maps() {
                Some(imperfect) if g.lookup_in_pass() => (
                    if imperfect { &IN_PASS_ISM } else { &IN_PASS_RASTER },
                    PixelVisibility::InPass { head: g.lookup_header(), imperfect },
                ),
                _ => (&GROUPED_PASS, PixelVisibility::Table { groups: g.table().groups }),
            },
        };
        let pixels = pixels_for(gpu);
        let source = desc.source(&body(visibility, pixels), scene.textured());
        let entry = desc.lobe_entry(glossy);
        let kernels = Kernels::val_ranges(gpu, scene, desc, source, entry, desc.workgroup, TILE_SIZE)?;
        Ok(Self { kernels, groups, pixels })
    }

    /// Cover frames of up to `max_vals` VALs (see [`Kernels::fit`]) and `pixels` pixels.
    pub fn fit(&mut self, gpu: &Gpu, scene: &GpuScene, max_vals: u32, pixels: u32) -> Result<(), GpuError> {
        if let Some(g) = &mut self.groups {
            g.fit(gpu, max_vals)?;
            g.fit_receivers(gpu, pixels)?;
        }
        self.kernels.fit(gpu, scene, max_vals)
    }

    /// `brute_force_ism`'s or `brute_force_clusters`' groups and maps (tests read them back).
    pub fn groups(&self) -> Option<&Clusters> {
        self.groups.as_ref()
    }
}

impl Technique for BruteForce {
    fn stages(&self) -> Vec<&'static str> {
        let mut stages = self.groups.as_ref().map_or_else(Vec::new, |g| g.stage_names());
        stages.push(PASS.label);
        stages
    }

    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError> {
        let camera = &frame.camera;
        let pixels = [camera.view.width, camera.view.height, 1];
        if let Some(g) = &self.groups {
            g.record_at(gpu, frame, rec, view("visibility", &camera.view.view), pixels[0] * pixels[1])?;
        }
        let mut resources = vec![
            view("visibility", &camera.view.view),
            buffer("indirect", &camera.indirect),
            buffer("vals", &frame.vals.buffer),
            buffer("val_count", &frame.vals.count),
        ];
        if let Some(g) = &self.groups {
            let t = g.table();
            resources.push(buffer("group_of_val", t.group_of_val));
            match g.lookup_resources().filter(|_| g.lookup_in_pass()) {
                Some(lookup) => resources.extend(lookup),
                None => resources.push(buffer("group_visibility", t.visibility)),
            }
        }
        let invocations = [pixels[0].div_ceil(self.pixels), pixels[1], 1];
        rec.stage(PASS.label, |e, s| self.kernels.run(gpu, e, frame.scene, &resources, invocations, s))
    }
}
