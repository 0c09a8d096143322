//! `settings.bounces` and `settings.second_bounce`.

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;
use crate::scene::validate::int_in;

/// Bounces of indirect light unless a scene says otherwise.
pub const DEFAULT_BOUNCES: u32 = 1;

/// The second bounce of indirect light (paper 004 §4.1, imperfect reflective shadow maps):
/// `points` points spread over the meshes by area are lit by the first bounce's VALs, and
/// `vals` of them, drawn by the flux they reflect, become the second bounce's VALs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SecondBounceSettings {
    /// Points lit by the first bounce (the candidates), in 16..=[`MAX_SECOND_BOUNCE_POINTS`];
    /// default 4096. Each costs one gather of every first-bounce VAL.
    pub points: u32,
    /// Second-bounce VALs drawn from them by flux, in 1..=[`MAX_SECOND_BOUNCE_VALS`]; default
    /// 1024 (the paper's VPL count).
    pub vals: u32,
}

/// Most points the first bounce lights for the second.
pub const MAX_SECOND_BOUNCE_POINTS: u32 = 1 << 18;
/// Most second-bounce VALs per frame.
pub const MAX_SECOND_BOUNCE_VALS: u32 = 1 << 16;

impl Default for SecondBounceSettings {
    fn default() -> Self {
        Self { points: 4096, vals: 1024 }
    }
}

impl SecondBounceSettings {
    /// Check every field, naming the first bad one under `field`.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        int_in(self.points, 16, MAX_SECOND_BOUNCE_POINTS, &format!("{field}.points"))?;
        int_in(self.vals, 1, MAX_SECOND_BOUNCE_VALS, &format!("{field}.vals"))
    }
}
