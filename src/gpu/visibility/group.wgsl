// Group visibility (`gpu/visibility/mod.rs`), included by the gather of a group visibility
// mode: the fraction of VAL `val`'s light that reaches sparse point `point` is its group's
// entry of the point's row. `GROUP_COUNT` (groups per row) is prepended.

@group(0) @binding(5) var<storage, read> group_of_val: array<u32>;
@group(0) @binding(6) var<storage, read> group_visibility: array<f32>;

fn val_visibility(point: u32, val: u32) -> f32 {
    if point >= frame.sparse_count {
        return 1.0;
    }
    return group_visibility[point * GROUP_COUNT + min(group_of_val[val], GROUP_COUNT - 1u)];
}
