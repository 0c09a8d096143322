// The first bounce's groups seen from the second bounce's points, included by `bounce2_points`
// when the sparse method's visibility mode is `clusters` or `ism` (`bounce_visibility.wgsl`
// filled the table): the fraction of first-bounce VAL `val`'s light reaching bounce point
// `point` is its group's entry of the point's row. `GROUP_COUNT` (groups per row) is
// prepended. Rust twin: `twin::bounce::grouped_candidate_vals`.

@group(0) @binding(4) var<storage, read> group_of_val: array<u32>;
@group(0) @binding(5) var<storage, read> bounce_visibility: array<f32>;

fn point_val_visibility(point: u32, val: u32) -> f32 {
    if point >= arrayLength(&bounce_points) {
        return 1.0;
    }
    return bounce_visibility[point * GROUP_COUNT + min(group_of_val[val], GROUP_COUNT - 1u)];
}
