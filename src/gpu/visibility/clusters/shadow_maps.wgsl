// One paraboloid shadow map per cluster, all in one depth atlas (paper 000 §4.2): instance k
// draws every triangle into cluster k's tile (the viewport). Edges are straight in the disc
// while the projection bends them, so the depth is not interpolated: each fragment casts its
// texel's ray from the cluster centre against its triangle (corners passed flat) and writes
// the exact distance beyond the map's near distance (`MapFrame`), encoded by `encode_map_depth`
// (any distance below 1, so no far plane: a cluster's centre may lie metres from the meshes);
// fragments whose ray misses the triangle (by more than SHADOW_RASTER_SLACK in barycentrics,
// which keeps neighbours watertight) or that lie nearer than CLUSTER_NEAR_FRACTION x the
// radius (the cluster's own surface) are dropped.

@group(0) @binding(0) var<storage, read> clusters: array<Cluster>;

// Cluster c's map frame; with FOCUS_BOUNDS the meshes' bounding sphere follows the clusters
// (`clusters/mod.rs`, written every frame).
fn frame_of(c: Cluster) -> MapFrame {
    if FOCUS_BOUNDS == 0u {
        return hemisphere_frame(c.normal);
    }
    return cluster_map_frame(c, clusters[CLUSTER_COUNT]);
}

// A distance (m) as the atlas stores it: t / (t + DEPTH_SCALE), monotone and below 1 for every
// finite distance (1, the cleared value, is nothing drawn). Rust twin: `twin::encode_map_depth`.
fn encode_map_depth(t: f32) -> f32 {
    return t / (t + DEPTH_SCALE);
}

struct ShadowVertex {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) cluster: u32,
    @location(1) @interpolate(flat) p0: vec3<f32>,
    @location(2) @interpolate(flat) p1: vec3<f32>,
    @location(3) @interpolate(flat) p2: vec3<f32>,
}

@vertex
fn vs_main(@builtin(vertex_index) vertex_index: u32, @builtin(instance_index) k: u32) -> ShadowVertex {
    let c = clusters[k];
    let triangle = vertex_index / 3u;
    let p0 = vertices[indices[3u * triangle]].position;
    let p1 = vertices[indices[3u * triangle + 1u]].position;
    let p2 = vertices[indices[3u * triangle + 2u]].position;
    var out = ShadowVertex(vec4<f32>(0.0, 0.0, 2.0, 1.0), k, p0, p1, p2);
    if c.count == 0.0 {
        return out;
    }
    let d = vertices[indices[vertex_index]].position - c.position;
    let v = d / max(length(d), 1e-20);
    // Corners behind the hemisphere land outside the disc; bounded so the raster stays sane.
    let f = frame_of(c);
    let t = any_perpendicular(f.axis);
    let q = vec2<f32>(dot(v, t), dot(v, cross(f.axis, t))) / max(1.0 + dot(v, f.axis), 1e-2) / f.scale;
    out.clip = vec4<f32>(q, 0.5, 1.0);
    return out;
}

@fragment
fn fs_main(in: ShadowVertex) -> @builtin(frag_depth) f32 {
    let c = clusters[in.cluster];
    let texel = vec2<i32>(floor(in.clip.xy)) - vec2<i32>(atlas_origin(in.cluster));
    let q = texel_disc(texel);
    if dot(q, q) > 1.0 {
        discard;
    }
    let f = frame_of(c);
    let v = map_direction(q, f);
    // Möller-Trumbore from the centre along v.
    let e1 = in.p1 - in.p0;
    let e2 = in.p2 - in.p0;
    let pv = cross(v, e2);
    let det = dot(e1, pv);
    if abs(det) < 1e-20 {
        discard;
    }
    let inv = 1.0 / det;
    let tv = c.position - in.p0;
    let u = dot(tv, pv) * inv;
    let qv = cross(tv, e1);
    let w = dot(v, qv) * inv;
    let t = dot(e2, qv) * inv;
    let slack = SHADOW_RASTER_SLACK;
    if u < -slack || w < -slack || u + w > 1.0 + slack || !(t > c.radius * CLUSTER_NEAR_FRACTION) || !(t < NOTHING) {
        discard;
    }
    // The depth beyond the map's near distance (0 for a hemisphere map): a focused map of a
    // cluster a kilometre away keeps centimetres where the whole distance would keep decimetres.
    return encode_map_depth(t - f.near);
}
