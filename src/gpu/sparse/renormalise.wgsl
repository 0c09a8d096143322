// Renormalisation (docs/design.md §4 step 2, paper eq. 11): per sparse point, a diffuse (and glossy)
// point light that reproduces exactly what was gathered there, bounded by the point's diffuse
// irradiance (`PointLight.bound`). Rust twins: `twin::renormalise_diffuse`,
// `twin::renormalise_glossy`, `twin::with_bound`.

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read> gathered_diffuse: array<Gathered>;
@group(0) @binding(2) var<storage, read_write> sparse_diffuse: array<PointLight>;
@group(0) @binding(3) var<storage, read> gathered_glossy: array<Gathered>;
@group(0) @binding(4) var<storage, read_write> sparse_glossy: array<PointLight>;

// Sparse point `i`'s diffuse light, stored; its gathered diffuse irradiance returned (the bound
// of its glossy light).
fn store_diffuse(i: u32) -> vec3<f32> {
    let p = sparse_points[i];
    let g = gathered_diffuse[i];
    sparse_diffuse[i] = renormalise_diffuse(p.position, p.normal, g.irradiance, g.position);
    return g.irradiance;
}

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.sparse_count {
        return;
    }
    store_diffuse(id.x);
}

@compute @workgroup_size(WORKGROUP_X)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= frame.sparse_count {
        return;
    }
    let irradiance = store_diffuse(id.x);
    let p = sparse_points[id.x];
    let s = gathered_glossy[id.x];
    var glossy = renormalise_glossy(p.position, p.normal, p.exponent, frame.eye, s.irradiance, s.position);
    glossy.bound = max(luminance(irradiance), 0.0);
    sparse_glossy[id.x] = glossy;
}
