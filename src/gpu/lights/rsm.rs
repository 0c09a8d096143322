//! RSM to VALs (`rsm.wgsl`): the light's visibility buffer becomes a compacted VAL list and a
//! distance-to-light shadow map. Rust twin: `twin::rsm::rsm_texel_val`. Run by
//! [`super::spot::SpotVals`].

use super::compact;
use crate::gpu::pass::{Entry, PassDesc, read_write, texture};
use crate::gpu::shader::{IMAGE_TILE, Wgsl};

pub const WGSL: &str = include_str!("rsm.wgsl");

/// The pass's WGSL after the shader prelude: `rsm.wgsl` and the in-order append.
pub fn body() -> String {
    Wgsl::new().include(WGSL).include(compact::WGSL).finish()
}

/// `main`: one invocation per RSM texel, writing `light_distance` (R², m) and the texel's
/// candidate; `compact` appends the candidates to `vals` (stopping at its capacity) after the
/// `val_count` already there.
pub const PASS: PassDesc = PassDesc {
    label: "rsm",
    bindings: &[
        texture("visibility"),
        read_write("vals"),
        read_write("val_count"),
        read_write("light_distance"),
        read_write("candidates"),
    ],
    entries: &[
        Entry { name: "main", bindings: 5, except: &["vals", "val_count"] },
        Entry { name: "compact", bindings: 5, except: &["visibility", "light_distance"] },
    ],
    workgroup: IMAGE_TILE,
    default_source: |textured| PASS.source(&body(), textured),
};
