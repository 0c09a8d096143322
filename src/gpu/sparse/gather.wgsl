// Gather at sparse points (docs/design.md §4 step 1): every VAL's irradiance summed at every sparse
// point, with the luminance-weighted mean VAL position; the glossy entry point also sums the
// Phong-lobe-weighted irradiance toward the eye and, when GLOSSY_MEAN, its mean position. VALs stream through
// workgroup memory in tiles of TILE_SIZE (`shader/val_tiles.wgsl`, prepended). Rust twin:
// `twin::gather_point`.
//
// One dispatch takes the VALs [VAL_BEGIN, VAL_BEGIN + VAL_SPAN). On GPUs that is all of them
// at once; CPU adapters end a shader's loops after a fixed iteration count (llvmpipe's
// LLVMPIPE_LOOP_LIMIT), so there the VALs are split into ranges, one dispatch each, and every
// range after the first merges its sums into what the earlier ones wrote (`Gathered.weight`
// carries the weight sum the means need).
//
// With the near field on (NEAR_FIELD_RADIUS > 0, prepended), each VAL counts here only with its
// far-field share `1 - near_field_weight(d)`: the near-field pass applies the rest per pixel.
//
// Each invocation gathers at RECEIVERS consecutive sparse points (prepended by `gather.rs`, with
// `add_to_receivers`, which adds one VAL to each of them written out once per receiver: a loop
// would count toward llvmpipe's loop limit, and constant indices keep the sums in registers):
// every VAL it reads from the tile then serves that many points. CPU adapters, whose
// invocations are SIMD lanes that each read the whole VAL from workgroup memory, run faster
// with several (the bench's `gather_variants`); GPUs take one, for parallelism.
//
// GPUs instead share each sparse point among LANES consecutive invocations (prepended by
// `gather.rs`; RECEIVERS is then 1): each sums every LANES-th VAL of each tile, and the lanes'
// sums are added in lane order at the end (`main_lanes`, `main_glossy_lanes`). A frame has a few
// thousand sparse points, and one invocation each leaves most of a large GPU's threads idle
// (an H200 gathered 8,192 points at a sixth of the brute force's pairs per second), while the
// sums only change their order.
//
// `val_visibility(point, val)` is the fraction of a VAL's light that reaches the point: 1
// without a group visibility mode (prepended by `gather.rs`), else its group's entry of the
// table (`gpu/visibility/group.wgsl`).
//
// `receiver_point(slot)` (prepended by `gather.rs`) says which sparse point a receiver slot
// gathers at, NO_POINT for none: slot i is point i up to the points gathered every frame
// (`gather`), or the i-th adaptive candidate chosen this frame (`adaptive_gather`: the list
// `adaptive.wgsl`'s `compact` wrote).

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read> vals: array<Val>;
@group(0) @binding(2) var<storage, read> val_count: u32;
@group(0) @binding(3) var<storage, read_write> gathered_diffuse: array<Gathered>;
@group(0) @binding(4) var<storage, read_write> gathered_glossy: array<Gathered>;

struct Sums {
    e: vec3<f32>,
    g: vec3<f32>,
    ld: vec3<f32>,
    ld2: vec3<f32>,
    ls: vec3<f32>,
    wd: f32,
    ws: f32,
}

const NO_POINT: u32 = 0xffffffffu;

// The point a receiver slot gathers at (a dummy for NO_POINT), its index, its eye direction
// and that direction's cosine to the normal.
struct Receiver {
    point: SparsePoint,
    index: u32,
    w_o: vec3<f32>,
    cos_o: f32,
}

fn receiver(index: u32) -> Receiver {
    var p = SparsePoint(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0);
    if index != NO_POINT {
        p = sparse_points[index];
    }
    let w_o = view_direction(p.position, p.normal, frame.eye);
    return Receiver(p, index, w_o, dot(p.normal, w_o));
}

// `s` with VAL `val` (the `val_index`-th) added as seen from the receiver `r`.
fn add_val(s: Sums, r: Receiver, val: Val, val_index: u32, glossy: bool) -> Sums {
    var out = s;
    let p = r.point;
    let geo = val_geometry(p.position, p.normal, val.position, val.normal, val.area);
    let far = 1.0 - near_field_weight(distance(val.position, p.position), NEAR_FIELD_RADIUS);
    let f = geo.weight * geo.cos_receiver * val_visibility(r.index, val_index) * far;
    let e_j = val.flux * f;
    let y = luminance(val.flux) * f;
    out.e += e_j;
    let gd = y + GATHER_EPSILON;
    out.ld += gd * val.position;
    out.ld2 += gd * val.position * val.position;
    out.wd += gd;
    if glossy {
        // dot(mirror(d, n), w_o) = 2 (n.d)(n.w_o) - d.w_o, with n.d the clamped
        // `cos_receiver`: where it clamps, `f` is 0 and so is whatever the lobe multiplies.
        let lobe = gather_lobe(2.0 * geo.cos_receiver * r.cos_o - dot(geo.direction, r.w_o), p.exponent);
        out.g += e_j * lobe;
        // The lobe-weighted mean position only renormalises the paper's glossy lights
        // (GLOSSY_MEAN, prepended); the interpolated glossy radiance needs the sum alone.
        if GLOSSY_MEAN {
            let gs = y * lobe + GATHER_EPSILON;
            out.ls += gs * val.position;
            out.ws += gs;
        }
    }
    return out;
}

// `phong_lobe(cos_r, k)`, but 0 where it is below 2^GATHER_LOBE_CUTOFF_LOG2 (twin:
// `twin::gather_lobe`). What that leaves out of a point's glossy sum is below 2^-64 of its
// irradiance `E` (the same pairs' `e_j`), far under float rounding; what it saves is the
// products of a tiny lobe with a small `e_j` that fall below f32's normal range: x86 runs
// arithmetic on subnormal floats through slow microcode, and on llvmpipe those products
// made up much of the glossy gather's extra time (docs/measurements/gather-variants.md). Written with
// selects: llvmpipe runs both sides of a branch anyway (`log2` of `cos_r <= 0`, whatever it
// gives, is selected away).
const GATHER_LOBE_CUTOFF_LOG2: f32 = -64.0;

fn gather_lobe(cos_r: f32, k: f32) -> f32 {
    let x = k * log2(cos_r);
    let lobe = select(exp2(x), 0.0, cos_r <= 0.0 || x < GATHER_LOBE_CUTOFF_LOG2);
    return select(lobe, 1.0, k <= 0.0);
}

// The sums of this dispatch's VALs at the points of slots [first, first + RECEIVERS).
fn gather_tiles(first: u32, local: u32, glossy: bool) -> array<Sums, RECEIVERS> {
    var sums: array<Sums, RECEIVERS>;
    var receivers: array<Receiver, RECEIVERS>;
    for (var r = 0u; r < RECEIVERS; r++) {
        sums[r] = Sums(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, 0.0);
        receivers[r] = receiver(receiver_point(first + r));
    }
    let end = val_range_end();
    for (var base = VAL_BEGIN; base < end; base += TILE_SIZE) {
        let n = load_tile(base, local, end);
        for (var j = 0u; j < n; j++) {
            add_to_receivers(&sums, &receivers, tile[j], base + j, glossy);
        }
        workgroupBarrier();
    }
    return sums;
}

// What the earlier VAL ranges gathered at point `i` (nothing for the first range).
fn earlier_diffuse(i: u32) -> Gathered {
    if VAL_BEGIN == 0u {
        return Gathered(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    }
    return gathered_diffuse[i];
}

fn earlier_glossy(i: u32) -> Gathered {
    if VAL_BEGIN == 0u {
        return Gathered(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    }
    return gathered_glossy[i];
}

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let first = id.x * RECEIVERS;
    let sums = gather_tiles(first, local, false);
    for (var r = 0u; r < RECEIVERS; r++) {
        let i = receiver_point(first + r);
        if i != NO_POINT {
            let s = sums[r];
            gathered_diffuse[i] = merge_gathered(earlier_diffuse(i), s.e, s.wd, s.ld, s.ld2);
        }
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let first = id.x * RECEIVERS;
    let sums = gather_tiles(first, local, true);
    for (var r = 0u; r < RECEIVERS; r++) {
        let i = receiver_point(first + r);
        if i != NO_POINT {
            let s = sums[r];
            gathered_diffuse[i] = merge_gathered(earlier_diffuse(i), s.e, s.wd, s.ld, s.ld2);
            gathered_glossy[i] = merge_gathered(earlier_glossy(i), s.g, s.ws, s.ls, vec3<f32>(0.0));
        }
    }
}

// The lanes' sums of one sparse point, in workgroup memory for the lane-order addition.
var<workgroup> lane_sums: array<Sums, WORKGROUP_X>;

fn add_sums(a: Sums, b: Sums) -> Sums {
    return Sums(a.e + b.e, a.g + b.g, a.ld + b.ld, a.ld2 + b.ld2, a.ls + b.ls, a.wd + b.wd, a.ws + b.ws);
}

// The sums of this dispatch's VALs at the point of receiver slot `slot`, shared by the LANES
// invocations of the workgroup from `local - lane` on: each adds every LANES-th VAL of a tile,
// from its `lane`-th. Every invocation gets the point's whole sums (uniform control flow for
// the barriers).
fn gather_lanes(slot: u32, local: u32, lane: u32, glossy: bool) -> Sums {
    var s = Sums(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, 0.0);
    let r = receiver(receiver_point(slot));
    let end = val_range_end();
    for (var base = VAL_BEGIN; base < end; base += TILE_SIZE) {
        let n = load_tile(base, local, end);
        for (var j = lane; j < n; j += LANES) {
            s = add_val(s, r, tile[j], base + j, glossy);
        }
        workgroupBarrier();
    }
    lane_sums[local] = s;
    workgroupBarrier();
    var total = lane_sums[local - lane];
    for (var k = 1u; k < LANES; k++) {
        total = add_sums(total, lane_sums[local - lane + k]);
    }
    return total;
}

@compute @workgroup_size(WORKGROUP_X)
fn main_lanes(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let lane = local % LANES;
    let s = gather_lanes(id.x / LANES, local, lane, false);
    let i = receiver_point(id.x / LANES);
    if lane == 0u && i != NO_POINT {
        gathered_diffuse[i] = merge_gathered(earlier_diffuse(i), s.e, s.wd, s.ld, s.ld2);
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn main_glossy_lanes(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let lane = local % LANES;
    let s = gather_lanes(id.x / LANES, local, lane, true);
    let i = receiver_point(id.x / LANES);
    if lane == 0u && i != NO_POINT {
        gathered_diffuse[i] = merge_gathered(earlier_diffuse(i), s.e, s.wd, s.ld, s.ld2);
        gathered_glossy[i] = merge_gathered(earlier_glossy(i), s.g, s.ws, s.ls, vec3<f32>(0.0));
    }
}
