// In-order append of a pass's candidate VALs (one slot per texel or grid cell; a slot whose
// `area` is negative holds none) to `vals` after the `val_count` already there. One workgroup
// (the pass's workgroup size, a power of two) walks the candidates in chunks, each invocation
// COMPACT_RUN consecutive ones, and a workgroup prefix sum gives every candidate its place: the VALs keep their slots' order
// whatever order the slots were written in. An atomic append instead orders them by the
// threads' timing, which changes from run to run, and with the order the float sums over
// VALs, the clusters' k-means seeds and the flux draw of the imperfect shadow maps.
// The count ends at min(count + appended, capacity), `arrayLength(&vals)` being the capacity
// (a count already past it stays), and nothing past the capacity is written. The includer
// binds `candidates: array<Val>`, `vals: array<Val>` and `val_count: atomic<u32>`. Rust twin:
// the cell order of `twin::rgbd::rgbd_vals`.

const COMPACT_THREADS: u32 = WORKGROUP_X * WORKGROUP_Y * WORKGROUP_Z;
const COMPACT_RUN: u32 = 4u;
// The slots one dispatch appends: `[COMPACT_BEGIN, COMPACT_BEGIN + COMPACT_SPAN)`, all by
// default. CPU adapters split the slots into several dispatches, one after the other, each
// under llvmpipe's loop limit (`gpu/lights/compact.rs`).
override COMPACT_BEGIN: u32 = 0u;
override COMPACT_SPAN: u32 = 0xffffffffu;

var<workgroup> compact_scan: array<u32, COMPACT_THREADS>;

fn is_candidate(c: u32, n: u32) -> bool {
    return c < n && !(candidates[c].area < 0.0);
}

@compute @workgroup_size(WORKGROUP_X, WORKGROUP_Y, WORKGROUP_Z)
fn compact(@builtin(local_invocation_index) t: u32) {
    let n = min(arrayLength(&candidates), COMPACT_BEGIN + min(COMPACT_SPAN, 0xffffffffu - COMPACT_BEGIN));
    let capacity = arrayLength(&vals);
    let count = atomicLoad(&val_count);
    var base = count;
    for (var start = COMPACT_BEGIN; start < n; start += COMPACT_THREADS * COMPACT_RUN) {
        let first = start + t * COMPACT_RUN;
        var mine = 0u;
        for (var i = 0u; i < COMPACT_RUN; i++) {
            mine += u32(is_candidate(first + i, n));
        }
        compact_scan[t] = mine;
        workgroupBarrier();
        // Inclusive prefix sum over the invocations (Hillis-Steele).
        for (var offset = 1u; offset < COMPACT_THREADS; offset *= 2u) {
            var add = 0u;
            if t >= offset {
                add = compact_scan[t - offset];
            }
            workgroupBarrier();
            compact_scan[t] += add;
            workgroupBarrier();
        }
        var slot = base + compact_scan[t] - mine;
        for (var i = 0u; i < COMPACT_RUN; i++) {
            if is_candidate(first + i, n) {
                if slot < capacity {
                    vals[slot] = candidates[first + i];
                }
                slot++;
            }
        }
        base += compact_scan[COMPACT_THREADS - 1u];
        workgroupBarrier();
    }
    if t == 0u {
        atomicStore(&val_count, max(count, min(base, capacity)));
    }
}
