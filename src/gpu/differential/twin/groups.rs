//! The VAL groups of the fast differential pass (`fast.wgsl`, twin
//! [`super::receiver_light_fast`]): the real VALs and the re-emitters, each split
//! separately into groups of nearby VALs, each group summed as one VAL where a receiver is far
//! enough from it.
//!
//! A group's aggregate stands for its members' sum `sum_i flux_i max(-n_i . w, 0) / (pi d² + a)`
//! seen from far: its position is the members' centroid weighted by their power, its normal the
//! direction of `N = sum_i p_i n_i` (`p_i` a member's power, the sum of its flux's channels) and
//! its flux `|N| / sum_i p_i` times the members' summed flux. While every member faces the
//! receiver the sum of the members' `cos` is `N . w`, so the aggregate's form factor differs from
//! the members' only by the spread of their distances and directions (of order `(r / d)²`, `r`
//! the group's radius) and by the colours of members that face differently.

use crate::twin::Val;
use glam::Vec3;

/// Real VALs per group at most (the median split stops at this size).
pub const GROUP_SIZE: usize = 16;

/// Re-emitters per group at most: smaller than the real VALs' groups, since a receiver at the
/// content's contact sees its nearest re-emitters at a few group radii.
pub const EMITTER_GROUP_SIZE: usize = 4;

/// A receiver sums a group as its aggregate only beyond `REACH` times the group's radius (a
/// group the content may block, beyond twice that: `twin::receiver_light_fast`). At 4 radii
/// the synthetic room's contact shadow came out 10.4 % too light; at 6, within 0.01 %, for a
/// fast pass 1.13x slower on the TUM replay (docs/measurements/differential.md).
pub const REACH: f32 = 6.0;

/// Groups whose members' normals agree less than this (`|N| / sum p_i`, 1 when all are alike)
/// are never summed as one: members facing away from a receiver would cancel others in `N`.
pub const MIN_COHERENCE: f32 = 0.9;

/// One group: its members are `vals[first .. first + count]` of its [`GroupedVals`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValGroup {
    /// The members summed as one VAL (module docs).
    pub aggregate: Val,
    /// Radius (m) of the sphere about `aggregate.position` that holds every member.
    pub radius: f32,
    /// Receivers farther than this from `aggregate.position` (m) may sum the aggregate:
    /// [`REACH`] times `radius`; `f32::MAX` (never) for a group of one member or of members
    /// whose normals disagree ([`MIN_COHERENCE`]).
    pub reach: f32,
    /// Receivers farther than this may sum the aggregate of a group the content may block, with
    /// one shadow ray for the whole group: twice `reach`, so that a group whose visibility is
    /// decided at once subtends at most half the angle (a bright patch, such as a spot light's,
    /// would otherwise be shadowed all or nothing).
    pub shadow_reach: f32,
    pub first: u32,
    pub count: u32,
    /// The member nearest the centroid: the target of the group's one shadow ray (the centroid
    /// of a curved patch lies inside the surface).
    pub representative: u32,
}

/// VALs in group order: `vals[.. real_count]` the real VALs, the rest the re-emitters;
/// `groups[.. real_groups]` hold the real ones.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GroupedVals {
    pub vals: Vec<Val>,
    pub groups: Vec<ValGroup>,
    pub real_count: usize,
    pub real_groups: usize,
}

/// Group `vals` (`vals[.. real_count]` real, the rest re-emitters) into groups of at most
/// `sizes.0` real VALs or `sizes.1` re-emitters by recursive median splits along the longest
/// axis of their positions' box, each summed as one beyond `reach` times its radius
/// ([`REACH`], [`GROUP_SIZE`] and [`EMITTER_GROUP_SIZE`] are the fast pass's).
pub fn group_vals(vals: &[Val], real_count: usize, sizes: (usize, usize), reach: f32) -> GroupedVals {
    let real_count = real_count.min(vals.len());
    let mut out = GroupedVals { real_count, ..Default::default() };
    for (range, real) in [(0..real_count, true), (real_count..vals.len(), false)] {
        let size = if real { sizes.0 } else { sizes.1 }.max(1);
        let mut members: Vec<Val> = vals[range].to_vec();
        let mut ranges = Vec::new();
        split(&mut members, 0, size, &mut ranges);
        let offset = out.vals.len() as u32;
        for (first, count) in ranges {
            let group = aggregate(&members[first..first + count], offset + first as u32, reach);
            out.groups.push(group);
        }
        out.vals.extend(members);
        if real {
            out.real_groups = out.groups.len();
        }
    }
    out
}

/// Split `members` (at `start` of the whole) in place until each part holds at most `size`,
/// appending each part's (start, count).
fn split(members: &mut [Val], start: usize, size: usize, out: &mut Vec<(usize, usize)>) {
    if members.len() <= size {
        if !members.is_empty() {
            out.push((start, members.len()));
        }
        return;
    }
    let (lo, hi) = members
        .iter()
        .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), v| (lo.min(v.position), hi.max(v.position)));
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = members.len() / 2;
    members.select_nth_unstable_by(mid, |a, b| a.position[axis].total_cmp(&b.position[axis]));
    let (left, right) = members.split_at_mut(mid);
    split(left, start, size, out);
    split(right, start + mid, size, out);
}

/// The group of `members`, the first at `first` in the grouped VALs (module docs).
fn aggregate(members: &[Val], first: u32, reach: f32) -> ValGroup {
    let power = |v: &Val| v.flux.max(Vec3::ZERO).element_sum();
    let total: f32 = members.iter().map(power).sum();
    let area: f32 = members.iter().map(|v| v.area).sum();
    // Centroid weighted by power, or by area (then by count) where the group emits nothing.
    let weight = |v: &Val| {
        if total > 0.0 {
            power(v)
        } else if area > 0.0 {
            v.area
        } else {
            1.0
        }
    };
    let weights: f32 = members.iter().map(weight).sum();
    let centre = members.iter().map(|v| v.position * weight(v)).sum::<Vec3>() / weights;
    let n = members.iter().map(|v| v.normal * weight(v)).sum::<Vec3>();
    let coherence = (n.length() / weights).min(1.0);
    let normal = n.try_normalize().unwrap_or(Vec3::Z);
    let flux = members.iter().map(|v| v.flux).sum::<Vec3>() * coherence;
    let radius = members.iter().map(|v| v.position.distance(centre)).fold(0.0, f32::max);
    let representative = members
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.position.distance_squared(centre).total_cmp(&b.1.position.distance_squared(centre)))
        .map_or(0, |(i, _)| i as u32);
    let reach = if members.len() > 1 && coherence >= MIN_COHERENCE { reach * radius } else { f32::MAX };
    ValGroup {
        aggregate: Val { position: centre, normal, area, flux },
        radius,
        reach,
        shadow_reach: if reach == f32::MAX { f32::MAX } else { 2.0 * reach },
        first,
        count: members.len() as u32,
        representative: first + representative,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn val(x: f32, y: f32, normal: Vec3, flux: f32) -> Val {
        Val { position: Vec3::new(x, y, 0.0), normal, area: 0.01, flux: Vec3::splat(flux) }
    }

    /// Every VAL lands in exactly one group, real ones before re-emitters; each group's sphere
    /// holds its members; the aggregate keeps the power of members facing one way.
    #[test]
    fn groups_cover_every_val_once() {
        let vals: Vec<Val> = (0..100).map(|i| val((i % 10) as f32, (i / 10) as f32, Vec3::Z, 1.0 + i as f32)).collect();
        let g = group_vals(&vals, 70, (8, 8), REACH);
        assert_eq!(g.vals.len(), 100);
        assert_eq!(g.real_count, 70);
        let mut seen = vec![0; 100];
        for (k, group) in g.groups.iter().enumerate() {
            assert!(group.count as usize <= 8 && group.count > 0);
            let members = &g.vals[group.first as usize..(group.first + group.count) as usize];
            assert_eq!(k < g.real_groups, (group.first as usize) < 70, "group {k}");
            for m in members {
                let i = (m.flux.x - 1.0) as usize;
                seen[i] += 1;
                assert_eq!(i < 70, k < g.real_groups, "VAL {i} in group {k}");
                assert!(m.position.distance(group.aggregate.position) <= group.radius + 1e-5);
            }
            let flux: Vec3 = members.iter().map(|m| m.flux).sum();
            assert!((group.aggregate.flux - flux).abs().max_element() <= 1e-3 * flux.x, "one normal: no loss");
            assert!(group.representative >= group.first && group.representative < group.first + group.count);
        }
        assert!(seen.iter().all(|s| *s == 1), "{seen:?}");
    }

    /// Two members facing opposite ways would cancel in the aggregate (only one of them faces
    /// any receiver): such a group is never summed as one; one facing one way is, beyond
    /// `REACH` radii.
    #[test]
    fn only_coherent_groups_are_summed_as_one() {
        let g = group_vals(&[val(0.0, 0.0, Vec3::Z, 1.0), val(0.1, 0.0, -Vec3::Z, 1.0)], 2, (4, 4), REACH);
        assert_eq!(g.groups.len(), 1);
        assert_eq!(g.groups[0].reach, f32::MAX);
        let g = group_vals(&[val(0.0, 0.0, Vec3::Z, 1.0), val(0.1, 0.0, Vec3::Z, 3.0)], 2, (4, 4), REACH);
        assert!((g.groups[0].aggregate.position.x - 0.075).abs() < 1e-6, "weighted by power");
        assert!((g.groups[0].reach - REACH * 0.075).abs() < 1e-6);
        assert_eq!(group_vals(&[val(0.0, 0.0, Vec3::Z, 1.0)], 1, (4, 4), REACH).groups[0].reach, f32::MAX);
    }
}
