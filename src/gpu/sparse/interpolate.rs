//! Per-vertex interpolation (`interpolate.wgsl`, DESIGN.md §4 step 4): each vertex averages the
//! point lights of its nearest sparse points. Rust twins: `twin::interpolation_weights`,
//! `twin::interpolate_lights`. Run by [`super::SparseMethod`].

use crate::gpu::pass::{Entry, PassDesc, read, read_write};
use crate::gpu::shader::WORKGROUP_SIZE;

pub const WGSL: &str = include_str!("interpolate.wgsl");

/// The pass's own WGSL for `neighbours` sparse points per vertex.
pub fn body(neighbours: u32) -> String {
    format!("const NEIGHBOURS: u32 = {neighbours}u;\n{WGSL}")
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
    ],
    entries: &[Entry::first("main", 4), Entry::first("main_glossy", 6)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| PASS.source(&body(crate::scene::DEFAULT_NEIGHBOURS), textured),
};
