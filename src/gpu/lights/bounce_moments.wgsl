// The second bounce's points with `disks` visibility (prepended to `bounce_points.wgsl`): each
// point keeps its irradiance and the luminance-weighted first and second moments of the VAL
// positions (the gather's `Gathered`, weighted as `gather.wgsl` weighs them), from which
// `bounce2_occlusion` makes its light sphere. A VAL range after the first merges its sums
// into what the earlier ones wrote. Rust twin: `twin::gather_point`'s moments.

@group(0) @binding(4) var<storage, read_write> bounce_moments: array<Gathered>;

fn store_moments(index: u32, e: vec3<f32>, w: f32, l: vec3<f32>, l2: vec3<f32>) {
    if index >= arrayLength(&bounce_moments) {
        return;
    }
    var before = Gathered(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if VAL_BEGIN != 0u {
        before = bounce_moments[index];
    }
    bounce_moments[index] = merge_gathered(before, e, w, l, l2);
}
