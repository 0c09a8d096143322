// What both differential passes share (`differential.wgsl`, `fast.wgsl`, included after this
// file): the receivers, their sums and the bindings other than the parameters (0), the BVH (4,
// 5, `bvh.wgsl`), the rounds' state (6, 7, `shader/rounds.wgsl`: per receiver, where its sums
// resume, each pass says how) and the fast pass's groups (8).

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
