// The brute force with per-pixel visibility (`brute_force_ism`), included before
// `brute_force.wgsl`: the fraction of VAL `val`'s light reaching pixel `pixel` is its group's
// entry of the pixel's row, which `brute_force_visibility.wgsl` filled with the imperfect
// shadow maps' lookup at the pixel's surface. `GROUP_COUNT` (groups per row) is prepended.
// Rust twin: `twin::shade_brute_force_grouped`.

@group(0) @binding(4) var<storage, read> group_of_val: array<u32>;
@group(0) @binding(5) var<storage, read> pixel_visibility: array<f32>;

fn pixel_val_visibility(pixel: u32, val: u32) -> f32 {
    if pixel >= frame.width * frame.height {
        return 1.0;
    }
    return pixel_visibility[pixel * GROUP_COUNT + min(group_of_val[val], GROUP_COUNT - 1u)];
}
