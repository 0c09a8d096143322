// Gather at sparse points (DESIGN.md §4 step 1): every VAL's irradiance summed at every sparse
// point, with the luminance-weighted mean VAL position; the glossy entry point also sums the
// Phong-lobe-weighted irradiance toward the eye and its mean position. VALs stream through
// workgroup memory in tiles of TILE_SIZE. Rust twin: `reference::gather_point`.

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read> vals: array<Val>;
@group(0) @binding(2) var<storage, read> val_count: u32;
@group(0) @binding(3) var<storage, read_write> gathered_diffuse: array<Gathered>;
@group(0) @binding(4) var<storage, read_write> gathered_glossy: array<Gathered>;

var<workgroup> tile: array<Val, TILE_SIZE>;

struct Sums {
    e: vec3<f32>,
    g: vec3<f32>,
    ld: vec3<f32>,
    ld2: vec3<f32>,
    ls: vec3<f32>,
    wd: f32,
    ws: f32,
}

fn gather_tiles(index: u32, local: u32, glossy: bool) -> Sums {
    var s = Sums(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 0.0, 0.0);
    var p = SparsePoint(vec3<f32>(0.0), 0.0, vec3<f32>(0.0, 1.0, 0.0), 0.0);
    if index < frame.sparse_count {
        p = sparse_points[index];
    }
    let w_o = view_direction(p.position, p.normal, frame.eye);
    let count = min(val_count, arrayLength(&vals));
    for (var base = 0u; base < count; base += TILE_SIZE) {
        if base + local < count {
            tile[local] = vals[base + local];
        }
        workgroupBarrier();
        let n = min(TILE_SIZE, count - base);
        for (var j = 0u; j < n; j++) {
            let val = tile[j];
            let geo = val_geometry(p.position, p.normal, val.position, val.normal, val.area);
            let f = geo.weight * geo.cos_receiver;
            let e_j = val.flux * f;
            let y = luminance(val.flux) * f;
            s.e += e_j;
            let gd = y + GATHER_EPSILON;
            s.ld += gd * val.position;
            s.ld2 += gd * val.position * val.position;
            s.wd += gd;
            if glossy {
                let lobe = phong_lobe(dot(mirror(geo.direction, p.normal), w_o), p.exponent);
                s.g += e_j * lobe;
                let gs = y * lobe + GATHER_EPSILON;
                s.ls += gs * val.position;
                s.ws += gs;
            }
        }
        workgroupBarrier();
    }
    return s;
}

fn diffuse_result(s: Sums) -> Gathered {
    let w = max(s.wd, GATHER_EPSILON);
    return Gathered(s.e, 0.0, s.ld / w, 0.0, s.ld2 / w, 0.0);
}

@compute @workgroup_size(TILE_SIZE)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let s = gather_tiles(id.x, local, false);
    if id.x < frame.sparse_count {
        gathered_diffuse[id.x] = diffuse_result(s);
    }
}

@compute @workgroup_size(TILE_SIZE)
fn main_glossy(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let s = gather_tiles(id.x, local, true);
    if id.x < frame.sparse_count {
        gathered_diffuse[id.x] = diffuse_result(s);
        gathered_glossy[id.x] = Gathered(s.g, 0.0, s.ls / max(s.ws, GATHER_EPSILON), 0.0, vec3<f32>(0.0), 0.0);
    }
}
