//! CPU twins of the imperfect shadow maps' shaders (same names, same order of operations):
//! the flux draw of the groups (`sampling.wgsl`), the points and their splat (`splat.wgsl`),
//! pull-push (`pull_push.wgsl`). A map here is its distances (m) row by row, `f32::INFINITY`
//! where it is empty; the lookup is the clusters' [`cluster_visibility`](super::super::clusters::twin::cluster_visibility).

use super::super::clusters::twin::{
    CLUSTER_NEAR_FRACTION, Cluster, KmeansParams, MapFrame, disc_texel, kmeans_step, map_project, val_is_lit,
};
use crate::twin::{Val, luminance, pcg_hash, unit_float};
use glam::Vec3;

/// VALs per block of the flux sums (one invocation sums a block, one scans the blocks).
pub const SAMPLE_BLOCK: u32 = 256;
/// Mixed into every point's hash: the points are the same in every frame and run.
pub const POINT_SEED: u32 = 0x9e37_79b9;

/// The lengths of the mode in metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IsmParams {
    pub resolution: u32,
    pub points: u32,
    pub levels: u32,
    /// Pull and push thresholds at the finest level (m).
    pub pull_threshold: f32,
    pub push_threshold: f32,
    /// Slope-scaled bias of the lookup (texels; `clusters::twin::slope_bias`): a splatted
    /// point lies anywhere in its texel, not on the texel's centre ray.
    pub slope_bias_texels: f32,
}

/// `distance` with its lowest 3 bits set to `level` (WGSL `encode_depth_at`, decoded).
pub fn at_level(distance: f32, level: u32) -> f32 {
    f32::from_bits((distance.to_bits() & !7) | level)
}

/// WGSL `encode_depth`: a splatted distance (level 0).
pub fn encode_depth(distance: f32) -> u32 {
    u32::MAX - at_level(distance, 0).to_bits()
}

/// WGSL `decode_depth`, empty as `f32::INFINITY`.
pub fn decode_depth(e: u32) -> f32 {
    if e == 0 { f32::INFINITY } else { f32::from_bits(u32::MAX - e) }
}

/// What the flux draw weighs an item by: its flux luminance, at least 0 (WGSL `val_weight`).
pub fn val_weight(v: &Val) -> f32 {
    luminance(v.flux).max(0.0)
}

/// The stratified draw by flux (WGSL `flux_blocks`, `flux_scan`, `flux_pick`, same order of
/// sums): for each k of `count` the item holding `(k + 0.5) / count` of the running sum of flux
/// luminance (`None` without lit items), and that sum's total.
pub fn flux_picks(vals: &[Val], count: u32) -> (Vec<Option<usize>>, f32) {
    let block = SAMPLE_BLOCK as usize;
    let blocks = vals.len().div_ceil(block);
    let mut prefix = vec![0.0f32; blocks + 1];
    for b in 0..blocks {
        prefix[b + 1] = vals[b * block..((b + 1) * block).min(vals.len())].iter().fold(0.0, |s, v| s + val_weight(v));
    }
    let mut sum = 0.0f32;
    for p in prefix.iter_mut().skip(1) {
        sum += *p;
        *p = sum;
    }
    let total = prefix[blocks];
    let picks = (0..count)
        .map(|k| {
            if blocks == 0 || total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return None;
            }
            let goal = (k as f32 + 0.5) / count as f32 * total;
            let (mut lo, mut hi) = (0, blocks - 1);
            while lo < hi {
                let mid = (lo + hi).div_ceil(2);
                if prefix[mid] <= goal { lo = mid } else { hi = mid - 1 }
            }
            let (mut sum, mut pick, mut last_lit) = (prefix[lo], None, None);
            for (i, v) in vals.iter().enumerate().take(((lo + 1) * block).min(vals.len())).skip(lo * block) {
                let w = val_weight(v);
                if w > 0.0 {
                    last_lit = Some(i);
                    sum += w;
                    if sum > goal {
                        pick = Some(i);
                        break;
                    }
                }
            }
            pick.or(last_lit)
        })
        .collect();
    (picks, total)
}

/// `count` groups seeded by flux (WGSL `flux_sample`): the VAL [`flux_picks`] draws for each,
/// as an empty cluster at its position and normal; all empty (count 0) without lit VALs.
pub fn flux_seeds(vals: &[Val], count: u32) -> Vec<Cluster> {
    let empty = Cluster { position: Vec3::ZERO, count: 0.0, normal: Vec3::Z, radius: 0.0 };
    flux_picks(vals, count)
        .0
        .into_iter()
        .map(|pick| match pick {
            Some(i) => Cluster { position: vals[i].position, count: 0.0, normal: vals[i].normal, radius: 0.0 },
            None => empty,
        })
        .collect()
}

/// The mode's groups: the flux seeds, then one assignment and update; each VAL's group.
pub fn groups(vals: &[Val], count: u32, params: &KmeansParams) -> (Vec<Cluster>, Vec<u32>) {
    let mut clusters = flux_seeds(vals, count);
    let groups = kmeans_step(&mut clusters, vals, params);
    debug_assert!(groups.iter().zip(vals).all(|(g, v)| !val_is_lit(v) || clusters[*g as usize].count > 0.0));
    (clusters, groups)
}

/// Running sums of each triangle's area times `density[triangle]` (its mesh's sparse points per
/// m²: the points are spread over the meshes as the scene's sparse points are, so a small
/// object the scene details gets its share), in f32 as uploaded. Without densities (or all
/// zero) plain areas.
pub fn triangle_cdf(positions: &[Vec3], indices: &[u32], density: &[f32]) -> Vec<f32> {
    let weighted = density.iter().any(|&d| d > 0.0);
    let mut sum = 0.0f64;
    indices
        .chunks_exact(3)
        .enumerate()
        .map(|(i, t)| {
            let [a, b, c] = [0, 1, 2].map(|k| positions[t[k] as usize]);
            let weight = if weighted { f64::from(density.get(i).copied().unwrap_or(0.0)) } else { 1.0 };
            sum += 0.5 * f64::from((b - a).cross(c - a).length()) * weight;
            sum as f32
        })
        .collect()
}

/// Point `j` of map `k` (WGSL `ism_point`).
pub fn ism_point(k: u32, j: u32, points: u32, cdf: &[f32], positions: &[Vec3], indices: &[u32]) -> Vec3 {
    let h0 = pcg_hash(k.wrapping_mul(points).wrapping_add(j) ^ POINT_SEED);
    let h1 = pcg_hash(h0);
    let h2 = pcg_hash(h1);
    let goal = unit_float(h0) * cdf[cdf.len() - 1];
    let t = cdf.partition_point(|&c| c <= goal).min(cdf.len() - 1);
    let (mut u, mut v) = (unit_float(h1), unit_float(h2));
    if u + v > 1.0 {
        (u, v) = (1.0 - u, 1.0 - v);
    }
    let [p0, p1, p2] = [0, 1, 2].map(|i| positions[indices[3 * t + i] as usize]);
    p0 + (p1 - p0) * u + (p2 - p0) * v
}

/// Map `k` of group `cluster` before pull-push (WGSL `splat`) in `frame`: each of its points in
/// the front hemisphere of the frame's axis lands in one texel, the nearest kept (the ISM's maps
/// take `MapFrame::hemisphere(cluster.normal)`, the clusters' a frame of
/// [`map_frame`](super::super::clusters::twin::map_frame)).
pub fn splat_in(
    cluster: &Cluster,
    frame: &MapFrame,
    k: u32,
    params: &IsmParams,
    cdf: &[f32],
    positions: &[Vec3],
    indices: &[u32],
) -> Vec<f32> {
    let n = params.resolution;
    let mut map = vec![f32::INFINITY; (n * n) as usize];
    if cluster.count == 0.0 {
        return map;
    }
    for j in 0..params.points {
        let d = ism_point(k, j, params.points, cdf, positions, indices) - cluster.position;
        let distance = d.length();
        // NaN distances are skipped too, as in WGSL.
        if distance.partial_cmp(&(cluster.radius * CLUSTER_NEAR_FRACTION)) != Some(std::cmp::Ordering::Greater)
            || !distance.is_finite()
        {
            continue;
        }
        let v = d / distance;
        if v.dot(frame.axis) <= 0.0 {
            continue;
        }
        let t = disc_texel(map_project(v, frame), n).floor();
        if t.x < 0.0 || t.y < 0.0 || t.x >= n as f32 || t.y >= n as f32 {
            continue;
        }
        let texel = &mut map[(t.y as u32 * n + t.x as u32) as usize];
        *texel = texel.min(at_level(distance, 0));
    }
    map
}

/// Level `level + 1` of a map from level `level` (side `fine_side`): WGSL `pull`, with
/// `threshold` the finest level's (m).
pub fn pull(fine: &[f32], fine_side: u32, level: u32, threshold: f32) -> Vec<f32> {
    let c = fine_side / 2;
    let scaled = threshold * (1u32 << level) as f32;
    (0..c * c)
        .map(|i| {
            let (x, y) = (i % c, i / c);
            let z: [f32; 4] =
                std::array::from_fn(|q| fine[((2 * y + q as u32 / 2) * fine_side + 2 * x + q as u32 % 2) as usize]);
            let nearest = z.iter().copied().fold(f32::INFINITY, f32::min);
            if !nearest.is_finite() {
                return f32::INFINITY;
            }
            let limit = nearest + scaled;
            let (mut sum, mut n) = (0.0f32, 0.0f32);
            for &d in &z {
                if d <= limit {
                    sum += d;
                    n += 1.0;
                }
            }
            at_level(sum / n, level + 1)
        })
        .collect()
}

/// Level `level` of a map (side `fine_side`) from level `level + 1`, in place: WGSL `push`.
pub fn push(fine: &mut [f32], fine_side: u32, coarse: &[f32], level: u32, threshold: f32) {
    let c = fine_side / 2;
    let scaled = threshold * (1u32 << level) as f32;
    for i in 0..fine_side * fine_side {
        let (x, y) = (i % fine_side, i / fine_side);
        let zc = coarse[((y / 2) * c + x / 2) as usize];
        if !zc.is_finite() {
            continue;
        }
        let zf = &mut fine[i as usize];
        if !zf.is_finite() || (*zf - zc).abs() > scaled {
            *zf = zc;
        }
    }
}

/// Pull `levels` levels, then push back down: the map as the lookup reads it.
pub fn pull_push(map: &mut [f32], side: u32, params: &IsmParams) {
    let mut pyramid = vec![map.to_vec()];
    for l in 0..params.levels {
        let next = pull(&pyramid[l as usize], side >> l, l, params.pull_threshold);
        pyramid.push(next);
    }
    for l in (0..params.levels as usize).rev() {
        let (finer, coarser) = pyramid.split_at_mut(l + 1);
        push(&mut finer[l], side >> l, &coarser[0], l as u32, params.push_threshold);
    }
    map.copy_from_slice(&pyramid[0]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::visibility::clusters::twin::{DepthTile, ShadowReceiver, cluster_visibility};
    use crate::scene::SoftShadows;

    const INF: f32 = f32::INFINITY;

    fn params(resolution: u32, points: u32, levels: u32) -> IsmParams {
        IsmParams {
            resolution,
            points,
            levels,
            pull_threshold: 0.05,
            push_threshold: 0.05,
            slope_bias_texels: crate::scene::IsmSettings::default().slope_bias,
        }
    }

    #[test]
    fn depth_encoding_orders_like_distance_and_zero_is_empty() {
        assert_eq!(decode_depth(0), INF);
        let ds = [1e-6f32, 0.5, 1.0, 1.000_001, 3.0, 1e6];
        for w in ds.windows(2) {
            assert!(encode_depth(w[0]) > encode_depth(w[1]), "nearer must encode larger: {w:?}");
        }
        for d in ds {
            assert_eq!(decode_depth(encode_depth(d)), at_level(d, 0));
            assert!((at_level(d, 0) - d).abs() <= 8.0 * f32::EPSILON * d, "3 ulps at most");
        }
        assert_eq!(at_level(1.0, 3).to_bits() & 7, 3);
    }

    /// Hand-made 4x4 map: a hole inside a flat surface at 1 m is filled with 1 m, an outlier at
    /// 5 m (a background point seen through the surface) is replaced, a real step of 0.02 m
    /// (under the threshold) is kept, and a fully empty quadrant stays empty after one level
    /// only where no coarser level holds anything.
    #[test]
    fn pull_push_fills_holes_and_replaces_outliers() {
        #[rustfmt::skip]
        let mut map = vec![
            1.0, INF, 1.02, 1.0,
            1.0, 1.0, 1.0,  5.0,
            INF, INF, 2.0,  2.0,
            INF, INF, 2.0,  2.0,
        ];
        let p = params(4, 0, 1);
        let coarse = pull(&map, 4, 0, p.pull_threshold);
        // Top-left: 1,1,1 (the hole skipped); top-right: 1.02 and two 1.0 within 0.05 of 1.0,
        // 5.0 rejected; bottom-left: empty; bottom-right: 2.
        let close = |a: f32, b: f32| (a - b).abs() < 1e-6;
        assert!(close(coarse[0], 1.0) && coarse[0].to_bits() & 7 == 1, "made at level 1: {coarse:?}");
        assert!(close(coarse[1], (1.02 + 1.0 + 1.0) / 3.0), "{coarse:?}");
        assert_eq!(coarse[2], INF);
        assert!(close(coarse[3], 2.0));
        pull_push(&mut map, 4, &p);
        assert!(close(map[1], 1.0) && map[1].to_bits() & 7 == 1, "the hole takes its parent's depth");
        assert_eq!(map[2], 1.02, "a step under the threshold stays");
        assert!((map[7] - coarse[1]).abs() < 1e-6, "the outlier takes its parent's depth");
        assert_eq!(&map[8..10], &[INF, INF], "nothing to fill from at one level");
        // Two levels: the empty quadrant takes the mean of the whole map's near cluster.
        let mut two = vec![1.0, 1.0, INF, INF, 1.0, 1.0, INF, INF, INF, INF, INF, INF, INF, INF, INF, INF];
        pull_push(&mut two, 4, &params(4, 0, 2));
        assert!(two.iter().all(|&d| (d - 1.0).abs() < 1e-6), "{two:?}");
    }

    /// Pull keeps the near surface: a texel block half at 1 m, half at 3 m averages the 1 m
    /// ones, so holes behind an edge fill with the occluder, never with a mean of both.
    #[test]
    fn pull_rejects_far_children() {
        let fine = vec![1.0, 3.0, 3.0, 1.01];
        assert!((pull(&fine, 2, 0, 0.05)[0] - 1.005).abs() < 1e-6);
        // At level 1 the threshold doubles: 0.1 m.
        assert!((pull(&[1.0, 1.08, INF, INF], 2, 1, 0.05)[0] - 1.04).abs() < 1e-6);
    }

    #[test]
    fn flux_seeds_follow_the_flux() {
        let val = |x: f32, flux: f32| Val {
            position: Vec3::new(x, 0.0, 0.0),
            normal: Vec3::Z,
            area: 0.01,
            flux: Vec3::splat(flux),
        };
        // 300 VALs over two blocks: one carries three quarters of the flux, the unlit ones none.
        let mut vals: Vec<Val> = (0..300).map(|i| val(i as f32, if i % 2 == 0 { 1.0 } else { 0.0 })).collect();
        vals[270] = val(270.0, 450.0);
        let seeds = flux_seeds(&vals, 8);
        let at_270 = seeds.iter().filter(|c| c.position.x == 270.0).count();
        assert_eq!(at_270, 6, "three quarters of 8 seeds: {seeds:?}");
        assert!(seeds.iter().all(|c| (c.position.x as u32).is_multiple_of(2)), "no unlit VAL is drawn");
        let dark: Vec<Val> = vals.iter().map(|v| Val { flux: Vec3::ZERO, ..*v }).collect();
        assert!(flux_seeds(&dark, 4).iter().all(|c| c.count == 0.0));
        assert!(flux_seeds(&[], 4).iter().all(|c| c.count == 0.0));
    }

    #[test]
    fn points_are_on_the_triangles_by_area() {
        // Two triangles, the second three times the area of the first.
        let positions = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(13.0, 0.0, 0.0),
            Vec3::new(10.0, 1.0, 0.0),
        ];
        let indices = [0, 1, 2, 3, 4, 5];
        let cdf = triangle_cdf(&positions, &indices, &[]);
        assert_eq!(cdf, vec![0.5, 2.0]);
        assert_eq!(triangle_cdf(&positions, &indices, &[6.0, 1.0]), vec![3.0, 4.5], "weighted by density");
        let n = 4000;
        let on_second = (0..n).filter(|&j| ism_point(3, j, n, &cdf, &positions, &indices).x >= 10.0).count();
        assert!((on_second as f32 / n as f32 - 0.75).abs() < 0.03, "{on_second} of {n}");
        for j in 0..n {
            let p = ism_point(0, j, n, &cdf, &positions, &indices);
            assert!(p.z == 0.0 && p.y >= 0.0 && (p.x < 1.0 + 1e-6 && p.x + p.y <= 1.0 + 1e-5 || p.x >= 10.0), "{p}");
        }
        assert_ne!(ism_point(0, 0, n, &cdf, &positions, &indices), ism_point(1, 0, n, &cdf, &positions, &indices));
    }

    /// A floor seen at grazing angles from a light above it holds only the floor's own points:
    /// without the slope-scaled bias, a point splatted off its texel's centre ray lies nearer
    /// than the receiver's tangent plane along that ray and the floor shadows itself; one texel
    /// of bias covers that offset.
    #[test]
    fn slope_bias_stops_a_grazing_floor_shadowing_itself() {
        let positions = [
            Vec3::new(-8.0, -1.0, 0.2),
            Vec3::new(8.0, -1.0, 0.2),
            Vec3::new(8.0, -1.0, 12.0),
            Vec3::new(-8.0, -1.0, 12.0),
        ];
        let indices = [0, 1, 2, 0, 2, 3];
        let cdf = triangle_cdf(&positions, &indices, &[]);
        let light = Cluster { position: Vec3::ZERO, count: 1.0, normal: Vec3::Z, radius: 0.0 };
        let receivers: Vec<ShadowReceiver> = (0..64)
            .map(|i| {
                let (x, z) = ((i % 8) as f32 - 3.5, 1.0 + (i / 8) as f32 * 1.3);
                ShadowReceiver { offset: Vec3::new(x, -1.0, z), normal: Vec3::Y }
            })
            .collect();
        // Dense points and no pull-push: every texel holds the floor's own nearest point, so the
        // only mismatch is where in its texel that point lies (under one texel).
        let shadowed = |slope_bias_texels: f32| {
            let p = IsmParams { slope_bias_texels, ..params(64, 200_000, 0) };
            let map = splat_in(&light, &MapFrame::hemisphere(light.normal), 0, &p, &cdf, &positions, &indices);
            let tile = DepthTile { resolution: 64, depths: &map, slope_bias_texels };
            receivers.iter().filter(|r| cluster_visibility(&tile, &light, r, SoftShadows::Pcf) < 1.0).count()
        };
        let without = shadowed(0.0);
        assert!(without > 16, "without the bias the floor shadows itself: {without} of 64 receivers");
        let with = shadowed(1.0);
        assert_eq!(with, 0, "with one texel of bias no receiver is shadowed (without: {without})");
    }

    /// The analytic plate: a 1 m square plate 1 m in front of a light, a receiver plane 2 m
    /// away. Receivers whose ray to the light crosses the plate (|x|, |y| < 0.5 at the plate:
    /// < 1 m at the receiver) must be shadowed. With enough points the map occludes them all;
    /// with few points the map has holes and light leaks through; pull-push closes the leak.
    #[test]
    fn plate_occludes_through_the_map_and_pull_push_closes_the_leak() {
        let positions = [
            Vec3::new(-0.5, -0.5, 1.0),
            Vec3::new(0.5, -0.5, 1.0),
            Vec3::new(0.5, 0.5, 1.0),
            Vec3::new(-0.5, 0.5, 1.0),
        ];
        let indices = [0, 1, 2, 0, 2, 3];
        let cdf = triangle_cdf(&positions, &indices, &[]);
        let light = Cluster { position: Vec3::ZERO, count: 1.0, normal: Vec3::Z, radius: 0.0 };
        // Receivers on z = 2 inside the shadow's core (|x|, |y| <= 0.8 m, the plate's shadow
        // reaches 1 m), facing the light.
        let receivers: Vec<ShadowReceiver> = (0..17 * 17)
            .map(|i| {
                let (x, y) = ((i % 17) as f32 / 16.0 * 1.6 - 0.8, (i / 17) as f32 / 16.0 * 1.6 - 0.8);
                ShadowReceiver { offset: Vec3::new(x, y, 2.0), normal: -Vec3::Z }
            })
            .collect();
        let lit_fraction = |points: u32, levels: u32| {
            let p = params(64, points, levels);
            let mut map = splat_in(&light, &MapFrame::hemisphere(light.normal), 0, &p, &cdf, &positions, &indices);
            pull_push(&mut map, 64, &p);
            let tile = DepthTile { resolution: 64, depths: &map, slope_bias_texels: p.slope_bias_texels };
            receivers.iter().map(|r| cluster_visibility(&tile, &light, r, SoftShadows::Hard)).sum::<f32>()
                / receivers.len() as f32
        };
        // Dense: ~6 points per covered texel (the plate spans ~ (0.5 / 2 * 64)^2 x 4 texels).
        assert_eq!(lit_fraction(6000, 0), 0.0, "a dense map occludes every receiver behind the plate");
        let sparse_leak = lit_fraction(300, 0);
        assert!(sparse_leak > 0.2, "few points leave holes: {sparse_leak} of the receivers lit");
        let filled = lit_fraction(300, 2);
        assert!(filled < 0.02, "pull-push closes the leak: {filled} lit (without: {sparse_leak})");
        // And the plate never shadows what is beside it.
        let p = params(64, 300, 2);
        let mut map = splat_in(&light, &MapFrame::hemisphere(light.normal), 0, &p, &cdf, &positions, &indices);
        pull_push(&mut map, 64, &p);
        let tile = DepthTile { resolution: 64, depths: &map, slope_bias_texels: p.slope_bias_texels };
        let beside = ShadowReceiver { offset: Vec3::new(2.0, 0.3, 2.0), normal: -Vec3::Z };
        assert_eq!(cluster_visibility(&tile, &light, &beside, SoftShadows::Hard), 1.0);
    }
}
