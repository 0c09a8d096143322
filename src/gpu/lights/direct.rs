//! Direct spot light with the RSM shadow map (`direct.wgsl`, docs/design.md §4 step 6). Rust twin
//! (without the shadow test): `twin::rsm::direct_radiance`. Run by
//! [`super::spot::DirectLight`].

use crate::gpu::pass::{Entry, PassDesc, read, read_write, texture};
use crate::gpu::shader::IMAGE_TILE;

pub const WGSL: &str = include_str!("direct.wgsl");

/// One invocation per pixel.
pub const PASS: PassDesc = PassDesc {
    label: "direct",
    bindings: &[texture("visibility"), read_write("direct"), read("light_distance")],
    entries: &[Entry::first("main", 3)],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(WGSL, textured),
};
