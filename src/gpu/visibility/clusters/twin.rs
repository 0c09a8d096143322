//! CPU twins of `clusters.wgsl` (same names, same argument order): k-means clustering of the
//! frame's VALs (paper 000 §5.1), the paraboloid projection of a cluster's shadow map around
//! its normal and its inverse (§4.2), and the percentage-closer soft shadow of one receiver
//! (paper 001: blocker search, penumbra from the cluster's radius and the mean blocker
//! distance, PCF).

use crate::scene::SoftShadows as Soft;
use crate::twin::{Val, luminance};
use glam::{IVec2, Vec2, Vec3};

/// WGSL `Cluster`: one cluster of VALs, the centre of its shadow map.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cluster {
    /// Mean position of its lit VALs (m).
    pub position: Vec3,
    /// Lit VALs assigned to it (0: empty, reseeded before the next assignment).
    pub count: f32,
    /// Unit mean normal of its VALs.
    pub normal: Vec3,
    /// Radius of the disc light standing for it, `sqrt(2 E|x - c|^2)` (m): a uniform disc of
    /// radius `a` has `E|x - c|^2 = a^2 / 2`.
    pub radius: f32,
}

/// What k-means needs besides the VALs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KmeansParams {
    /// 1 / the length that counts as one unit of distance (1/m): the scene's bounding
    /// diagonal, so the criterion does not depend on the scene's scale.
    pub position_scale: f32,
    /// Weight of the normal angle (per radian) against the scaled position distance.
    pub normal_weight: f32,
}

/// The paper's clustering distance (000 §5.1, `d = w_x dx + w_a da`): scaled Euclidean
/// distance plus `normal_weight` times the angle between the normals (radians).
pub fn cluster_distance(position: Vec3, normal: Vec3, cluster: &Cluster, params: &KmeansParams) -> f32 {
    let angle = normal.dot(cluster.normal).clamp(-1.0, 1.0).acos();
    (position - cluster.position).length() * params.position_scale + params.normal_weight * angle
}

/// Whether a VAL emits anything: only lit VALs move the centres.
pub fn val_is_lit(val: &Val) -> bool {
    luminance(val.flux) > 0.0
}

/// Give every empty cluster (count 0: the first frame, or a cluster that lost its VALs) the
/// position and normal of VAL `k n / m`, so that no cluster stays lost (000 §5.2).
pub fn kmeans_seed(clusters: &mut [Cluster], vals: &[Val]) {
    let (m, n) = (clusters.len(), vals.len());
    if n == 0 {
        return;
    }
    for (k, c) in clusters.iter_mut().enumerate() {
        if c.count == 0.0 {
            let v = &vals[k * n / m];
            *c = Cluster { position: v.position, count: 0.0, normal: v.normal, radius: 0.0 };
        }
    }
}

/// The index of the nearest cluster (the first one on ties).
pub fn kmeans_assign(position: Vec3, normal: Vec3, clusters: &[Cluster], params: &KmeansParams) -> u32 {
    let mut best = (f32::INFINITY, 0u32);
    for (k, c) in clusters.iter().enumerate() {
        let d = cluster_distance(position, normal, c, params);
        if d < best.0 {
            best = (d, k as u32);
        }
    }
    best.1
}

/// WGSL `ClusterSums`: one cluster's sums over some lit VALs, offsets from its old centre.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClusterSums {
    pub offset: Vec3,
    pub count: f32,
    pub normal: Vec3,
    pub offset_sq: f32,
}

impl ClusterSums {
    pub fn add(&mut self, val: &Val, centre: Vec3) {
        let d = val.position - centre;
        self.offset += d;
        self.count += 1.0;
        self.normal += val.normal;
        self.offset_sq += d.length_squared();
    }

    pub fn merge(&mut self, other: &ClusterSums) {
        self.offset += other.offset;
        self.count += other.count;
        self.normal += other.normal;
        self.offset_sq += other.offset_sq;
    }
}

/// The new centre from the sums of its VALs: mean position and normal, disc radius from the
/// spread. A cluster without VALs keeps its place with count 0.
pub fn kmeans_centre(old: &Cluster, sums: &ClusterSums) -> Cluster {
    if sums.count == 0.0 {
        return Cluster { count: 0.0, radius: 0.0, ..*old };
    }
    let mean = sums.offset / sums.count;
    let variance = (sums.offset_sq / sums.count - mean.length_squared()).max(0.0);
    let normal = if sums.normal.length_squared() > 1e-12 { sums.normal.normalize() } else { old.normal };
    Cluster { position: old.position + mean, count: sums.count, normal, radius: (2.0 * variance).sqrt() }
}

/// `iterations` rounds of seed, assign, update from `clusters` (last frame's centres, or all
/// empty); returns each VAL's cluster (the last assignment, of which the centres are the means).
pub fn kmeans(clusters: &mut [Cluster], vals: &[Val], params: &KmeansParams, iterations: u32) -> Vec<u32> {
    let mut groups = vec![0; vals.len()];
    for _ in 0..iterations {
        kmeans_seed(clusters, vals);
        groups = kmeans_step(clusters, vals, params);
    }
    groups
}

/// One assignment and update from `clusters` as they are (no seeding); returns each VAL's
/// cluster.
pub fn kmeans_step(clusters: &mut [Cluster], vals: &[Val], params: &KmeansParams) -> Vec<u32> {
    let groups: Vec<u32> = vals.iter().map(|v| kmeans_assign(v.position, v.normal, clusters, params)).collect();
    let mut sums = vec![ClusterSums::default(); clusters.len()];
    for (g, v) in groups.iter().zip(vals) {
        if val_is_lit(v) {
            sums[*g as usize].add(v, clusters[*g as usize].position);
        }
    }
    for (c, s) in clusters.iter_mut().zip(&sums) {
        *c = kmeans_centre(c, s);
    }
    groups
}

/// An orthonormal frame `(tangent, bitangent, normal)` around `n` (the shadow map's axes).
pub fn cluster_frame(n: Vec3) -> (Vec3, Vec3) {
    let t = crate::twin::any_perpendicular(n);
    (t, n.cross(t))
}

/// Paraboloid projection around the cluster normal: the direction `v` (unit, world) to its
/// point in the unit disc, `(v_t, v_b) / (1 + v_n)`; the front hemisphere fills the disc.
pub fn paraboloid_project(v: Vec3, normal: Vec3) -> Vec2 {
    let (t, b) = cluster_frame(normal);
    Vec2::new(v.dot(t), v.dot(b)) / (1.0 + v.dot(normal)).max(1e-6)
}

/// Inverse of [`paraboloid_project`]: the unit direction of disc point `q` (`|q| <= 1`).
pub fn paraboloid_direction(q: Vec2, normal: Vec3) -> Vec3 {
    let (t, b) = cluster_frame(normal);
    let r2 = q.length_squared();
    let vn = (1.0 - r2) / (1.0 + r2);
    let s = 1.0 + vn;
    (t * q.x * s + b * q.y * s + normal * vn).normalize()
}

/// A map's frame: its axis, and the disc's scale, `tan` of half the widest angle from the axis
/// it holds (1: the hemisphere, paper 000's paraboloid map).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapFrame {
    pub axis: Vec3,
    pub scale: f32,
    /// Distance (m) before which the map holds nothing: 0 for the hemisphere, the distance to the
    /// meshes' bounding sphere for a map focused on it. The shadow test's relative bias is taken
    /// of the depth beyond it ([`SHADOW_RELATIVE_BIAS`]).
    pub near: f32,
}

impl MapFrame {
    /// The hemisphere around `normal`.
    pub fn hemisphere(normal: Vec3) -> Self {
        Self { axis: normal, scale: 1.0, near: 0.0 }
    }
}

/// The meshes' bounding radius is widened by this factor before a map is focused on it
/// (rounding: every point of the meshes must land inside the disc).
pub const FOCUS_MARGIN: f32 = 1.01;

/// WGSL `cluster_map_frame`: the frame of `cluster`'s map. The hemisphere around its normal, or
/// with `bounds` (the meshes' bounding sphere: centre, radius), when the centre lies outside it,
/// the narrowest cone around the direction to the sphere that holds it: all the map's texels go
/// to the meshes, however far the cluster is (a real room's VALs metres from a small virtual
/// object, which a hemisphere map of 64² would hold in a couple of texels).
pub fn map_frame(cluster: &Cluster, bounds: Option<(Vec3, f32)>) -> MapFrame {
    let Some((centre, radius)) = bounds else {
        return MapFrame::hemisphere(cluster.normal);
    };
    let d = centre - cluster.position;
    let distance = d.length();
    let r = radius * FOCUS_MARGIN;
    // Also the hemisphere for a NaN distance, as in WGSL.
    if distance.partial_cmp(&r) != Some(std::cmp::Ordering::Greater) {
        return MapFrame::hemisphere(cluster.normal);
    }
    let s = r / distance;
    MapFrame { axis: d / distance, scale: s / (1.0 + (1.0 - s * s).max(0.0).sqrt()), near: distance - r }
}

/// [`paraboloid_project`] around the frame's axis, scaled to its disc (WGSL `map_project`).
pub fn map_project(v: Vec3, frame: &MapFrame) -> Vec2 {
    paraboloid_project(v, frame.axis) / frame.scale
}

/// Inverse of [`map_project`] (WGSL `map_direction`).
pub fn map_direction(q: Vec2, frame: &MapFrame) -> Vec3 {
    paraboloid_direction(q * frame.scale, frame.axis)
}

/// Disc point of texel `texel` of a `resolution`² map: texel centres, `y` down.
pub fn texel_disc(texel: IVec2, resolution: u32) -> Vec2 {
    let r = resolution as f32;
    Vec2::new((texel.x as f32 + 0.5) / r * 2.0 - 1.0, 1.0 - (texel.y as f32 + 0.5) / r * 2.0)
}

/// Continuous texel coordinates of disc point `q` (inverse of [`texel_disc`] at centres).
pub fn disc_texel(q: Vec2, resolution: u32) -> Vec2 {
    let r = resolution as f32;
    Vec2::new((q.x + 1.0) * 0.5 * r, (1.0 - q.y) * 0.5 * r)
}

/// Taps per axis of the blocker search and the PCF grid.
pub const SHADOW_TAPS: u32 = 5;
/// PCF radius of `soft: "pcf"` (texels).
pub const PCF_RADIUS_TEXELS: f32 = 1.5;
/// Widest blocker search and PCF radius (radians, seen from the cluster centre).
pub const MAX_SHADOW_FILTER_ANGLE: f32 = 0.35;
/// Geometry closer to the cluster centre than this fraction of its radius is ignored (000 §5.1:
/// the centre may lie inside curved geometry).
pub const CLUSTER_NEAR_FRACTION: f32 = 0.5;
/// The shadow-map raster keeps a fragment whose ray hits its triangle's plane up to this far
/// outside the triangle (barycentrics): the raster's straight edges and the projection's
/// curved ones differ, and neighbours must still cover every texel between them.
pub const SHADOW_RASTER_SLACK: f32 = 0.1;
/// Relative depth bias of the shadow test (receiver-plane depths are exact for planes; this
/// covers curved receivers and rounding), of the depth beyond the map's near distance
/// ([`MapFrame::near`]).
pub const SHADOW_RELATIVE_BIAS: f32 = 0.02;

/// WGSL `encode_map_depth` (`shadow_maps.wgsl`): what the rasterised atlas stores for a distance
/// `t` (m), `t / (t + scale)` with `scale` the meshes' diagonal. It keeps the order of distances,
/// maps all of them, however far, below 1 (the cleared atlas: nothing drawn), and loses little
/// precision: a float's relative step near 1 is 6e-8, so a distance 100 diagonals away keeps
/// about 6e-6 relative, far under the lookup's bias ([`SHADOW_RELATIVE_BIAS`]).
pub fn encode_map_depth(t: f32, scale: f32) -> f32 {
    t / (t + scale)
}

/// WGSL `decode_map_depth` (`raster_depth.wgsl`): the distance (m) of a stored depth,
/// `f32::INFINITY` for 1 (nothing drawn).
pub fn decode_map_depth(d: f32, scale: f32) -> f32 {
    if d >= 1.0 { f32::INFINITY } else { scale * d / (1.0 - d) }
}

/// One cluster's shadow map: distances (m) from the centre along each texel's direction,
/// `f32::INFINITY` where nothing was drawn.
pub struct DepthTile<'a> {
    pub resolution: u32,
    pub depths: &'a [f32],
    /// Texels of slope-scaled bias ([`slope_bias`]): 0 for exact depths per texel.
    pub slope_bias_texels: f32,
}

impl DepthTile<'_> {
    /// Distance at `texel`; outside the map, nothing.
    pub fn depth(&self, texel: IVec2) -> f32 {
        let r = self.resolution as i32;
        if texel.x < 0 || texel.y < 0 || texel.x >= r || texel.y >= r {
            return f32::INFINITY;
        }
        self.depths[(texel.y * r + texel.x) as usize]
    }
}

/// The receiver seen from one cluster.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowReceiver {
    /// Receiver minus cluster centre (m).
    pub offset: Vec3,
    pub normal: Vec3,
}

/// Distance from the centre along `v` to the receiver's tangent plane (receiver-plane depth:
/// the receiver's own surface is never its blocker); infinite where `v` misses the plane.
pub fn receiver_plane_depth(r: &ShadowReceiver, v: Vec3) -> f32 {
    let den = v.dot(r.normal);
    let num = r.offset.dot(r.normal);
    if den < -1e-4 && num < 0.0 { num / den } else { f32::INFINITY }
}

/// Whether the map's texel `texel` holds a blocker of `r`, and its distance.
fn blocker_at(tile: &DepthTile<'_>, frame: &MapFrame, r: &ShadowReceiver, texel: IVec2) -> Option<f32> {
    let z = tile.depth(texel);
    if !z.is_finite() {
        return None;
    }
    let v = map_direction(texel_disc(texel, tile.resolution), frame);
    let zr = receiver_plane_depth(r, v).min(r.offset.length() * 4.0);
    // The relative bias is of the depth beyond the frame's near distance (a cluster a kilometre
    // away sees a small object within centimetres of depth, which 2 % of the whole distance
    // would miss), the slope bias of the whole distance, as its texel angles are: `zr - (zr -
    // near) bias - zr slope`, which adds exactly 0 for a hemisphere map.
    let kept = 1.0 - SHADOW_RELATIVE_BIAS - slope_bias(tile, v, frame, r.normal) * depth_spread(z);
    (z < zr * kept + frame.near * SHADOW_RELATIVE_BIAS).then_some(z)
}

/// WGSL `depth_spread`: texels a stored depth stands for, `2^level` from its lowest 3 bits (an
/// imperfect map's pull-push level; it only scales the slope bias, 0 for rasterised maps).
pub fn depth_spread(z: f32) -> f32 {
    (1u32 << (z.to_bits() & 7)) as f32
}

/// Most tangent of the incidence angle the slope-scaled bias uses (about 84°).
pub const MAX_SLOPE: f32 = 10.0;

/// WGSL `slope_bias`: `slope_bias_texels` texel angles times the tangent of the ray's incidence
/// on the receiver's plane (relative depth); 0 for maps with exact per-texel depths.
pub fn slope_bias(tile: &DepthTile<'_>, v: Vec3, frame: &MapFrame, receiver_normal: Vec3) -> f32 {
    if tile.slope_bias_texels == 0.0 {
        return 0.0;
    }
    let cos_i = (-v.dot(receiver_normal)).clamp(1e-3, 1.0);
    let tan_i = ((1.0 - cos_i * cos_i).sqrt() / cos_i).min(MAX_SLOPE);
    tile.slope_bias_texels * tan_i / map_texels_per_radian(v, frame, tile.resolution)
}

/// The `SHADOW_TAPS`² grid of texels over `[-radius, radius]²` around `centre` (texel coords).
fn taps(centre: Vec2, radius: f32) -> impl Iterator<Item = IVec2> {
    let n = SHADOW_TAPS;
    (0..n * n).map(move |i| {
        let s = Vec2::new((i % n) as f32, (i / n) as f32) / (n - 1) as f32 * 2.0 - 1.0;
        (centre + s * radius).floor().as_ivec2()
    })
}

/// PCSS step 1: mean distance of the blockers among the taps within `radius` texels, if any.
pub fn blocker_search(
    tile: &DepthTile<'_>,
    frame: &MapFrame,
    r: &ShadowReceiver,
    centre: Vec2,
    radius: f32,
) -> Option<f32> {
    let (mut sum, mut n) = (0.0, 0u32);
    for t in taps(centre, radius) {
        if let Some(z) = blocker_at(tile, frame, r, t) {
            sum += z;
            n += 1;
        }
    }
    (n > 0).then_some(sum / n as f32)
}

/// PCF: fraction of the taps within `radius` texels that no blocker hides.
pub fn pcf(tile: &DepthTile<'_>, frame: &MapFrame, r: &ShadowReceiver, centre: Vec2, radius: f32) -> f32 {
    let blocked = taps(centre, radius).filter(|t| blocker_at(tile, frame, r, *t).is_some()).count();
    1.0 - blocked as f32 / (SHADOW_TAPS * SHADOW_TAPS) as f32
}

/// Angular half-width of the penumbra seen from the centre: a disc light of radius `a`,
/// blockers at distance `z_b`, receiver at `z_r` (paper 000 Fig. 3, `p = a (d - z_avg) / z_avg`
/// on the receiver, divided by `d`).
pub fn penumbra_angle(radius: f32, z_blocker: f32, z_receiver: f32) -> f32 {
    radius * (z_receiver - z_blocker).max(0.0) / (z_blocker * z_receiver)
}

/// Texels per radian at the direction whose cosine to the normal is `cos_theta` (the
/// paraboloid disc radius is `tan(theta / 2)`, the disc spans `resolution / 2` texels per unit).
pub fn texels_per_radian(cos_theta: f32, resolution: u32) -> f32 {
    resolution as f32 * 0.5 / (1.0 + cos_theta)
}

/// Texels per radian of a map of `frame` in direction `v` (WGSL `map_texels_per_radian`).
pub fn map_texels_per_radian(v: Vec3, frame: &MapFrame, resolution: u32) -> f32 {
    texels_per_radian(v.dot(frame.axis), resolution) / frame.scale
}

/// Fraction of `cluster`'s light reaching receiver `r` (`offset` from its centre): 1 for an
/// empty cluster, a receiver behind its plane or facing away from it (no shadow information
/// there: 000 §5.1 assumes full visibility).
pub fn cluster_visibility(tile: &DepthTile<'_>, cluster: &Cluster, r: &ShadowReceiver, soft: Soft) -> f32 {
    cluster_visibility_in(tile, cluster, &MapFrame::hemisphere(cluster.normal), r, soft)
}

/// [`cluster_visibility`] through a map of `frame` ([`map_frame`]).
pub fn cluster_visibility_in(
    tile: &DepthTile<'_>,
    cluster: &Cluster,
    frame: &MapFrame,
    r: &ShadowReceiver,
    soft: Soft,
) -> f32 {
    let zr = r.offset.length();
    if cluster.count == 0.0 || zr <= 0.0 {
        return 1.0;
    }
    let v = r.offset / zr;
    let cos_theta = v.dot(cluster.normal);
    if cos_theta <= 0.0 || r.normal.dot(v) >= 0.0 {
        return 1.0;
    }
    let res = tile.resolution;
    let centre = disc_texel(map_project(v, frame), res);
    let per_radian = map_texels_per_radian(v, frame, res);
    let max_texels = MAX_SHADOW_FILTER_ANGLE * per_radian;
    match soft {
        Soft::Hard => pcf(tile, frame, r, centre, 0.0),
        Soft::Pcf => pcf(tile, frame, r, centre, PCF_RADIUS_TEXELS),
        Soft::Pcss => {
            let near = (cluster.radius * CLUSTER_NEAR_FRACTION).max(1e-4 * zr);
            let search = (penumbra_angle(cluster.radius, near, zr) * per_radian).min(max_texels);
            match blocker_search(tile, frame, r, centre, search) {
                None => 1.0,
                Some(zb) => {
                    let w = (penumbra_angle(cluster.radius, zb, zr) * per_radian).min(max_texels);
                    pcf(tile, frame, r, centre, w)
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn val(position: Vec3, normal: Vec3) -> Val {
        Val { position, normal, area: 1e-3, flux: Vec3::ONE }
    }

    const PARAMS: KmeansParams = KmeansParams { position_scale: 1.0, normal_weight: 0.5 };

    /// Two blobs of VALs on two perpendicular walls: two clusters find them, each centre the
    /// blob's mean, from any seeding, and the normal term splits VALs that are close but face
    /// different ways.
    #[test]
    fn kmeans_finds_two_walls() {
        let mut vals = Vec::new();
        for i in 0..50 {
            let s = i as f32 * 0.01;
            vals.push(val(Vec3::new(s, 0.0, 0.0), Vec3::Y));
            vals.push(val(Vec3::new(0.0, 0.01 + s, 0.0), Vec3::X));
        }
        let mut clusters = vec![Cluster::default(); 2];
        let groups = kmeans(&mut clusters, &vals, &PARAMS, 8);
        for (g, v) in groups.iter().zip(&vals) {
            let c = &clusters[*g as usize];
            assert!(c.normal.dot(v.normal) > 0.999, "VAL {v:?} in cluster {c:?}");
        }
        let floor = clusters.iter().find(|c| c.normal.y > 0.9).expect("a floor cluster");
        assert!((floor.position - Vec3::new(0.245, 0.0, 0.0)).length() < 1e-5, "{floor:?}");
        assert_eq!(floor.count, 50.0);
        // 50 points evenly over 0.49 m: E|x - c|^2 = 0.49^2 (n^2 - 1) / (12 (n - 1)^2).
        let var = 0.49f32.powi(2) * (2500.0 - 1.0) / (12.0 * 49.0 * 49.0);
        assert!((floor.radius - (2.0 * var).sqrt()).abs() < 1e-4, "{floor:?}");
    }

    /// Unlit VALs are assigned but move no centre; an empty cluster is reseeded from VAL k n/m.
    #[test]
    fn kmeans_update_ignores_unlit_vals_and_reseeds_empty_clusters() {
        let mut vals = vec![val(Vec3::ZERO, Vec3::Y), val(Vec3::X, Vec3::Y)];
        vals[1].flux = Vec3::ZERO;
        let mut clusters =
            vec![Cluster { position: Vec3::new(5.0, 0.0, 0.0), normal: Vec3::Y, count: 0.0, radius: 0.0 }];
        let groups = kmeans(&mut clusters, &vals, &PARAMS, 1);
        assert_eq!(groups, vec![0, 0]);
        assert_eq!(clusters[0].position, Vec3::ZERO, "seeded at VAL 0, moved only by the lit VAL");
        assert_eq!(clusters[0].count, 1.0);
    }

    /// The previous frame's centres are kept when the VALs do not move.
    #[test]
    fn kmeans_from_last_centres_is_a_fixed_point() {
        let vals: Vec<Val> = (0..40).map(|i| val(Vec3::new((i % 10) as f32, 0.0, (i / 10) as f32), Vec3::Y)).collect();
        let mut clusters = vec![Cluster::default(); 4];
        let groups = kmeans(&mut clusters, &vals, &PARAMS, 10);
        let before = clusters.clone();
        let again = kmeans(&mut clusters, &vals, &PARAMS, 1);
        assert_eq!(groups, again);
        assert_eq!(before, clusters);
    }

    #[test]
    fn paraboloid_projection_inverts() {
        for normal in [Vec3::Z, Vec3::new(0.3, -0.8, 0.2).normalize(), Vec3::NEG_Y] {
            for i in 0..200 {
                let a = i as f32 * 0.37;
                let q = Vec2::new(a.cos(), a.sin()) * ((i % 17) as f32 / 17.0);
                let v = paraboloid_direction(q, normal);
                assert!(v.dot(normal) >= -1e-6);
                assert!((paraboloid_project(v, normal) - q).length() < 1e-5, "{q} {normal}");
            }
        }
        assert!((paraboloid_direction(Vec2::ZERO, Vec3::Z) - Vec3::Z).length() < 1e-6);
        // The rim is the horizon.
        assert!(paraboloid_direction(Vec2::X, Vec3::Z).z.abs() < 1e-6);
        let q = Vec2::new(0.25, -0.5);
        assert!((texel_disc(disc_texel(q, 64).floor().as_ivec2(), 64) - q).length() < 2.0 / 64.0);
        assert_eq!(disc_texel(texel_disc(IVec2::new(3, 7), 64), 64), Vec2::new(3.5, 7.5));
    }

    /// Cluster at the origin facing +z, receivers on the plane z = 2 facing -z, a map of
    /// resolution 64 with depth 1 m on the left half (x < 0 in the disc) and nothing elsewhere.
    fn half_map() -> (Vec<f32>, Cluster) {
        let res = 64;
        let depths = (0..res * res).map(|i| if i % res < res / 2 { 1.0 } else { f32::INFINITY }).collect();
        (depths, Cluster { position: Vec3::ZERO, count: 10.0, normal: Vec3::Z, radius: 0.2 })
    }

    fn receiver(x: f32) -> ShadowReceiver {
        ShadowReceiver { offset: Vec3::new(x, 0.0, 2.0), normal: Vec3::NEG_Z }
    }

    #[test]
    fn blocker_search_and_pcf_on_a_hand_made_map() {
        let (depths, cluster) = half_map();
        let tile = DepthTile { resolution: 64, depths: &depths, slope_bias_texels: 0.0 };
        let r = receiver(0.0);
        let frame = MapFrame::hemisphere(cluster.normal);
        let t = tile_of(&cluster, &r, 64);
        // Receiver straight ahead: texel coordinate 32.0, the edge; taps at 32 + {-4,-2,0,2,4}.
        assert_eq!(t, Vec2::new(32.0, 32.0));
        assert_eq!(blocker_search(&tile, &frame, &r, t, 4.0), Some(1.0));
        assert_eq!(blocker_search(&tile, &frame, &r, t + Vec2::new(10.0, 0.0), 4.0), None);
        // Two of five columns fall left of the edge.
        assert!((pcf(&tile, &frame, &r, t, 4.0) - 3.0 / 5.0).abs() < 1e-6);
        assert_eq!(pcf(&tile, &frame, &r, t - Vec2::new(10.0, 0.0), 4.0), 0.0);
        assert_eq!(pcf(&tile, &frame, &r, t + Vec2::new(10.0, 0.0), 4.0), 1.0);
        // A receiver nearer than the blockers is lit.
        let near = ShadowReceiver { offset: Vec3::new(-0.1, 0.0, 0.5), normal: Vec3::NEG_Z };
        assert_eq!(cluster_visibility(&tile, &cluster, &near, Soft::Pcss), 1.0);
    }

    fn tile_of(cluster: &Cluster, r: &ShadowReceiver, res: u32) -> Vec2 {
        disc_texel(paraboloid_project(r.offset.normalize(), cluster.normal), res)
    }

    /// A receiver behind the cluster's plane or facing away from it is unaffected, whatever
    /// the map holds.
    #[test]
    fn receivers_facing_away_are_unaffected() {
        let depths = vec![0.5; 64 * 64];
        let tile = DepthTile { resolution: 64, depths: &depths, slope_bias_texels: 0.0 };
        let cluster = Cluster { position: Vec3::ZERO, count: 10.0, normal: Vec3::Z, radius: 0.2 };
        for soft in [Soft::Pcss, Soft::Pcf, Soft::Hard] {
            let away = ShadowReceiver { offset: Vec3::new(0.0, 0.0, 2.0), normal: Vec3::Z };
            assert_eq!(cluster_visibility(&tile, &cluster, &away, soft), 1.0);
            let behind = ShadowReceiver { offset: Vec3::new(0.0, 0.0, -2.0), normal: Vec3::Z };
            assert_eq!(cluster_visibility(&tile, &cluster, &behind, soft), 1.0);
            let facing = ShadowReceiver { offset: Vec3::new(0.0, 0.0, 2.0), normal: Vec3::NEG_Z };
            assert_eq!(cluster_visibility(&tile, &cluster, &facing, soft), 0.0);
        }
    }

    /// The shadow map of a square plate (side `2 h`, at distance `zb` on the axis) as the
    /// raster draws it: the exact distance along each texel centre's direction.
    fn plate_map(res: u32, h: f32, zb: f32) -> Vec<f32> {
        (0..res * res)
            .map(|i| {
                let v = paraboloid_direction(texel_disc(IVec2::new((i % res) as i32, (i / res) as i32), res), Vec3::Z);
                let t = zb / v.z.max(1e-6);
                let p = v * t;
                if v.z > 0.0 && p.x.abs() <= h && p.y.abs() <= h { t } else { f32::INFINITY }
            })
            .collect()
    }

    /// A cluster a kilometre away (an environment's VALs) with its map focused on a small
    /// object's bounding sphere: a 10 cm plate 10 cm in front of a receiver shadows it, a
    /// receiver beside the plate and the plate's own surface stay lit. With the bias taken of
    /// the whole distance (2 % of 1 km) the plate shadowed nothing.
    #[test]
    fn a_far_cluster_sees_a_small_blocker_through_its_focused_map() {
        let (res, far, plate_z, h) = (64, 1000.0, 0.05, 0.05);
        let cluster = Cluster { position: Vec3::new(0.0, 0.0, far), count: 10.0, normal: Vec3::NEG_Z, radius: 1.0 };
        let frame = map_frame(&cluster, Some((Vec3::ZERO, 0.2)));
        assert!(frame.near > far - 0.21 && frame.near < far - 0.2, "{frame:?}");
        let depths: Vec<f32> = (0..res * res)
            .map(|i| {
                let v = map_direction(texel_disc(IVec2::new((i % res) as i32, (i / res) as i32), res), &frame);
                let t = (plate_z - far) / v.z.min(-1e-9);
                let p = cluster.position + v * t;
                if p.x.abs() <= h && p.y.abs() <= h { t } else { f32::INFINITY }
            })
            .collect();
        let tile = DepthTile { resolution: res, depths: &depths, slope_bias_texels: 0.0 };
        let at = |x: f32, z: f32| ShadowReceiver { offset: Vec3::new(x, 0.0, z) - cluster.position, normal: Vec3::Z };
        for soft in [Soft::Hard, Soft::Pcss] {
            assert_eq!(cluster_visibility_in(&tile, &cluster, &frame, &at(0.0, -0.05), soft), 0.0, "{soft:?}");
            assert_eq!(cluster_visibility_in(&tile, &cluster, &frame, &at(0.15, -0.05), soft), 1.0, "{soft:?}");
            assert_eq!(cluster_visibility_in(&tile, &cluster, &frame, &at(0.0, plate_z), soft), 1.0, "{soft:?}");
        }
    }

    /// A plate between a cluster and receivers on a parallel plane: visibility 0 in the
    /// umbra, 1 outside, monotone in between, and the penumbra as wide as PCSS's own
    /// estimate says (to a filter tap).
    #[test]
    fn plate_casts_umbra_penumbra_and_light() {
        let (res, h, zb, zr) = (256, 0.5, 1.0, 2.0);
        let depths = plate_map(res, h, zb);
        let tile = DepthTile { resolution: res, depths: &depths, slope_bias_texels: 0.0 };
        let cluster = Cluster { position: Vec3::ZERO, count: 10.0, normal: Vec3::Z, radius: 0.1 };
        let vis = |x: f32| {
            let r = ShadowReceiver { offset: Vec3::new(x, 0.0, zr), normal: Vec3::NEG_Z };
            cluster_visibility(&tile, &cluster, &r, Soft::Pcss)
        };
        // The plate's shadow edge seen from the centre is at x = h zr / zb = 1 m.
        let edge = h * zr / zb;
        assert_eq!(vis(0.0), 0.0, "umbra");
        assert_eq!(vis(0.5), 0.0, "umbra");
        assert_eq!(vis(1.6), 1.0, "lit");
        let xs: Vec<f32> = (0..=100).map(|i| 0.6 + i as f32 * 0.008).collect();
        let vs: Vec<f32> = xs.iter().map(|&x| vis(x)).collect();
        for w in vs.windows(2) {
            assert!(w[1] >= w[0] - 1e-6, "monotone: {vs:?}");
        }
        // Penumbra: the angular half-width from the distances along the edge's direction
        // (theta from the axis), times dx/dtheta = zr / cos^2(theta) on the receiver plane.
        let cos = zr / (edge * edge + zr * zr).sqrt();
        let half = penumbra_angle(cluster.radius, zb / cos, zr / cos) * zr / (cos * cos);
        let first_lit = xs.iter().zip(&vs).find(|(_, v)| **v > 0.0).map(|(x, _)| *x).unwrap();
        let last_dark = xs.iter().zip(&vs).rev().find(|(_, v)| **v < 1.0).map(|(x, _)| *x).unwrap();
        let width = last_dark - first_lit;
        assert!((width - 2.0 * half).abs() < 0.25 * 2.0 * half + 0.02, "penumbra {width} m, formula {} m", 2.0 * half);
        assert!(((first_lit + last_dark) / 2.0 - edge).abs() < 0.03, "centred on the edge");
    }
}

/// `ray_members.wgsl`'s lists: cluster `k`'s VALs (indices into the frame's VALs) are
/// `members[starts[k]..starts[k + 1]]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MemberLists {
    /// Clusters + 1 entries.
    pub starts: Vec<u32>,
    pub members: Vec<u32>,
}

impl MemberLists {
    /// Cluster `k`'s members.
    pub fn of(&self, k: usize) -> &[u32] {
        &self.members[self.starts[k] as usize..self.starts[k + 1] as usize]
    }
}

/// Twin of `ray_members.wgsl`: the VALs of each of `clusters` clusters, by `group_of_val` (an
/// index past the last cluster counts as the last, as the WGSL clamps it), each list in VAL
/// order (the GPU's order within a list is its atomics').
pub fn member_lists(group_of_val: &[u32], clusters: u32) -> MemberLists {
    let m = clusters as usize;
    let mut lists = vec![Vec::new(); m];
    for (v, &g) in group_of_val.iter().enumerate() {
        lists[(g as usize).min(m - 1)].push(v as u32);
    }
    let mut starts = vec![0];
    for l in &lists {
        starts.push(starts.last().copied().unwrap_or(0) + l.len() as u32);
    }
    MemberLists { starts, members: lists.concat() }
}

/// Twin of `ray_visibility.wgsl`'s `ray_visibility` for sparse point `i` (at `position` with
/// `normal`, its rays leaving along the face normal `geometric`) and cluster `k` of `clusters`: `rays` of the cluster's members drawn
/// systematically from its list, offset by a hash of the entry, each ray's outcome weighted by
/// the VAL's unoccluded irradiance luminance at the point; 1 where none of them lights it.
/// Traced through `occluders` without the shader's loop budget.
#[allow(clippy::too_many_arguments)]
pub fn ray_visibility(
    i: u32,
    k: u32,
    position: Vec3,
    normal: Vec3,
    geometric: Vec3,
    lists: &MemberLists,
    vals: &[Val],
    occluders: &crate::twin::bvh::Occluders,
    rays: u32,
    clusters: u32,
) -> f32 {
    let members = lists.of(k as usize);
    let count = members.len() as u32;
    if count == 0 {
        return 1.0;
    }
    let origin = position + geometric * crate::twin::exact_cpu::RAY_OFFSET;
    let xi = crate::twin::unit_float(crate::twin::pcg_hash(i.wrapping_mul(clusters).wrapping_add(k)));
    let (mut seen, mut lit) = (0.0f32, 0.0f32);
    for s in 0..rays {
        let m = (((s as f32 + xi) * count as f32 / rays as f32) as u32).min(count - 1);
        let val = &vals[members[m as usize] as usize];
        let geo = crate::twin::val_geometry(position, normal, val.position, val.normal, val.area);
        let light = luminance(val.flux) * geo.weight * geo.cos_receiver;
        if light > 0.0 {
            let target = val.position + val.normal * crate::twin::exact_cpu::RAY_OFFSET;
            seen += light;
            if !occluders.bvh.occluded(&occluders.positions, &occluders.triangles, origin, target) {
                lit += light;
            }
        }
    }
    if seen > 0.0 { lit / seen } else { 1.0 }
}
