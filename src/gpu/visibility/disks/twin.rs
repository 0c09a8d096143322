//! CPU twin of the disc-occluder approximation of indirect visibility (docs/design.md §4 step 3,
//! paper §3.3). This is the statement of the
//! maths and its analytic tests, which the GPU pass will be checked against.
//!
//! Per sparse point `x`, the VALs it sees are summarised as a sphere `S` at the averaged light
//! position `l'_d` whose radius is the largest per-axis weighted standard deviation of the VAL
//! positions. Every other sparse point is a disc occluder. Sphere and discs are projected onto
//! `x`'s tangent-plane unit circle (Nusselt's analogue: a projected area is `pi * F`), both are
//! approximated by axis-aligned squares of the same area, and a disc occludes the fraction of
//! the sphere's square it overlaps, fully when it is nearer than the sphere's near side, scaled
//! linearly to zero between the near side and the centre, not at all beyond the centre.
//!
//! A disc occludes only when its plane separates `x` from the sphere's centre ([`separates`]):
//! the paper's test is angular and by depth only, so a disc lying on the lit surface itself (a
//! wall point beside the VALs on that wall, seen from the ceiling) overlapped the sphere's square,
//! was nearer than its near side, and darkened receivers that nothing occludes: on an open room
//! every wall point darkened the walls and ceiling around it. In a convex room no wall disc
//! separates a receiver from a light inside the room, so walls no longer occlude; the faces of
//! an object between the two (either side of it) still do.

use crate::twin::exact_cpu::morton_code;
use crate::twin::{COINCIDENT_DISTANCE_SQ, any_perpendicular};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// The sphere standing for all the light a sparse point receives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSphere {
    pub centre: Vec3,
    /// m
    pub radius: f32,
}

/// A sparse point seen as an occluder: a disc (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disc {
    pub position: Vec3,
    pub normal: Vec3,
    pub radius: f32,
}

/// How the occlusion of several discs combines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Combine {
    /// The paper: `clamp(sum o_i, 0, 1)`; overlapping occluders are counted twice.
    Sum,
    /// `1 - prod (1 - o_i)`: occluders treated as independent.
    Product,
}

/// The light sphere from the weighted first and second moments of the VAL positions
/// (`mean = sum g l / sum g`, `second = sum g l^2 / sum g`, per axis).
pub fn light_sphere(mean: Vec3, second: Vec3) -> LightSphere {
    let variance = (second - mean * mean).max(Vec3::ZERO);
    LightSphere { centre: mean, radius: variance.max_element().sqrt() }
}

/// A shape projected onto the unit circle of `x`'s tangent plane: centre and square side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projected {
    pub centre: Vec2,
    pub side: f32,
    /// Distance from `x` to the shape (m).
    pub distance: f32,
}

/// Project a disc of area `area` at `centre` onto the tangent-plane unit circle of (`x`, `n`)
/// with tangent frame (`t`, `b`). `cos_shape` is the cosine between the shape's normal and the
/// direction to `x` (1 for a sphere). `None` when the shape is behind `x`'s horizon.
pub fn project(x: Vec3, n: Vec3, t: Vec3, b: Vec3, centre: Vec3, cos_shape: f32, area: f32) -> Option<Projected> {
    let v = centre - x;
    let d2 = v.length_squared();
    if d2 <= COINCIDENT_DISTANCE_SQ {
        return None;
    }
    let d = d2.sqrt();
    let u = v / d;
    let cos_x = n.dot(u);
    if cos_x <= 0.0 {
        return None;
    }
    let form_factor = cos_x * cos_shape.abs() * area / (PI * d2 + area);
    Some(Projected { centre: Vec2::new(u.dot(t), u.dot(b)), side: (PI * form_factor).sqrt(), distance: d })
}

/// Fraction of the occluder's effect kept at distance `d` from `x` for a light sphere at
/// distance `d_s` with radius `r`: 1 in front of the sphere, linear to 0 at its centre, 0 beyond.
pub fn depth_scale(d: f32, d_s: f32, r: f32) -> f32 {
    if d >= d_s {
        0.0
    } else if d <= d_s - r || r <= 0.0 {
        1.0
    } else {
        (d_s - d) / r
    }
}

/// Area of the intersection of two axis-aligned squares.
pub fn square_overlap(a: &Projected, b: &Projected) -> f32 {
    let overlap = |ca: f32, cb: f32| {
        let lo = (ca - a.side * 0.5).max(cb - b.side * 0.5);
        let hi = (ca + a.side * 0.5).min(cb + b.side * 0.5);
        (hi - lo).max(0.0)
    };
    overlap(a.centre.x, b.centre.x) * overlap(a.centre.y, b.centre.y)
}

/// Whether the disc's plane strictly separates `x` from the light's centre `c` (the point light
/// the sparse point's light is renormalised into): the only discs that can lie between them.
pub fn separates(x: Vec3, c: Vec3, disc: &Disc) -> bool {
    disc.normal.dot(x - disc.position) * disc.normal.dot(c - disc.position) < 0.0
}

/// Occlusion `o` in [0, 1] of the light sphere by one disc, seen from (`x`, `n`).
pub fn disc_occlusion(x: Vec3, n: Vec3, sphere: &LightSphere, disc: &Disc) -> f32 {
    if !separates(x, sphere.centre, disc) {
        return 0.0;
    }
    let Some((t, b, s)) = projected_sphere(x, n, sphere) else {
        return 0.0;
    };
    let to_disc = (disc.position - x).normalize_or(n);
    let area = PI * disc.radius * disc.radius;
    let Some(o) = project(x, n, t, b, disc.position, disc.normal.dot(to_disc), area) else {
        return 0.0;
    };
    let fraction = (square_overlap(&s, &o) / (s.side * s.side)).min(1.0);
    fraction * depth_scale(o.distance, s.distance, sphere.radius)
}

/// Visibility factor `1 - occlusion` by which the gathered `E_x` and `G_x` are multiplied.
pub fn visibility(x: Vec3, n: Vec3, sphere: &LightSphere, discs: &[Disc], rule: Combine) -> f32 {
    let os = discs.iter().map(|d| disc_occlusion(x, n, sphere, d));
    let occlusion = match rule {
        Combine::Sum => os.sum::<f32>().clamp(0.0, 1.0),
        Combine::Product => 1.0 - os.map(|o| 1.0 - o).product::<f32>(),
    };
    1.0 - occlusion
}

/// Relative slack of [`group_may_occlude`]'s bounds: they rule a group out only with this much
/// room, so that float rounding in the bounds never drops a disc that occludes.
pub const GROUP_CULL_SLACK: f32 = 1e-3;

/// A group of disc occluders, bounded: every disc's centre within `radius` of `centre`, no disc
/// larger than `largest_disc` (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiscGroup {
    pub centre: Vec3,
    pub radius: f32,
    pub largest_disc: f32,
}

/// The order that puts nearby points next to each other: along a Morton curve over the points'
/// bounding box (the exact reference's code, `twin::exact_cpu::morton_code`), ties by index.
pub fn morton_order(positions: &[Vec3]) -> Vec<u32> {
    let (lo, hi) = positions.iter().fold((Vec3::MAX, Vec3::MIN), |(a, b), &p| (a.min(p), b.max(p)));
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.sort_by_cached_key(|&i| (morton_code(positions[i as usize], lo, hi), i));
    order
}

/// The bounds of consecutive runs of `size` discs taken in `order` (the last run shorter).
pub fn disc_groups(discs: &[Disc], order: &[u32], size: usize) -> Vec<DiscGroup> {
    order
        .chunks(size)
        .map(|run| {
            let run: Vec<&Disc> = run.iter().map(|&i| &discs[i as usize]).collect();
            let (lo, hi) = run.iter().fold((Vec3::MAX, Vec3::MIN), |(a, b), d| (a.min(d.position), b.max(d.position)));
            let centre = (lo + hi) * 0.5;
            let radius = run.iter().map(|d| d.position.distance(centre)).fold(0.0, f32::max);
            let largest_disc = run.iter().map(|d| d.radius).fold(0.0, f32::max);
            DiscGroup { centre, radius, largest_disc }
        })
        .collect()
}

/// Whether any disc of `group` may occlude the light sphere of (`x`, `n`) (tangent frame `t`,
/// `b`), whose projection is `s`: false only when no disc of the group can, for one of three
/// reasons that hold for every disc within the group's bounds: all lie behind `x`'s tangent
/// plane (no projection), all lie farther than the sphere's centre (depth scale 0), or all
/// project farther from the sphere's square than the largest disc's square reaches (no
/// overlap). A disc's direction from `x` is within the angle `asin(radius / distance)` of the
/// group centre's, and its square's half side at most `sqrt(pi) / 2 * r / distance`
/// ([`project`]'s form factor is below `r² / d²`). Conservative by [`GROUP_CULL_SLACK`]: the
/// pass that skips the groups it rules out sums exactly the discs' non-zero terms.
pub fn group_may_occlude(x: Vec3, n: Vec3, t: Vec3, b: Vec3, s: &Projected, group: &DiscGroup) -> bool {
    let v = group.centre - x;
    let d = v.length();
    if n.dot(v) + group.radius < -GROUP_CULL_SLACK * (d + group.radius) {
        return false;
    }
    let near = d - group.radius;
    if near <= GROUP_CULL_SLACK * d {
        return true;
    }
    if near > s.distance * (1.0 + GROUP_CULL_SLACK) {
        return false;
    }
    let u = v / d;
    let spread = (group.radius / d).min(1.0).asin();
    let largest = PI.sqrt() * 0.5 * group.largest_disc / near;
    let gap = (Vec2::new(u.dot(t), u.dot(b)) - s.centre).abs().max_element();
    gap <= (s.side * 0.5 + spread + largest) * (1.0 + GROUP_CULL_SLACK) + GROUP_CULL_SLACK
}

/// The light sphere's projection seen from (`x`, `n`) with the tangent frame of [`disc_occlusion`],
/// `None` where nothing can occlude it (behind the horizon, or a point).
pub fn projected_sphere(x: Vec3, n: Vec3, sphere: &LightSphere) -> Option<(Vec3, Vec3, Projected)> {
    let t = any_perpendicular(n);
    let b = n.cross(t);
    let s = project(x, n, t, b, sphere.centre, 1.0, PI * sphere.radius * sphere.radius)?;
    (s.side > 0.0).then_some((t, b, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square plate of discs tiling `[-h, h]^2` at height `y`, each of the tile's area.
    fn plate(y: f32, h: f32, n: usize) -> Vec<Disc> {
        let step = 2.0 * h / n as f32;
        let radius = step / PI.sqrt();
        (0..n * n)
            .map(|k| {
                let (i, j) = ((k % n) as f32, (k / n) as f32);
                Disc { position: Vec3::new(-h + (i + 0.5) * step, y, -h + (j + 0.5) * step), normal: -Vec3::Y, radius }
            })
            .collect()
    }

    fn sheet() -> LightSphere {
        // A 0.4 m sheet of VALs 2 m above the receiver: std dev of a uniform 0.4 m square.
        light_sphere(Vec3::new(0.0, 2.0, 0.0), Vec3::new(0.04 / 3.0, 4.0, 0.04 / 3.0))
    }

    #[test]
    fn sphere_radius_is_the_largest_standard_deviation() {
        let s = light_sphere(Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0 + 0.04, 4.0 + 0.09, 9.0));
        assert!((s.radius - 0.3).abs() < 1e-5);
        assert_eq!(light_sphere(Vec3::ONE, Vec3::splat(0.5)).radius, 0.0, "negative variance from rounding clamps");
    }

    /// A large opaque plate between the VAL sheet and the receiver blocks everything under the
    /// paper's sum rule (to within slivers). The product rule treats the plate's tiles as independent occluders and
    /// lets about exp(-sum o) through instead: it under-occludes surfaces tiled by many small discs,
    /// which is what sparse points on a mesh are.
    #[test]
    fn plate_between_light_and_receiver_occludes_fully() {
        let discs = plate(1.0, 2.0, 40);
        let s = sheet();
        // Not exactly 0: the squares of 1600 discs leave slivers at the plate's projected edge.
        let sum = visibility(Vec3::ZERO, Vec3::Y, &s, &discs, Combine::Sum);
        assert!(sum < 0.02, "sum rule lets {sum} through");
        let total: f32 = discs.iter().map(|d| disc_occlusion(Vec3::ZERO, Vec3::Y, &s, d)).sum();
        assert!(total > 0.9, "the plate's discs cover the sphere: sum of o = {total}");
        let product = visibility(Vec3::ZERO, Vec3::Y, &s, &discs, Combine::Product);
        // Measured: 0.32 (each tile hides ~10 % of the sphere, so prod(1 - o) is near exp(-1)).
        assert!(product > 0.25 && product <= (-total).exp(), "product rule lets {product} through, sum o = {total}");
    }

    /// Occluders below the horizon, beside the path, or beyond the sphere's centre do nothing.
    #[test]
    fn occluders_out_of_the_way_do_nothing() {
        let s = sheet();
        let below = plate(-1.0, 2.0, 10);
        let beside: Vec<Disc> = plate(1.0, 0.3, 6)
            .into_iter()
            .map(|mut d| {
                d.position.x += 3.0;
                d
            })
            .collect();
        let beyond = plate(2.5, 2.0, 10);
        for discs in [below, beside, beyond] {
            assert_eq!(visibility(Vec3::ZERO, Vec3::Y, &s, &discs, Combine::Sum), 1.0);
        }
    }

    /// The open-room bias: seen from the ceiling, discs on a lit wall between the ceiling and the
    /// wall's VALs overlap the light sphere's square and are nearer than its near side, so the
    /// paper's angular-and-depth test counts them as occluders (checked here term by term); they
    /// lie beside the light, not between, and occlude nothing. The same discs moved 0.3 m off
    /// the wall into the room, between ceiling and light, still occlude.
    #[test]
    fn discs_on_the_lit_wall_do_not_occlude() {
        // VALs on the wall x = -1 (normal +X) around (-1, 1, 0), a 0.8 m square: per-axis standard
        // deviation 0.8 / sqrt(12) in y and z, 0 in x.
        let var = 0.64 / 12.0;
        let sphere = light_sphere(Vec3::new(-1.0, 1.0, 0.0), Vec3::new(1.0, 1.0 + var, var));
        let (x, n) = (Vec3::new(-0.6, 2.0, 0.0), -Vec3::Y);
        // The wall's sparse points between the ceiling and the lit patch, 0.1 m apart.
        let wall: Vec<Disc> = (0..6)
            .flat_map(|i| (-3..=3).map(move |k| (i, k)))
            .map(|(i, k)| Disc {
                position: Vec3::new(-1.0, 1.45 + 0.1 * i as f32, 0.1 * k as f32),
                normal: Vec3::X,
                radius: 0.06,
            })
            .collect();
        let (t, b) = (any_perpendicular(n), n.cross(any_perpendicular(n)));
        let s = project(x, n, t, b, sphere.centre, 1.0, PI * sphere.radius * sphere.radius).unwrap();
        let paper_would_occlude = wall.iter().any(|d| {
            let cos = d.normal.dot((d.position - x).normalize());
            project(x, n, t, b, d.position, cos, PI * d.radius * d.radius).is_some_and(|o| {
                square_overlap(&s, &o) > 0.0 && depth_scale(o.distance, s.distance, sphere.radius) > 0.0
            })
        });
        assert!(paper_would_occlude, "the case must be the biased one");
        assert!(wall.iter().all(|d| !separates(x, sphere.centre, d)));
        assert_eq!(visibility(x, n, &sphere, &wall, Combine::Sum), 1.0);
        let in_front: Vec<Disc> = wall.iter().map(|d| Disc { position: d.position + Vec3::X * 0.3, ..*d }).collect();
        let v = visibility(x, n, &sphere, &in_front, Combine::Sum);
        assert!(v < 0.9, "discs between the ceiling and the light occlude: visibility {v}");
    }

    /// A group ruled out by [`group_may_occlude`] holds no disc that occludes: random groups of
    /// discs (some a few disc radii from the receiver, some far), random receivers and light
    /// spheres, every disc of every ruled-out group checked with [`disc_occlusion`]. Each of the
    /// three reasons must rule out some groups, and some groups kept must occlude.
    #[test]
    fn a_group_ruled_out_holds_no_occluding_disc() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let unit = |rng: &mut rand_chacha::ChaCha8Rng| {
            Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                .normalize_or(Vec3::Y)
        };
        let (mut ruled_out, mut kept_occluding, mut checked) = (0, 0, 0);
        let mut reasons = [0; 3];
        for _ in 0..4000 {
            let centre = unit(&mut rng) * rng.random_range(0.0..3.0);
            let spread = rng.random_range(0.02..0.6);
            let discs: Vec<Disc> = (0..16)
                .map(|_| Disc {
                    // Most near the bounds' surface, where the bounds are tight.
                    position: centre + unit(&mut rng) * spread * rng.random_range(0.0f32..1.0).sqrt().sqrt(),
                    normal: unit(&mut rng),
                    radius: rng.random_range(0.005..0.3),
                })
                .collect();
            let order: Vec<u32> = (0..discs.len() as u32).collect();
            let group = disc_groups(&discs, &order, discs.len())[0];
            for _ in 0..40 {
                let x = unit(&mut rng) * rng.random_range(0.0..3.0);
                let n = unit(&mut rng);
                let sphere =
                    LightSphere { centre: x + unit(&mut rng) * rng.random_range(0.05..4.0), radius: rng.random_range(0.0..1.0) };
                let Some((t, b, s)) = projected_sphere(x, n, &sphere) else { continue };
                checked += 1;
                let occluding = discs.iter().filter(|d| disc_occlusion(x, n, &sphere, d) > 0.0).count();
                if group_may_occlude(x, n, t, b, &s, &group) {
                    kept_occluding += usize::from(occluding > 0);
                    continue;
                }
                ruled_out += 1;
                assert_eq!(occluding, 0, "a ruled-out group occludes: x {x}, n {n}, {sphere:?}, {group:?}");
                let v = group.centre - x;
                let d = v.length();
                reasons[if n.dot(v) + group.radius < 0.0 {
                    0
                } else if d - group.radius > s.distance {
                    1
                } else {
                    2
                }] += 1;
            }
        }
        assert!(kept_occluding > 100 && ruled_out > 1000, "checked {checked}: ruled out {ruled_out}, kept and occluding {kept_occluding}");
        assert!(reasons.iter().all(|&r| r > 50), "ruled out behind, beyond, beside: {reasons:?}");
    }

    #[test]
    fn morton_order_keeps_neighbours_together() {
        // A 16 x 16 grid in shuffled order: each run of 16 in Morton order spans a 4 x 4 block.
        let mut positions: Vec<Vec3> = (0..256).map(|k| Vec3::new((k % 16) as f32, 0.0, (k / 16) as f32)).collect();
        positions.reverse();
        let order = morton_order(&positions);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..256).collect::<Vec<u32>>(), "a permutation");
        for run in order.chunks(16) {
            let (lo, hi) = run.iter().fold((Vec3::MAX, Vec3::MIN), |(a, b), &i| {
                (a.min(positions[i as usize]), b.max(positions[i as usize]))
            });
            assert_eq!(hi - lo, Vec3::new(3.0, 0.0, 3.0), "run {run:?}");
        }
        let discs: Vec<Disc> = positions.iter().map(|&p| Disc { position: p, normal: Vec3::Y, radius: 0.1 }).collect();
        let groups = disc_groups(&discs, &order, 16);
        assert_eq!(groups.len(), 16);
        assert!(groups.iter().all(|g| (g.radius - (4.5f32).sqrt()).abs() < 1e-5 && g.largest_disc == 0.1));
    }

    /// Inside the sphere the occlusion is scaled linearly with depth.
    #[test]
    fn occluder_inside_the_sphere_is_scaled() {
        assert_eq!(depth_scale(1.0, 2.0, 0.5), 1.0);
        assert_eq!(depth_scale(1.75, 2.0, 0.5), 0.5);
        assert_eq!(depth_scale(2.0, 2.0, 0.5), 0.0);
        assert_eq!(depth_scale(3.0, 2.0, 0.5), 0.0);
        // A big disc right on the axis covers the sphere's whole square: o is the depth scale.
        let s = LightSphere { centre: Vec3::new(0.0, 2.0, 0.0), radius: 0.5 };
        for (y, want) in [(1.0, 1.0), (1.75, 0.5), (1.9, 0.2)] {
            let disc = Disc { position: Vec3::new(0.0, y, 0.0), normal: -Vec3::Y, radius: 2.0 };
            let o = disc_occlusion(Vec3::ZERO, Vec3::Y, &s, &disc);
            assert!((o - want).abs() < 1e-4, "disc at {y}: {o} vs {want}");
        }
    }

    /// Two coincident occluders each hiding about half the sphere: the sum counts the same
    /// shadow twice, the product does not.
    #[test]
    fn sum_double_counts_where_product_does_not() {
        let s = LightSphere { centre: Vec3::new(0.0, 2.0, 0.0), radius: 0.3 };
        let shifted = Disc { position: Vec3::new(0.0, 1.0, 0.0), normal: -Vec3::Y, radius: 0.1 };
        let o = disc_occlusion(Vec3::ZERO, Vec3::Y, &s, &shifted);
        assert!(o > 0.3 && o < 0.7, "{o}");
        let two = [shifted, shifted];
        let sum = visibility(Vec3::ZERO, Vec3::Y, &s, &two, Combine::Sum);
        let product = visibility(Vec3::ZERO, Vec3::Y, &s, &two, Combine::Product);
        assert!((sum - (1.0 - (2.0 * o).min(1.0))).abs() < 1e-5);
        assert!((product - (1.0 - o) * (1.0 - o)).abs() < 1e-5);
        assert!(product > sum);
    }
}
