//! Visibility modes of the sparse method: a stage between the gather and the renormalisation
//! that scales what each sparse point gathered by the fraction of it that arrives (DESIGN.md §4
//! step 3).
//!
//! A mode is a folder here holding its Rust, its WGSL and its CPU twin (`disks/`: `mod.rs`,
//! `disks.wgsl`, `twin.rs`), a type that implements [`SparseVisibility`], and one line in
//! [`for_settings`], where the scene's setting picks it. Nothing else changes: the sparse
//! technique runs whatever [`for_settings`] returns, and its stage appears in the timings
//! under [`SparseVisibility::stage`].

pub mod disks;

use crate::gpu::scene::GpuScene;
use crate::gpu::timing::Span;
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::scene::{Occlusion, OcclusionRule};

/// A visibility mode, as the sparse technique runs it.
pub trait SparseVisibility {
    /// The stage's name in the frame's timings.
    fn stage(&self) -> &'static str;

    /// Scale `gathered` (both lobes) in place by the visibility of what each sparse point
    /// gathered.
    fn record(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        gathered: &Lobes,
        span: Option<Span<'_>>,
    );
}

/// The mode the settings ask for; `None` when visibility is off (no stage, no buffer).
pub fn for_settings(
    gpu: &Gpu,
    scene: &GpuScene,
    mode: Occlusion,
    rule: OcclusionRule,
    glossy: bool,
) -> Result<Option<Box<dyn SparseVisibility>>, GpuError> {
    Ok(match mode {
        Occlusion::Off => None,
        Occlusion::Disks => Some(Box::new(disks::Disks::new(gpu, scene, glossy, rule == OcclusionRule::Product)?)),
    })
}
