//! Per-pixel sparse shading (`shade.wgsl`, docs/design.md §4 step 5): each pixel applies the two
//! point lights interpolated across its triangle, or, with `glossy_interpolation: "radiance"`,
//! the diffuse one and the interpolated glossy sums. Rust twins: `twin::shade_sparse`,
//! `twin::glossy_from_radiance`. Run by [`super::SparseMethod`].

use crate::gpu::pass::{Entry, PassDesc, read, read_write, texture};
use crate::gpu::shader::IMAGE_TILE;

pub const WGSL: &str = include_str!("shade.wgsl");

/// One invocation per pixel.
pub const PASS: PassDesc = PassDesc {
    label: "shade",
    bindings: &[
        texture("visibility"),
        read_write("indirect"),
        read("vertex_diffuse"),
        read("vertex_glossy"),
        read("vertex_glossy_radiance"),
    ],
    entries: &[
        Entry::first("main", 3),
        Entry::first("main_glossy", 4),
        Entry { name: "main_glossy_radiance", bindings: 5, except: &["vertex_glossy"] },
    ],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(WGSL, textured),
};
