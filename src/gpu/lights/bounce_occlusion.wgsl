// The second bounce with `disks` visibility, after `bounce2_points`: every bounce point's
// candidate is scaled by the disc occluders' visibility of its light sphere (the sparse points
// as discs, the sparse points' own `occlusion` lookup, `visibility/disks/disk_lookup.wgsl`,
// prepended with the scene's combination rule), as the sparse points' gathered irradiance is.
// A bounce point is not a sparse point, so no disc is skipped. One invocation per point.
// Rust twin: `twin::bounce::disk_occluded_candidate_vals`.

// Binding 0, `bounce_points`: `bounce_point.wgsl` (prepended).
@group(0) @binding(1) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(2) var<storage, read> bounce_moments: array<Gathered>;
@group(0) @binding(3) var<storage, read_write> candidates: array<Val>;

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let index = id.x;
    let point = bounce_invocation(index);
    var g = Gathered(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if point.inside {
        g = bounce_moments[index];
    }
    let visible = disc_visibility(point.surface.position, point.surface.normal, g.position, g.second_moment, 0xffffffffu, point.inside, local);
    if point.inside {
        candidates[index].flux *= visible;
    }
}
