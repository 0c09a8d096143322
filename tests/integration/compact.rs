//! The in-order append of a VAL pass's candidates (`gpu::lights::compact`,
//! `compact_vals.wgsl`): every candidate slot that holds a VAL (area not negative) is appended
//! after the VALs already in the buffer, in the slots' order, never past the capacity; split
//! into several dispatches (as on CPU adapters, whose loop limit a large frame would pass) it
//! appends the same.

use super::{gpu, load_scene};
use relume::gpu::lights::compact::{self, Compact};
use relume::gpu::pass::{Entry, PassDesc, buffer, module_from_source, read_write};
use relume::gpu::raw::RawVal;
use relume::gpu::scene::{FlatScene, GpuScene};

/// A pass that is only the append: the three bindings `compact_vals.wgsl` expects.
const PASS: PassDesc = PassDesc {
    label: "compact_test",
    bindings: &[read_write("vals"), read_write("val_count"), read_write("candidates")],
    entries: &[Entry::first("compact", 3)],
    workgroup: [64, 1, 1],
    default_source: |textured| PASS.source(&body(), textured),
};

fn body() -> String {
    "@group(0) @binding(0) var<storage, read_write> vals: array<Val>;\n\
     @group(0) @binding(1) var<storage, read_write> val_count: atomic<u32>;\n\
     @group(0) @binding(2) var<storage, read_write> candidates: array<Val>;\n"
        .to_owned()
        + compact::WGSL
}

/// Candidate `i`: a VAL (its position x = i) for two slots in three, none (area -1) for the
/// third; one VAL of area 0 (kept: only a negative area means none).
fn candidates(n: u32) -> Vec<RawVal> {
    (0..n)
        .map(|i| {
            let area = match i % 3 {
                2 => -1.0,
                _ if i == 7 => 0.0,
                _ => 1.0,
            };
            RawVal { position: [i as f32, 0.0, 0.0], area, ..Default::default() }
        })
        .collect()
}

/// Append `slots` candidates after `before` VALs into a buffer of `capacity`, `span` slots per
/// dispatch; returns the count and the buffer.
fn append(slots: u32, before: u32, capacity: u32, span: u32) -> (u32, Vec<RawVal>, usize) {
    let gpu = gpu();
    let scene = GpuScene::new(&gpu, FlatScene::from_scene(&load_scene("cornell_bunny_small"))).unwrap();
    let module = module_from_source(&gpu, PASS.label, PASS.source(&body(), scene.textured())).unwrap();
    let compact = Compact::with_span(&gpu, &scene, &PASS, &module, slots, span).unwrap();
    gpu.queue.write_buffer(&compact.candidates, 0, bytemuck::cast_slice(&candidates(slots)));
    let sentinel = RawVal { area: -7.0, ..Default::default() };
    let vals =
        gpu.storage_buffer("test.vals", &vec![sentinel; capacity as usize], wgpu::BufferUsages::COPY_SRC).unwrap();
    let count = gpu.storage_buffer("test.val_count", &[before], wgpu::BufferUsages::COPY_SRC).unwrap();
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    compact.record_after(&gpu, &mut encoder, &scene, &[], (buffer("vals", &vals), &count), None);
    gpu.submit_and_wait(encoder).unwrap();
    let out = gpu.read_buffer::<RawVal>(&vals, capacity as usize).unwrap();
    (gpu.read_buffer::<u32>(&count, 1).unwrap()[0], out, compact.parts())
}

/// The slots' VALs in order, as the twin of the append.
fn expected(slots: u32) -> Vec<RawVal> {
    // No candidate area is NaN here: "not negative" is ">= 0".
    candidates(slots).into_iter().filter(|v| v.area >= 0.0).collect()
}

#[test]
fn candidates_are_appended_in_their_slots_order_in_one_or_many_dispatches() {
    let slots = 5000;
    let want = expected(slots);
    for span in [u32::MAX, 1024, 1000, 777] {
        let (count, out, parts) = append(slots, 3, 3 + want.len() as u32 + 10, span);
        assert_eq!(parts, if span == u32::MAX { 1 } else { slots.div_ceil(span) as usize }, "span {span}");
        assert_eq!(count as usize, 3 + want.len(), "span {span}");
        assert!(out[..3].iter().all(|v| v.area == -7.0), "span {span}: the VALs already there were overwritten");
        assert_eq!(&out[3..3 + want.len()], &want[..], "span {span}");
        assert!(out[3 + want.len()..].iter().all(|v| v.area == -7.0), "span {span}: written past the count");
    }
}

#[test]
fn the_append_stops_at_the_capacity_and_a_count_past_it_stays() {
    let slots = 3000;
    let want = expected(slots);
    for span in [u32::MAX, 700] {
        // Room for 100 after the 5 already there: the first 100, and the count at the capacity.
        let (count, out, _) = append(slots, 5, 105, span);
        assert_eq!(count, 105, "span {span}");
        assert_eq!(&out[5..], &want[..100], "span {span}");
        // Already over the capacity: nothing written, the count as it was.
        let (count, out, _) = append(slots, 200, 105, span);
        assert_eq!(count, 200, "span {span}");
        assert!(out.iter().all(|v| v.area == -7.0), "span {span}");
    }
}
