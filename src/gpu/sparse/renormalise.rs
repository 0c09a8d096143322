//! Renormalisation (`renormalise.wgsl`, docs/design.md §4 step 2): the gathered sums of each sparse
//! point become point lights that reproduce them. Rust twins: `twin::renormalise_diffuse`,
//! `twin::renormalise_glossy`. Run by [`super::SparseMethod`].

use crate::gpu::pass::{Entry, PassDesc, read, read_write};
use crate::gpu::shader::WORKGROUP_SIZE;

pub const WGSL: &str = include_str!("renormalise.wgsl");

/// One invocation per sparse point.
pub const PASS: PassDesc = PassDesc {
    label: "renormalise",
    bindings: &[
        read("sparse_points"),
        read("gathered_diffuse"),
        read_write("sparse_diffuse"),
        read("gathered_glossy"),
        read_write("sparse_glossy"),
    ],
    entries: &[Entry::first("main", 3), Entry::first("main_glossy", 5)],
    workgroup: [WORKGROUP_SIZE, 1, 1],
    default_source: |textured| PASS.source(WGSL, textured),
};
