//! The renderer's technique cache: a technique is kept with the settings it was built for and
//! built anew when asked for with others.

use crate::gpu::GpuError;
use crate::gpu::references::brute_force::BruteForce;
use crate::gpu::references::estimator::Estimator;
use crate::gpu::references::exact::Exact;
use crate::gpu::sparse::{SparseMethod, SparseSettings};
use crate::gpu::visibility::VisibilitySettings;

/// A technique with the settings it was built for: asked for with other settings, it is built
/// anew.
pub(super) struct Built<K, T> {
    pub(super) key: K,
    pub(super) technique: T,
}

/// `slot`'s technique if it was built for `key`, else `build()` in its place.
pub(super) fn built_for<K: PartialEq, T>(
    slot: &mut Option<Built<K, T>>,
    key: K,
    build: impl FnOnce() -> Result<T, GpuError>,
) -> Result<&mut T, GpuError> {
    if slot.as_ref().is_none_or(|b| b.key != key) {
        *slot = None;
        *slot = Some(Built { key, technique: build()? });
    }
    Ok(&mut slot.as_mut().expect("set above").technique)
}

/// The indirect techniques, each kept (with its buffers) until it is asked for with other
/// settings or [`super::Renderer::release_reference_passes`] drops it.
#[derive(Default)]
pub(super) struct Indirect {
    /// Keyed by its settings and, when its visibility traces rays through a BVH of the placed
    /// geometry (`clusters.shadow_maps: "rays"`), the placement generation (else 0).
    pub(super) sparse: Option<Built<(SparseSettings, u64), SparseMethod>>,
    /// Keyed by `glossy`.
    pub(super) brute_force: Option<Built<bool, BruteForce>>,
    /// `brute_force_ism` or `brute_force_clusters`, keyed by `glossy` and the visibility
    /// settings of its groups (mode `ism` or `clusters`).
    pub(super) brute_force_grouped: Option<Built<(bool, VisibilitySettings), BruteForce>>,
    /// Keyed by (`glossy`, VAL stride, placement generation: the BVH is the placed geometry's).
    pub(super) exact: Option<Built<(bool, u32, u64), Exact>>,
    /// Keyed by (`glossy`, samples, seed, placement generation).
    pub(super) estimator: Option<Built<(bool, u32, u32, u64), Estimator>>,
}
