//! Per-vertex interpolation (`interpolate.wgsl`, docs/design.md §4 step 4): each vertex averages the
//! point lights of its nearest sparse points with the scene's kernel, and carries their bound.
//! Rust twins: `twin::interpolation_weights`, `twin::interpolate_lights`. Run by
//! [`super::SparseMethod`].

use crate::gpu::pass::{Binding, Entry, PassDesc, Res, buffer, read, read_write};
use crate::gpu::shader::WORKGROUP_SIZE;
use crate::gpu::shader::Wgsl;
use crate::scene::{InterpolationKernel, LightBound};

pub const WGSL: &str = include_str!("interpolate.wgsl");

/// The interpolation weights over a receiver's sparse neighbours, which the adaptive
/// candidates' score shares (`interpolation_weights.wgsl`).
pub const WEIGHTS_WGSL: &str = include_str!("interpolation_weights.wgsl");

/// The weights' constants for `neighbours` sparse points per receiver and the `kernel`, then
/// [`WEIGHTS_WGSL`]: what a pass using `neighbourhood_at` prepends.
pub fn weights_head(neighbours: u32, kernel: InterpolationKernel) -> String {
    let smooth = kernel == InterpolationKernel::Smooth;
    Wgsl::new()
        .u32("NEIGHBOURS", neighbours)
        .bool("SMOOTH_KERNEL", smooth)
        .f32("PLANE_FALLOFF", crate::twin::PLANE_FALLOFF)
        .f32("FACING_EPSILON", crate::twin::FACING_EPSILON)
        .include(WEIGHTS_WGSL)
        .finish()
}

/// The adaptive candidates' part of a vertex's neighbourhood (`adaptive_candidates.wgsl`).
pub const CANDIDATES_WGSL: &str = include_str!("adaptive_candidates.wgsl");

/// The pass's own WGSL for `neighbours` sparse points per vertex, the `kernel`'s weights and
/// the `bound`; `base_points`: with adaptive candidates, how many points come before them
/// ([`ADAPTIVE_PASS`]).
pub fn body(neighbours: u32, kernel: InterpolationKernel, bound: LightBound, base_points: Option<u32>) -> String {
    let bounded = bound == LightBound::Gathered;
    let head = Wgsl::new()
        .include(&weights_head(neighbours, kernel))
        .bool("BOUNDED", bounded)
        .f32("BOUND_WEIGHT_FLOOR", crate::twin::BOUND_WEIGHT_FLOOR);
    let head = match base_points {
        None => head.expression("ROW", "u32", "NEIGHBOURS").include(
            "fn adaptive_candidates(v: u32, nb: VertexNeighbourhood, d_max: f32) -> VertexNeighbourhood {\n    \
             return nb;\n}\n",
        ),
        Some(base) => {
            head.expression("ROW", "u32", "2u * NEIGHBOURS").u32("BASE_POINTS", base).include(CANDIDATES_WGSL)
        }
    };
    head.include(WGSL).finish()
}

/// The bindings of both passes: [`PASS`] leaves out the candidates' two. Every entry runs
/// over `vertex_list` (the vertices to light: all of them, or those of the camera's simplified
/// triangles, `GpuScene::camera_vertices`).
const BINDINGS: &[Binding] = &[
    read("sparse_points"),
    read("vertex_neighbours"),
    read("sparse_diffuse"),
    read_write("vertex_diffuse"),
    read("sparse_glossy"),
    read_write("vertex_glossy"),
    read_write("vertex_centres"),
    read("gathered_glossy"),
    read_write("vertex_glossy_radiance"),
    read("vertex_candidates"),
    read("chosen"),
    read("vertex_list"),
];

/// One invocation per vertex of `vertex_list`.
pub const PASS: PassDesc = PassDesc {
    label: "interpolate",
    bindings: BINDINGS,
    entries: &ENTRIES,
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        let body = body(crate::scene::DEFAULT_NEIGHBOURS, InterpolationKernel::default(), LightBound::default(), None);
        PASS.source(&body, textured)
    },
};

/// The entry points, each with the bindings it leaves out; the last two of each list are the
/// candidates' ([`ADAPTIVE_ENTRIES`] binds them).
const ENTRIES: [Entry; 4] = [
    Entry {
        name: "main",
        bindings: 12,
        except: &[
            "sparse_glossy",
            "vertex_glossy",
            "vertex_centres",
            "gathered_glossy",
            "vertex_glossy_radiance",
            "vertex_candidates",
            "chosen",
        ],
    },
    Entry {
        name: "main_glossy",
        bindings: 12,
        except: &["vertex_centres", "gathered_glossy", "vertex_glossy_radiance", "vertex_candidates", "chosen"],
    },
    Entry {
        name: "centres",
        bindings: 12,
        except: &[
            "sparse_diffuse",
            "vertex_diffuse",
            "sparse_glossy",
            "vertex_glossy",
            "gathered_glossy",
            "vertex_glossy_radiance",
            "vertex_candidates",
            "chosen",
        ],
    },
    Entry {
        name: "main_glossy_radiance",
        bindings: 12,
        except: &["sparse_glossy", "vertex_glossy", "vertex_centres", "vertex_candidates", "chosen"],
    },
];

/// [`ENTRIES`] binding the candidates too.
const ADAPTIVE_ENTRIES: [Entry; 4] = [
    with_candidates(ENTRIES[0]),
    with_candidates(ENTRIES[1]),
    with_candidates(ENTRIES[2]),
    with_candidates(ENTRIES[3]),
];

const fn with_candidates(entry: Entry) -> Entry {
    Entry { except: entry.except.split_at(entry.except.len() - 2).0, ..entry }
}

/// [`PASS`] for a scene with adaptive candidates: every entry also reads each vertex's nearest
/// candidates and which were chosen this frame (`adaptive_candidates.wgsl`).
pub const ADAPTIVE_PASS: PassDesc = PassDesc {
    bindings: BINDINGS,
    entries: &ADAPTIVE_ENTRIES,
    default_source: |textured| {
        let neighbours = crate::scene::DEFAULT_NEIGHBOURS;
        let body = body(neighbours, InterpolationKernel::default(), LightBound::default(), Some(64));
        ADAPTIVE_PASS.source(&body, textured)
    },
    ..PASS
};

/// The interpolation pass for a scene with (`adaptive`) or without adaptive candidates.
pub fn pass(adaptive: bool) -> &'static PassDesc {
    if adaptive { &ADAPTIVE_PASS } else { &PASS }
}

/// The resources [`ADAPTIVE_PASS`] binds after [`PASS`]'s: `chosen` per candidate.
pub fn adaptive_resources<'a>(scene: &'a crate::gpu::scene::GpuScene, chosen: &'a wgpu::Buffer) -> [Res<'a>; 2] {
    let candidates = scene.vertex_candidates.as_ref().expect("a scene with adaptive candidates");
    [buffer("vertex_candidates", candidates), buffer("chosen", chosen)]
}
