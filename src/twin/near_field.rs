//! Twin of the near field's grid (`gpu/sparse/near_field*.wgsl`): the frame's VALs sorted into
//! the buckets of a hashed uniform grid of cells twice the near-field radius wide, each cell's
//! in [`COLUMNS`] columns along x, and the per-pixel sum over the columns of the 2 x 2 x 2
//! cells around a receiver that its sphere reaches ([`ValGrid::runs_around`]). The sum equals
//! [`super::shade_near_field`] over every VAL up to float order: a VAL left out lies farther
//! than the radius, where its weight is 0 (`tests::grid_sum_equals_the_sum_over_every_val`).
//!
//! Interleaved (`settings.sparse.near_field_interleave` = side N > 1): the VALs fall into N²
//! subsets by a hash of their index ([`val_subset`]), each pixel of an N x N block sums one
//! subset ([`pixel_subset`]) times N² ([`near_field_terms`]), and a filter over the block
//! ([`filter`]) averages the pixels that lie on the same surface as the pixel: where all of
//! them do, every subset counts once, and the pixel gets the whole near field. The VALs within
//! [`close_radius`] (the radius over N) light every pixel, through a second grid of cells that
//! much smaller (about 1/8 of the per-pixel work at N = 4), and their close share is the
//! pixel's own, not filtered ([`NearParts`]): it changes fastest from pixel to pixel.

use glam::{IVec3, Vec3};

use super::{
    Val, mirror, near_field_weight, pcg_hash, phong_lobe, phong_normalisation, val_geometry_sided, view_direction,
};
use crate::scene::{InterpolationKernel, Material};

/// Fewest and most buckets: the scan's workgroup (64) splits them into runs, and the most keeps
/// each run (2^20 / 64 = 16,384 buckets, two loops) under llvmpipe's loop limit.
pub const BUCKET_RANGE: (u32, u32) = (1 << 10, 1 << 20);

/// Buckets for up to `max_vals` VALs: the power of two at least twice that, within
/// [`BUCKET_RANGE`], so that few cells share a bucket.
pub fn bucket_count(max_vals: u32) -> u32 {
    let wanted = (2 * u64::from(max_vals)).next_power_of_two();
    wanted.clamp(u64::from(BUCKET_RANGE.0), u64::from(BUCKET_RANGE.1)) as u32
}

pub use crate::scene::NEAR_FIELD_INTERLEAVE_SIDES as INTERLEAVE_SIDES;

/// Slots of the grid (cell buckets x subsets x [`COLUMNS`]) for up to `max_vals` VALs in
/// `subsets` subsets: [`bucket_count`] of the VALs times the columns, at most
/// `BUCKET_RANGE.1` (the one-workgroup scan's cost grows with the slots), and at least 256 cell
/// buckets. The cells are twice the near-field radius wide, so a frame's VALs occupy far fewer
/// cells than there are VALs wherever the near field is worth its cost.
pub fn slot_count(max_vals: u32, subsets: u32) -> u32 {
    (bucket_count(max_vals) * COLUMNS).min(BUCKET_RANGE.1).max(256 * subsets * COLUMNS)
}

/// Columns per cell: each cell is split along x into this many slices, and each of a bucket's
/// subsets into one slot per column, in column order, so that the VALs of a run of columns are
/// one run of the grid's VALs. A receiver's sphere, as wide as a cell, reaches about half of the
/// columns of the two cells it spans on x (plus the two it enters partly), so it reads about
/// `1/2 + 1/COLUMNS` of their VALs instead of all of them.
pub const COLUMNS: u32 = 8;

/// The column (of [`COLUMNS`]) of the cell of side `cell` and index `cell_x` along x that the
/// x coordinate `x` falls in, clamped to the cell's (`near_field.wgsl`'s `column_of`).
pub fn column_of(x: f32, cell_x: i32, cell: f32) -> u32 {
    let columns = COLUMNS as f32;
    ((x / (cell / columns)).floor() - cell_x as f32 * columns).clamp(0.0, columns - 1.0) as u32
}

/// The columns `[first, end)` that the x extent [`lo`, `hi`] of a receiver's sphere reaches in
/// the cells `corner_x` and `corner_x + 1` along x, of side `cell`; the second is empty where
/// the extent ends in the first (`near_field_shade.wgsl`'s `column_runs`).
pub fn column_runs(lo: f32, hi: f32, corner_x: i32, cell: f32) -> [(u32, u32); 2] {
    let first = column_of(lo, corner_x, cell);
    if ((hi / cell).floor() as i32) <= corner_x {
        return [(first, column_of(hi, corner_x, cell) + 1), (0, 0)];
    }
    [(first, COLUMNS), (0, column_of(hi, corner_x + 1, cell) + 1)]
}

/// The subset (of `subsets`, a power of two) VAL `index` of the frame falls in.
pub fn val_subset(index: u32, subsets: u32) -> u32 {
    pcg_hash(index) & (subsets - 1)
}

/// The subset pixel (`x`, `y`) sums, on a block `side` pixels wide: every `side` x `side`
/// window holds each subset once.
pub fn pixel_subset(x: u32, y: u32, side: u32) -> u32 {
    x % side + side * (y % side)
}

/// What a pixel's near VALs deliver before its material: the irradiance (W/m², RGB) and the
/// same weighted by the Phong lobe toward the eye, so that the radiance is
/// `diffuse / pi * irradiance + specular * phong_normalisation(k) * lobe` ([`NearTerms::radiance`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NearTerms {
    pub irradiance: Vec3,
    pub lobe: Vec3,
}

impl NearTerms {
    /// The radiance toward the eye at a surface of `material` (its lobe when `glossy`).
    pub fn radiance(&self, material: &Material, glossy: bool) -> Vec3 {
        let mut l = material.diffuse / std::f32::consts::PI * self.irradiance;
        if glossy {
            l += material.specular * phong_normalisation(material.exponent) * self.lobe;
        }
        l
    }
}

/// The radius (m) within which every pixel takes every VAL also when the near field of radius
/// `radius` is interleaved over blocks `side` wide: the radius over the side (0 when not
/// interleaved). A VAL that close lights a pixel far more than its neighbours a few pixels away
/// (its light falls with the squared distance), so shading it at one pixel of 16 and spreading
/// the result over the block would make fireflies; beyond it a VAL's light varies little over a
/// block. Each VAL's near share splits into this close share, [`super::near_field_weight`] at
/// this radius, and the interleaved rest.
pub fn close_radius(radius: f32, side: u32) -> f32 {
    if side > 1 { radius / side as f32 } else { 0.0 }
}

/// An interleaved pixel's near field in two parts: every VAL's close share ([`close_radius`]),
/// which the pixel adds itself, and the rest of the near share of its subset's VALs times the
/// subsets, which [`filter`] averages over the block. Not interleaved, the close share is 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NearParts {
    pub close: NearTerms,
    pub rest: NearTerms,
}

impl NearParts {
    /// Both parts together: [`super::shade_near_field`]'s terms when not interleaved.
    pub fn sum(&self) -> NearTerms {
        NearTerms { irradiance: self.close.irradiance + self.rest.irradiance, lobe: self.close.lobe + self.rest.lobe }
    }
}

/// [`super::shade_near_field`] before the material as an interleaved pixel of subset `subset` of
/// `subsets` (side²) takes it: every VAL's close share ([`close_radius`]) and, for the VALs of
/// its subset (`vals` in the frame's order, whose index decides the subset), the rest of the
/// near share times `subsets`.
#[allow(clippy::too_many_arguments)]
pub fn near_field_terms(
    receiver: (Vec3, Vec3, Vec3),
    exponent: f32,
    eye: Vec3,
    centre: Vec3,
    vals: &[Val],
    (subset, subsets): (u32, u32),
    glossy: bool,
    radius: f32,
) -> NearParts {
    let close = close_radius(radius, (subsets as f32).sqrt().round() as u32);
    let share = |v: &Val| near_field_weight(v.position.distance(centre), close);
    let close_terms = terms_weighted(receiver, exponent, eye, vals.iter().map(|v| (v, share(v))), glossy);
    let mine = vals.iter().enumerate().filter(|(i, _)| val_subset(*i as u32, subsets) == subset);
    let rest = mine.map(|(_, v)| (v, near_field_weight(v.position.distance(centre), radius) - share(v)));
    let rest = terms_weighted(receiver, exponent, eye, rest, glossy);
    let scale = subsets as f32;
    NearParts { close: close_terms, rest: NearTerms { irradiance: scale * rest.irradiance, lobe: scale * rest.lobe } }
}

/// The terms of `vals` at receiver (`p`, shading normal `n` toward the viewer, geometric `n_g`)
/// whose near-field centre is `centre`, each VAL weighted by its near-field share.
pub fn terms_over<'a>(
    receiver: (Vec3, Vec3, Vec3),
    exponent: f32,
    eye: Vec3,
    centre: Vec3,
    vals: impl IntoIterator<Item = &'a Val>,
    glossy: bool,
    radius: f32,
) -> NearTerms {
    let weighted = vals.into_iter().map(|v| (v, near_field_weight(v.position.distance(centre), radius)));
    terms_weighted(receiver, exponent, eye, weighted, glossy)
}

/// The terms of each VAL of `vals` at the receiver times its weight.
pub fn terms_weighted<'a>(
    (p, n, n_g): (Vec3, Vec3, Vec3),
    exponent: f32,
    eye: Vec3,
    vals: impl IntoIterator<Item = (&'a Val, f32)>,
    glossy: bool,
) -> NearTerms {
    let w_o = view_direction(p, n, eye);
    let mut terms = NearTerms::default();
    for (val, weight) in vals {
        if weight <= 0.0 {
            continue;
        }
        let geo = val_geometry_sided(p, n, n_g, val.position, val.normal, val.area);
        let e = val.flux * (geo.weight * geo.cos_receiver * weight);
        terms.irradiance += e;
        if glossy {
            terms.lobe += phong_lobe(mirror(geo.direction, n).dot(w_o), exponent) * e;
        }
    }
    terms
}

/// A covered pixel's interleaved near field: its two parts ([`near_field_terms`]) and its
/// surface point.
#[derive(Clone, Copy, Debug)]
pub struct NearPixel {
    pub parts: NearParts,
    pub position: Vec3,
    /// The geometric normal, toward the viewer: which neighbours lie on the pixel's surface is
    /// a question of the facets' planes. (Shading normals bend across flat walls in meshes such
    /// as Sponza's, which sent a tenth to two fifths of its pixels to the redo.)
    pub normal: Vec3,
}

/// Neighbours whose normals differ by more than this cosine's angle (about 26 degrees) are on
/// another surface for the filter.
pub const FILTER_NORMAL_COS: f32 = 0.9;
/// Neighbours farther from the pixel's tangent plane than this fraction of their distance
/// (about 6 degrees) are on another surface for the filter.
pub const FILTER_PLANE: f32 = 0.1;
/// Neighbours farther than this fraction of the near-field radius from the pixel are not
/// averaged (the floor on both sides of a pillar).
pub const FILTER_DISTANCE: f32 = 0.25;

/// How much neighbour `q` counts in pixel `p`'s filter: 0 on another surface
/// ([`FILTER_NORMAL_COS`], [`FILTER_PLANE`], [`FILTER_DISTANCE`]), else 1.
pub fn filter_weight(p: &NearPixel, q: &NearPixel, radius: f32) -> f32 {
    let d = q.position - p.position;
    let same = p.normal.dot(q.normal) >= FILTER_NORMAL_COS
        && p.normal.dot(d).abs() <= FILTER_PLANE * d.length()
        && d.length_squared() <= (FILTER_DISTANCE * radius).powi(2);
    if same { 1.0 } else { 0.0 }
}

/// The weight of offset `o` of a window of half-width `half` on one axis: the window is
/// `2 half + 1` pixels wide, its two end pixels weigh a half each (they hold the same subset),
/// so each subset weighs 1 in all; `half` 0 is the pixel alone.
pub fn window_weight(o: i32, half: i32) -> f32 {
    if half > 0 && o.abs() == half { 0.5 } else { 1.0 }
}

/// A pixel whose window holds less than this fraction of the block's subsets on its own
/// surface (by [`window_weight`] and [`filter_weight`]) takes every near VAL itself instead of
/// the filter's average: at corners and image edges the filter would otherwise keep the
/// pixel's own subset times `side²`, a noisy estimate that dominated the interleaved error.
pub const FILTER_REDO_BELOW: f32 = 0.5;

/// The filter over blocks `side` wide of an image `width` pixels wide (row-major, `None` where
/// not covered): each covered pixel's close share plus its rest averaged over its window's
/// pixels on the same surface ([`filter_weight`]), weighted by [`window_weight`]; a pixel whose
/// window's weight falls under [`FILTER_REDO_BELOW`] of `side²` takes `whole(i)`, its every near
/// VAL, instead. `side` 1 returns the terms.
pub fn filter(
    pixels: &[Option<NearPixel>],
    width: u32,
    side: u32,
    radius: f32,
    whole: impl Fn(usize) -> NearTerms,
) -> Vec<Option<NearTerms>> {
    let (w, h) = (width as i32, (pixels.len() as u32 / width.max(1)) as i32);
    let half = (side / 2) as i32;
    (0..pixels.len())
        .map(|i| {
            let p = pixels[i]?;
            let (x, y) = (i as i32 % w, i as i32 / w);
            let (mut sum, mut total) = (NearTerms::default(), 0.0);
            for dy in -half..=half {
                for dx in -half..=half {
                    let (qx, qy) = (x + dx, y + dy);
                    if qx < 0 || qy < 0 || qx >= w || qy >= h {
                        continue;
                    }
                    let Some(q) = pixels[(qy * w + qx) as usize] else { continue };
                    let weight = window_weight(dx, half) * window_weight(dy, half) * filter_weight(&p, &q, radius);
                    if weight > 0.0 {
                        sum.irradiance += weight * q.parts.rest.irradiance;
                        sum.lobe += weight * q.parts.rest.lobe;
                        total += weight;
                    }
                }
            }
            if side > 1 && total < FILTER_REDO_BELOW * (side * side) as f32 {
                return Some(whole(i));
            }
            let close = p.parts.close;
            Some(NearTerms {
                irradiance: close.irradiance + sum.irradiance / total,
                lobe: close.lobe + sum.lobe / total,
            })
        })
        .collect()
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

/// The VALs sorted into hashed buckets, each bucket split into the subsets' slots and each of
/// those into [`COLUMNS`] columns: slot `(bucket * subsets + subset) * COLUMNS + column`.
pub struct ValGrid {
    pub radius: f32,
    /// VAL subsets (1 without interleaving).
    pub subsets: u32,
    /// Per slot: its VALs' count and first index in `vals`.
    pub counts: Vec<u32>,
    pub starts: Vec<u32>,
    /// The VALs in slot order (in input order within a slot).
    pub vals: Vec<Val>,
}

impl ValGrid {
    /// Sort `vals` for near-field radius `radius` (m, > 0) into `slots` slots (a power of two, a
    /// multiple of `subsets` x [`COLUMNS`]), `subsets` x [`COLUMNS`] of them per cell bucket.
    pub fn build(vals: &[Val], radius: f32, slots: u32, subsets: u32) -> Self {
        let cell = cell_size(radius);
        let buckets = slots / (subsets * COLUMNS);
        let slot = |i: usize, v: &Val| {
            let c = cell_of(v.position, cell);
            let column = column_of(v.position.x, c.x, cell);
            ((bucket_of(c, buckets) * subsets + val_subset(i as u32, subsets)) * COLUMNS + column) as usize
        };
        let mut counts = vec![0u32; slots as usize];
        for (i, v) in vals.iter().enumerate() {
            counts[slot(i, v)] += 1;
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
        for (i, v) in vals.iter().enumerate() {
            let b = slot(i, v);
            sorted[next[b] as usize] = *v;
            next[b] += 1;
        }
        Self { radius, subsets, counts, starts, vals: sorted }
    }

    /// The buckets a receiver at `p` reads and the columns `[first, end)` of each, in the
    /// shader's order: the cells from the one holding `p - radius` on every axis, x fastest, the
    /// columns that the sphere's x extent reaches ([`column_runs`]), less those an earlier cell
    /// in the same bucket read (`near_field_shade.wgsl`'s `unread_columns`: two cells of one x
    /// offset read the same columns; of the two offsets the first's run ends its cell and the
    /// second's starts it, so what is left is one run).
    pub fn runs_around(&self, p: Vec3) -> Vec<(u32, (u32, u32))> {
        let cell = cell_size(self.radius);
        let corner = cell_of(p - Vec3::splat(self.radius), cell);
        let runs = column_runs(p.x - self.radius, p.x + self.radius, corner.x, cell);
        let buckets = self.counts.len() as u32 / (self.subsets * COLUMNS);
        let mut read: Vec<(u32, usize)> = Vec::with_capacity(8);
        let mut out = Vec::with_capacity(8);
        for c in 0..8 {
            let offset = IVec3::new(c & 1, (c >> 1) & 1, c >> 2);
            let x = offset.x as usize;
            let b = bucket_of(corner + offset, buckets);
            let seen = |o: usize| read.contains(&(b, o));
            let (mut first, mut end) = runs[x];
            if first >= end || seen(x) {
                continue;
            }
            if x == 1 && seen(0) {
                end = end.min(runs[0].0);
            }
            if x == 0 && seen(1) {
                first = first.max(runs[1].1);
            }
            read.push((b, x));
            if first < end {
                out.push((b, (first, end)));
            }
        }
        out
    }

    /// The VALs of `subset` in the columns around `p` that [`ValGrid::runs_around`] reads (a
    /// superset of those of the subset within the radius).
    pub fn near_vals(&self, p: Vec3, subset: u32) -> impl Iterator<Item = &Val> {
        self.runs_around(p).into_iter().flat_map(move |(b, (first, end))| {
            let slots = ((b * self.subsets + subset) * COLUMNS) as usize;
            let start = self.starts[slots + first as usize] as usize;
            let last = slots + end as usize - 1;
            &self.vals[start..(self.starts[last] + self.counts[last]) as usize]
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

    /// Every VAL within the radius of a receiver is in the columns it reads, and none twice,
    /// so the grid's sum is the sum over every VAL. Few buckets (8 for a scene 7 cells wide)
    /// make cells share buckets, also cells of both x offsets, whose columns the visit must not
    /// read twice; the tolerance is float order (relative 1e-4). Interleaved, a subset's slots
    /// hold exactly that subset's VALs, and the subsets' sums add up to the whole. The columns
    /// must save reads: under 3/4 of the VALs of the buckets' slots are read (about 1/2 +
    /// 1/COLUMNS where cells do not share buckets).
    #[test]
    fn grid_sum_equals_the_sum_over_every_val() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let vals = random_vals(&mut rng, 3000, 4.0);
        let surface =
            Material { diffuse: Vec3::splat(0.7), specular: Vec3::splat(0.2), exponent: 30.0, diffuse_texture: None };
        let close = |a: Vec3, b: Vec3, scale: f32| (a - b).abs().max_element() <= 1e-4 * scale + 1e-12;
        for (slots, subsets) in [
            (8 * COLUMNS, 1),
            (BUCKET_RANGE.0, 1),
            (bucket_count(3000) * COLUMNS, 1),
            (64 * COLUMNS, 16),
            (slot_count(3000, 4), 4),
        ] {
            let grid = ValGrid::build(&vals, 0.3, slots, subsets);
            let (mut lit, mut read, mut in_buckets) = (0, 0, 0);
            for _ in 0..300 {
                let p = Vec3::new(rng.random(), rng.random(), rng.random()) * 4.0 - 2.0;
                let n = Vec3::new(rng.random::<f32>() - 0.5, -1.0, rng.random::<f32>() - 0.5).normalize();
                let eye = Vec3::new(0.0, -3.0, 0.0);
                // The centre up to a third of the radius away from the pixel, as at a corner.
                let centre = p + (Vec3::new(rng.random(), rng.random(), rng.random()) - 0.5) * 0.2;
                let all = shade_near_field(p, n, n, &surface, eye, centre, &vals, true, grid.radius);
                let mut parts = Vec3::ZERO;
                for subset in 0..subsets {
                    read += grid.near_vals(centre, subset).count();
                    for (b, _) in grid.runs_around(centre) {
                        let slots = ((b * subsets + subset) * COLUMNS) as usize;
                        in_buckets += grid.counts[slots..slots + COLUMNS as usize].iter().sum::<u32>() as usize;
                    }
                    let mine = terms_over((p, n, n), 30.0, eye, centre, grid.near_vals(centre, subset), true, 0.3);
                    let of_subset = vals.iter().enumerate().filter(|(i, _)| val_subset(*i as u32, subsets) == subset);
                    let expected = terms_over((p, n, n), 30.0, eye, centre, of_subset.map(|(_, v)| v), true, 0.3);
                    let (a, b) = (mine.radiance(&surface, true), expected.radiance(&surface, true));
                    assert!(close(a, b, b.max_element()), "subset {subset} of {subsets}: {a} vs {b}");
                    parts += mine.radiance(&surface, true);
                }
                assert!(close(all, parts, all.max_element()), "{all} vs {parts}");
                lit += usize::from(all.max_element() > 0.0);
            }
            assert!(lit > 200, "only {lit} of 300 receivers had a VAL within the radius");
            assert!(4 * read < 3 * in_buckets, "{slots} slots: {read} VALs read of {in_buckets} in the buckets read");
        }
    }

    #[test]
    fn subsets_are_even_and_every_window_holds_each_once() {
        for side in INTERLEAVE_SIDES {
            let subsets = side * side;
            let mut counts = vec![0u32; subsets as usize];
            for i in 0..64_000 {
                counts[val_subset(i, subsets) as usize] += 1;
            }
            let expected = 64_000 / subsets;
            assert!(counts.iter().all(|&c| c.abs_diff(expected) < expected / 10 + 10), "{side}: {counts:?}");
            // The window of half-width side / 2 around any pixel, its ends at half weight.
            let half = (side / 2) as i32;
            for (x, y) in [(0, 0), (5, 9), (17, 3)] {
                let mut weights = vec![0.0f32; subsets as usize];
                for dy in -half..=half {
                    for dx in -half..=half {
                        let s = pixel_subset((x + 8 + dx) as u32, (y + 8 + dy) as u32, side);
                        weights[s as usize] += window_weight(dx, half) * window_weight(dy, half);
                    }
                }
                assert!(weights.iter().all(|&w| w == 1.0), "side {side} at ({x}, {y}): {weights:?}");
            }
            let slots = slot_count(1000, subsets);
            assert!(slots.is_power_of_two() && slots >= 256 * subsets * COLUMNS && slots <= BUCKET_RANGE.1);
        }
    }

    /// Each of the filter's three tests alone keeps a neighbour out: its normal, its height
    /// over the pixel's tangent plane, its distance.
    #[test]
    fn filter_weight_rejects_each_other_surface() {
        let radius = 1.0;
        let pixel = |position: Vec3, normal: Vec3| NearPixel { parts: NearParts::default(), position, normal };
        let p = pixel(Vec3::ZERO, Vec3::Z);
        let tilted = |degrees: f32| Vec3::new(degrees.to_radians().sin(), 0.0, degrees.to_radians().cos());
        assert_eq!(filter_weight(&p, &p, radius), 1.0);
        assert_eq!(filter_weight(&p, &pixel(Vec3::new(0.1, 0.05, 0.0), Vec3::Z), radius), 1.0);
        assert_eq!(filter_weight(&p, &pixel(Vec3::new(0.1, 0.0, 0.0), tilted(20.0)), radius), 1.0);
        assert_eq!(filter_weight(&p, &pixel(Vec3::new(0.1, 0.0, 0.0), tilted(30.0)), radius), 0.0);
        assert_eq!(filter_weight(&p, &pixel(Vec3::new(0.1, 0.0, 0.005), Vec3::Z), radius), 1.0);
        assert_eq!(filter_weight(&p, &pixel(Vec3::new(0.1, 0.0, 0.02), Vec3::Z), radius), 0.0);
        assert_eq!(filter_weight(&p, &pixel(Vec3::new(0.2, 0.0, 0.0), Vec3::Z), radius), 1.0);
        assert_eq!(filter_weight(&p, &pixel(Vec3::new(0.3, 0.0, 0.0), Vec3::Z), radius), 0.0);
    }

    /// Where every pixel of a block sees the same surface point, the interleaved pixels' filter
    /// is the whole near field (each subset once); at the image's corner, whose window holds a
    /// quarter of the subsets, the pixel's own whole near field. A second surface at right
    /// angles is kept out of the filter.
    #[test]
    fn the_filter_recombines_the_subsets_on_one_surface_only() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let vals = random_vals(&mut rng, 4000, 2.0);
        let (eye, radius) = (Vec3::new(0.0, -3.0, 0.0), 0.8);
        let (floor, wall) = ((Vec3::new(0.1, -0.2, 0.0), -Vec3::Y), (Vec3::new(0.3, 0.0, 0.1), Vec3::X));
        let terms = |(p, n): (Vec3, Vec3), subset, subsets| {
            near_field_terms((p, n, n), 20.0, eye, p, &vals, (subset, subsets), true, radius)
        };
        for side in INTERLEAVE_SIDES {
            let (width, height) = (24u32, 12u32);
            // The left half sees the floor, the right half the wall (not on the floor's plane).
            let surface_of = |x: u32| if x < width / 2 { floor } else { wall };
            let pixels: Vec<Option<NearPixel>> = (0..width * height)
                .map(|i| {
                    let (x, y) = (i % width, i / width);
                    let (position, normal) = surface_of(x);
                    let parts = terms((position, normal), pixel_subset(x, y, side), side * side);
                    Some(NearPixel { parts, position, normal })
                })
                .collect();
            // The wall's terms a thousand times brighter: a floor pixel by the seam that took
            // any wall pixel in would be far brighter than every floor pixel.
            let marked: Vec<Option<NearPixel>> = pixels
                .iter()
                .map(|p| {
                    p.map(|mut p| {
                        if p.normal == wall.1 {
                            p.parts.rest.irradiance *= 1000.0;
                        }
                        p
                    })
                })
                .collect();
            let whole = [floor, wall].map(|s| terms(s, 0, 1).sum());
            let whole_of = |i: usize| whole[usize::from(i as u32 % width >= width / 2)];
            let filtered = filter(&pixels, width, side, radius, whole_of);
            let brightest_floor = pixels.iter().flatten().filter(|p| p.normal == floor.1);
            let brightest_floor = brightest_floor.map(|p| p.parts.sum().irradiance.max_element()).fold(0.0, f32::max);
            let by_seam = filter(&marked, width, side, radius, whole_of);
            for (i, f) in by_seam.iter().enumerate() {
                if i as u32 % width < width / 2 {
                    assert!(f.unwrap().irradiance.max_element() <= brightest_floor * 1.0001, "side {side}, pixel {i}");
                }
            }
            let half = side / 2;
            for (i, f) in filtered.iter().enumerate() {
                let (x, y) = (i as u32 % width, i as u32 / width);
                let inside = y >= half
                    && y + half < height
                    && (x >= half && x + half < width / 2 || x >= width / 2 + half && x + half < width);
                let w = whole[usize::from(x >= width / 2)];
                let f = f.unwrap();
                let close = (f.irradiance - w.irradiance).abs().max_element() <= 1e-4 * w.irradiance.max_element()
                    && (f.lobe - w.lobe).abs().max_element() <= 1e-4 * w.lobe.max_element() + 1e-9;
                // The image's corner: about a quarter of the window (from 4 on, under half the
                // block's subsets), so the pixel takes every near VAL itself.
                if inside || side == 1 || (x, y) == (0, 0) && side >= 4 {
                    assert!(close, "side {side}, pixel ({x}, {y}): {f:?} vs {w:?}");
                }
            }
            assert!(whole[0].irradiance.max_element() > 0.0 && whole[1].irradiance.max_element() > 0.0);
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
