// The clusters' members as lists, for the shadow rays of `ray_visibility.wgsl`: a counting sort
// of the VALs by cluster (`group_of_val`, which k-means wrote). `ray_members` holds, in order,
// CLUSTER_COUNT cursors, CLUSTER_COUNT + 1 starts (cluster k's VALs are members
// [start[k], start[k + 1])) and the members, VAL indices. The host zeroes the cursors; then
// `members_count` counts each cluster's VALs into its cursor, `members_scan` (one invocation)
// turns the counts into starts and sets each cursor to its start, and `members_scatter`
// appends each VAL at its cluster's cursor. The order within a cluster is the atomics' (any).
// Rust twin: `twin::member_lists`.

@group(0) @binding(0) var<storage, read> val_count: u32;
@group(0) @binding(1) var<storage, read> group_of_val: array<u32>;
@group(0) @binding(2) var<storage, read_write> ray_members: array<atomic<u32>>;

// The frame's VALs that have a cluster.
fn vals_in_clusters() -> u32 {
    return min(val_count, arrayLength(&group_of_val));
}

fn cluster_of(v: u32) -> u32 {
    return min(group_of_val[v], CLUSTER_COUNT - 1u);
}

@compute @workgroup_size(WORKGROUP_X)
fn members_count(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < vals_in_clusters() {
        atomicAdd(&ray_members[cluster_of(id.x)], 1u);
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn members_scan(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x != 0u {
        return;
    }
    var start = 0u;
    for (var k = 0u; k < CLUSTER_COUNT; k++) {
        let count = atomicLoad(&ray_members[k]);
        atomicStore(&ray_members[CLUSTER_COUNT + k], start);
        atomicStore(&ray_members[k], start);
        start += count;
    }
    atomicStore(&ray_members[2u * CLUSTER_COUNT], start);
}

@compute @workgroup_size(WORKGROUP_X)
fn members_scatter(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < vals_in_clusters() {
        let slot = atomicAdd(&ray_members[cluster_of(id.x)], 1u);
        atomicStore(&ray_members[2u * CLUSTER_COUNT + 1u + slot], id.x);
    }
}
