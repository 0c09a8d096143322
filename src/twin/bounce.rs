//! The second bounce (paper 004 §4.1, imperfect reflective shadow maps) on the CPU: the twin of
//! `gpu/lights/bounce_points.wgsl` and `bounce_draw.wgsl`, and the exact reference's own second
//! bounce, whose points see the first bounce's VALs through shadow rays.
//!
//! Bounce points are spread over every mesh by area at load ([`bounce_points`]: triangle +
//! barycentrics, so they follow moving meshes); each is lit by the first bounce's VALs and
//! becomes a candidate VAL re-emitting the diffuse part of what it receives
//! ([`candidate_vals`]: flux `rho_d * E * area`, docs/design.md §1-3; [`grouped_candidate_vals`]
//! through the first bounce's groups with the sparse method's `clusters` or `ism` mode;
//! [`disk_occluded_candidate_vals`] scaled by the sparse points' discs with `disks`);
//! `count` of them, drawn by flux
//! ([`draw_vals`], the imperfect shadow maps' stratified draw), are the second bounce's VALs,
//! appended to the frame's so that every later stage runs unchanged.

use super::bvh::{ShadowTraversal, TraceBvh};
use super::exact_cpu::RAY_OFFSET;
use super::{Val, val_geometry_sided};
use super::{pcg_hash, unit_float};
use crate::gpu::visibility::disks::twin::{Combine, Disc, light_sphere, visibility};
use crate::gpu::visibility::ism::twin::{flux_picks, val_weight};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// A point of the second bounce: a triangle of the flattened scene, barycentrics of its
/// corners 1 and 2, and the area (m²) it stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BouncePoint {
    pub triangle: u32,
    pub barycentrics: Vec2,
    pub area: f32,
}

/// `count` points spread over the triangles (`indices` into `positions`, world space) by area,
/// stratified: point k at `(k + jitter) / count` of the running area, its barycentrics uniform
/// over the triangle, all from a hash of (`seed`, k), so the same in every run. Each stands for
/// `total area / count`. Empty when the triangles have no area.
pub fn bounce_points(positions: &[Vec3], indices: &[u32], count: u32, seed: u64) -> Vec<BouncePoint> {
    let mut sum = 0.0f64;
    let cdf: Vec<f64> = indices
        .chunks_exact(3)
        .map(|t| {
            let [a, b, c] = [0, 1, 2].map(|k| positions[t[k] as usize]);
            sum += 0.5 * f64::from((b - a).cross(c - a).length());
            sum
        })
        .collect();
    if sum <= 0.0 || count == 0 {
        return Vec::new();
    }
    let area = (sum / f64::from(count)) as f32;
    let seed = (seed as u32) ^ ((seed >> 32) as u32) ^ 0x5bd1_e995;
    (0..count)
        .map(|k| {
            let h0 = pcg_hash(k ^ seed);
            let (h1, h2) = (pcg_hash(h0), pcg_hash(pcg_hash(h0)));
            let goal = (f64::from(k) + f64::from(unit_float(h0))) / f64::from(count) * sum;
            let triangle = cdf.partition_point(|&c| c <= goal).min(cdf.len() - 1) as u32;
            let (mut u, mut v) = (unit_float(h1), unit_float(h2));
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            BouncePoint { triangle, barycentrics: Vec2::new(u, v), area }
        })
        .collect()
}

/// A bounce point on the surface this frame: position (m), unit shading normal, unit geometric
/// normal (the face's, on the shading normal's side), diffuse albedo and the area it stands for
/// (m²). It takes light through the shading normal's cosine and none from below its geometric
/// surface (`twin::val_geometry_sided`; docs/design.md §3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BounceSurface {
    pub position: Vec3,
    pub normal: Vec3,
    pub geometric: Vec3,
    pub albedo: Vec3,
    pub area: f32,
}

impl BounceSurface {
    /// Point `p` of `flat` as placed now (WGSL `bounce_surface`).
    pub fn at(flat: &crate::twin::flat::FlatScene, p: &BouncePoint) -> Self {
        let (position, normal, m) = flat.surface_at(p.triangle, p.barycentrics);
        let geometric = flat.geometric_normal(p.triangle, normal);
        BounceSurface { position, normal, geometric, albedo: m.diffuse, area: p.area }
    }

    /// VAL `v`'s geometry at the point (WGSL `val_geometry_sided`).
    fn geometry(&self, v: &Val) -> super::ValGeometry {
        val_geometry_sided(self.position, self.normal, self.geometric, v.position, v.normal, v.area)
    }
}

/// Each point as a candidate VAL (WGSL `bounce_points.wgsl`): its irradiance from every VAL of
/// `vals` that `bvh` (when given) lets through, re-emitted as a Lambertian disc of the point's
/// area with flux `albedo * E * area`. Shadow rays run as the exact reference's, from
/// `x + n_g RAY_OFFSET` to `l + n_l RAY_OFFSET`, and only for pairs with a non-zero term.
pub fn candidate_vals(points: &[BounceSurface], vals: &[Val], bvh: Option<&TraceBvh>) -> Vec<Val> {
    let targets: Vec<Vec3> = vals.iter().map(|v| v.position + v.normal * RAY_OFFSET).collect();
    points
        .par_iter()
        .map_init(
            || (Vec::new(), Vec::new(), Vec::new()),
            |(terms, lit_targets, blocked): &mut (Vec<Vec3>, Vec<Vec3>, Vec<bool>), p| {
                terms.clear();
                lit_targets.clear();
                let mut e = Vec3::ZERO;
                for (v, t) in vals.iter().zip(&targets) {
                    let g = p.geometry(v);
                    let term = v.flux * (g.weight * g.cos_receiver);
                    if bvh.is_none() {
                        e += term;
                    } else if term != Vec3::ZERO {
                        terms.push(term);
                        lit_targets.push(*t);
                    }
                }
                if let Some(bvh) = bvh {
                    let origin = p.position + p.geometric * RAY_OFFSET;
                    bvh.shadow_rays(origin, lit_targets, ShadowTraversal::Single, blocked);
                    e = terms.iter().zip(blocked.iter()).filter(|(_, b)| !**b).map(|(t, _)| *t).sum();
                }
                Val { position: p.position, normal: p.normal, area: p.area, flux: p.albedo * e * p.area }
            },
        )
        .collect()
}

/// Each point's gathered light from every VAL of `vals` (WGSL `bounce_points.wgsl`'s sums, kept
/// by `store_moments`): irradiance and the luminance-weighted moments of the VAL positions, as
/// the gather weighs them (`twin::gather_point`), at the point's two normals. No glossy lobe:
/// the glossy fields are the diffuse ones.
pub fn point_gathered(p: &BounceSurface, vals: &[Val]) -> super::Gathered {
    let (mut e, mut l, mut l2, mut w) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, 0.0f32);
    for v in vals {
        let geo = p.geometry(v);
        let f = geo.weight * geo.cos_receiver;
        e += v.flux * f;
        let g = super::luminance(v.flux) * f + super::GATHER_EPSILON;
        l += g * v.position;
        l2 += g * v.position * v.position;
        w += g;
    }
    super::Gathered {
        irradiance: e,
        diffuse_position: l / w,
        diffuse_second_moment: l2 / w,
        glossy_irradiance: e,
        glossy_position: l / w,
    }
}

/// Each point as a candidate VAL with `disks` visibility (WGSL `bounce_points.wgsl` with
/// `bounce_moments.wgsl`, then `bounce_occlusion.wgsl`): [`candidate_vals`]' unoccluded
/// candidate scaled by the visibility of the point's light sphere (from [`point_gathered`]'s
/// moments) through `discs` (the sparse points) combined by `rule`, as the sparse points'
/// gathered irradiance is (`disks::twin::visibility`).
pub fn disk_occluded_candidate_vals(points: &[BounceSurface], vals: &[Val], discs: &[Disc], rule: Combine) -> Vec<Val> {
    points
        .par_iter()
        .map(|p| {
            let g = point_gathered(p, vals);
            let sphere = light_sphere(g.diffuse_position, g.diffuse_second_moment);
            let visible = visibility(p.position, p.normal, &sphere, discs, rule);
            Val {
                position: p.position,
                normal: p.normal,
                area: p.area,
                flux: p.albedo * g.irradiance * p.area * visible,
            }
        })
        .collect()
}

/// Each point as a candidate VAL seen through the first bounce's groups (WGSL
/// `visibility/group.wgsl`, with the sparse method's `clusters` or `ism` mode): VAL j's
/// irradiance at point i times its group's entry `visibility[i * groups + group_of_val[j]]`
/// (the clusters' lookup of the first bounce's maps at the point, `bounce_visibility.wgsl`),
/// re-emitted as in [`candidate_vals`].
pub fn grouped_candidate_vals(
    points: &[BounceSurface],
    vals: &[Val],
    group_of_val: &[u32],
    visibility: &[f32],
    groups: usize,
) -> Vec<Val> {
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let row = &visibility[i * groups..(i + 1) * groups];
            let e: Vec3 = vals
                .iter()
                .zip(group_of_val)
                .map(|(v, &g)| {
                    let geo = p.geometry(v);
                    v.flux * (geo.weight * geo.cos_receiver * row[(g as usize).min(groups - 1)])
                })
                .sum();
            Val { position: p.position, normal: p.normal, area: p.area, flux: p.albedo * e * p.area }
        })
        .collect()
}

/// `count` second-bounce VALs drawn from `candidates` by flux (WGSL `bounce_sample`): draw k is
/// [`flux_picks`]'s, its flux divided by its probability (`flux * total / (count * luminance)`),
/// its area `area`; a dark VAL (zero flux) where nothing is lit.
pub fn draw_vals(candidates: &[Val], count: u32, area: f32) -> Vec<Val> {
    let (picks, total) = flux_picks(candidates, count);
    picks
        .into_iter()
        .map(|pick| match pick {
            Some(i) => {
                let c = &candidates[i];
                let scale = total / (count as f32 * val_weight(c));
                Val { position: c.position, normal: c.normal, area, flux: c.flux * scale }
            }
            None => Val { position: Vec3::ZERO, normal: Vec3::Z, area, flux: Vec3::ZERO },
        })
        .collect()
}

/// The area (m²) of each drawn VAL: the patch one bounce point stands for (all points stand for
/// the same area). Not the larger mean patch a drawn VAL stands for (`count` times fewer
/// VALs than points): the disc form factor `cos cos a / (pi d² + a)` delivers less than a point
/// to receivers within a few disc radii, so discs that large lose light in a closed room's
/// corners (measured in the white furnace test: 6.4 % of the second bounce's flux with discs of
/// `total / vals`, 2.5 % with a point's patch, about as the first bounce's RSM discs: 2.3 %).
pub fn drawn_area(points: &[BouncePoint]) -> f32 {
    points.first().map_or(0.0, |p| p.area)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two unit squares, one of 4x the area: points land on them in proportion (stratified:
    /// within a point), every barycentric pair inside its triangle, the same in every run and
    /// different for another seed.
    #[test]
    fn points_spread_by_area_and_repeat() {
        let positions = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(2.0, 0.0, 1.0),
            Vec3::new(0.0, 2.0, 1.0),
            Vec3::new(2.0, 2.0, 1.0),
        ];
        let indices = [0, 1, 2, 1, 3, 2, 4, 5, 6, 5, 7, 6];
        let points = bounce_points(&positions, &indices, 1000, 1);
        assert_eq!(points.len(), 1000);
        let on_big = points.iter().filter(|p| p.triangle >= 2).count();
        assert!((799..=801).contains(&on_big), "{on_big} of 1000 on the square of 80 % of the area");
        assert!(points.iter().all(|p| p.barycentrics.min_element() >= 0.0 && p.barycentrics.element_sum() <= 1.0));
        assert!(points.iter().all(|p| (p.area - 5.0 / 1000.0).abs() < 1e-7));
        assert_eq!(points, bounce_points(&positions, &indices, 1000, 1));
        assert_ne!(points, bounce_points(&positions, &indices, 1000, 2));
        assert!(bounce_points(&positions, &[], 10, 1).is_empty());
    }

    /// The draw keeps the flux: grey candidates' drawn flux sums to theirs exactly (each draw
    /// carries total / count), each candidate is drawn about as often as its share of the flux,
    /// unlit ones never, and nothing lit gives dark VALs.
    #[test]
    fn draw_keeps_the_flux_and_follows_it() {
        let val = |x: f32, flux: f32| Val {
            position: Vec3::new(x, 0.0, 0.0),
            normal: Vec3::Z,
            area: 0.1,
            flux: Vec3::splat(flux),
        };
        let candidates: Vec<Val> =
            (0..600u32).map(|i| val(i as f32, if i.is_multiple_of(3) { 0.0 } else { 1.0 + (i % 7) as f32 })).collect();
        let drawn = draw_vals(&candidates, 100, 0.25);
        let total: Vec3 = candidates.iter().map(|c| c.flux).sum();
        let sum: Vec3 = drawn.iter().map(|v| v.flux).sum();
        assert!((sum - total).abs().max_element() < 1e-3 * total.x, "{sum} vs {total}");
        assert!(drawn.iter().all(|v| v.area == 0.25 && !(v.position.x as usize).is_multiple_of(3)));
        let dark = draw_vals(&[val(0.0, 0.0); 4], 3, 0.25);
        assert!(dark.iter().all(|v| v.flux == Vec3::ZERO));
    }

    /// Through the groups' table: all ones is the unoccluded sum; a group's 0 at a point takes
    /// exactly its VALs' light from that point and no other's; a fraction scales it.
    #[test]
    fn grouped_candidates_follow_the_table() {
        let val =
            |x: f32| Val { position: Vec3::new(x, 0.0, 2.0), normal: -Vec3::Z, area: 0.01, flux: Vec3::splat(4.0) };
        let vals = [val(-0.5), val(0.0), val(0.5)];
        let point = |x: f32| BounceSurface {
            position: Vec3::new(x, 0.0, 0.0),
            normal: Vec3::Z,
            geometric: Vec3::Z,
            albedo: Vec3::splat(0.5),
            area: 0.2,
        };
        let points = [point(-1.0), point(1.0)];
        let groups = [0, 1, 1];
        let open = candidate_vals(&points, &vals, None);
        let all = grouped_candidate_vals(&points, &vals, &groups, &[1.0; 4], 2);
        for (a, o) in all.iter().zip(&open) {
            assert!((a.flux - o.flux).abs().max_element() < 1e-6 * o.flux.x, "{a:?} vs {o:?}");
        }
        // Point 0 sees group 1 at a quarter, point 1 loses group 0.
        let seen = grouped_candidate_vals(&points, &vals, &groups, &[1.0, 0.25, 0.0, 1.0], 2);
        let alone = |p: &BounceSurface, v: &[Val]| candidate_vals(std::slice::from_ref(p), v, None)[0].flux;
        let want0 = alone(&points[0], &vals[..1]) + 0.25 * alone(&points[0], &vals[1..]);
        let want1 = alone(&points[1], &vals[1..]);
        assert!((seen[0].flux - want0).abs().max_element() < 1e-6 * want0.x);
        assert!((seen[1].flux - want1).abs().max_element() < 1e-6 * want1.x);
        assert!(seen[1].flux.x < open[1].flux.x);
    }

    /// A point facing a VAL receives its irradiance; behind a plate it receives nothing
    /// through the shadow rays, and the same without them.
    #[test]
    fn candidates_see_the_vals_through_shadow_rays() {
        let light = Val { position: Vec3::new(0.0, 0.0, 2.0), normal: -Vec3::Z, area: 0.01, flux: Vec3::splat(4.0) };
        let point = BounceSurface {
            position: Vec3::ZERO,
            normal: Vec3::Z,
            geometric: Vec3::Z,
            albedo: Vec3::splat(0.5),
            area: 0.2,
        };
        let plate = [Vec3::new(-1.0, -1.0, 1.0), Vec3::new(1.0, -1.0, 1.0), Vec3::new(0.0, 1.0, 1.0)];
        let bvh = TraceBvh::build(&plate, &[[0, 1, 2]]);
        let open = candidate_vals(&[point], &[light], None)[0];
        let e = crate::twin::val_irradiance(point.position, point.normal, &light);
        assert!((open.flux - 0.5 * e * 0.2).abs().max_element() < 1e-7 && open.flux.x > 0.0);
        assert_eq!(candidate_vals(&[point], &[light], Some(&bvh))[0].flux, Vec3::ZERO);
    }

    /// A point whose shading normal is bent 45° toward a VAL just below its geometric surface
    /// receives nothing from it (in its candidate and in its moments); raised above the
    /// surface, the VAL lights it through the shading normal's cosine.
    #[test]
    fn a_bounce_point_takes_no_light_from_below_its_geometric_surface() {
        let point = BounceSurface {
            position: Vec3::ZERO,
            normal: Vec3::new(1.0, 0.0, 1.0).normalize(),
            geometric: Vec3::Z,
            albedo: Vec3::splat(0.5),
            area: 0.2,
        };
        let val =
            |z: f32| Val { position: Vec3::new(2.0, 0.0, z), normal: -Vec3::X, area: 0.01, flux: Vec3::splat(4.0) };
        assert_eq!(candidate_vals(&[point], &[val(-0.1)], None)[0].flux, Vec3::ZERO);
        assert_eq!(point_gathered(&point, &[val(-0.1)]).irradiance, Vec3::ZERO);
        let lit = candidate_vals(&[point], &[val(0.1)], None)[0].flux;
        let e = crate::twin::val_irradiance(point.position, point.normal, &val(0.1));
        assert!(lit.x > 0.0 && (lit - 0.5 * e * 0.2).abs().max_element() < 1e-7, "{lit} vs {}", 0.5 * e * 0.2);
        // The shading normal alone would take the VAL below.
        assert!(crate::twin::val_irradiance(point.position, point.normal, &val(-0.1)).x > 0.0);
    }
}
