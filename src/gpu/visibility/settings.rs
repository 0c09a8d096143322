//! The registry of visibility modes and the settings they share. This file and every mode's
//! `settings.rs` are data (the bottom layer, `tests/integration/layers.rs`): the scene
//! description holds them without importing the GPU code beside them.
//!
//! [`visibility_modes!`] is the one list of modes. Each layer expands it into what it needs:
//! here the [`Occlusion`] and [`OcclusionSetting`] enums (and so the JSON names and the OpenAPI
//! lists), the modes' settings in [`VisibilitySettings`] and their overrides in
//! `settings.tuning` (`scene/settings/tuning.rs`); in `gpu/visibility/mod.rs` the mode folders'
//! declarations and the dispatch from the setting to the mode's technique. The protobuf enum is
//! matched by name and tested against the list (`service/wire`).

use serde::{Deserialize, Serialize};

use crate::scene::SceneError;

/// Calls `$then!` with the list of visibility modes, one line each:
///
/// `Variant "json name" folder { settings_field: SettingsType, TuningType }`
///
/// - `Variant` becomes a variant of [`Occlusion`] and [`OcclusionSetting`]; `"json name"` its
///   name in scene files, on the service and in benchmarks, the variant's in snake case (the
///   enums' serde and OpenAPI names are derived from the variant: a test checks they agree); `folder` the module in
///   `src/gpu/visibility/` holding the mode (its `settings.rs`, its technique with
///   `pub fn mode(gpu, scene, &VisibilitySettings, glossy)` in `mod.rs`, its twin, its WGSL and
///   its tests);
/// - the optional `{ field: Settings, Tuning }` gives the mode settings at
///   `VisibilitySettings::field` (resolved; `Settings::validate(&self, field)` and `Default`)
///   and overrides at `settings.tuning.field` (`Tuning::apply` and `set_fields`, as made by
///   `scene::settings::overrides!`).
///
/// Adding a mode is its folder and its line here.
macro_rules! visibility_modes {
    ($then:ident) => {
        $then! {
            /// Disc occluders at the sparse points (docs/design.md §4 step 3); how they combine is
            /// `occlusion_rule`.
            Disks "disks" disks,
            /// Shadow maps of clusters of VALs (`clusters`).
            Clusters "clusters" clusters { clusters: $crate::gpu::visibility::clusters::settings::ClusterSettings, $crate::gpu::visibility::clusters::settings::ClusterTuning },
            /// Imperfect shadow maps of VALs drawn by flux (`ism`).
            Ism "ism" ism { ism: $crate::gpu::visibility::ism::settings::IsmSettings, $crate::gpu::visibility::ism::settings::IsmTuning },
        }
    };
}
pub(crate) use visibility_modes;

/// The data types of the list: the enums and the resolved settings.
macro_rules! define_settings {
    ($($(#[$doc:meta])* $variant:ident $name:literal $module:ident $({ $field:ident: $settings:ty, $tuning:ty })?,)*) => {
        /// Indirect visibility mode, as resolved.
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Deserialize, Serialize, utoipa::ToSchema)]
        #[serde(rename_all = "snake_case")]
        pub enum Occlusion {
            /// No indirect visibility: every VAL reaches every receiver.
            #[default]
            Off,
            $($(#[$doc])* $variant,)*
        }

        /// Indirect visibility as a scene file asks for it: a mode, or `"auto"`, the quality
        /// level's choice.
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
        #[serde(rename_all = "snake_case")]
        pub enum OcclusionSetting {
            /// The level's choice (disks when the scene can occlude itself, else off, at the
            /// default level).
            #[default]
            Auto,
            /// No indirect visibility.
            Off,
            $($(#[$doc])* $variant,)*
        }

        impl Occlusion {
            /// Every mode, `Off` first, in the registry's order.
            pub const ALL: &[Occlusion] = &[Occlusion::Off, $(Occlusion::$variant,)*];

            /// Its name in scene files, on the service and in benchmarks.
            pub fn name(self) -> &'static str {
                match self {
                    Occlusion::Off => "off",
                    $(Occlusion::$variant => $name,)*
                }
            }

            /// The mode named `name`, if there is one.
            pub fn from_name(name: &str) -> Option<Self> {
                Self::ALL.iter().copied().find(|mode| mode.name() == name)
            }
        }

        impl OcclusionSetting {
            /// The mode asked for, `auto` standing for the level's `auto`.
            pub fn or(self, auto: Occlusion) -> Occlusion {
                match self {
                    OcclusionSetting::Auto => auto,
                    OcclusionSetting::Off => Occlusion::Off,
                    $(OcclusionSetting::$variant => Occlusion::$variant,)*
                }
            }
        }

        impl From<Occlusion> for OcclusionSetting {
            /// The setting that asks for exactly `mode`.
            fn from(mode: Occlusion) -> Self {
                match mode {
                    Occlusion::Off => OcclusionSetting::Off,
                    $(Occlusion::$variant => OcclusionSetting::$variant,)*
                }
            }
        }

        /// Everything that picks and parametrises the visibility mode: the mode, the disc
        /// occluders' rule, and every mode's settings.
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        pub struct VisibilitySettings {
            pub mode: Occlusion,
            /// How the disks' occluders combine.
            pub rule: OcclusionRule,
            $($(pub $field: $settings,)?)*
        }

        impl VisibilitySettings {
            /// Check every mode's settings, naming the first bad field under `field` (the
            /// mode's settings are at `{field}.{mode's field}`).
            pub fn validate(&self, field: &str) -> Result<(), SceneError> {
                let _ = field;
                $($(self.$field.validate(&format!("{field}.{}", stringify!($field)))?;)?)*
                Ok(())
            }
        }
    };
}
visibility_modes!(define_settings);

/// Combination rule of disc occluders (the `"disks"` mode).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum OcclusionRule {
    /// `clamp(sum o_i, 0, 1)`: the paper's; double-counts overlapping occluders.
    Sum,
    /// `1 - prod(1 - o_i)`: closer to exact visibility on both measured fixtures (docs/measurements/disc-occlusion.md).
    #[default]
    Product,
}

/// How a shadow map's lookup is filtered (the `"clusters"` and `"ism"` modes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum SoftShadows {
    /// Percentage-closer soft shadows: blocker search, penumbra from the cluster's radius and
    /// the mean blocker distance, PCF of that width (paper 001).
    Pcss,
    /// PCF of a fixed width (1.5 texels).
    Pcf,
    /// One texel (the clusters' default).
    #[default]
    Hard,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_match_serde() {
        for &mode in Occlusion::ALL {
            assert_eq!(Occlusion::from_name(mode.name()), Some(mode));
            assert_eq!(serde_json::to_string(&mode).unwrap(), format!("\"{}\"", mode.name()));
            let setting: OcclusionSetting = serde_json::from_str(&format!("\"{}\"", mode.name())).unwrap();
            assert_eq!(setting.or(Occlusion::Off), mode);
        }
        assert_eq!(OcclusionSetting::Auto.or(Occlusion::Ism), Occlusion::Ism);
        assert_eq!(Occlusion::from_name("auto"), None);
    }
}
