//! The RGB-D VAL pass (`gpu::lights::rgbd`) against its CPU twin (`twin::rgbd`, docs/design.md §2
//! "RGB-D frames") on a small synthetic frame, and its append contract: after what is already
//! in the VAL buffer, never past the capacity.
//!
//! Each GPU VAL is matched to its grid cell: projected back into the camera, it lands on its
//! cell's centre pixel (to ~1e-4 px), and is compared with the twin's VAL of that cell; the
//! cells come in the twin's (row-major) order.
//!
//! Tolerances: both sides run the same f32 operations except `exp` (filter weights), `pow`
//! (sRGB), `sqrt` and possibly fused multiply-adds, which lavapipe evaluates within a few ulp.
//! The filtered depths therefore agree to ~1e-6 relative, and so do positions (1e-5 m allowed,
//! on a scene ~3 m across), areas and fluxes (1e-4 relative allowed). Normals come from
//! differences of neighbouring positions ~0.1 m apart, which divide those errors by the spacing:
//! 1e-4 allowed. The frame keeps every classification (valid depth, same surface) far from its
//! threshold, so both sides make the same VALs.

use super::{gpu, load_scene};
use glam::{Affine3A, DAffine3, DQuat, DVec3, UVec2, Vec3};
use relume::gpu::Gpu;
use relume::gpu::lights::rgbd::RgbdVals;
use relume::gpu::raw::RawVal;
use relume::gpu::scene::{FlatScene, GpuScene};
use relume::gpu::technique::Vals;
use relume::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use relume::twin::Val;
use relume::twin::rgbd::{cell_block, cell_centre, rgbd_vals_by_cell};
use std::collections::HashMap;

const SMALL: Intrinsics = Intrinsics { width: 64, height: 48, fx: 60.0, fy: 60.0, cx: 31.5, cy: 23.5 };

fn pose() -> DAffine3 {
    DAffine3::from_rotation_translation(
        DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 0.7),
        DVec3::new(-0.4, 1.2, 2.5),
    )
}

/// `frame`'s pose in f32, as the GPU pass takes it (the user's origin is the scene's here).
fn local(frame: &RgbdFrame) -> Affine3A {
    relume::scene::local_pose(DVec3::ZERO, &frame.camera_to_world)
}

/// A sloped wall ~2.2 m away, a box at 1.2 m in front of it (a 1 m depth step), a hole of no
/// depth in one corner, scattered 0 / NaN / negative / too-far / too-near pixels, a colour
/// gradient and a non-identity pose.
fn synthetic_frame() -> RgbdFrame {
    let (w, h) = (SMALL.width, SMALL.height);
    let mut depth = Vec::new();
    let mut color = Vec::new();
    for v in 0..h {
        for u in 0..w {
            let (x, y) = (u as f32, v as f32);
            let mut z = if (20..36).contains(&u) && (14..30).contains(&v) {
                1.2 + 0.002 * x
            } else {
                2.0 + 0.01 * x - 0.005 * y
            };
            if u >= 56 && v < 8 {
                z = 0.0;
            }
            z = match (u * 7 + v * 13) % 41 {
                0 => 0.0,
                1 => f32::NAN,
                2 => -1.0,
                3 => 50.0,
                4 => 0.01,
                _ => z,
            };
            depth.push(z);
            color.push([(u * 4) as u8, (v * 5) as u8, (128 + u + v) as u8]);
        }
    }
    RgbdFrame { timestamp: 0.0, intrinsics: SMALL, color, depth, camera_to_world: pose() }
}

struct Fixture {
    gpu: Gpu,
    scene: GpuScene,
}

fn fixture() -> Fixture {
    let gpu = gpu();
    let scene = GpuScene::new(&gpu, FlatScene::from_scene(&load_scene("cornell_bunny_small"))).unwrap();
    Fixture { gpu, scene }
}

/// Run the pass on `frame` into a VAL buffer of `buffer_len` elements holding `initial` (the
/// rest filled with `SENTINEL`) with `val_count = initial.len()`; returns the final count and
/// the whole buffer.
fn run(
    f: &Fixture,
    pass: &RgbdVals,
    frame: &RgbdFrame,
    initial: &[RawVal],
    buffer_len: usize,
    capacity: u32,
) -> (u32, Vec<RawVal>) {
    let gpu = &f.gpu;
    let mut contents = vec![SENTINEL; buffer_len];
    contents[..initial.len()].copy_from_slice(initial);
    let vals = gpu.storage_buffer("test.vals", &contents, wgpu::BufferUsages::COPY_SRC).unwrap();
    let count = gpu.storage_buffer("test.val_count", &[initial.len() as u32], wgpu::BufferUsages::COPY_SRC).unwrap();
    pass.upload(gpu, frame, &local(frame)).unwrap();
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.rgbd") });
    let vals = Vals { buffer: vals, count, capacity };
    pass.append(gpu, &mut encoder, &f.scene, &vals, None);
    gpu.submit_and_wait(encoder).unwrap();
    (gpu.read_buffer::<u32>(&vals.count, 1).unwrap()[0], gpu.read_buffer::<RawVal>(&vals.buffer, buffer_len).unwrap())
}

const SENTINEL: RawVal =
    RawVal { position: [-7.0; 3], area: -7.0, normal: [-7.0; 3], _pad0: -7.0, flux: [-7.0; 3], _pad1: -7.0 };

/// The grid cell whose centre pixel a VAL's position projects to.
fn cell_of(val: &Val, frame: &RgbdFrame, settings: &RgbdSettings) -> UVec2 {
    let p = local(frame).inverse().transform_point3(val.position);
    let i = &frame.intrinsics;
    let (u, v) = ((p.x / p.z * i.fx + i.cx).round(), (p.y / p.z * i.fy + i.cy).round());
    let step = settings.grid_step.max(1);
    let cell = UVec2::new(u as u32 / step, v as u32 / step);
    assert_eq!(cell_centre(cell_block(i, cell, settings)), UVec2::new(u as u32, v as u32), "{val:?}");
    cell
}

/// Largest errors seen: position (m), normal, relative area, relative flux.
#[derive(Debug, Default)]
struct Errors {
    position: f32,
    normal: f32,
    area: f32,
    flux: f32,
}

/// Every GPU VAL matches the twin's VAL of its cell, each cell at most once; returns the
/// cells matched and the largest errors.
fn match_twin(gpu_vals: &[RawVal], frame: &RgbdFrame, settings: &RgbdSettings) -> (Vec<UVec2>, Errors) {
    let twin: HashMap<UVec2, Val> = rgbd_vals_by_cell(frame, settings).into_iter().collect();
    let mut cells = Vec::new();
    let mut e = Errors::default();
    for raw in gpu_vals {
        let g = Val::from(raw);
        let cell = cell_of(&g, frame, settings);
        let c = twin.get(&cell).unwrap_or_else(|| panic!("GPU VAL {g:?} in cell {cell}, which the twin leaves empty"));
        assert!(!cells.contains(&cell), "cell {cell} appended twice");
        cells.push(cell);
        let rel = |a: Vec3, b: Vec3| (a - b).abs().max_element() / b.abs().max_element().max(1e-30);
        e.position = e.position.max((g.position - c.position).abs().max_element());
        e.normal = e.normal.max((g.normal - c.normal).abs().max_element());
        e.area = e.area.max((g.area - c.area).abs() / c.area);
        e.flux = e.flux.max(rel(g.flux, c.flux));
        assert!((g.position - c.position).abs().max_element() <= 1e-5, "cell {cell}: position {g:?} vs {c:?}");
        assert!((g.normal - c.normal).abs().max_element() <= 1e-4, "cell {cell}: normal {g:?} vs {c:?}");
        assert!((g.area - c.area).abs() <= 1e-4 * c.area, "cell {cell}: area {g:?} vs {c:?}");
        assert!(rel(g.flux, c.flux) <= 1e-4, "cell {cell}: flux {g:?} vs {c:?}");
    }
    (cells, e)
}

#[test]
fn rgbd_vals_match_the_cpu_twin() {
    let f = fixture();
    let frame = synthetic_frame();
    // Step 4 tiles the frame; step 3 leaves partial cells on the right edge.
    for step in [4, 3] {
        let settings = RgbdSettings { grid_step: step, ..Default::default() };
        let pass = RgbdVals::new(&f.gpu, &f.scene, SMALL, &settings).unwrap();
        let twin = rgbd_vals_by_cell(&frame, &settings);
        assert!(twin.len() > 100 && twin.len() < pass.max_vals() as usize, "step {step}: {} VALs", twin.len());
        let capacity = pass.max_vals();
        let (count, out) = run(&f, &pass, &frame, &[], capacity as usize, capacity);
        assert_eq!(count as usize, twin.len(), "step {step}");
        let (cells, errors) = match_twin(&out[..count as usize], &frame, &settings);
        assert_eq!(cells.len(), twin.len());
        // In the twin's (row-major) cell order, so a frame's VALs are the same from run to run.
        let twin_cells: Vec<UVec2> = twin.iter().map(|(cell, _)| *cell).collect();
        assert_eq!(cells, twin_cells, "step {step}: the GPU's VALs are not in the cells' order");
        eprintln!("rgbd twin, step {step}, {} VALs, largest errors: {errors:?}", cells.len());
    }
}

#[test]
fn rgbd_frame_without_depth_appends_nothing() {
    let f = fixture();
    let settings = RgbdSettings { grid_step: 4, ..Default::default() };
    let pass = RgbdVals::new(&f.gpu, &f.scene, SMALL, &settings).unwrap();
    let mut frame = synthetic_frame();
    for bad in [0.0, f32::NAN, -3.0, 1e3] {
        frame.depth.iter_mut().for_each(|z| *z = bad);
        let (count, out) = run(&f, &pass, &frame, &[], 16, 16);
        assert_eq!(count, 0, "depth {bad}");
        assert!(out.iter().all(|v| *v == SENTINEL));
    }
}

#[test]
fn rgbd_appends_after_existing_vals_within_capacity() {
    let f = fixture();
    let settings = RgbdSettings { grid_step: 4, ..Default::default() };
    let pass = RgbdVals::new(&f.gpu, &f.scene, SMALL, &settings).unwrap();
    let frame = synthetic_frame();
    let made = rgbd_vals_by_cell(&frame, &settings).len();
    let existing: Vec<RawVal> = (0..5)
        .map(|i| RawVal { position: [i as f32, 1.0, 2.0], area: 0.5, flux: [1.0, 2.0, 3.0], ..Default::default() })
        .collect();
    let k = existing.len();

    // Room for everything: the spot-light VALs stay, the frame's follow.
    let len = k + pass.max_vals() as usize;
    let (count, out) = run(&f, &pass, &frame, &existing, len, len as u32);
    assert_eq!(count as usize, k + made);
    assert_eq!(&out[..k], &existing[..]);
    match_twin(&out[k..k + made], &frame, &settings);
    assert!(out[k + made..].iter().all(|v| *v == SENTINEL));

    // Room for 10 more: exactly 10 are written (the first 10 cells'), the counter stops at the capacity and nothing
    // past it is touched, even though the buffer is longer.
    let capacity = k + 10;
    let (count, out) = run(&f, &pass, &frame, &existing, len, capacity as u32);
    assert_eq!(count as usize, capacity);
    assert_eq!(&out[..k], &existing[..]);
    let (cells, _) = match_twin(&out[k..capacity], &frame, &settings);
    let first: Vec<UVec2> = rgbd_vals_by_cell(&frame, &settings).iter().take(10).map(|(cell, _)| *cell).collect();
    assert_eq!(cells, first, "the first 10 cells in order");
    assert!(out[capacity..].iter().all(|v| *v == SENTINEL));

    // A capacity past the buffer's end is the buffer's end.
    let (count, _) = run(&f, &pass, &frame, &existing, k + 3, u32::MAX);
    assert_eq!(count as usize, k + 3);

    // Already full (or over): nothing is written and the count stays.
    for capacity in [k as u32, 3, 0] {
        let (count, out) = run(&f, &pass, &frame, &existing, len, capacity);
        assert_eq!(count as usize, k, "capacity {capacity}");
        assert_eq!(&out[..k], &existing[..]);
        assert!(out[k..].iter().all(|v| *v == SENTINEL), "capacity {capacity}");
    }
}

#[test]
fn rgbd_upload_refuses_a_frame_of_another_size() {
    let f = fixture();
    let pass = RgbdVals::new(&f.gpu, &f.scene, SMALL, &RgbdSettings::default()).unwrap();
    let mut frame = synthetic_frame();
    frame.intrinsics.width = 32;
    assert!(pass.upload(&f.gpu, &frame, &local(&frame)).is_err());
    let mut frame = synthetic_frame();
    frame.depth.pop();
    assert!(pass.upload(&f.gpu, &frame, &local(&frame)).is_err());
}
