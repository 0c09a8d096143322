// Group visibility (`gpu/visibility/mod.rs`, `group_wgsl`), included by every pass that lights
// receivers through a group visibility mode's table: the gather (sparse points), `bounce2_points`
// (the second bounce's points, through the first bounce's groups) and `brute_force_ism` (the
// pixels). The fraction of VAL `val`'s light that reaches receiver `receiver` is its group's
// entry of the receiver's row, which the mode's lookup pass filled. `GROUP_COUNT` (groups per
// row) and `GROUP_BINDING` (`group_of_val`'s binding; the table's is the next) are prepended.
// An index past the table (an invocation past the last receiver, whose result is dropped)
// reads 1. Rust twins: `clusters::twin`'s tables as `twin::gather_point`,
// `twin::bounce::grouped_candidate_vals` and `twin::shade_brute_force_grouped` use them.

@group(0) @binding(GROUP_BINDING) var<storage, read> group_of_val: array<u32>;
@group(0) @binding(GROUP_BINDING + 1u) var<storage, read> group_visibility: array<f32>;

fn val_visibility(receiver: u32, val: u32) -> f32 {
    let i = receiver * GROUP_COUNT + min(group_of_val[val], GROUP_COUNT - 1u);
    if i >= arrayLength(&group_visibility) {
        return 1.0;
    }
    return group_visibility[i];
}
