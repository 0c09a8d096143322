// The brute force through the clusters' maps (`brute_force_clusters`), looked up in its own
// pass: before its VALs, each invocation looks every cluster up at each of its pixels (the
// lookup of `../visibility/clusters/cluster_visibility.wgsl`, prepended with the maps it reads,
// at the receiver's position and its normal as the mesh gives it, unflipped as the sparse
// points' and the table's lookups take it), so no table of pixels x clusters is
// stored and any image size fits. Uncovered pixels get 1. Rust twin:
// `clusters::twin::cluster_visibility` at the pixels' surfaces, then
// `twin::shade_brute_force_grouped`.

@group(0) @binding(4) var<storage, read> group_of_val: array<u32>;

// Every cluster's visibility at each of the invocation's pixels.
var<private> pixel_visibility: array<array<f32, CLUSTER_COUNT>, PIXELS>;

fn prepare_visibility(receivers: ptr<function, array<Receiver, PIXELS>>) {
    for (var r = 0u; r < PIXELS; r++) {
        let p = (*receivers)[r];
        for (var k = 0u; k < CLUSTER_COUNT; k++) {
            var v = 1.0;
            if p.covered {
                let c = clusters[k];
                v = cluster_visibility(k, c, p.surface.position - c.position, p.given_normal);
            }
            pixel_visibility[r][k] = v;
        }
    }
}

fn pixel_val_visibility(r: Receiver, slot: u32, val: u32) -> f32 {
    return pixel_visibility[slot][min(group_of_val[val], CLUSTER_COUNT - 1u)];
}
