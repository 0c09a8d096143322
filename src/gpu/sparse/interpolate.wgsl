// Per-vertex interpolation (docs/design.md §4 step 4, paper eqs. 12-13): each vertex averages the
// point lights of its NEIGHBOURS nearest sparse points. The weights are the paper's
// (1 - d / d_max) * facing(n_v, n_x) when SMOOTH_KERNEL is false, else the smooth kernel
// (1 - (d / d_max)^2)^2 * facing(n_v, n_x) * plane factor (`facing` is the paper's
// clamp(dot(n_v, n_x), 0, 1) with cosines up to FACING_EPSILON taken as 0). When BOUNDED, the
// vertex's light carries the largest bound of its neighbours of positive weight, else 0
// (unbounded). With `glossy_interpolation: "radiance"`, `main_glossy_radiance` writes the
// diffuse light and the interpolated glossy sums instead of a glossy light. With the near field on, `centres` writes each vertex's near-field centre: the
// mean of its neighbours' positions with the same weights (`twin::near_field::vertex_centre`),
// so that the per-pixel near field leaves out of a pixel what its sparse points left in.
// NEIGHBOURS, SMOOTH_KERNEL, BOUNDED, PLANE_FALLOFF, FACING_EPSILON and the weights
// (`interpolation_weights.wgsl`) are prepended (`interpolate::body`). Rust twins: `twin::interpolation_weights`, `twin::interpolate_lights`.

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read> vertex_neighbours: array<array<u32, NEIGHBOURS>>;
@group(0) @binding(2) var<storage, read> sparse_diffuse: array<PointLight>;
@group(0) @binding(3) var<storage, read_write> vertex_diffuse: array<PointLight>;
@group(0) @binding(4) var<storage, read> sparse_glossy: array<PointLight>;
@group(0) @binding(5) var<storage, read_write> vertex_glossy: array<PointLight>;
// Only with the near field (`centres`): per vertex, the weighted mean of its neighbours' positions.
@group(0) @binding(6) var<storage, read_write> vertex_centres: array<vec4<f32>>;
// Only with `glossy_interpolation: "radiance"` (`main_glossy_radiance`): the gathered glossy
// sums in, and per vertex their weighted mean out.
@group(0) @binding(7) var<storage, read> gathered_glossy: array<Gathered>;
@group(0) @binding(8) var<storage, read_write> vertex_glossy_radiance: array<vec4<f32>>;
// The vertices to light, one invocation each: every vertex, or those of the camera's simplified
// triangles (`GpuScene::camera_vertices`).
@group(0) @binding(11) var<storage, read> vertex_list: array<u32>;

// A vertex's weighted sparse points: its NEIGHBOURS nearest points gathered every frame, then,
// with adaptive candidates (`adaptive_candidates`, prepended by `interpolate::body`), those of
// its nearest candidates chosen this frame. ROW (prepended) holds both.
struct VertexNeighbourhood {
    ids: array<u32, ROW>,
    weights: array<f32, ROW>,
    count: u32,
    total: f32,
}

fn neighbourhood(v: u32) -> VertexNeighbourhood {
    let vertex = vertices[v];
    let nb = neighbourhood_at(vertex.position, vertex.normal, vertex_neighbours[v]);
    var out: VertexNeighbourhood;
    for (var j = 0u; j < NEIGHBOURS; j++) {
        if j < nb.count {
            out.ids[j] = nb.ids[j];
            out.weights[j] = nb.weights[j];
        }
    }
    out.count = nb.count;
    out.total = nb.total;
    return adaptive_candidates(v, out, nb.d_max);
}

// The weighted mean of the lights `l` of the neighbourhood and, when BOUNDED, the largest
// bound among those whose share of the weight is over BOUND_WEIGHT_FLOOR (`twin::interpolate_lights`).
fn accumulate(out: PointLight, l: PointLight, weight: f32, total: f32) -> PointLight {
    var r = out;
    r.position += l.position * (weight / total);
    r.intensity += l.intensity * (weight / total);
    if BOUNDED && weight > BOUND_WEIGHT_FLOOR * total {
        r.bound = max(r.bound, l.bound);
    }
    return r;
}

fn interpolate_diffuse(nb: VertexNeighbourhood) -> PointLight {
    var out = PointLight(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if nb.total <= 0.0 {
        return out;
    }
    for (var j = 0u; j < ROW; j++) {
        if j < nb.count {
            out = accumulate(out, sparse_diffuse[nb.ids[j]], nb.weights[j], nb.total);
        }
    }
    return out;
}

fn interpolate_glossy(nb: VertexNeighbourhood) -> PointLight {
    var out = PointLight(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0);
    if nb.total <= 0.0 {
        return out;
    }
    for (var j = 0u; j < ROW; j++) {
        if j < nb.count {
            out = accumulate(out, sparse_glossy[nb.ids[j]], nb.weights[j], nb.total);
        }
    }
    return out;
}

@compute @workgroup_size(WORKGROUP_X)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= arrayLength(&vertex_list) {
        return;
    }
    let v = vertex_list[id.x];
    vertex_diffuse[v] = interpolate_diffuse(neighbourhood(v));
}

@compute @workgroup_size(WORKGROUP_X)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= arrayLength(&vertex_list) {
        return;
    }
    let v = vertex_list[id.x];
    let nb = neighbourhood(v);
    vertex_diffuse[v] = interpolate_diffuse(nb);
    vertex_glossy[v] = interpolate_glossy(nb);
}

// `glossy_interpolation: "radiance"`: the diffuse light as `main` does, and the weighted mean
// of the glossy sums the neighbours gathered toward the eye (`twin::interpolate_radiance`,
// `twin::glossy_toward_eye`), which the shade pass multiplies by the pixel's lobe factor.
@compute @workgroup_size(WORKGROUP_X)
fn main_glossy_radiance(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= arrayLength(&vertex_list) {
        return;
    }
    let v = vertex_list[id.x];
    let nb = neighbourhood(v);
    vertex_diffuse[v] = interpolate_diffuse(nb);
    var g = vec3<f32>(0.0);
    if nb.total > 0.0 {
        for (var j = 0u; j < nb.count; j++) {
            let p = sparse_points[nb.ids[j]];
            if dot(p.normal, view_direction(p.position, p.normal, frame.eye)) > 0.0 {
                g += max(gathered_glossy[nb.ids[j]].irradiance, vec3<f32>(0.0)) * (nb.weights[j] / nb.total);
            }
        }
    }
    vertex_glossy_radiance[v] = vec4<f32>(g, 0.0);
}

// The near field's centre of each vertex (`twin::near_field::vertex_centre`): where its
// neighbours are, weighted as the interpolation weighs them; the vertex itself without any.
@compute @workgroup_size(WORKGROUP_X)
fn centres(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= arrayLength(&vertex_list) {
        return;
    }
    let v = vertex_list[id.x];
    let nb = neighbourhood(v);
    var c = vertices[v].position;
    if nb.total > 0.0 {
        c = vec3<f32>(0.0);
        for (var j = 0u; j < nb.count; j++) {
            c += sparse_points[nb.ids[j]].position * (nb.weights[j] / nb.total);
        }
    }
    vertex_centres[v] = vec4<f32>(c, 0.0);
}
