// Disc-occluder visibility (docs/design.md §4 step 3, paper §3.3): every other sparse point is a
// disc that may hide part of the sphere standing for the light a sparse point gathered; the
// gathered irradiance (and glossy irradiance) is scaled by the visible fraction before
// renormalisation. A disc occludes only when its plane separates the point from the sphere's
// centre (`separates`). The lookup (`disk_lookup.wgsl`, prepended with OCCLUSION_PRODUCT, the
// combination rule) streams the sparse points through workgroup memory in tiles. Rust twins
// in `disks/twin.rs`.

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read_write> gathered_diffuse: array<Gathered>;
@group(0) @binding(2) var<storage, read_write> gathered_glossy: array<Gathered>;

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let visible = visibility(id.x, local);
    if id.x < frame.sparse_count {
        gathered_diffuse[id.x].irradiance *= visible;
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let visible = visibility(id.x, local);
    if id.x < frame.sparse_count {
        gathered_diffuse[id.x].irradiance *= visible;
        gathered_glossy[id.x].irradiance *= visible;
    }
}

// 1 - occlusion of sparse point `index`'s light sphere (uniform control flow for barriers).
fn visibility(index: u32, local: u32) -> f32 {
    let count = frame.sparse_count;
    var p = SparsePoint(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0);
    var g = Gathered(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if index < count {
        p = sparse_points[index];
        g = gathered_diffuse[index];
    }
    return disc_visibility(p.position, p.normal, g.position, g.second_moment, index, index < count, local);
}
