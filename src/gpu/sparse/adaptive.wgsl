// Adaptive sparse points (`settings.sparse.adaptive`, beyond the paper). The scene's last
// CANDIDATES sparse points are candidates, linked to their NEIGHBOURS nearest points among the
// BASE_POINTS gathered every frame. After the gather at those, every frame:
// - `score`: each candidate's score, the weighted mean absolute deviation of its neighbours'
//   gathered light (HYSTERESIS times higher if it was chosen the frame before), into a
//   histogram of SCORE_BINS bins of 1/BINS_PER_OCTAVE octave;
// - `threshold`: the lowest bin whose candidates fit the BUDGET from the top bin down;
// - `compact`: every candidate at or above it is chosen and listed for the gather
//   (`gather.wgsl` with `receiver_point` reading the list: the `adaptive_gather` stage).
// The vertices then weigh the chosen ones among their points (`adaptive_candidates.wgsl`).
// Rust twins: `twin::adaptive::{candidate_score, score_bin, threshold_bin, select}`. The
// interpolation weights (`interpolation_weights.wgsl`) and the constants are prepended
// (`adaptive::body`).

@group(0) @binding(0) var<storage, read> sparse_points: array<SparsePoint>;
@group(0) @binding(1) var<storage, read> candidate_neighbours: array<array<u32, NEIGHBOURS>>;
@group(0) @binding(2) var<storage, read_write> scores: array<f32>;
@group(0) @binding(3) var<storage, read_write> histogram: array<atomic<u32>>;
// Per candidate, 1 when chosen: the frame before's until `compact` writes this frame's.
@group(0) @binding(4) var<storage, read_write> chosen: array<u32>;
@group(0) @binding(5) var<storage, read_write> threshold: u32;
@group(0) @binding(6) var<storage, read_write> receiver_list: array<u32>;
@group(0) @binding(7) var<storage, read_write> receiver_count: atomic<u32>;
@group(0) @binding(8) var<storage, read> gathered_diffuse: array<Gathered>;
@group(0) @binding(9) var<storage, read> gathered_glossy: array<Gathered>;

const NO_BIN: u32 = 0xffffffffu;

// `twin::adaptive::score_bin`.
fn score_bin(score: f32) -> u32 {
    if !(score > 0.0) || score > 3.4028235e38 {
        return NO_BIN;
    }
    let bin = floor((log2(score) - SCORE_LOG2_MIN) * BINS_PER_OCTAVE);
    return u32(clamp(bin, 0.0, f32(SCORE_BINS - 1u)));
}

// `twin::adaptive::scored_light`. Each entry point reads only the lobes it binds, so the
// glossy sum is added by the glossy one's caller.
fn diffuse_light(i: u32) -> f32 {
    return luminance(gathered_diffuse[i].irradiance);
}

fn glossy_light(i: u32) -> f32 {
    return luminance(gathered_diffuse[i].irradiance) + luminance(gathered_glossy[i].irradiance);
}

fn candidate_neighbourhood(c: u32) -> Neighbourhood {
    let p = sparse_points[BASE_POINTS + c];
    return neighbourhood_at(p.position, p.normal, candidate_neighbours[c]);
}

// `twin::adaptive::candidate_score` of the neighbourhood `nb` whose lights are `y`.
fn score_candidate(c: u32, nb: Neighbourhood, y: array<f32, NEIGHBOURS>) {
    var score = 0.0;
    if nb.total > 0.0 {
        var mean = 0.0;
        for (var j = 0u; j < nb.count; j++) {
            mean += nb.weights[j] * y[j];
        }
        mean /= nb.total;
        var spread = 0.0;
        for (var j = 0u; j < nb.count; j++) {
            spread += nb.weights[j] * abs(y[j] - mean);
        }
        score = spread / nb.total;
        if chosen[c] != 0u {
            score *= HYSTERESIS;
        }
    }
    scores[c] = score;
    let bin = score_bin(score);
    if bin != NO_BIN {
        atomicAdd(&histogram[bin], 1u);
    }
}

@compute @workgroup_size(WORKGROUP_X)
fn score(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= CANDIDATES {
        return;
    }
    let nb = candidate_neighbourhood(id.x);
    var y: array<f32, NEIGHBOURS>;
    for (var j = 0u; j < nb.count; j++) {
        y[j] = diffuse_light(nb.ids[j]);
    }
    score_candidate(id.x, nb, y);
}

@compute @workgroup_size(WORKGROUP_X)
fn score_glossy(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= CANDIDATES {
        return;
    }
    let nb = candidate_neighbourhood(id.x);
    var y: array<f32, NEIGHBOURS>;
    for (var j = 0u; j < nb.count; j++) {
        y[j] = glossy_light(nb.ids[j]);
    }
    score_candidate(id.x, nb, y);
}

// `twin::adaptive::threshold_bin`: one invocation walks the bins from the top.
@compute @workgroup_size(WORKGROUP_X)
fn choose_threshold(@builtin(local_invocation_index) local: u32) {
    if local != 0u {
        return;
    }
    var above = 0u;
    var t = 0u;
    for (var b = SCORE_BINS; b > 0u; b--) {
        above += atomicLoad(&histogram[b - 1u]);
        if above > BUDGET {
            t = b;
            break;
        }
    }
    threshold = t;
}

@compute @workgroup_size(WORKGROUP_X)
fn compact(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= CANDIDATES {
        return;
    }
    let bin = score_bin(scores[id.x]);
    let take = bin != NO_BIN && bin >= threshold;
    chosen[id.x] = u32(take);
    if take {
        let slot = atomicAdd(&receiver_count, 1u);
        if slot < arrayLength(&receiver_list) {
            receiver_list[slot] = BASE_POINTS + id.x;
        }
    }
}
