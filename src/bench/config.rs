//! One configuration of the sweep: what it overrides of the scene's settings, and its
//! description in words.

use crate::scene::{
    ClusterSettings, GlossyInterpolation, InterpolationKernel, LightBound, Occlusion, ShadowMapSource, SoftShadows,
};

/// One configuration of the sweep.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Config {
    /// Sparse points on every mesh; `None`: each mesh's own count from the scene file.
    pub sparse_points_per_mesh: Option<u32>,
    /// Sparse points each vertex interpolates from; `None`: the scene's
    /// `settings.interpolation_neighbours`.
    pub neighbours: Option<u32>,
    /// Near-field radius in whole sparse point spacings; `None`: the scene's
    /// `settings.sparse.near_field`.
    pub near_field: Option<u32>,
    /// `settings.sparse.glossy_interpolation`; `None`: the scene's.
    pub glossy_interpolation: Option<GlossyInterpolation>,
    /// `settings.sparse.adaptive` in hundredths (adaptive points per 100 sparse points);
    /// `None`: the scene's.
    pub adaptive_percent: Option<u32>,
    /// `settings.sparse.kernel`, `bound` and `subdivision` (whole spacings); `None`: the scene's.
    pub kernel: Option<InterpolationKernel>,
    pub bound: Option<LightBound>,
    pub subdivision: Option<u32>,
    /// RSM side R: at most R² VALs (only lit texels become VALs).
    pub rsm_resolution: u32,
    pub occlusion: Occlusion,
    /// Whether the glossy gather may run (it runs only when the scene has a glossy material).
    pub glossy: bool,
    pub width: u32,
    pub height: u32,
    /// The `ism` mode's settings where they differ from the scene's `settings.ism` (set only
    /// when `occlusion` is `ism`).
    pub ism_count: Option<u32>,
    pub ism_resolution: Option<u32>,
    pub ism_points: Option<u32>,
    pub ism_pull_push_levels: Option<u32>,
    /// The `clusters` mode's settings where they differ from the scene's `settings.clusters`
    /// (set only when `occlusion` is `clusters`).
    pub clusters: ClusterOverrides,
}

impl Config {
    /// A configuration of these settings and size that overrides nothing else of the scene's.
    pub const fn new(rsm_resolution: u32, occlusion: Occlusion, glossy: bool, width: u32, height: u32) -> Self {
        Config {
            sparse_points_per_mesh: None,
            neighbours: None,
            near_field: None,
            glossy_interpolation: None,
            adaptive_percent: None,
            kernel: None,
            bound: None,
            subdivision: None,
            rsm_resolution,
            occlusion,
            glossy,
            width,
            height,
            ism_count: None,
            ism_resolution: None,
            ism_points: None,
            ism_pull_push_levels: None,
            clusters: ClusterOverrides::NONE,
        }
    }
}

/// Overrides of `settings.clusters` (`None`: the scene's).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ClusterOverrides {
    pub count: Option<u32>,
    pub shadow_map_resolution: Option<u32>,
    pub soft: Option<SoftShadows>,
    pub shadow_maps: Option<ShadowMapSource>,
    pub rays: Option<u32>,
}

impl ClusterOverrides {
    /// No override.
    pub const NONE: Self = Self { count: None, shadow_map_resolution: None, soft: None, shadow_maps: None, rays: None };

    /// `base` with these overrides.
    pub fn apply(&self, base: &ClusterSettings) -> ClusterSettings {
        ClusterSettings {
            count: self.count.unwrap_or(base.count),
            shadow_map_resolution: self.shadow_map_resolution.unwrap_or(base.shadow_map_resolution),
            soft: self.soft.unwrap_or(base.soft),
            shadow_maps: self.shadow_maps.unwrap_or(base.shadow_maps),
            rays: self.rays.unwrap_or(base.rays),
            ..*base
        }
    }

    pub(super) fn is_none(&self) -> bool {
        *self == Self::NONE
    }
}

/// `soft`'s name in settings, CSV and labels.
pub(super) fn soft_name(s: SoftShadows) -> &'static str {
    match s {
        SoftShadows::Pcss => "pcss",
        SoftShadows::Pcf => "pcf",
        SoftShadows::Hard => "hard",
    }
}

/// `kernel`'s name in settings, CSV and labels.
pub(super) fn kernel_name(k: InterpolationKernel) -> &'static str {
    match k {
        InterpolationKernel::Paper => "paper",
        InterpolationKernel::Smooth => "smooth",
    }
}

/// `bound`'s name in settings, CSV and labels.
pub(super) fn bound_name(b: LightBound) -> &'static str {
    match b {
        LightBound::Off => "off",
        LightBound::Gathered => "gathered",
    }
}

/// `glossy_interpolation`'s name in settings, CSV and labels.
pub(super) fn glossy_interpolation_name(g: GlossyInterpolation) -> &'static str {
    match g {
        GlossyInterpolation::Lights => "lights",
        GlossyInterpolation::Radiance => "radiance",
    }
}

/// `shadow_maps`' name in settings, CSV and labels.
pub(super) fn maps_name(m: ShadowMapSource) -> &'static str {
    match m {
        ShadowMapSource::Raster => "raster",
        ShadowMapSource::Ism => "ism",
        ShadowMapSource::Rays => "rays",
    }
}

impl Config {
    /// The `ism` settings of this configuration: `base` with its overrides.
    pub fn ism_settings(&self, base: &crate::scene::IsmSettings) -> crate::scene::IsmSettings {
        crate::scene::IsmSettings {
            count: self.ism_count.unwrap_or(base.count),
            resolution: self.ism_resolution.unwrap_or(base.resolution),
            points: self.ism_points.or(base.points),
            pull_push_levels: self.ism_pull_push_levels.unwrap_or(base.pull_push_levels),
            ..*base
        }
    }

    /// Whether any `ism` setting is overridden.
    pub(super) fn has_ism(&self) -> bool {
        self.ism_count.is_some()
            || self.ism_resolution.is_some()
            || self.ism_points.is_some()
            || self.ism_pull_push_levels.is_some()
    }
}

impl Config {
    pub(super) fn without_ism(self) -> Config {
        Config { ism_count: None, ism_resolution: None, ism_points: None, ism_pull_push_levels: None, ..self }
    }
}

/// A configuration in words, for progress lines and plot labels.
pub fn describe(c: &Config) -> String {
    let sparse = c.sparse_points_per_mesh.map_or("scene".to_owned(), |n| n.to_string());
    let neighbours = c.neighbours.map_or(String::new(), |k| format!(", {k} neighbours"));
    let near = c.near_field.map_or(String::new(), |n| format!(", near field {n}"));
    let adaptive = c.adaptive_percent.map_or(String::new(), |a| format!(", adaptive {}", f64::from(a) / 100.0));
    let kernel = c.kernel.map_or(String::new(), |k| format!(", kernel {}", kernel_name(k)));
    let bound = c.bound.map_or(String::new(), |b| format!(", bound {}", bound_name(b)));
    let subdivision = c.subdivision.map_or(String::new(), |d| format!(", subdivision {d}"));
    let glossy_interpolation =
        c.glossy_interpolation.map_or(String::new(), |g| format!(", glossy {}", glossy_interpolation_name(g)));
    format!(
        "sparse/mesh {sparse}{neighbours}{near}{adaptive}{kernel}{bound}{subdivision}{glossy_interpolation}, R {}, occlusion {}, glossy {}, {}x{}",
        c.rsm_resolution,
        c.occlusion.name(),
        if c.glossy { "on" } else { "off" },
        c.width,
        c.height
    ) + &if c.has_ism() {
        let v = |o: Option<u32>| o.map_or("scene".to_owned(), |n| n.to_string());
        format!(
            ", ism {} maps of {}, {} points, {} pull-push levels",
            v(c.ism_count),
            v(c.ism_resolution),
            v(c.ism_points),
            v(c.ism_pull_push_levels)
        )
    } else {
        String::new()
    } + &if c.clusters.is_none() {
        String::new()
    } else {
        let o = &c.clusters;
        let v = |o: Option<String>| o.unwrap_or_else(|| "scene".to_owned());
        format!(
            ", clusters {} maps of {}, soft {}, {} maps",
            v(o.count.map(|n| n.to_string())),
            v(o.shadow_map_resolution.map(|n| n.to_string())),
            v(o.soft.map(|s| soft_name(s).to_owned())),
            v(o.shadow_maps.map(|m| maps_name(m).to_owned()))
        ) + &o.rays.map_or(String::new(), |r| format!(", {r} rays"))
    }
}
