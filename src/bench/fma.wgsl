// An FMA-bound kernel for `relume bench`: the adapter's arithmetic throughput, to compare the
// gather's against. Each invocation runs FMA_CHAINS independent vec4 chains of
// a = fma(a, m, c) for FMA_ITERATIONS steps (FMA_CHAINS x 4 x FMA_ITERATIONS FMAs) and stores
// their sum so that nothing is optimised away. The constants are prepended by src/bench/fma.rs.

@group(0) @binding(0) var<storage, read_write> sink: array<vec4<f32>>;

@compute @workgroup_size(FMA_WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = f32(id.x) * 1e-7;
    var a: array<vec4<f32>, FMA_CHAINS>;
    for (var k = 0u; k < FMA_CHAINS; k++) {
        a[k] = vec4<f32>(s + f32(k), s + 0.25, s + 0.5, s + 0.75);
    }
    let m = vec4<f32>(0.99990001);
    let c = vec4<f32>(1e-4);
    for (var i = 0u; i < FMA_ITERATIONS; i++) {
        // Unrolled so the chains are independent instructions in one basic block.
        a[0] = fma(a[0], m, c);
        a[1] = fma(a[1], m, c);
        a[2] = fma(a[2], m, c);
        a[3] = fma(a[3], m, c);
        a[4] = fma(a[4], m, c);
        a[5] = fma(a[5], m, c);
        a[6] = fma(a[6], m, c);
        a[7] = fma(a[7], m, c);
    }
    var total = vec4<f32>(0.0);
    for (var k = 0u; k < FMA_CHAINS; k++) {
        total += a[k];
    }
    sink[id.x] = total;
}
