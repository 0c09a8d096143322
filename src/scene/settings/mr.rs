//! `settings.mr`: mixed-reality compositing (differential rendering, `mr::differential`).

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::validate::{in_closed, int_in, positive};

/// Largest `settings.mr.receiver_margin` (m): receivers cost one pass over every VAL each.
pub const MAX_RECEIVER_MARGIN: f32 = 10.0;

/// Mixed-reality compositing settings (`settings.mr` of a scene file); every field has a
/// default.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(default, deny_unknown_fields)]
pub struct MrSettings {
    /// Render the virtual content's shadow and reflected light onto the real surfaces; default
    /// true.
    pub differential: bool,
    /// Real surfaces within this distance (m) of the virtual content's bounding box receive;
    /// in (0, 10], default 0.3.
    pub receiver_margin: f32,
    /// One receiver per `receiver_step x receiver_step` depth pixels, 1..=64; default 4.
    pub receiver_step: u32,
    /// Where the differential pass runs: `auto` (default: the CPU on CPU adapters such as
    /// lavapipe, the GPU otherwise), `gpu` or `cpu`. Both give the same sums.
    pub device: DifferentialDevice,
    /// How the differential pass computes its sums: `fast` (the VALs in groups, a far group
    /// summed as one, receivers interpolated where the content's effect is smooth) or `exact`
    /// (every receiver sums every VAL with a shadow ray: the reference). Unset (the default),
    /// it follows the quality level: `exact` beside the exact reference (quality `reference`),
    /// `fast` at the other levels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub differential_method: Option<DifferentialMethod>,
}

impl Default for MrSettings {
    fn default() -> Self {
        Self {
            differential: true,
            receiver_margin: 0.3,
            receiver_step: 4,
            device: DifferentialDevice::Auto,
            differential_method: None,
        }
    }
}

/// Where the differential pass runs (`settings.mr.device`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DifferentialDevice {
    /// The CPU on CPU adapters, the GPU otherwise. On lavapipe the GPU pass runs one
    /// invocation per workgroup (for llvmpipe's loop limit) and is two orders of magnitude
    /// slower than the CPU backend (docs/measurements/mixed-reality.md, "The differential pass
    /// on the CPU").
    #[default]
    Auto,
    /// The GPU pass (`differential.wgsl`).
    Gpu,
    /// The pass's CPU twin over rayon's threads, each shadow ray decided through obvhs's CWBVH
    /// (`TraceBvh`, the CPU exact reference's tree) by the GPU pass's triangle test. The trees
    /// differ only in which triangles they test: on the plate-and-box test 2 receivers in 1,089,
    /// whose rays start on the box's surface, differ from the GPU's.
    Cpu,
}

/// How the differential pass computes its sums (`settings.mr.differential_method`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DifferentialMethod {
    /// The VALs in groups, a group far from a receiver summed as one VAL with one shadow ray
    /// (none where its cone misses the content), receivers computed on a coarse grid and refined
    /// where the content's effect changes (docs/techniques/differential.md).
    #[default]
    Fast,
    /// Every receiver sums every VAL and every re-emitter with a shadow ray through the virtual
    /// meshes: the reference.
    Exact,
}

impl DifferentialMethod {
    /// The method of frames whose indirect light is the exact reference (`exact_reference`) or
    /// not, with the pass on the GPU (`gpu_backend`) or on the CPU: `setting` when the scene or
    /// the request chose one, else the exact pass beside the exact reference (quality
    /// `reference`) and on the GPU, where it is also the faster (an H200 on the TUM replay: the
    /// differential stage 216 ms a frame against the fast pass's 499 ms, which waits on the host
    /// between its adaptive levels; docs/measurements/gpu.md), and the fast one on the CPU
    /// beside every other method.
    pub fn for_frames(
        setting: Option<DifferentialMethod>,
        exact_reference: bool,
        gpu_backend: bool,
    ) -> DifferentialMethod {
        setting.unwrap_or(if exact_reference || gpu_backend {
            DifferentialMethod::Exact
        } else {
            DifferentialMethod::Fast
        })
    }
}

impl MrSettings {
    /// Ranges of every field, naming the field of the first value out of range.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        let m = self;
        positive(m.receiver_margin, &format!("{field}.receiver_margin"))?;
        in_closed(m.receiver_margin, 0.0, MAX_RECEIVER_MARGIN, &format!("{field}.receiver_margin"))?;
        int_in(m.receiver_step, 1, 64, &format!("{field}.receiver_step"))
    }
}
