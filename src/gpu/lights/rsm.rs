//! RSM to VALs (`rsm.wgsl`): the light's visibility buffer becomes a compacted VAL list and a
//! distance-to-light shadow map. Rust twin: `twin::rsm::rsm_texel_val`. Run by
//! [`super::spot::SpotVals`].

use crate::gpu::pass::{Entry, PassDesc, read_write, texture};
use crate::gpu::shader::IMAGE_TILE;

pub const WGSL: &str = include_str!("rsm.wgsl");

/// One invocation per RSM texel; `vals` appends stop at its capacity, `val_count` counts on
/// from what is there, `light_distance` is R² (m).
pub const PASS: PassDesc = PassDesc {
    label: "rsm",
    bindings: &[texture("visibility"), read_write("vals"), read_write("val_count"), read_write("light_distance")],
    entries: &[Entry::first("main", 4)],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(WGSL, textured),
};
