// The adaptive candidates' part of a vertex's neighbourhood (`settings.sparse.adaptive`),
// prepended to `interpolate.wgsl` by `interpolate::body` for a scene with candidates: of the
// vertex's NEIGHBOURS nearest candidates, each chosen this frame joins its weighted points with
// the interpolation's kernel over the radius `min(d_max, e_max)`, where `d_max` is its nearest
// points' largest distance (the radius their own weights fall to 0 at) and `e_max` the listed
// candidates' largest: a candidate entering either list does so at weight 0, so the light stays
// continuous over the surface. With none chosen the vertex's light is exactly the one without
// candidates. Rust twin: `twin::adaptive::candidate_weights`.

@group(0) @binding(9) var<storage, read> vertex_candidates: array<array<u32, NEIGHBOURS>>;
// Per candidate (point index minus BASE_POINTS): 1 when chosen this frame.
@group(0) @binding(10) var<storage, read> chosen: array<u32>;

fn adaptive_candidates(v: u32, nb: VertexNeighbourhood, d_max: f32) -> VertexNeighbourhood {
    let vertex = vertices[v];
    let ids = vertex_candidates[v];
    var e_max = 0.0;
    var count = 0u;
    for (var j = 0u; j < NEIGHBOURS; j++) {
        if ids[j] == NO_NEIGHBOUR {
            break;
        }
        e_max = max(e_max, distance(sparse_points[ids[j]].position, vertex.position));
        count += 1u;
    }
    let radius = min(d_max, e_max);
    var out = nb;
    if radius <= 0.0 {
        return out;
    }
    for (var j = 0u; j < count; j++) {
        if chosen[ids[j] - BASE_POINTS] == 0u {
            continue;
        }
        let p = sparse_points[ids[j]];
        let w = spatial_weight(vertex.normal, p.normal, p.position - vertex.position, radius) * facing(vertex.normal, p.normal);
        if w > 0.0 {
            out.ids[out.count] = ids[j];
            out.weights[out.count] = w;
            out.count += 1u;
            out.total += w;
        }
    }
    return out;
}
