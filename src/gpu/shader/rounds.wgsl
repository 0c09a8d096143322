// A pass run in rounds under llvmpipe's loop limit (the exact reference, the differential
// passes; the host's side is `gpu::rounds_done`): each invocation runs a loop budget per round
// and keeps in `progress` where it resumes, ROUND_DONE once finished (zeroed before the first
// round), and the host dispatches again until `status` counts none left.
@group(0) @binding(6) var<storage, read_write> progress: array<u32>;
// [invocations not finished after this round, invocations that made no progress in it]
@group(0) @binding(7) var<storage, read_write> status: array<atomic<u32>, 2>;

const ROUND_DONE: u32 = 0xffffffffu;

// The end of an invocation's round: `progress[slot]` becomes `next` while it is below `count`
// (the invocation counted as unfinished, and as stuck when it made no progress), else ROUND_DONE.
fn end_round(slot: u32, next: u32, count: u32, stuck: bool) {
    if next < count {
        progress[slot] = next;
        atomicAdd(&status[0], 1u);
        if stuck {
            atomicAdd(&status[1], 1u);
        }
    } else {
        progress[slot] = ROUND_DONE;
    }
}
