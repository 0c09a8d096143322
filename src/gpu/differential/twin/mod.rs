//! CPU twins of `differential.wgsl` and `fast.wgsl`: what one receiver's sums are, with the same
//! shadow rays (`twin::bvh::Bvh::occluded` through [`Occluders`], the GPU traversal's twin, from
//! `p + n RAY_OFFSET` to `l + n_l RAY_OFFSET`).

pub mod groups;

use crate::twin::bvh::{Occluders, PACKET_RAYS};
use crate::twin::exact_cpu::RAY_OFFSET;
use crate::twin::{Val, val_form_factor};
use glam::Vec3;
use groups::GroupedVals;

/// A real surface point that receives light: world position (m) and unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Receiver {
    pub position: Vec3,
    pub normal: Vec3,
}

/// What the virtual content does to one receiver's irradiance (W/m², RGB).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReceiverLight {
    /// Irradiance of every real VAL, no visibility: what the receiver gets without the virtual
    /// content (the real room's own occlusion is already in the camera image).
    pub unoccluded: Vec3,
    /// The part of `unoccluded` whose shadow ray a virtual triangle blocks.
    pub blocked: Vec3,
    /// Irradiance of the virtual re-emitters whose shadow ray is free.
    pub added: Vec3,
}

impl ReceiverLight {
    /// The change the virtual content makes: `added - blocked` (W/m²).
    pub fn change(&self) -> Vec3 {
        self.added - self.blocked
    }

    /// Add one VAL's irradiance `e` (W/m²): a real VAL's to `unoccluded`, and to `blocked` when
    /// its shadow ray is; a re-emitter's to `added` when its ray is free.
    fn add(&mut self, e: Vec3, real: bool, blocked: bool) {
        if real {
            self.unoccluded += e;
            if blocked {
                self.blocked += e;
            }
        } else if !blocked {
            self.added += e;
        }
    }
}

/// The sums of `differential.wgsl` at `receiver`: `vals[.. real_count]` are real VALs, the
/// rest the virtual content's re-emitters; `content` is the virtual triangles.
pub fn receiver_light(receiver: &Receiver, vals: &[Val], real_count: usize, content: &Occluders) -> ReceiverLight {
    receiver_light_with(receiver, vals, real_count, |origin, targets| content.blocked_mask(origin, targets))
}

/// Shadow rays at most this many at a time: the width of the mask `blocked` returns (the
/// trees' masks, `TraceBvh::blocked_mask` and `Occluders::blocked_mask`).
pub const SHADOW_BATCH: usize = PACKET_RAYS;

/// The sums at `receiver`, with `blocked(from, targets)` deciding the shadow rays from `from` to
/// at most [`SHADOW_BATCH`] targets at a time (bit `j` set when the segment to `targets[j]` is
/// blocked). The sums are taken in the VALs' order, so they are the same however the rays are
/// decided.
pub fn receiver_light_with(
    receiver: &Receiver,
    vals: &[Val],
    real_count: usize,
    blocked: impl Fn(Vec3, &[Vec3]) -> u32,
) -> ReceiverLight {
    sums_with(receiver, vals, real_count, 0.0, || false, blocked)
}

/// The virtual content's bounding sphere for the fast pass's cull: centre and radius (m), padded
/// so that it holds every shadow ray's end offsets too.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContentSphere {
    pub centre: Vec3,
    pub radius: f32,
}

impl ContentSphere {
    /// The sphere about the box `bounds` (min, max corners), padded by a few ray offsets.
    pub fn around(bounds: (Vec3, Vec3)) -> Self {
        let centre = (bounds.0 + bounds.1) * 0.5;
        Self { centre, radius: (bounds.1 - bounds.0).length() * 0.5 + 4.0 * RAY_OFFSET }
    }

    /// Whether a segment from `origin` to a point of the sphere (`centre`, `radius`) can cross
    /// this sphere: false only when the cone from `origin` around that sphere and the cone
    /// around this one are apart, or this one lies wholly beyond the other. Twin of
    /// `may_be_blocked` in `fast.wgsl`.
    pub fn may_block(&self, origin: Vec3, centre: Vec3, radius: f32) -> bool {
        let (to_content, to_group) = (self.centre - origin, centre - origin);
        let (dc, dg) = (to_content.length(), to_group.length());
        if dc <= self.radius || dg <= radius {
            return true;
        }
        if dc - self.radius >= dg + radius {
            return false;
        }
        // The cones' half-angles a and b (sin a = r / d); the segment can cross when the angle
        // between their axes is under a + b: cos(a + b) = cos a cos b - sin a sin b, no
        // trigonometric function (a + b of 90° or more: always).
        let (sa, sb) = (self.radius / dc, (radius / dg).min(1.0));
        let cos_spread = (1.0 - sa * sa).sqrt() * (1.0 - sb * sb).sqrt() - sa * sb;
        cos_spread <= 0.0 || to_content.dot(to_group) > dc * dg * cos_spread
    }
}

/// The sums of `fast.wgsl` at `receiver` over `grouped` (real VALs and re-emitters in groups).
/// A group beyond its reach is summed as its aggregate: a real one adds it to `unoccluded`
/// without a shadow ray when its cone misses `sphere`, the content's bounding sphere (nothing
/// can block it); a re-emitter group adds it to `added` when the shadow ray to its
/// representative member is free, or without a ray when it lights the receiver with less than
/// `ray_share` of its estimated irradiance ([`irradiance_estimate`]; it faces the receiver, and
/// the content's own surface hides a faint group from it rarely: measured in
/// docs/measurements/differential.md, "Faint members"). A real group whose cone may meet the
/// content is summed as one only beyond its `shadow_reach`, and blocked as a whole when the ray
/// to its representative is.
/// Every other group has its members summed one by one, as [`receiver_light`] sums them, but for
/// a real group whose cone misses the content (its members are summed without rays) and for the
/// members that light the receiver with less than `ray_share` of its estimated irradiance:
/// a real group's take the visibility of the group's representative member, one ray for all of
/// them; a re-emitter group's are counted as seen, as a faint far re-emitter group is.
/// `content` is the virtual triangles.
pub fn receiver_light_fast(
    receiver: &Receiver,
    grouped: &GroupedVals,
    sphere: &ContentSphere,
    ray_share: f32,
    content: &Occluders,
) -> ReceiverLight {
    receiver_light_fast_with(receiver, grouped, sphere, ray_share, |origin, targets| {
        content.blocked_mask(origin, targets)
    })
}

/// The irradiance `receiver` would get from the real groups' aggregates, no visibility (W/m²,
/// the sum of the channels): the scale of [`receiver_light_fast`]'s `ray_share`. The sum runs
/// in the groups' order, as `fast.wgsl`'s `irradiance_estimate`.
pub fn irradiance_estimate(receiver: &Receiver, grouped: &GroupedVals) -> f32 {
    let mut sum = 0.0;
    for group in &grouped.groups[..grouped.real_groups] {
        if let Some(e) = lit_by(receiver, &group.aggregate) {
            sum += e.element_sum();
        }
    }
    sum
}

/// [`receiver_light_fast`] with `blocked` deciding the shadow rays, as for
/// [`receiver_light_with`].
pub fn receiver_light_fast_with(
    receiver: &Receiver,
    grouped: &GroupedVals,
    sphere: &ContentSphere,
    ray_share: f32,
    blocked: impl Fn(Vec3, &[Vec3]) -> u32 + Copy,
) -> ReceiverLight {
    let origin = receiver.position + receiver.normal * RAY_OFFSET;
    let one_blocked = |target: &Val| blocked(origin, &[target.position + target.normal * RAY_OFFSET]) & 1 == 1;
    let cutoff = if ray_share > 0.0 { ray_share * irradiance_estimate(receiver, grouped) } else { 0.0 };
    let mut sums = ReceiverLight::default();
    for (k, group) in grouped.groups.iter().enumerate() {
        let real = k < grouped.real_groups;
        let a = &group.aggregate;
        if below(receiver, a.position, group.radius) {
            continue;
        }
        // Distances compared squared (a reach of f32::MAX, never, squares to infinity).
        let d2 = (a.position - receiver.position).length_squared();
        let far = d2 > group.reach * group.reach;
        if far && (!real || !sphere.may_block(origin, a.position, group.radius)) {
            let Some(e) = lit_by(receiver, a) else { continue };
            if real {
                sums.unoccluded += e;
            } else if e.element_sum() < cutoff || !one_blocked(&grouped.vals[group.representative as usize]) {
                // A faint re-emitter group facing the receiver is counted as seen, without a ray.
                sums.added += e;
            }
            continue;
        }
        if d2 > group.shadow_reach * group.shadow_reach {
            // A real group that the content may block, far enough: its aggregate, blocked as a
            // whole when the ray to its representative member is.
            let Some(e) = lit_by(receiver, a) else { continue };
            sums.unoccluded += e;
            if one_blocked(&grouped.vals[group.representative as usize]) {
                sums.blocked += e;
            }
            continue;
        }
        let members = &grouped.vals[group.first as usize..(group.first + group.count) as usize];
        // A real group whose members' rays all pass clear of the content (their targets lie
        // within the radius and a ray offset of the aggregate) is summed without rays: the same
        // sums, in the same order, as with them.
        let part = if real && !sphere.may_block(origin, a.position, group.radius + RAY_OFFSET) {
            receiver_light_with(receiver, members, members.len(), |_, _| 0)
        } else {
            let shared = std::cell::OnceCell::new();
            let representative = &grouped.vals[group.representative as usize];
            let real_count = if real { members.len() } else { 0 };
            sums_with(
                receiver,
                members,
                real_count,
                cutoff,
                || real && *shared.get_or_init(|| one_blocked(representative)),
                blocked,
            )
        };
        sums.unoccluded += part.unoccluded;
        sums.blocked += part.blocked;
        sums.added += part.added;
    }
    sums
}

/// The irradiance (W/m²) `val` gives `receiver` without visibility, when its form factor there
/// is positive (`fast.wgsl`'s `f > 0.0`): the one test every sum of the twins makes. The form
/// factor is [`val_form_factor`], which tests the cosines before the division (a VAL below the
/// receiver's tangent plane or facing away: most of a group's members at a receiver that opens
/// it).
#[inline]
fn lit_by(receiver: &Receiver, val: &Val) -> Option<Vec3> {
    let f = val_form_factor(receiver.position, receiver.normal, val.position, val.normal, val.area);
    (f > 0.0).then(|| val.flux * f)
}

/// Whether the sphere (`centre`, `radius`) lies wholly below `receiver`'s tangent plane, by a
/// ray offset: every VAL in it has a receiver cosine of 0, so a group in it adds nothing and is
/// passed without a look at its members (`fast.wgsl`'s `below`).
fn below(receiver: &Receiver, centre: Vec3, radius: f32) -> bool {
    receiver.normal.dot(centre - receiver.position) < -(radius + RAY_OFFSET)
}

/// The sums of `vals` at `receiver` (`vals[.. real_count]` real, the rest re-emitters), the
/// shadow rays of the VALs that light it decided by `blocked` at most [`SHADOW_BATCH`] at a
/// time, but for those whose irradiance (the sum of its channels) is under a positive `cutoff`:
/// these take `shared()`'s visibility. Summed in the VALs' order, so the sums are the same
/// however the rays are decided.
fn sums_with(
    receiver: &Receiver,
    vals: &[Val],
    real_count: usize,
    cutoff: f32,
    shared: impl Fn() -> bool,
    blocked: impl Fn(Vec3, &[Vec3]) -> u32,
) -> ReceiverLight {
    let origin = receiver.position + receiver.normal * RAY_OFFSET;
    let mut sums = ReceiverLight::default();
    for (c, chunk) in vals.chunks(SHADOW_BATCH).enumerate() {
        // The chunk's VALs that light the receiver: irradiance, index and whether a ray of its
        // own decides it; the rays' targets.
        let mut lit = [(Vec3::ZERO, 0usize, false); SHADOW_BATCH];
        let mut targets = [Vec3::ZERO; SHADOW_BATCH];
        let (mut n, mut rays) = (0, 0);
        for (i, val) in chunk.iter().enumerate() {
            if let Some(e) = lit_by(receiver, val) {
                let ray = !(cutoff > 0.0 && e.element_sum() < cutoff);
                if ray {
                    targets[rays] = val.position + val.normal * RAY_OFFSET;
                    rays += 1;
                }
                lit[n] = (e, c * SHADOW_BATCH + i, ray);
                n += 1;
            }
        }
        let mask = if rays > 0 { blocked(origin, &targets[..rays]) } else { 0 };
        let mut ray = 0;
        for &(e, j, own) in &lit[..n] {
            let hit = if own {
                ray += 1;
                mask >> (ray - 1) & 1 == 1
            } else {
                shared()
            };
            sums.add(e, j < real_count, hit);
        }
    }
    sums
}
