// What both differential passes share (`differential.wgsl`, `fast.wgsl`, included after this
// file): the receivers, their sums and the bindings other than the parameters (0), the BVH (4,
// 5, `bvh.wgsl`) and the fast pass's groups (8).

struct Receiver {
    position: vec3<f32>,
    _pad0: f32,
    normal: vec3<f32>,
    _pad1: f32,
}

struct ReceiverLight {
    unoccluded: vec4<f32>,
    blocked: vec4<f32>,
    added: vec4<f32>,
}

@group(0) @binding(1) var<storage, read> receivers: array<Receiver>;
@group(0) @binding(2) var<storage, read> vals: array<Val>;
@group(0) @binding(3) var<storage, read_write> light: array<ReceiverLight>;
// Per receiver, where its sums resume in the next round (each pass says how; zeroed before the
// first round).
@group(0) @binding(6) var<storage, read_write> progress: array<u32>;
// [receivers not finished after this round, receivers that made no progress in it]
@group(0) @binding(7) var<storage, read_write> status: array<atomic<u32>, 2>;
