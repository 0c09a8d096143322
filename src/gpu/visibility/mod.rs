//! Visibility modes of the sparse method (docs/design.md §4 step 3). A mode is one of two kinds:
//!
//! - a **scaling** mode ([`SparseVisibility`]: `disks/`) runs between the gather and the
//!   renormalisation and scales what each sparse point gathered by the fraction of it that
//!   arrives;
//! - a **group visibility** mode ([`GroupVisibility`]: `clusters/`, `ism/`) runs before the gather and
//!   produces a table `group_visibility[point * groups + group]` (the fraction of group
//!   `group`'s light that reaches sparse point `point`) and `group_of_val[val]` (each VAL's
//!   group); the gather then scales every VAL's contribution by its group's visibility at the
//!   receiver (`group.wgsl`). Per-VAL visibility needs this form: the k-means clusters of paper
//!   000 produce it, and the imperfect shadow maps of paper 004 (`ism/`: VALs drawn by flux
//!   instead of k-means, maps splatted from points instead of rasterised, the same lookup).
//!
//! The group modes' machinery ([`clusters::Clusters`]) also serves two other sets of receivers
//! with instances of its own ([`clusters::Receivers`]): the second bounce's points
//! (`gpu::lights::bounce`: the first bounce's groups, so that the bounce points see the first
//! bounce through the sparse method's `ism` or `clusters` maps) and the camera's pixels
//! (`gpu::references::brute_force`'s `brute_force_ism`: ISM visibility per pixel).
//!
//! A mode is a folder here and one line in the registry, `settings.rs`'s `visibility_modes!`.
//! The folder holds its settings (`settings.rs`, data, if it has any), its technique (`mod.rs`:
//! a type implementing one of the traits below and `pub fn mode(gpu, scene, settings, glossy)`
//! making it), its WGSL, its CPU twin (`twin.rs`) and its tests. The registry line declares the
//! folder's module, names the mode in scene files, on the service and in benchmarks, puts its
//! settings in [`VisibilitySettings`] and their overrides in `settings.tuning`, and routes the
//! scene's setting to its `mode` ([`for_settings`]). Its stages appear in the timings under
//! their names.

pub mod settings;

/// Every mode's folder, from the registry.
macro_rules! declare_modes {
    ($($(#[$doc:meta])* $variant:ident $name:literal $module:ident $({ $field:ident: $settings:ty, $tuning:ty })?,)*) => {
        $(pub mod $module;)*

        /// Every mode's compute passes, in the registry's order.
        pub fn passes() -> Vec<&'static PassDesc> {
            [$($module::PASSES,)*].concat()
        }

        /// The mode the settings ask for; `None` when visibility is off (no stage, no buffer).
        pub fn for_settings(
            gpu: &Gpu,
            scene: &GpuScene,
            settings: &VisibilitySettings,
            glossy: bool,
        ) -> Result<Option<Mode>, GpuError> {
            Ok(match settings.mode {
                Occlusion::Off => None,
                $(Occlusion::$variant => Some($module::mode(gpu, scene, settings, glossy)?),)*
            })
        }
    };
}
settings::visibility_modes!(declare_modes);

use crate::gpu::pass::PassDesc;
use crate::gpu::scene::GpuScene;
use crate::gpu::shader::Wgsl;
use crate::gpu::technique::Frame;
use crate::gpu::timing::{Recorder, Span};
use crate::gpu::{Gpu, GpuError, Lobes};
use crate::scene::Occlusion;
pub use crate::scene::VisibilitySettings;

/// A visibility mode that scales the gathered sums, as the sparse technique runs it.
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

/// The WGSL a pass lighting receivers through a group visibility mode includes (the gather,
/// `bounce2_points`, `brute_force_ism`): the two bindings and `val_visibility(receiver, val)`;
/// `GROUP_COUNT` and `GROUP_BINDING` are prepended by [`group_wgsl`].
pub const GROUP_WGSL: &str = include_str!("group.wgsl");

/// `val_visibility(receiver, val)` for a pass whose `group_of_val` is at `binding` (the table
/// at the next): [`GROUP_WGSL`] for `groups` groups, or 1 for every VAL without a group mode.
pub fn group_wgsl(groups: Option<u32>, binding: u32) -> String {
    match groups {
        Some(g) => Wgsl::new().u32("GROUP_COUNT", g).u32("GROUP_BINDING", binding).include(GROUP_WGSL).finish(),
        None => "fn val_visibility(receiver: u32, val: u32) -> f32 {\n    return 1.0;\n}\n".to_owned(),
    }
}

/// The buffers a group visibility mode hands to the gather.
pub struct GroupTable<'a> {
    /// Groups per sparse point (the table's row length).
    pub groups: u32,
    /// `array<u32>`, one per VAL: its group.
    pub group_of_val: &'a wgpu::Buffer,
    /// `array<f32>`, `sparse points x groups`: fraction of each group's light reaching each point.
    pub visibility: &'a wgpu::Buffer,
}

/// A visibility mode that gives every (sparse point, group of VALs) a visibility, recorded
/// before the gather, which consumes it per VAL.
pub trait GroupVisibility: std::any::Any {
    /// Its stages, in order: their names in the frame's timings.
    fn stages(&self) -> Vec<&'static str>;

    /// What the gather reads.
    fn table(&self) -> GroupTable<'_>;

    /// Cover frames of up to `max_vals` VALs.
    fn fit(&mut self, gpu: &Gpu, max_vals: u32) -> Result<(), GpuError>;

    /// Record its stages: fill [`GroupVisibility::table`] for the frame's VALs.
    fn record(&self, gpu: &Gpu, frame: &Frame<'_>, rec: &mut Recorder<'_>) -> Result<(), GpuError>;

    /// For tests and tools that know the concrete mode.
    fn as_any(&self) -> &dyn std::any::Any;
}

/// A visibility mode of either kind.
pub enum Mode {
    Scale(Box<dyn SparseVisibility>),
    Groups(Box<dyn GroupVisibility>),
}

impl Mode {
    /// Its own stages, in order (the sparse technique puts them before or after the gather).
    pub fn stages(&self) -> Vec<&'static str> {
        match self {
            Mode::Scale(m) => vec![m.stage()],
            Mode::Groups(g) => g.stages(),
        }
    }
}
