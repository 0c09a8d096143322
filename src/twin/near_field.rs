//! Twin of the near field's grid (`gpu/sparse/near_field*.wgsl`): the frame's VALs sorted into
//! the buckets of a hashed uniform grid of cells twice the near-field radius wide, and the
//! per-pixel sum over the buckets of the 2 x 2 x 2 cells around a receiver. The sum equals
//! [`super::shade_near_field`] over every VAL up to float order: a VAL left out lies farther
//! than the radius, where its weight is 0 (`tests::grid_sum_equals_the_sum_over_every_val`).

use glam::{IVec3, Vec3};

use super::Val;
use crate::scene::InterpolationKernel;

/// Fewest and most buckets: the scan's workgroup (64) splits them into runs, and the most keeps
/// each run (2^20 / 64 = 16,384 buckets, two loops) under llvmpipe's loop limit.
pub const BUCKET_RANGE: (u32, u32) = (1 << 10, 1 << 20);

/// Buckets for up to `max_vals` VALs: the power of two at least twice that, within
/// [`BUCKET_RANGE`], so that few cells share a bucket.
pub fn bucket_count(max_vals: u32) -> u32 {
    let wanted = (2 * u64::from(max_vals)).next_power_of_two();
    wanted.clamp(u64::from(BUCKET_RANGE.0), u64::from(BUCKET_RANGE.1)) as u32
}

/// The grid's cell for near-field radius `radius` (m): twice it, so a sphere of the radius
/// lies in 2 x 2 x 2 cells.
pub fn cell_size(radius: f32) -> f32 {
    2.0 * radius
}

/// The cell (of side `cell`) holding `p`.
pub fn cell_of(p: Vec3, cell: f32) -> IVec3 {
    (p / cell).floor().as_ivec3()
}

/// A cell's bucket among `buckets` (a power of two): the spatial hash of Teschner et al. 2003.
pub fn bucket_of(c: IVec3, buckets: u32) -> u32 {
    let u = c.as_uvec3();
    (u.x.wrapping_mul(73_856_093) ^ u.y.wrapping_mul(19_349_663) ^ u.z.wrapping_mul(83_492_791)) & (buckets - 1)
}

/// A vertex's near-field centre (`interpolate.wgsl`'s `centres`): the mean of its sparse
/// points' positions with the weights its interpolation gives them
/// ([`super::interpolation_weights`]); the vertex's own position when it has none. The near
/// field splits a VAL's light at a pixel by the VAL's distance to this point (interpolated over
/// the pixel's triangle), so that what a pixel adds is, to first order in the points' spread,
/// what its sparse points left out.
pub fn vertex_centre(kernel: InterpolationKernel, position: Vec3, normal: Vec3, neighbours: &[(Vec3, Vec3)]) -> Vec3 {
    let offsets: Vec<Vec3> = neighbours.iter().map(|(p, _)| *p - position).collect();
    let normals: Vec<Vec3> = neighbours.iter().map(|(_, n)| *n).collect();
    let w = super::interpolation_weights(kernel, normal, &offsets, &normals);
    let total: f32 = w.iter().sum();
    if total <= 0.0 {
        return position;
    }
    neighbours.iter().zip(&w).map(|((p, _), w)| *p * (w / total)).sum()
}

/// The VALs sorted into hashed buckets.
pub struct ValGrid {
    pub radius: f32,
    /// Per bucket: its VALs' count and first index in `vals`.
    pub counts: Vec<u32>,
    pub starts: Vec<u32>,
    /// The VALs in bucket order (in input order within a bucket).
    pub vals: Vec<Val>,
}

impl ValGrid {
    /// Sort `vals` for near-field radius `radius` (m, > 0) into `buckets` buckets.
    pub fn build(vals: &[Val], radius: f32, buckets: u32) -> Self {
        let cell = cell_size(radius);
        let bucket = |v: &Val| bucket_of(cell_of(v.position, cell), buckets) as usize;
        let mut counts = vec![0u32; buckets as usize];
        for v in vals {
            counts[bucket(v)] += 1;
        }
        let starts: Vec<u32> = counts
            .iter()
            .scan(0u32, |start, &c| {
                let s = *start;
                *start += c;
                Some(s)
            })
            .collect();
        let mut next = starts.clone();
        let mut sorted = vec![Val { position: Vec3::ZERO, normal: Vec3::Y, area: 0.0, flux: Vec3::ZERO }; vals.len()];
        for v in vals {
            let b = bucket(v);
            sorted[next[b] as usize] = *v;
            next[b] += 1;
        }
        Self { radius, counts, starts, vals: sorted }
    }

    /// The buckets a receiver at `p` visits, each once, in the shader's order: the cells from
    /// the one holding `p - radius` on every axis, x fastest.
    pub fn buckets_around(&self, p: Vec3) -> Vec<u32> {
        let corner = cell_of(p - Vec3::splat(self.radius), cell_size(self.radius));
        let mut visited: Vec<u32> = Vec::with_capacity(8);
        for c in 0..8 {
            let offset = IVec3::new(c & 1, (c >> 1) & 1, c >> 2);
            let b = bucket_of(corner + offset, self.counts.len() as u32);
            if !visited.contains(&b) {
                visited.push(b);
            }
        }
        visited
    }

    /// The VALs of the buckets around `p` (a superset of those within the radius).
    pub fn near_vals(&self, p: Vec3) -> impl Iterator<Item = &Val> {
        self.buckets_around(p).into_iter().flat_map(|b| {
            let start = self.starts[b as usize] as usize;
            &self.vals[start..start + self.counts[b as usize] as usize]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Material;
    use crate::twin::shade_near_field;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_vals(rng: &mut ChaCha8Rng, n: usize, extent: f32) -> Vec<Val> {
        (0..n)
            .map(|_| {
                let position = Vec3::new(rng.random(), rng.random(), rng.random()) * extent - extent / 2.0;
                let normal = Vec3::new(rng.random::<f32>() - 0.5, rng.random(), rng.random::<f32>() - 0.5).normalize();
                Val { position, normal, area: 1e-3, flux: Vec3::new(1.0, 0.8, 0.6) * rng.random::<f32>() }
            })
            .collect()
    }

    #[test]
    fn bucket_count_is_a_power_of_two_in_range() {
        assert_eq!(bucket_count(0), BUCKET_RANGE.0);
        assert_eq!(bucket_count(1000), 2048);
        assert_eq!(bucket_count(1025), 4096);
        assert_eq!(bucket_count(u32::MAX), BUCKET_RANGE.1);
    }

    #[test]
    fn cells_and_buckets_of_negative_coordinates() {
        assert_eq!(cell_of(Vec3::new(-0.1, 0.1, 2.5), 1.0), IVec3::new(-1, 0, 2));
        for c in [IVec3::new(-1, -1, -1), IVec3::new(i32::MIN, 0, i32::MAX)] {
            assert!(bucket_of(c, 1024) < 1024);
        }
    }

    /// Every VAL within the radius of a receiver is in the buckets it visits, and none twice,
    /// so the grid's sum is the sum over every VAL. Few buckets (8 for a scene 7 cells wide)
    /// make cells share buckets, which the visit must not count twice; the tolerance is float
    /// order (relative 1e-4).
    #[test]
    fn grid_sum_equals_the_sum_over_every_val() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let vals = random_vals(&mut rng, 3000, 4.0);
        let surface =
            Material { diffuse: Vec3::splat(0.7), specular: Vec3::splat(0.2), exponent: 30.0, diffuse_texture: None };
        for buckets in [8, BUCKET_RANGE.0, bucket_count(3000)] {
            let grid = ValGrid::build(&vals, 0.3, buckets);
            let mut lit = 0;
            for _ in 0..300 {
                let p = Vec3::new(rng.random(), rng.random(), rng.random()) * 4.0 - 2.0;
                let n = Vec3::new(rng.random::<f32>() - 0.5, -1.0, rng.random::<f32>() - 0.5).normalize();
                let eye = Vec3::new(0.0, -3.0, 0.0);
                // The centre up to a third of the radius away from the pixel, as at a corner.
                let centre = p + (Vec3::new(rng.random(), rng.random(), rng.random()) - 0.5) * 0.2;
                let all = shade_near_field(p, n, n, &surface, eye, centre, &vals, true, grid.radius);
                let near = shade_near_field(p, n, n, &surface, eye, centre, grid.near_vals(centre), true, grid.radius);
                assert!((all - near).abs().max_element() <= 1e-4 * all.max_element() + 1e-12, "{all} vs {near}");
                lit += usize::from(all.max_element() > 0.0);
            }
            assert!(lit > 200, "only {lit} of 300 receivers had a VAL within the radius");
        }
    }

    /// The centre is the interpolation's weighted mean of the neighbours: on a flat wall with
    /// neighbours placed symmetrically about the vertex it is the vertex; with every neighbour on
    /// one side (a corner) it moves to that side; facing-away neighbours weigh nothing; without
    /// neighbours it is the vertex.
    #[test]
    fn vertex_centre_is_where_the_interpolation_takes_its_light() {
        let (v, n) = (Vec3::new(1.0, 2.0, 0.0), Vec3::Z);
        for kernel in [InterpolationKernel::Paper, InterpolationKernel::Smooth] {
            // Two rings, so that the inner one weighs more than nothing (d_max is the outer's).
            let ring = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y];
            let symmetric: Vec<(Vec3, Vec3)> =
                ring.iter().chain(&ring.map(|o| 2.0 * o)).map(|o| (v + 0.1 * *o, n)).collect();
            assert!(vertex_centre(kernel, v, n, &symmetric).distance(v) < 1e-6);
            let one_side = [(v + Vec3::new(0.1, 0.0, 0.0), n), (v + Vec3::new(0.2, 0.05, 0.0), n)];
            let c = vertex_centre(kernel, v, n, &one_side);
            assert!(c.x > v.x + 0.09 && c.x < v.x + 0.2, "{kernel:?}: {c}");
            let mut away = symmetric.to_vec();
            away.push((v + Vec3::new(0.0, 0.0, 0.05), -Vec3::Z));
            assert!(vertex_centre(kernel, v, n, &away).distance(v) < 1e-6, "{kernel:?}");
            assert_eq!(vertex_centre(kernel, v, n, &[]), v);
        }
    }

    #[test]
    fn near_field_weight_splits_each_val_once() {
        use crate::twin::near_field_weight;
        assert_eq!(near_field_weight(0.3, 0.0), 0.0);
        assert_eq!(near_field_weight(0.0, 1.0), 1.0);
        assert_eq!(near_field_weight(0.5, 1.0), 1.0);
        assert!((near_field_weight(0.75, 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(near_field_weight(1.0, 1.0), 0.0);
        assert_eq!(near_field_weight(2.0, 1.0), 0.0);
        let steps: Vec<f32> = (0..=100).map(|i| near_field_weight(i as f32 / 100.0, 1.0)).collect();
        assert!(steps.windows(2).all(|w| w[1] <= w[0]), "not monotone");
    }
}
