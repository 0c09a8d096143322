// Disc-occluder visibility (docs/design.md §4 step 3, paper §3.3): every other sparse point is a
// disc that may hide part of the sphere standing for the light a sparse point gathered; the
// gathered irradiance (and glossy irradiance) is scaled by the visible fraction before
// renormalisation. A disc occludes only when its plane separates the point from the sphere's
// centre (`disc_terms.wgsl`, included before, with OCCLUSION_PRODUCT, the combination rule).
//
// The sparse points come in `disc_occluders` in a Morton order (`GpuScene::disc_occluders`), so
// that a workgroup's receivers and a group's discs are each near one another, cut into groups
// of DISC_GROUP bounded in `disc_groups`, TILE_SIZE / DISC_GROUP groups to a tile. A workgroup
// loads a group into workgroup memory only when one of its receivers cannot rule the group out
// (`group_may_occlude`: every disc behind its horizon, beyond its light's centre, or projected
// away from the light's square), and only those receivers walk it: the discs skipped add
// exactly 0, so the result is the sum over every disc. Rust twins in `disks/twin.rs`.

struct Occluder {
    position: vec3<f32>,
    radius: f32,
    normal: vec3<f32>,
    // The sparse point's index (its gathered light's).
    index: u32,
}

struct DiscGroup {
    centre: vec3<f32>,
    radius: f32,
    largest_disc: f32,
}

@group(0) @binding(0) var<storage, read> disc_occluders: array<Occluder>;
@group(0) @binding(1) var<storage, read> disc_groups: array<DiscGroup>;
@group(0) @binding(2) var<storage, read_write> gathered_diffuse: array<Gathered>;
@group(0) @binding(3) var<storage, read_write> gathered_glossy: array<Gathered>;

var<workgroup> tile: array<Occluder, TILE_SIZE>;
// Which of a tile's groups a receiver of the workgroup needs (a bit each), for two tiles in
// turn: one is read while the next is cleared.
var<workgroup> needed: array<atomic<u32>, 2>;

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let visible = visibility(id.x, local);
    if id.x < frame.sparse_count {
        let i = disc_occluders[id.x].index;
        gathered_diffuse[i].irradiance *= visible;
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let visible = visibility(id.x, local);
    if id.x < frame.sparse_count {
        let i = disc_occluders[id.x].index;
        gathered_diffuse[i].irradiance *= visible;
        gathered_glossy[i].irradiance *= visible;
    }
}

// Twin: `disks::twin::group_may_occlude`, with the same slack.
fn group_may_occlude(x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, s: Projected, g: DiscGroup) -> bool {
    let v = g.centre - x;
    let d = length(v);
    if dot(n, v) + g.radius < -GROUP_CULL_SLACK * (d + g.radius) {
        return false;
    }
    let near = d - g.radius;
    if near <= GROUP_CULL_SLACK * d {
        return true;
    }
    if near > s.distance * (1.0 + GROUP_CULL_SLACK) {
        return false;
    }
    let u = v / d;
    let spread = asin(min(g.radius / d, 1.0));
    let largest = sqrt(PI) * 0.5 * g.largest_disc / near;
    let gap = abs(vec2<f32>(dot(u, t), dot(u, b)) - s.centre);
    return max(gap.x, gap.y) <= (s.side * 0.5 + spread + largest) * (1.0 + GROUP_CULL_SLACK) + GROUP_CULL_SLACK;
}

// 1 - occlusion of the light sphere of the `id`-th sparse point in Morton order (uniform
// control flow for the barriers: every invocation walks the tiles).
fn visibility(id: u32, local: u32) -> f32 {
    let count = frame.sparse_count;
    var x = vec3<f32>(0.0);
    var n = vec3<f32>(0.0, 1.0, 0.0);
    var skip = 0xffffffffu;
    var g = Gathered(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if id < count {
        let receiver = disc_occluders[id];
        x = receiver.position;
        n = receiver.normal;
        skip = receiver.index;
        g = gathered_diffuse[receiver.index];
    }
    let sphere = light_sphere(g.position, g.second_moment);
    let t = any_perpendicular(n);
    let b = cross(n, t);
    let s = project(x, n, t, b, sphere.centre, 1.0, PI * sphere.radius * sphere.radius);
    let occludable = id < count && s.visible && s.side > 0.0;
    if local < 2u {
        atomicStore(&needed[local], 0u);
    }
    workgroupBarrier();
    var sum = 0.0;
    var product = 1.0;
    let groups = (count + DISC_GROUP - 1u) / DISC_GROUP;
    for (var base = 0u; base < count; base += TILE_SIZE) {
        let turn = (base / TILE_SIZE) & 1u;
        // Bit q: this receiver needs the tile's q-th group.
        var mine = 0u;
        if occludable {
            for (var q = 0u; q < TILE_SIZE / DISC_GROUP; q++) {
                let k = base / DISC_GROUP + q;
                if k < groups && group_may_occlude(x, n, t, b, s, disc_groups[k]) {
                    mine |= 1u << q;
                }
            }
        }
        if mine != 0u {
            atomicOr(&needed[turn], mine);
        }
        // Every invocation read the other tile's flags before the last barrier: clear them for
        // the next tile.
        if local == 0u {
            atomicStore(&needed[1u - turn], 0u);
        }
        workgroupBarrier();
        let wanted = (atomicLoad(&needed[turn]) >> (local / DISC_GROUP)) & 1u;
        if wanted != 0u && base + local < count {
            tile[local] = disc_occluders[base + local];
        }
        workgroupBarrier();
        let in_tile = min(TILE_SIZE, count - base);
        for (var q = 0u; q < TILE_SIZE / DISC_GROUP; q++) {
            if ((mine >> q) & 1u) == 0u {
                continue;
            }
            let end = min((q + 1u) * DISC_GROUP, in_tile);
            for (var j = q * DISC_GROUP; j < end; j++) {
                let d = tile[j];
                if d.index == skip {
                    continue;
                }
                let occ = disc_term(x, n, t, b, sphere, s, d.position, d.normal, d.radius);
                sum += occ;
                product *= 1.0 - occ;
            }
        }
    }
    if !occludable {
        return 1.0;
    }
    if OCCLUSION_PRODUCT {
        return product;
    }
    return 1.0 - clamp(sum, 0.0, 1.0);
}
