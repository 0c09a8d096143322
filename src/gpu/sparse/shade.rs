//! Per-pixel sparse shading (`shade.wgsl`, DESIGN.md §4 step 5): each pixel applies the two
//! point lights interpolated across its triangle. Rust twin: `twin::shade_sparse`. Run by
//! [`super::SparseMethod`].

use crate::gpu::pass::{Entry, PassDesc, read, read_write, texture};
use crate::gpu::shader::IMAGE_TILE;

pub const WGSL: &str = include_str!("shade.wgsl");

/// One invocation per pixel.
pub const PASS: PassDesc = PassDesc {
    label: "shade",
    bindings: &[texture("visibility"), read_write("indirect"), read("vertex_diffuse"), read("vertex_glossy")],
    entries: &[Entry::first("main", 3), Entry::first("main_glossy", 4)],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(WGSL, textured),
};
