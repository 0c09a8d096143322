//! What a frame is asked for (the method of the indirect light, the components) and what it
//! returns ([`Rendered`]).

use crate::gpu::timing::StageTimings;
use crate::image::LinearImage;

/// How the indirect light is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The sparse model-space method (docs/design.md §4).
    Sparse,
    /// Every VAL at every visible pixel (docs/design.md §5).
    BruteForce,
    /// The brute force with each VAL weighted by its group's imperfect-shadow-map lookup at the
    /// pixel (`settings.ism`): the ISMs' visibility without the sparse interpolation
    /// (`gpu::references::brute_force`).
    BruteForceIsm,
    /// The brute force with each VAL weighted by its cluster's shadow-map lookup at the pixel
    /// (`settings.tuning.clusters`): the clusters' visibility where the light lands, without
    /// the sparse sampling and interpolation (`gpu::references::brute_force`).
    BruteForceClusters,
    /// Brute force with a shadow ray per pixel and VAL through a BVH (docs/design.md §5); see
    /// [`super::Renderer::set_exact_val_stride`].
    Exact,
    /// The exact reference estimated: per pixel, VALs drawn in proportion to their unoccluded
    /// contribution, a shadow ray each (`gpu::references::estimator`); see
    /// [`super::Renderer::set_estimator`].
    Estimator,
}

impl Method {
    /// The method's name as requests and frames give it (`sparse`, `brute-force`, `exact`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Method::Sparse => "sparse",
            Method::BruteForce => "brute-force",
            Method::BruteForceIsm => "brute-force-ism",
            Method::BruteForceClusters => "brute-force-clusters",
            Method::Exact => "exact",
            Method::Estimator => "estimator",
        }
    }
}

/// The method a scene's resolved technique asks for (`settings.quality`: the exact reference
/// at `reference`, the sparse method otherwise).
impl From<crate::scene::Technique> for Method {
    fn from(technique: crate::scene::Technique) -> Method {
        match technique {
            crate::scene::Technique::Exact => Method::Exact,
            crate::scene::Technique::Sparse => Method::Sparse,
            crate::scene::Technique::Estimator => Method::Estimator,
            crate::scene::Technique::BruteForceClusters => Method::BruteForceClusters,
        }
    }
}

/// Which light the image shows.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, utoipa::ToSchema, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum Component {
    /// Direct plus indirect.
    #[default]
    Full,
    Direct,
    Indirect,
}

impl Component {
    /// This component of a frame.
    pub fn of(self, frame: &Rendered) -> LinearImage {
        match self {
            Component::Full => frame.direct.add(&frame.indirect),
            Component::Direct => frame.direct.clone(),
            Component::Indirect => frame.indirect.clone(),
        }
    }

    /// What a frame must compute to show it.
    pub fn needs(self) -> Components {
        match self {
            Component::Full => Components::ALL,
            Component::Direct => Components::DIRECT,
            Component::Indirect => Components::INDIRECT,
        }
    }
}

/// Which components a frame computes. A component left out runs none of its techniques (a
/// direct-only frame has no gather); its image comes back black with the coverage in alpha.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Components {
    pub direct: bool,
    pub indirect: bool,
}

impl Components {
    pub const ALL: Self = Self { direct: true, indirect: true };
    pub const DIRECT: Self = Self { direct: true, indirect: false };
    pub const INDIRECT: Self = Self { direct: false, indirect: true };
}

/// One rendered frame: linear radiance (W/(m² sr)), alpha = 1 where geometry covers the pixel.
#[derive(Clone)]
pub struct Rendered {
    pub direct: LinearImage,
    pub indirect: LinearImage,
    pub timings: StageTimings,
    /// The stages of the technique that computed the indirect light (empty when it was not
    /// asked for).
    pub indirect_stages: Vec<&'static str>,
    /// VALs with non-zero flux this frame.
    pub val_count: u32,
    /// Method::Exact: the rounds it took (see `gpu::references::exact`); 0 for the other methods.
    pub exact_rounds: u32,
    /// The frame's estimated error against the exact reference, when the renderer was asked to
    /// estimate it (`Renderer::set_error_estimate`) and the frame has indirect light.
    pub error_estimate: Option<super::estimate::ErrorEstimate>,
}

impl Rendered {
    /// Time of the stages that computed the indirect light (ms).
    pub fn indirect_ms(&self) -> f64 {
        self.timings.total_of(&self.indirect_stages)
    }
}

#[cfg(test)]
mod tests {
    use super::Method;
    use clap::ValueEnum;

    /// A frame's `method` parameter names the method as a request and the CLI's `--method` do.
    #[test]
    fn the_name_is_the_requests_and_the_clis() {
        for &method in Method::value_variants() {
            assert_eq!(serde_json::to_value(method).unwrap(), method.name(), "{method:?}");
            assert_eq!(method.to_possible_value().unwrap().get_name(), method.name(), "{method:?}");
        }
    }
}
