// Interpolation weights over a receiver's nearest sparse points (docs/design.md §4 step 4), shared by
// the per-vertex interpolation (`interpolate.wgsl`) and the adaptive candidates' score
// (`adaptive.wgsl`), which both declare `sparse_points`. NEIGHBOURS, SMOOTH_KERNEL,
// PLANE_FALLOFF and FACING_EPSILON are prepended (`interpolate::weights_head`). Rust twins:
// `twin::interpolation_weights`, `twin::paper_weight`, `twin::smooth_weight`, `twin::facing`.

// `twin::paper_weight` and `twin::smooth_weight` of a neighbour at `offset` with normal `n_j`.
fn spatial_weight(n_v: vec3<f32>, n_j: vec3<f32>, offset: vec3<f32>, d_max: f32) -> f32 {
    if d_max <= 0.0 {
        return 1.0;
    }
    if !SMOOTH_KERNEL {
        return max(1.0 - length(offset) / d_max, 0.0);
    }
    let q = max(1.0 - dot(offset, offset) / (d_max * d_max), 0.0);
    // Depth behind the smooth surface through both points (their normals' mean), not behind
    // the vertex's tangent plane: a curved surface's own points stay in.
    let plane = clamp(1.0 + 0.5 * dot(n_v + n_j, offset) / (PLANE_FALLOFF * d_max), 0.0, 1.0);
    return q * q * plane;
}

// `twin::facing`: cosines up to FACING_EPSILON count as facing away, so that perpendicular
// surfaces weigh exactly nothing however the scene is turned.
fn facing(n_v: vec3<f32>, n: vec3<f32>) -> f32 {
    return clamp((dot(n_v, n) - FACING_EPSILON) / (1.0 - FACING_EPSILON), 0.0, 1.0);
}

struct Neighbourhood {
    ids: array<u32, NEIGHBOURS>,
    weights: array<f32, NEIGHBOURS>,
    count: u32,
    total: f32,
    // The farthest point's distance, where the kernel falls to 0.
    d_max: f32,
}

// The weights of the sparse points `ids` (NO_NEIGHBOUR-terminated) for a receiver at `position`
// with unit normal `normal`: a vertex, or an adaptive candidate taking its neighbours' light
// (`twin::interpolation_weights`). The points are read where they are used rather than copied
// into local arrays: llvmpipe keeps a dynamically indexed local array in memory, which made this
// function most of the interpolation's time on a CPU adapter.
fn neighbourhood_at(position: vec3<f32>, normal: vec3<f32>, ids: array<u32, NEIGHBOURS>) -> Neighbourhood {
    var count = 0u;
    var d_max = 0.0;
    for (var j = 0u; j < NEIGHBOURS; j++) {
        if ids[j] == NO_NEIGHBOUR {
            break;
        }
        d_max = max(d_max, length(sparse_points[ids[j]].position - position));
        count += 1u;
    }
    var w: array<f32, NEIGHBOURS>;
    var total = 0.0;
    for (var j = 0u; j < NEIGHBOURS; j++) {
        if j < count {
            let p = sparse_points[ids[j]];
            w[j] = spatial_weight(normal, p.normal, p.position - position, d_max) * facing(normal, p.normal);
            total += w[j];
        }
    }
    if total <= 0.0 && count > 0u {
        // Every weight 0: the first neighbour facing the receiver at all takes it whole.
        var fallback = 0u;
        for (var j = count; j > 0u; j--) {
            if dot(normal, sparse_points[ids[j - 1u]].normal) > FACING_EPSILON {
                fallback = j - 1u;
            }
        }
        w[fallback] = 1.0;
        total = 1.0;
    }
    return Neighbourhood(ids, w, count, total, d_max);
}
