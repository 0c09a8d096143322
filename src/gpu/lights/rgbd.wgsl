// RGB-D frame to VALs (docs/design.md §2 "RGB-D frames"), two dispatches over the grid of
// `grid_step`-pixel cells: `filter_grid` writes each cell's bilateral-filtered depth (0 = no
// VAL), then `main` turns every cell with depth into a candidate VAL, and `compact`
// (`compact_vals.wgsl`) appends them to `vals` in the cells' order. The rules
// (grid, filter, normals, footprint area, colour) are stated once, in the Rust twins of
// `src/twin/rgbd.rs`, whose functions have these names and argument order; the images
// (`depth`, `color`, `grid_depth`) are read from the bindings here instead of passed in, and
// `None` is a zero vector. `MIN_FOOTPRINT_COSINE` is prepended by `src/gpu/rgbd.rs`.

// `rgbd::Intrinsics`: pinhole of the depth image (pixels; optical axes x right, y down, z
// forward; pixel centres at integer coordinates).
struct Intrinsics {
    width: u32,
    height: u32,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
}

// `rgbd::RgbdSettings` (m, W/(m² sr), pixels).
struct RgbdSettings {
    grid_step: u32,
    min_depth: f32,
    max_depth: f32,
    radiance_scale: f32,
    bilateral_radius: u32,
    bilateral_depth_sigma: f32,
    min_cosine: f32,
}

// The frame's constants: its pose (camera-to-world, optical axes), intrinsics and settings.
struct RgbdParams {
    camera_to_world: mat4x4<f32>,
    intrinsics: Intrinsics,
    settings: RgbdSettings,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// One VAL per cell at most, or no VAL: what `grid_cell_val` returns.
struct CellVal {
    val: Val,
    valid: bool,
}

@group(0) @binding(0) var<storage, read> params: RgbdParams;
// Depth along the optical axis (m), row-major; 0, negative, NaN or out of range = none.
@group(0) @binding(1) var<storage, read> depth: array<f32>;
// Filtered depth per grid cell (m), row-major; 0 = no VAL.
@group(0) @binding(2) var<storage, read_write> grid_depth: array<f32>;
// sRGB colour, one RGBA8 texel per u32 (red in the low byte), row-major.
@group(0) @binding(3) var<storage, read> color: array<u32>;
// Bound with exactly the caller's capacity, so `arrayLength(&vals)` is the capacity.
@group(0) @binding(4) var<storage, read_write> vals: array<Val>;
@group(0) @binding(5) var<storage, read_write> val_count: atomic<u32>;
// One candidate per grid cell, row-major, written by `main` (area -1: none) and appended in
// that order by `compact` (`compact_vals.wgsl`).
@group(0) @binding(6) var<storage, read_write> candidates: array<Val>;

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    return select(pow((c + 0.055) / 1.055, vec3<f32>(2.4)), c / 12.92, c <= vec3<f32>(0.04045));
}

fn valid_depth(z: f32, settings: RgbdSettings) -> bool {
    // Finite by its exponent bits: WGSL lets implementations assume that comparisons never see
    // NaN or infinity.
    let finite = (bitcast<u32>(z) & 0x7f800000u) != 0x7f800000u;
    return finite && z > 0.0 && z >= settings.min_depth && z <= settings.max_depth;
}

fn grid_step(settings: RgbdSettings) -> u32 {
    return max(settings.grid_step, 1u);
}

fn grid_size(intrinsics: Intrinsics, settings: RgbdSettings) -> vec2<u32> {
    let s = grid_step(settings);
    let size = vec2<u32>(intrinsics.width, intrinsics.height);
    return size / s + select(vec2<u32>(0u), vec2<u32>(1u), size % s != vec2<u32>(0u));
}

fn cell_block(intrinsics: Intrinsics, cell: vec2<u32>, settings: RgbdSettings) -> vec4<u32> {
    let s = grid_step(settings);
    let size = vec2<u32>(intrinsics.width, intrinsics.height);
    let start = cell * s;
    let end = start + min(size - start, vec2<u32>(s));
    return vec4<u32>(start, end);
}

fn cell_centre(block: vec4<u32>) -> vec2<u32> {
    return (block.xy + block.zw - 1u) / 2u;
}

fn bilateral_range_weight(dz: f32, sigma: f32) -> f32 {
    if sigma > 0.0 {
        let t = dz / sigma;
        return exp(-t * t);
    }
    return select(0.0, 1.0, dz == 0.0);
}

fn bilateral_depth(intrinsics: Intrinsics, u: u32, v: u32, settings: RgbdSettings) -> f32 {
    let w = i32(intrinsics.width);
    let h = i32(intrinsics.height);
    let zc = depth[v * intrinsics.width + u];
    if !valid_depth(zc, settings) {
        return 0.0;
    }
    let r = i32(settings.bilateral_radius);
    if r == 0 {
        return zc;
    }
    // Gaussian exp(-d^2 / (2 sigma^2)) with sigma = r / 2.
    let spatial = -2.0 / f32(r * r);
    var sum = 0.0;
    var weight = 0.0;
    for (var dy = -r; dy <= r; dy++) {
        let y = i32(v) + dy;
        if y < 0 || y >= h {
            continue;
        }
        for (var dx = -r; dx <= r; dx++) {
            let x = i32(u) + dx;
            if x < 0 || x >= w {
                continue;
            }
            let z = depth[u32(y * w + x)];
            if !valid_depth(z, settings) {
                continue;
            }
            let wt = exp(spatial * f32(dx * dx + dy * dy)) * bilateral_range_weight(z - zc, settings.bilateral_depth_sigma);
            sum += wt * z;
            weight += wt;
        }
    }
    // The centre has weight 1, so `weight >= 1`.
    return sum / weight;
}

fn unproject(intrinsics: Intrinsics, u: f32, v: f32, z: f32) -> vec3<f32> {
    return vec3<f32>((u - intrinsics.cx) * z / intrinsics.fx, (v - intrinsics.cy) * z / intrinsics.fy, z);
}

fn same_surface(z: f32, z_neighbour: f32, lateral: f32, min_cosine: f32) -> bool {
    let c = clamp(min_cosine, MIN_FOOTPRINT_COSINE, 1.0);
    return abs(z_neighbour - z) * c <= lateral * sqrt(1.0 - c * c);
}

// Neighbours are (position, 1) when usable, 0 when not; returns (difference, 1) or 0.
fn axis_difference(p: vec3<f32>, before: vec4<f32>, after: vec4<f32>) -> vec4<f32> {
    if before.w != 0.0 && after.w != 0.0 {
        return vec4<f32>(after.xyz - before.xyz, 1.0);
    }
    if after.w != 0.0 {
        return vec4<f32>(after.xyz - p, 1.0);
    }
    if before.w != 0.0 {
        return vec4<f32>(p - before.xyz, 1.0);
    }
    return vec4<f32>(0.0);
}

// Zero when there is no normal.
fn grid_normal(p: vec3<f32>, left: vec4<f32>, right: vec4<f32>, up: vec4<f32>, down: vec4<f32>) -> vec3<f32> {
    let dx = axis_difference(p, left, right);
    let dy = axis_difference(p, up, down);
    if dx.w == 0.0 || dy.w == 0.0 {
        return vec3<f32>(0.0);
    }
    let n = cross(dx.xyz, dy.xyz);
    let len2 = dot(n, n);
    // Parallel (or vanishing) differences: sin^2 of their angle below 1e-12.
    if !(len2 > 1e-12 * dot(dx.xyz, dx.xyz) * dot(dy.xyz, dy.xyz)) {
        return vec3<f32>(0.0);
    }
    let unit = n / sqrt(len2);
    return select(unit, -unit, dot(unit, p) > 0.0);
}

fn footprint_area(intrinsics: Intrinsics, p: vec3<f32>, n: vec3<f32>, pixels: u32, min_cosine: f32) -> f32 {
    let d = length(p);
    let cos_alpha = p.z / d;
    let cos_view = -dot(n, p) / d;
    let front = (p.z / intrinsics.fx) * (p.z / intrinsics.fy) * f32(pixels);
    return front * cos_alpha / max(cos_view, max(min_cosine, MIN_FOOTPRINT_COSINE));
}

fn block_color(intrinsics: Intrinsics, block: vec4<u32>) -> vec3<f32> {
    var sum = vec3<f32>(0.0);
    for (var y = block.y; y < block.w; y++) {
        for (var x = block.x; x < block.z; x++) {
            sum += srgb_to_linear(unpack4x8unorm(color[y * intrinsics.width + x]).rgb);
        }
    }
    return sum / f32((block.z - block.x) * (block.w - block.y));
}

// (position, 1) of the usable neighbour cell `cell + offset`, else 0.
fn grid_neighbour(intrinsics: Intrinsics, settings: RgbdSettings, z: f32, cell: vec2<u32>, offset: vec2<i32>) -> vec4<f32> {
    let g = grid_size(intrinsics, settings);
    let n = vec2<i32>(cell) + offset;
    if n.x < 0 || n.y < 0 || n.x >= i32(g.x) || n.y >= i32(g.y) {
        return vec4<f32>(0.0);
    }
    let nu = vec2<u32>(n);
    let zn = grid_depth[nu.y * g.x + nu.x];
    if zn <= 0.0 {
        return vec4<f32>(0.0);
    }
    let here = vec2<f32>(cell_centre(cell_block(intrinsics, cell, settings)));
    let there = vec2<f32>(cell_centre(cell_block(intrinsics, nu, settings)));
    let lateral = z * (abs(there.x - here.x) / intrinsics.fx + abs(there.y - here.y) / intrinsics.fy);
    if !same_surface(z, zn, lateral, settings.min_cosine) {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(unproject(intrinsics, there.x, there.y, zn), 1.0);
}

fn grid_cell_val(intrinsics: Intrinsics, camera_to_world: mat4x4<f32>, settings: RgbdSettings, cell: vec2<u32>) -> CellVal {
    var out: CellVal;
    let g = grid_size(intrinsics, settings);
    let z = grid_depth[cell.y * g.x + cell.x];
    if z <= 0.0 {
        return out;
    }
    let block = cell_block(intrinsics, cell, settings);
    let c = vec2<f32>(cell_centre(block));
    let p = unproject(intrinsics, c.x, c.y, z);
    var n = grid_normal(
        p,
        grid_neighbour(intrinsics, settings, z, cell, vec2<i32>(-1, 0)),
        grid_neighbour(intrinsics, settings, z, cell, vec2<i32>(1, 0)),
        grid_neighbour(intrinsics, settings, z, cell, vec2<i32>(0, -1)),
        grid_neighbour(intrinsics, settings, z, cell, vec2<i32>(0, 1)),
    );
    if all(n == vec3<f32>(0.0)) {
        n = -p / length(p);
    }
    let pixels = (block.z - block.x) * (block.w - block.y);
    let area = footprint_area(intrinsics, p, n, pixels, settings.min_cosine);
    let radiance = settings.radiance_scale * block_color(intrinsics, block);
    out.val.position = (camera_to_world * vec4<f32>(p, 1.0)).xyz;
    out.val.area = area;
    out.val.normal = normalize((camera_to_world * vec4<f32>(n, 0.0)).xyz);
    out.val.flux = PI * radiance * area;
    out.valid = true;
    return out;
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn filter_grid(@builtin(global_invocation_id) id: vec3<u32>) {
    let g = grid_size(params.intrinsics, params.settings);
    if id.x >= g.x || id.y >= g.y {
        return;
    }
    let c = cell_centre(cell_block(params.intrinsics, id.xy, params.settings));
    grid_depth[id.y * g.x + id.x] = bilateral_depth(params.intrinsics, c.x, c.y, params.settings);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let g = grid_size(params.intrinsics, params.settings);
    if id.x >= g.x || id.y >= g.y {
        return;
    }
    let cell = grid_cell_val(params.intrinsics, params.camera_to_world, params.settings, id.xy);
    var val = cell.val;
    if !cell.valid {
        val.area = -1.0;
    }
    candidates[id.y * g.x + id.x] = val;
}
