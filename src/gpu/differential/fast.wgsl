// The fast differential pass (`settings.mr.differential_method: "fast"`): the sums of
// `differential.wgsl` over VAL groups (`gpu::differential::groups`). A group beyond its reach is
// summed as its aggregate: a real one adds it to `unoccluded` without a ray when its cone misses
// the virtual content's bounding sphere; a re-emitter group adds it to `added` when the shadow ray
// to its representative member is free, or without a ray when it lights the receiver with less
// than `params.ray_share` of its estimated irradiance. A real group the content may block is
// summed as one only beyond its `shadow_reach`, blocked as a whole when the ray to its
// representative is. Every other group has its members summed one by one, a shadow ray each, as
// the exact pass sums them (none for a real group whose cone misses the content), but the
// members that light the receiver with less than `params.ray_share` of its estimated irradiance
// (`irradiance_estimate`): a real group's take the visibility of the group's representative
// member, whose ray is cast as the group is opened; a re-emitter group's are counted as seen.
// Twin: `gpu::differential::twin::receiver_light_fast`.
//
// Resumable in rounds, as `differential.wgsl`: the state between rounds is the group and the
// member (1-based, 0 at the group's own test; bit 31 the representative's ray, `SHARED_HIT`,
// bit 30 whether the content may block the members' rays, `BLOCKABLE`) in `progress[2 i]` and
// `progress[2 i + 1]`.

struct FastParams {
    receiver_count: u32,
    group_count: u32,
    real_groups: u32,
    // Members that light a receiver with less than this share of its estimated irradiance take
    // their group's shared ray.
    ray_share: f32,
    // The virtual content's bounding sphere: centre and radius (m).
    content: vec4<f32>,
}

struct ValGroup {
    position: vec3<f32>,
    area: f32,
    normal: vec3<f32>,
    radius: f32,
    flux: vec3<f32>,
    reach: f32,
    first: u32,
    count: u32,
    representative: u32,
    shadow_reach: f32,
}

@group(0) @binding(0) var<storage, read> params: FastParams;
// Bindings 1 to 3 and the `Receiver` and `ReceiverLight` structs: `receivers.wgsl`; 6 and 7:
// `shader/rounds.wgsl`.
@group(0) @binding(8) var<storage, read> groups: array<ValGroup>;

// Bits of the member word: set when the opened group's representative is blocked, and when the
// content may block its members' rays (decided once, as the group is opened); the rest is the
// member index.
const SHARED_HIT: u32 = 0x80000000u;
const BLOCKABLE: u32 = 0x40000000u;
const MEMBER_INDEX: u32 = 0x3fffffffu;

// Twin of `irradiance_estimate`: the sum of the channels of the irradiance of the real groups'
// aggregates at `r`, no visibility, in the groups' order.
fn irradiance_estimate(r: Receiver) -> f32 {
    var sum = 0.0;
    let n = min(params.real_groups, arrayLength(&groups));
    for (var k = 0u; k < n; k++) {
        let group = groups[k];
        let f = val_form_factor(r.position, r.normal, group.position, group.normal, group.area);
        if f > 0.0 {
            let e = group.flux * f;
            sum += e.x + e.y + e.z;
        }
    }
    return sum;
}

// Twin of `ContentSphere::may_block`: whether a segment from `origin` to a point of the sphere
// (`centre`, `radius`) can cross the content's bounding sphere.
fn may_be_blocked(origin: vec3<f32>, centre: vec3<f32>, radius: f32) -> bool {
    let to_content = params.content.xyz - origin;
    let to_group = centre - origin;
    let dc = length(to_content);
    let dg = length(to_group);
    let rc = params.content.w;
    if dc <= rc || dg <= radius {
        return true;
    }
    if dc - rc >= dg + radius {
        return false;
    }
    // cos of the sum of the cones' half-angles, without trigonometric functions.
    let sa = rc / dc;
    let sb = min(radius / dg, 1.0);
    let cos_spread = sqrt(1.0 - sa * sa) * sqrt(1.0 - sb * sb) - sa * sb;
    return cos_spread <= 0.0 || dot(to_content, to_group) > dc * dg * cos_spread;
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y, WORKGROUP_Z)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.receiver_count {
        return;
    }
    var g = progress[2u * i];
    var m = progress[2u * i + 1u];
    if g == ROUND_DONE {
        return;
    }
    let start_g = g;
    let start_m = m;
    var sums = ReceiverLight(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    if g > 0u || m > 0u {
        sums = light[i];
    }
    let r = receivers[i];
    let origin = r.position + r.normal * RAY_OFFSET;
    let count = min(params.group_count, arrayLength(&groups));
    var steps = 0u;
    var cutoff = 0.0;
    if params.ray_share > 0.0 {
        cutoff = params.ray_share * irradiance_estimate(r);
        steps = min(params.real_groups, arrayLength(&groups));
    }
    while g < count && steps < FAST_DIFFERENTIAL_LOOP_BUDGET {
        steps += 1u;
        let group = groups[g];
        let real = g < params.real_groups;
        if m == 0u && dot(r.normal, group.position - r.position) < -(group.radius + RAY_OFFSET) {
            // Wholly below the receiver's tangent plane: no member lights it (twin `below`).
            g += 1u;
        } else if m == 0u {
            // Distances compared squared (a reach of f32::MAX, never, squares to infinity).
            let d = group.position - r.position;
            let far = dot(d, d) > group.reach * group.reach;
            if far && (!real || !may_be_blocked(origin, group.position, group.radius)) {
                let f = val_form_factor(r.position, r.normal, group.position, group.normal, group.area);
                if f > 0.0 {
                    let e = vec4<f32>(group.flux * f, 0.0);
                    if real {
                        sums.unoccluded += e;
                    } else if params.ray_share > 0.0 && e.x + e.y + e.z < cutoff {
                        // A faint re-emitter group: facing the receiver, counted as seen.
                        sums.added += e;
                    } else {
                        let t = vals[group.representative];
                        let ray = occluded(origin, t.position + t.normal * RAY_OFFSET, FAST_DIFFERENTIAL_LOOP_BUDGET - steps);
                        steps += ray.steps;
                        if !ray.complete {
                            break;
                        }
                        if !ray.hit {
                            sums.added += e;
                        }
                    }
                }
                g += 1u;
            } else if dot(d, d) > group.shadow_reach * group.shadow_reach {
                // A real group the content may block, far enough: its aggregate, blocked as a
                // whole when the ray to its representative member is.
                let f = val_form_factor(r.position, r.normal, group.position, group.normal, group.area);
                if f > 0.0 {
                    let t = vals[group.representative];
                    let ray = occluded(origin, t.position + t.normal * RAY_OFFSET, FAST_DIFFERENTIAL_LOOP_BUDGET - steps);
                    steps += ray.steps;
                    if !ray.complete {
                        break;
                    }
                    let e = vec4<f32>(group.flux * f, 0.0);
                    sums.unoccluded += e;
                    if ray.hit {
                        sums.blocked += e;
                    }
                }
                g += 1u;
            } else {
                // The group is opened: a real group's representative's ray, for the members too
                // faint for their own (a re-emitter group's faint members are counted as seen).
                // A real group whose cone misses the content (its members' targets lie within its
                // radius and a ray offset): no member's ray can be blocked, none is cast.
                let blockable = !real || may_be_blocked(origin, group.position, group.radius + RAY_OFFSET);
                var representative_hit = 0u;
                if params.ray_share > 0.0 && real && blockable {
                    let t = vals[group.representative];
                    let ray = occluded(origin, t.position + t.normal * RAY_OFFSET, FAST_DIFFERENTIAL_LOOP_BUDGET - steps);
                    steps += ray.steps;
                    if !ray.complete {
                        break;
                    }
                    if ray.hit {
                        representative_hit = SHARED_HIT;
                    }
                }
                m = 1u | representative_hit | select(0u, BLOCKABLE, blockable);
            }
        } else {
            let val = vals[group.first + (m & MEMBER_INDEX) - 1u];
            let f = val_form_factor(r.position, r.normal, val.position, val.normal, val.area);
            if f > 0.0 {
                let e = vec4<f32>(val.flux * f, 0.0);
                // A member too faint for its own ray takes the representative's (never set for a
                // re-emitter group: seen).
                var hit = false;
                if (m & BLOCKABLE) != 0u {
                    if params.ray_share > 0.0 && e.x + e.y + e.z < cutoff {
                        hit = (m & SHARED_HIT) != 0u;
                    } else {
                        let ray = occluded(origin, val.position + val.normal * RAY_OFFSET, FAST_DIFFERENTIAL_LOOP_BUDGET - steps);
                        steps += ray.steps;
                        if !ray.complete {
                            break;
                        }
                        hit = ray.hit;
                    }
                }
                if real {
                    sums.unoccluded += e;
                    if hit {
                        sums.blocked += e;
                    }
                } else if !hit {
                    sums.added += e;
                }
            }
            m += 1u;
            if (m & MEMBER_INDEX) > group.count {
                m = 0u;
                g += 1u;
            }
        }
    }
    light[i] = sums;
    // The member is read only while its group is not ROUND_DONE.
    progress[2u * i + 1u] = m;
    end_round(2u * i, g, count, g == start_g && m == start_m);
}
