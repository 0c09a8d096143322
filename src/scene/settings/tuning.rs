//! `settings.tuning`: the research knobs. Every field is optional; a value given here overrides
//! what the scene's `quality` level chose (`super::quality::resolve`), field by field: a
//! `"sparse": {"near_field": 4}` changes the near field and keeps the level's subdivision.

use serde::{Deserialize, Serialize};

use super::{
    DirectSettings, DirectShadows, GlossyInterpolation, InterpolationKernel, LightBound, Occlusion, OcclusionRule,
    OcclusionSetting, SecondBounceSettings, SparseShading, VisibilitySettings,
};
use crate::gpu::visibility::settings::visibility_modes;

/// One overridden value: its path under `settings.tuning` and the value as the scene file wrote it.
pub type SetField = (String, String);

/// A struct of optional overrides of one settings struct: each field `Some` replaces the base's.
/// `plain` fields override a field of the same type; `optional` fields override an `Option`
/// field of the base (`null` and absent alike leave the base's).
macro_rules! overrides {
    (
        $(#[$meta:meta])*
        $name:ident for $base:ident {
            plain { $($(#[$pmeta:meta])* $plain:ident: $pty:ty,)* }
            optional { $($(#[$ometa:meta])* $opt:ident: $oty:ty,)* }
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, ::serde::Serialize, ::serde::Deserialize, utoipa::ToSchema)]
        #[serde(deny_unknown_fields)]
        pub struct $name {
            $($(#[$pmeta])* #[serde(default, skip_serializing_if = "Option::is_none")] pub $plain: Option<$pty>,)*
            $($(#[$ometa])* #[serde(default, skip_serializing_if = "Option::is_none")] pub $opt: Option<$oty>,)*
        }

        impl $name {
            /// `base` with every given field replaced.
            pub fn apply(&self, base: $base) -> $base {
                $base {
                    $($plain: self.$plain.unwrap_or(base.$plain),)*
                    $($opt: self.$opt.or(base.$opt),)*
                }
            }

            /// These overrides, each one not given taken from `other`.
            pub fn or(self, other: Self) -> Self {
                Self {
                    $($plain: self.$plain.or(other.$plain),)*
                    $($opt: self.$opt.or(other.$opt),)*
                }
            }

            /// The given fields, as `(prefix.field, value)`.
            pub fn set_fields(&self, prefix: &str) -> Vec<$crate::scene::settings::SetField> {
                let mut set = Vec::new();
                $(if let Some(value) = &self.$plain {
                    set.push((format!("{prefix}.{}", stringify!($plain)), $crate::scene::settings::json_value(value)));
                })*
                $(if let Some(value) = &self.$opt {
                    set.push((format!("{prefix}.{}", stringify!($opt)), $crate::scene::settings::json_value(value)));
                })*
                set
            }
        }
    };
}
pub(crate) use overrides;

/// A value as JSON text (`"disks"`, `4`, `0.5`), for the reasons of the resolved configuration.
pub(crate) fn json_value<T: Serialize>(value: &T) -> String {
    serde_json::to_string(value).unwrap_or_else(|_| "?".to_owned())
}

overrides! {
    /// Overrides of the sparse method's interpolation, light bound, subdivision, near field,
    /// adaptive points and the fraction of sparse points placed ([`SparseShading`], whose fields say what each does and its range).
    SparseTuning for SparseShading {
        plain {
            /// `"smooth"` or `"paper"`.
            kernel: InterpolationKernel,
            /// `"gathered"` or `"off"`.
            bound: LightBound,
            /// Edge length in sparse point spacings, in [1, 16].
            subdivision: f32,
            /// Near-field radius in sparse point spacings, in [0, 8].
            near_field: f32,
            /// Near-field interleaving block side: 1, 2, 4 or 8.
            near_field_interleave: u32,
            /// `"radiance"` or `"lights"`.
            glossy_interpolation: GlossyInterpolation,
            /// Adaptive points as a fraction of each mesh's sparse points, in [0, 1].
            adaptive: f32,
            /// Fraction of each mesh's sparse points placed, in [1/16, 1].
            points: f32,
        }
        optional {}
    }
}

overrides! {
    /// Overrides of the shadows and VAL budget of the scene's `lights` ([`DirectSettings`]).
    DirectTuning for DirectSettings {
        plain {
            shadows: DirectShadows,
            /// m, in (0, 1e4].
            d_init: f32,
            /// Side of each paraboloid shadow map, texels, in 16..=1024.
            shadow_map_resolution: u32,
            /// In 1..=1024.
            max_lights: u32,
            /// In 1..=1048576.
            val_budget: u32,
        }
        optional {
            /// m, > 0.
            z_far: f32,
        }
    }
}

overrides! {
    /// Overrides of the second bounce's points and VALs ([`SecondBounceSettings`]).
    SecondBounceTuning for SecondBounceSettings {
        plain {
            /// In 16..=262144.
            points: u32,
            /// In 1..=65536.
            vals: u32,
        }
        optional {}
    }
}

/// `settings.tuning` (its struct names a field per visibility mode with settings: the list in
/// `gpu/visibility/settings.rs`).
macro_rules! define_tuning {
    ($($(#[$doc:meta])* $variant:ident $name:literal $module:ident $({ $field:ident: $settings:ty, $tuning:ty })?,)*) => {
        /// `settings.tuning`: research knobs. Each is optional: absent, the scene's `quality` level
        /// chooses it (the resolved configuration says what it chose and why); given, it wins.
        #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
        #[serde(deny_unknown_fields)]
        pub struct Tuning {
            /// RSM side, texels, in 8..=2048 (the spot `light`'s VALs are its square).
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub rsm_resolution: Option<u32>,
            /// Sparse points each vertex interpolates from (paper eqs. 12-13), in 1..=16.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub interpolation_neighbours: Option<u32>,
            /// Indirect visibility: `"off"`, `"disks"` (docs/design.md §4 step 3), `"clusters"` (shadow
            /// maps of k-means clusters of the VALs, `clusters`) or `"ism"` (imperfect shadow maps,
            /// `ism`); `"auto"` is the level's choice, as absent. `occlusion` is this key's deprecated
            /// alias (accepted, not both at once).
            #[serde(default, rename = "visibility", alias = "occlusion", skip_serializing_if = "Option::is_none")]
            pub visibility: Option<OcclusionSetting>,
            /// How disc occluders combine: `"product"` or `"sum"` (the paper's).
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub occlusion_rule: Option<OcclusionRule>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub sparse: Option<SparseTuning>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub direct: Option<DirectTuning>,
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub second_bounce: Option<SecondBounceTuning>,
            $($(
                #[doc = concat!("Overrides of the `\"", $name, "\"` visibility mode.")]
                #[serde(default, skip_serializing_if = "Option::is_none")]
                pub $field: Option<$tuning>,
            )?)*
        }

        impl Tuning {
            /// The visibility settings: `mode` and `rule` with every mode's settings overridden
            /// as given.
            pub fn visibility_settings(&self, mode: Occlusion, rule: OcclusionRule) -> VisibilitySettings {
                VisibilitySettings {
                    mode,
                    rule,
                    $($($field: self.$field.map_or(<$settings>::default(), |t| t.apply(<$settings>::default())),)?)*
                }
            }

            /// The given overrides of the modes' settings, as `(at.field.path, value)`.
            fn visibility_set_fields(&self, at: &str) -> Vec<SetField> {
                let mut set = Vec::new();
                $($(set.extend(self.$field.map(|t| t.set_fields(&format!("{at}.{}", stringify!($field)))).unwrap_or_default());)?)*
                set
            }
        }
    };
}
visibility_modes!(define_tuning);

impl Tuning {
    /// Every field the scene file gives, as `(settings.tuning.path, value)`, in field order.
    pub fn set_fields(&self) -> Vec<SetField> {
        const AT: &str = "tuning";
        let mut set = Vec::new();
        if let Some(r) = self.rsm_resolution {
            set.push((format!("{AT}.rsm_resolution"), r.to_string()));
        }
        if let Some(k) = self.interpolation_neighbours {
            set.push((format!("{AT}.interpolation_neighbours"), k.to_string()));
        }
        if let Some(v) = self.visibility.filter(|v| *v != OcclusionSetting::Auto) {
            set.push((format!("{AT}.visibility"), json_value(&v)));
        }
        if let Some(rule) = self.occlusion_rule {
            set.push((format!("{AT}.occlusion_rule"), json_value(&rule)));
        }
        set.extend(self.sparse.map(|t| t.set_fields(&format!("{AT}.sparse"))).unwrap_or_default());
        set.extend(self.visibility_set_fields(AT));
        set.extend(self.direct.map(|t| t.set_fields(&format!("{AT}.direct"))).unwrap_or_default());
        set.extend(self.second_bounce.map(|t| t.set_fields(&format!("{AT}.second_bounce"))).unwrap_or_default());
        set
    }
}
