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
    let t = any_perpendicular(n);
    let b = n.cross(t);
    let sphere_area = PI * sphere.radius * sphere.radius;
    let Some(s) = project(x, n, t, b, sphere.centre, 1.0, sphere_area) else {
        return 0.0;
    };
    if s.side <= 0.0 {
        return 0.0;
    }
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
