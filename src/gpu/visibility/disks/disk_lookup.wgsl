// The disc occluders' visibility of a light sphere for the second bounce's `bounce2_occlusion`
// (`gpu/lights/bounce_occlusion.wgsl`): every sparse point is a disc that may hide part of the
// sphere standing for the light a receiver gathered (`disc_terms.wgsl`, included before). Sparse
// points stream through workgroup memory in tiles (the includer binds `sparse_points`). The
// sparse points' own `occlusion` pass (`disks.wgsl`) skips groups of discs instead. Rust twin:
// `disks/twin.rs`.

var<workgroup> occluders: array<SparsePoint, TILE_SIZE>;

// 1 - occlusion of the light sphere of a receiver at `x` with normal `n` whose VALs' weighted
// first and second position moments are `mean` and `second`, by every sparse point but the
// `skip`-th (the receiver itself when it is one). `has_receiver`: whether this invocation has a
// receiver (uniform control flow for the barriers: every invocation walks the tiles).
fn disc_visibility(x: vec3<f32>, n: vec3<f32>, mean: vec3<f32>, second: vec3<f32>, skip: u32, has_receiver: bool, local: u32) -> f32 {
    let count = frame.sparse_count;
    let sphere = light_sphere(mean, second);
    let t = any_perpendicular(n);
    let b = cross(n, t);
    let s = project(x, n, t, b, sphere.centre, 1.0, PI * sphere.radius * sphere.radius);
    let occludable = has_receiver && s.visible && s.side > 0.0;
    var sum = 0.0;
    var product = 1.0;
    for (var base = 0u; base < count; base += TILE_SIZE) {
        if base + local < count {
            occluders[local] = sparse_points[base + local];
        }
        workgroupBarrier();
        let in_tile = min(TILE_SIZE, count - base);
        if occludable {
            for (var j = 0u; j < in_tile; j++) {
                if base + j == skip {
                    continue;
                }
                let d = occluders[j];
                let occ = disc_term(x, n, t, b, sphere, s, d.position, d.normal, d.occluder_radius);
                sum += occ;
                product *= 1.0 - occ;
            }
        }
        workgroupBarrier();
    }
    if !occludable {
        return 1.0;
    }
    if OCCLUSION_PRODUCT {
        return product;
    }
    return 1.0 - clamp(sum, 0.0, 1.0);
}
