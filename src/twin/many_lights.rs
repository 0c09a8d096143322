//! CPU twins of the many-light direct pass (`gpu::lights::many`, docs/measurements/many-lights.md):
//! LightCluster's minimum-distance clustering of the lights (paper 003 §3.1), each light's
//! direct radiance, the dual-paraboloid shadow-map lookup per group, and the reference: a
//! shadow ray per receiver and light through the scene's BVH.

use super::above_surface;
use super::bvh::TraceBvh;
use super::exact_cpu::{RAY_OFFSET, Receiver};
use super::flat::{FlatScene, Hit};
use super::rsm::direct_radiance;
use crate::gpu::visibility::clusters::twin::{Cluster, DepthTile, ShadowReceiver, cluster_visibility};
use crate::image::LinearImage;
use crate::scene::{Light, Material, SoftShadows, SpotLight};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// The axis of every group's two paraboloid maps: map `2k` looks along +AXIS, `2k + 1` along
/// -AXIS.
pub const AXIS: Vec3 = Vec3::Y;

/// The lights grouped: each group is drawn from one representative light.
#[derive(Clone, Debug, PartialEq)]
pub struct LightGroups {
    /// Per group: the index of its representative light (its centre).
    pub centres: Vec<u32>,
    /// Per light: its group.
    pub group_of_light: Vec<u32>,
    /// Per group: the largest distance from the centre to one of its lights (m), the radius of
    /// the disc light that stands for it (0 for a group of one light: hard shadows).
    pub radius: Vec<f32>,
}

impl LightGroups {
    /// Every light its own group (the `"per_light"` mode).
    pub fn singletons(lights: usize) -> Self {
        Self {
            centres: (0..lights as u32).collect(),
            group_of_light: (0..lights as u32).collect(),
            radius: vec![0.0; lights],
        }
    }

    pub fn len(&self) -> usize {
        self.centres.len()
    }

    pub fn is_empty(&self) -> bool {
        self.centres.is_empty()
    }

    /// Each group's two paraboloid maps (`2k`: +[`AXIS`], `2k + 1`: -[`AXIS`]) at its centre,
    /// `positions` being the lights'.
    pub fn maps(&self, positions: &[Vec3]) -> Vec<Cluster> {
        let mut maps = Vec::with_capacity(2 * self.len());
        for (k, &c) in self.centres.iter().enumerate() {
            for normal in [AXIS, -AXIS] {
                maps.push(Cluster { position: positions[c as usize], count: 1.0, normal, radius: self.radius[k] });
            }
        }
        maps
    }
}

/// The minimum distance below which a light joins a centre at `centre`: `d_init`, or with
/// `view = (camera position, z_far)` `d_init (1 - |centre - camera| / z_far)`, at least 0
/// (paper 003 §3.1.2).
pub fn min_distance(d_init: f32, centre: Vec3, view: Option<(Vec3, f32)>) -> f32 {
    match view {
        None => d_init,
        Some((camera, z_far)) => (d_init * (1.0 - centre.distance(camera) / z_far)).max(0.0),
    }
}

/// LightCluster's minimum-distance clustering (paper 003 §3.1): the lights in order of
/// decreasing range (`ranges`, infinite for none; ties in index order) each become a new centre
/// when they are farther than [`min_distance`] from every centre so far; then every other light
/// joins its nearest centre (ties: the earlier centre). Every light is clustered: the paper's
/// view-frustum culling is applied later, per frame, to the groups' shadow maps
/// (`gpu::lights::many::ManyLights::groups_in_view`), so the groups do not change with the view.
pub fn min_distance_clusters(
    positions: &[Vec3],
    ranges: &[f32],
    d_init: f32,
    view: Option<(Vec3, f32)>,
) -> LightGroups {
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.sort_by(|&a, &b| ranges[b as usize].total_cmp(&ranges[a as usize]).then(a.cmp(&b)));
    let mut centres: Vec<u32> = Vec::new();
    for &i in &order {
        let p = positions[i as usize];
        let near = centres.iter().any(|&c| {
            let q = positions[c as usize];
            p.distance(q) <= min_distance(d_init, q, view)
        });
        if !near {
            centres.push(i);
        }
    }
    let mut group_of_light = vec![0u32; positions.len()];
    let mut radius = vec![0.0f32; centres.len()];
    for (i, &p) in positions.iter().enumerate() {
        let (k, d) = centres
            .iter()
            .enumerate()
            .map(|(k, &c)| (k, p.distance(positions[c as usize])))
            .fold((0, f32::INFINITY), |best, x| if x.1 < best.1 { x } else { best });
        group_of_light[i] = k as u32;
        radius[k] = radius[k].max(d);
    }
    LightGroups { centres, group_of_light, radius }
}

/// A point light's window on the inverse-square falloff, `clamp(1 - (d / range)^4, 0, 1)^2`: 1
/// at the light, 0 from `range` on; 1 everywhere without a range.
pub fn range_window(d: f32, range: Option<f32>) -> f32 {
    match range {
        None => 1.0,
        Some(r) => {
            let x = (d / r).powi(4);
            let w = (1.0 - x).clamp(0.0, 1.0);
            w * w
        }
    }
}

/// A light's range for the clustering's order (infinite without one; a spot has none).
pub fn light_range(light: &Light) -> f32 {
    match light {
        Light::Point(p) => p.range.unwrap_or(f32::INFINITY),
        Light::Spot(_) => f32::INFINITY,
    }
}

/// A point light as the spot the GPU shades it as: a cone of half-angle pi with a hard edge
/// (falloff 1 in every direction).
pub fn as_spot(light: &Light) -> SpotLight {
    match *light {
        Light::Spot(s) => s,
        Light::Point(p) => SpotLight {
            position: p.position,
            direction: Vec3::NEG_Y,
            inner_angle: PI,
            outer_angle: PI,
            intensity: p.intensity,
            up: Vec3::Z,
        },
    }
}

/// Direct radiance (W/(m² sr)) toward `eye` at (`p`, `n`) from one light through the Phong
/// BRDF, without visibility.
pub fn light_radiance(p: Vec3, n: Vec3, surface: &Material, eye: Vec3, light: &Light) -> Vec3 {
    let window = match light {
        Light::Point(point) => range_window(p.distance(point.position), point.range),
        Light::Spot(_) => 1.0,
    };
    if window == 0.0 {
        return Vec3::ZERO;
    }
    direct_radiance(p, n, surface, eye, &as_spot(light)) * window
}

/// The reference: every light through the Phong BRDF at receiver `r` (normals facing the viewer,
/// [`Receiver::sided`]), none from below its geometric surface ([`above_surface`]), each shadowed
/// by one ray from `r.position + r.geometric RAY_OFFSET` to the light (the segment's end at the
/// light itself; docs/design.md §3, shading and geometric normals).
pub fn direct_exact(bvh: &TraceBvh, r: &Receiver, eye: Vec3, lights: &[Light]) -> Vec3 {
    let origin = r.position + r.geometric * RAY_OFFSET;
    lights
        .iter()
        .map(|light| {
            let l = unshadowed_radiance(r, eye, light);
            if l == Vec3::ZERO || bvh.segment_blocked(origin, light.position()) { Vec3::ZERO } else { l }
        })
        .sum()
}

/// [`light_radiance`] at receiver `r`'s shading normal, 0 for a light below its geometric
/// surface: one light's direct radiance before its shadow.
pub fn unshadowed_radiance(r: &Receiver, eye: Vec3, light: &Light) -> Vec3 {
    let above = above_surface(r.geometric, light.position() - r.position);
    if above == 0.0 {
        return Vec3::ZERO;
    }
    light_radiance(r.position, r.normal, &r.surface, eye, light)
}

/// The map (of a group's two) that sees a receiver `offset` from its centre: 0 (+[`AXIS`]) when
/// `offset . AXIS >= 0`, else 1.
pub fn map_side(offset: Vec3) -> usize {
    if offset.dot(AXIS) >= 0.0 { 0 } else { 1 }
}

/// One texel's test of a group's map (the `"per_light"` mode's lookup, `hard_visibility` in
/// `many_lights.wgsl`): [`cluster_visibility`] with [`SoftShadows::Hard`] tests the one texel
/// `SHADOW_TAPS²` times; the answer is the same.
pub fn group_visibility(
    maps: &[Vec<f32>],
    resolution: u32,
    clusters: &[Cluster],
    k: usize,
    p: Vec3,
    n: Vec3,
    soft: SoftShadows,
) -> f32 {
    let offset = p - clusters[2 * k].position;
    let m = 2 * k + map_side(offset);
    let tile = DepthTile { resolution, depths: &maps[m], slope_bias_texels: 0.0 };
    cluster_visibility(&tile, &clusters[m], &ShadowReceiver { offset, normal: n }, soft)
}

/// The shadow-mapped direct radiance at receiver `r`: every light through the Phong BRDF, none
/// from below the geometric surface ([`unshadowed_radiance`]), its visibility its group's
/// ([`group_visibility`] at the geometric normal: `soft` over the group's maps `maps`, `2k` and
/// `2k + 1`).
#[allow(clippy::too_many_arguments)]
pub fn direct_shadow_mapped(
    r: &Receiver,
    eye: Vec3,
    lights: &[Light],
    groups: &LightGroups,
    maps: &[Vec<f32>],
    resolution: u32,
    soft: SoftShadows,
) -> Vec3 {
    let positions: Vec<Vec3> = lights.iter().map(Light::position).collect();
    let clusters = groups.maps(&positions);
    let visibility: Vec<f32> = (0..groups.len())
        .map(|k| group_visibility(maps, resolution, &clusters, k, r.position, r.geometric, soft))
        .collect();
    lights
        .iter()
        .enumerate()
        .map(|(i, light)| unshadowed_radiance(r, eye, light) * visibility[groups.group_of_light[i] as usize])
        .sum()
}

/// The direct radiance each pixel of a camera view from `eye` sees (`hits`, row-major, from
/// `VisibilityTarget::read`), `shade` giving it from the pixel's receiver
/// (`FlatScene::receiver_at`: position, both normals facing the viewer, material); alpha is the
/// coverage. Pixels in parallel (rayon).
pub fn image_of(
    flat: &FlatScene,
    hits: &[Option<Hit>],
    (width, height): (u32, u32),
    eye: Vec3,
    shade: impl Fn(&Receiver) -> Vec3 + Sync,
) -> LinearImage {
    let pixels = hits
        .par_iter()
        .map(|hit| match hit {
            None => [0.0; 4],
            Some(h) => {
                let l = shade(&flat.receiver_at(h.triangle, h.barycentrics, eye));
                [l.x, l.y, l.z, 1.0]
            }
        })
        .collect();
    LinearImage { width, height, pixels }
}

/// [`direct_exact`] at every pixel of a camera view: the reference image (no noise: one
/// deterministic shadow ray per pixel and light).
pub fn exact_image(
    flat: &FlatScene,
    hits: &[Option<Hit>],
    size: (u32, u32),
    eye: Vec3,
    lights: &[Light],
) -> LinearImage {
    let bvh = flat.trace_bvh();
    image_of(flat, hits, size, eye, |r| direct_exact(&bvh, r, eye, lights))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(xs: &[f32]) -> Vec<Vec3> {
        xs.iter().map(|&x| Vec3::new(x, 0.0, 0.0)).collect()
    }

    /// Lights on a line at 0, 0.3, 0.8, 3, 3.3 with d_init = 0.5: 0 is a centre, 0.3 joins it,
    /// 0.8 is 0.8 from 0 so a new centre, 3 a centre, 3.3 joins it; 0.3 stays with 0 (0.5
    /// from 0.8).
    #[test]
    fn min_distance_clusters_known_answer_on_a_line() {
        let p = line(&[0.0, 0.3, 0.8, 3.0, 3.3]);
        let g = min_distance_clusters(&p, &[f32::INFINITY; 5], 0.5, None);
        assert_eq!(g.centres, vec![0, 2, 3]);
        assert_eq!(g.group_of_light, vec![0, 0, 1, 2, 2]);
        assert!((g.radius[0] - 0.3).abs() < 1e-6 && g.radius[1] == 0.0 && (g.radius[2] - 0.3).abs() < 1e-6);
    }

    /// The second pass assigns a non-centre to its nearest centre, not to the first within
    /// d_min (paper 003 Fig. 3, bottom right): 0, 0.9 (centre: 0.9 > 0.6 from 0), then 0.55 is
    /// within 0.6 of 0 but nearer 0.9.
    #[test]
    fn remaining_lights_join_the_nearest_centre() {
        let p = line(&[0.0, 0.9, 0.55]);
        let g = min_distance_clusters(&p, &[f32::INFINITY; 3], 0.6, None);
        assert_eq!(g.centres, vec![0, 1]);
        assert_eq!(g.group_of_light, vec![0, 1, 1]);
        assert!((g.radius[1] - 0.35).abs() < 1e-6);
    }

    /// Lights are tried as centres by decreasing range: the longest-range light (index 2)
    /// becomes the first centre and takes its neighbour 1.
    #[test]
    fn centres_are_tried_by_decreasing_range() {
        let p = line(&[0.0, 0.45, 0.9]);
        let g = min_distance_clusters(&p, &[1.0, 1.0, 5.0], 0.5, None);
        assert_eq!(g.centres, vec![2, 0]);
        assert_eq!(g.group_of_light, vec![1, 0, 0]);
    }

    /// A tiny d_init leaves every light alone; a huge one makes one group whose radius is the
    /// farthest light's distance from the first.
    #[test]
    fn extreme_distances_give_singletons_or_one_group() {
        let p = line(&[0.0, 1.0, 2.5, -1.0]);
        let g = min_distance_clusters(&p, &[f32::INFINITY; 4], 1e-3, None);
        assert_eq!(g, LightGroups::singletons(4));
        let g = min_distance_clusters(&p, &[f32::INFINITY; 4], 100.0, None);
        assert_eq!((g.centres.clone(), g.group_of_light.clone()), (vec![0], vec![0; 4]));
        assert!((g.radius[0] - 2.5).abs() < 1e-6);
    }

    /// With the view scaling, d_min shrinks with the centre's distance from the camera: at the
    /// camera it is d_init (0.5: 0.4 joins 0), halfway to z_far it is half (10 and 10.4 stay
    /// apart).
    #[test]
    fn view_scaling_shrinks_the_distance_away_from_the_camera() {
        let p = line(&[0.0, 0.4, 10.0, 10.4]);
        let g = min_distance_clusters(&p, &[f32::INFINITY; 4], 0.5, Some((Vec3::ZERO, 20.0)));
        assert_eq!(g.centres, vec![0, 2, 3]);
        assert!((min_distance(0.5, Vec3::new(10.0, 0.0, 0.0), Some((Vec3::ZERO, 20.0))) - 0.25).abs() < 1e-6);
    }

    #[test]
    fn range_window_is_one_at_the_light_and_zero_from_the_range() {
        assert_eq!(range_window(0.0, Some(2.0)), 1.0);
        assert_eq!(range_window(2.0, Some(2.0)), 0.0);
        assert_eq!(range_window(3.0, Some(2.0)), 0.0);
        assert!((range_window(1.0, Some(2.0)) - (15.0f32 / 16.0).powi(2)).abs() < 1e-6);
        assert_eq!(range_window(1e6, None), 1.0);
    }

    /// A point light 2 m above a white Lambertian plate: E = I / d^2, L = rho / pi E.
    #[test]
    fn point_light_radiance_is_the_inverse_square_law() {
        let light = Light::Point(crate::scene::PointLight {
            position: Vec3::new(0.0, 2.0, 0.0),
            intensity: Vec3::splat(8.0),
            range: None,
        });
        let m = Material { diffuse: Vec3::ONE, specular: Vec3::ZERO, exponent: 1.0, diffuse_texture: None };
        let l = light_radiance(Vec3::ZERO, Vec3::Y, &m, Vec3::new(0.0, 1.0, 1.0), &light);
        assert!((l - Vec3::splat(2.0 / PI)).abs().max_element() < 1e-6, "{l}");
        // Behind the plate: nothing.
        let below = light_radiance(Vec3::ZERO, Vec3::NEG_Y, &m, Vec3::new(0.0, 1.0, 1.0), &light);
        assert_eq!(below, Vec3::ZERO);
    }

    /// A quad between a light and a receiver blocks the reference's shadow ray; moved aside it
    /// does not.
    #[test]
    fn exact_shadow_rays_see_a_blocker() {
        let quad = |y: f32, x0: f32| {
            vec![
                Vec3::new(x0, y, -1.0),
                Vec3::new(x0 + 2.0, y, -1.0),
                Vec3::new(x0 + 2.0, y, 1.0),
                Vec3::new(x0, y, 1.0),
            ]
        };
        let triangles = [[0u32, 1, 2], [0, 2, 3]];
        let light = Light::Point(crate::scene::PointLight {
            position: Vec3::new(0.0, 2.0, 0.0),
            intensity: Vec3::ONE,
            range: None,
        });
        let m = Material { diffuse: Vec3::ONE, specular: Vec3::ZERO, exponent: 1.0, diffuse_texture: None };
        let eye = Vec3::new(0.0, 1.0, 3.0);
        let r = Receiver::new(Vec3::ZERO, Vec3::Y, m, eye);
        let blocked = TraceBvh::build(&quad(1.0, -1.0), &triangles);
        assert_eq!(direct_exact(&blocked, &r, eye, &[light]), Vec3::ZERO);
        let aside = TraceBvh::build(&quad(1.0, 5.0), &triangles);
        let lit = direct_exact(&aside, &r, eye, &[light]);
        assert!((lit - Vec3::splat(0.25 / PI)).abs().max_element() < 1e-6, "{lit}");
    }

    /// A light below the geometric surface lights nothing, though the shading normal (tilted 45°
    /// towards it) faces it; raised above the surface it lights the receiver through the shading
    /// normal's cosine.
    #[test]
    fn a_light_below_the_geometric_surface_is_rejected() {
        let m = Material { diffuse: Vec3::ONE, specular: Vec3::ZERO, exponent: 1.0, diffuse_texture: None };
        let eye = Vec3::new(0.0, 3.0, 0.5);
        let r = Receiver::sided(Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0).normalize(), Vec3::Y, m, eye);
        let point = |y: f32| {
            Light::Point(crate::scene::PointLight {
                position: Vec3::new(2.0, y, 0.0),
                intensity: Vec3::ONE,
                range: None,
            })
        };
        assert_eq!(unshadowed_radiance(&r, eye, &point(-0.1)), Vec3::ZERO);
        let above = unshadowed_radiance(&r, eye, &point(0.1));
        let expected = light_radiance(r.position, r.normal, &r.surface, eye, &point(0.1));
        assert!(above.max_element() > 0.0 && above == expected, "{above} vs {expected}");
        // Without the rule the shading normal alone would take the light from below.
        assert!(light_radiance(r.position, r.normal, &r.surface, eye, &point(-0.1)).max_element() > 0.0);
    }
}
