//! Per-vertex interpolation (`interpolate.wgsl`, DESIGN.md §4 step 4): each vertex averages the
//! point lights of its nearest sparse points with the scene's kernel, and carries their bound.
//! Rust twins: `twin::interpolation_weights`, `twin::interpolate_lights`. Run by
//! [`super::SparseMethod`].

use crate::gpu::pass::{Entry, PassDesc, read, read_write};
use crate::gpu::shader::WORKGROUP_SIZE;
use crate::scene::{InterpolationKernel, LightBound};

pub const WGSL: &str = include_str!("interpolate.wgsl");

/// The pass's own WGSL for `neighbours` sparse points per vertex, the `kernel`'s weights and
/// the `bound`.
pub fn body(neighbours: u32, kernel: InterpolationKernel, bound: LightBound) -> String {
    let smooth = kernel == InterpolationKernel::Smooth;
    let bounded = bound == LightBound::Gathered;
    format!(
        "const NEIGHBOURS: u32 = {neighbours}u;\nconst SMOOTH_KERNEL: bool = {smooth};\n\
         const BOUNDED: bool = {bounded};\nconst PLANE_FALLOFF: f32 = {:?};\n\
         const FACING_EPSILON: f32 = {:?};\nconst BOUND_WEIGHT_FLOOR: f32 = {:?};\n{WGSL}",
        crate::twin::PLANE_FALLOFF,
        crate::twin::FACING_EPSILON,
        crate::twin::BOUND_WEIGHT_FLOOR
    )
}

/// One invocation per vertex.
pub const PASS: PassDesc = PassDesc {
    label: "interpolate",
    bindings: &[
        read("sparse_points"),
        read("vertex_neighbours"),
        read("sparse_diffuse"),
        read_write("vertex_diffuse"),
        read("sparse_glossy"),
        read_write("vertex_glossy"),
        read_write("vertex_centres"),
        read("gathered_glossy"),
        read_write("vertex_glossy_radiance"),
    ],
    entries: &[
        Entry::first("main", 4),
        Entry::first("main_glossy", 6),
        Entry {
            name: "centres",
            bindings: 7,
            except: &["sparse_diffuse", "vertex_diffuse", "sparse_glossy", "vertex_glossy"],
        },
        Entry {
            name: "main_glossy_radiance",
            bindings: 9,
            except: &["sparse_glossy", "vertex_glossy", "vertex_centres"],
        },
    ],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| {
        let body = body(crate::scene::DEFAULT_NEIGHBOURS, InterpolationKernel::default(), LightBound::default());
        PASS.source(&body, textured)
    },
};
