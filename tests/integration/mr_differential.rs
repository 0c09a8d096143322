//! Differential rendering onto real surfaces: the GPU passes (exact and fast) against their CPU
//! twins, a real plate under a virtual box against the exact reference rendered with and without
//! the box, and the fast pass against the exact one on the bundled TUM recording and on a
//! synthetic closed-loop recording.

use super::gpu;
use glam::Vec3;
use relume::gpu::differential::{Differential, DifferentialDevice, Receiver, Sums, scene_occluders, twin};
use relume::gpu::scene::{FlatScene, GpuScene};
use relume::mr::differential::relit_radiance;
use relume::scene::{Material, Scene};
use relume::twin::Val;
use relume::twin::bvh::{Occluders, TraceBvh};
use relume::twin::exact_cpu::{self, ExactScene, Receivers, ValSampling};

/// A closed cube from `lo` to `hi` as OBJ text (outward faces).
fn cube_obj(lo: Vec3, hi: Vec3) -> String {
    let mut obj = String::new();
    for i in 0..8 {
        let p = Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    // Corner index = 1 + x + 2y + 4z.
    obj += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
    obj
}

/// The virtual box: 0.2 m wide, floating 2 cm above the plate (z = 0), 0.2 m tall.
fn box_scene(albedo: f32) -> Scene {
    let obj = cube_obj(Vec3::new(-0.1, -0.1, 0.02), Vec3::new(0.1, 0.1, 0.22));
    let json = serde_json::json!({
        "meshes": [{ "obj": "box.obj", "obj_text": obj, "sparse_points": 96,
                     "material": { "diffuse": [albedo, albedo, albedo] } }],
        "camera": { "position": [0, -2, 1], "target": [0, 0, 0], "fov_y_deg": 45, "width": 64, "height": 48 }
    });
    Scene::from_json_str(&json.to_string(), std::path::Path::new(".")).expect("box scene")
}

/// An 8 x 8 grid of downward VALs 1 m above the plate, over [-0.5, 0.5]².
fn lights_above() -> Vec<Val> {
    (0..64)
        .map(|i| Val {
            position: Vec3::new(-0.5 + (i % 8) as f32 / 7.0, -0.5 + (i / 8) as f32 / 7.0, 1.0),
            normal: -Vec3::Z,
            area: 0.01,
            flux: Vec3::new(1.0, 0.8, 0.6),
        })
        .collect()
}

/// Receivers on the plate z = 0 facing up: a 33 x 33 grid over [-0.8, 0.8]².
fn plate_receivers() -> Vec<Receiver> {
    (0..33 * 33)
        .map(|i| Receiver {
            position: Vec3::new(-0.8 + 0.05 * (i % 33) as f32, -0.8 + 0.05 * (i / 33) as f32, 0.0),
            normal: Vec3::Z,
        })
        .collect()
}

/// The lamps above and the box's re-emitters lit (`vals`, the first `real_count` real) and the
/// plate's receivers, in the scene's frame: the pass works relative to the scene's floating
/// origin (the box's centre), so the real lights and receivers, given in world coordinates, are
/// moved into it.
fn lit_plate(scene: &Scene) -> (Vec<Val>, usize, Vec<Receiver>) {
    let origin = scene.origin.as_vec3();
    let mut vals: Vec<Val> = lights_above().into_iter().map(|v| Val { position: v.position - origin, ..v }).collect();
    let real_count = vals.len();
    let emitters = relume::mr::differential::emitters(scene);
    let lit: Vec<Vec3> = emitters.iter().map(|e| Vec3::splat(5.0) * (0.5 + 0.5 * e.normal.z.abs())).collect();
    vals.extend(relume::mr::differential::emitter_vals(&emitters, &lit));
    let receivers = plate_receivers().into_iter().map(|r| Receiver { position: r.position - origin, ..r }).collect();
    (vals, real_count, receivers)
}

fn gpu_box(gpu: &relume::gpu::Gpu, albedo: f32) -> (Scene, GpuScene) {
    let scene = box_scene(albedo);
    let flat = FlatScene::from_scene(&scene);
    let gpu_scene = GpuScene::new(gpu, flat).expect("upload");
    (scene, gpu_scene)
}

/// The GPU pass and its twin agree at every receiver, for real VALs (blocked light) and for the
/// box's own sparse points re-emitting (added light): both cast the same shadow rays with the
/// same arithmetic (`twin::bvh::Bvh::occluded` is the GPU traversal's twin), so they differ by
/// the order of float sums only: 1e-4 of the receiver's total plus 1e-6 W/m² (one flipped ray
/// toward a VAL of these fluxes would move a sum by over 1e-3 of it).
///
/// The CPU backend walks another tree (obvhs's CWBVH) with the same triangle test. It is held
/// to the sums with every ray decided by testing every triangle of the box, at all but 2 of the
/// 1,089 receivers: the two at the middle of the box's foot (x or y = 0, on a side face's
/// plane), whose rays start on the box's surface, where a hit lies at t = 0 to rounding and
/// the node tests round too: each tree leaves out some triangles that block. Blocked light
/// there: 0.73 W/m² through the GPU layout's tree, 0.82 through the CWBVH, 0.92 through every
/// triangle. A tree only ever tests fewer triangles, so there the CPU backend must block no more
/// than every triangle does.
#[test]
fn mr_differential_gpu_matches_twin() {
    let gpu = gpu();
    let (scene, gpu_scene) = gpu_box(&gpu, 0.7);
    let (vals, real_count, receivers) = lit_plate(&scene);
    let occluders = scene_occluders(&gpu_scene);
    let every_triangle = |origin: Vec3, targets: &[Vec3]| {
        targets.iter().enumerate().fold(0u32, |mask, (j, &target)| {
            let blocked = occluders.triangles.iter().any(|t| {
                let [a, b, c] = t.map(|i| occluders.positions[i as usize]);
                relume::twin::bvh::ray_triangle(origin, target - origin, a, b, c).is_some_and(|s| s > 0.0 && s < 1.0)
            });
            mask | u32::from(blocked) << j
        })
    };
    for device in [DifferentialDevice::Gpu, DifferentialDevice::Cpu] {
        let mut pass = Differential::on(&gpu, &gpu_scene, device).unwrap();
        assert_eq!(pass.device(), device);
        let (light, rounds) = pass.run(&gpu, &gpu_scene, &receivers, Sums::Exact { vals: &vals, real_count }).unwrap();
        let (mut blocked, mut added, mut skipping) = (0, 0, 0);
        for (r, got) in receivers.iter().zip(&light) {
            let want = match device {
                DifferentialDevice::Cpu => twin::receiver_light_with(r, &vals, real_count, every_triangle),
                _ => twin::receiver_light(r, &vals, real_count, &occluders),
            };
            let scale = (want.unoccluded + want.added).max_element();
            let tol = 1e-4 * scale + 1e-6;
            for (g, w, what) in [
                (got.unoccluded, want.unoccluded, "unoccluded"),
                (got.blocked, want.blocked, "blocked"),
                (got.added, want.added, "added"),
            ] {
                let off = (g - w).abs().max_element() > tol;
                if off && device == DifferentialDevice::Cpu && what == "blocked" && g.cmple(w + tol).all() {
                    eprintln!("Cpu: blocked {g} at {}, every triangle {w}", r.position);
                    skipping += 1;
                    continue;
                }
                assert!(!off, "{device:?} {what} at {}: {g} vs {w}", r.position);
            }
            blocked += usize::from(want.blocked.x > 0.0);
            added += usize::from(want.added.x > 0.0);
        }
        eprintln!("{device:?}: {} receivers, {rounds} rounds: {blocked} shadowed, {added} lit", receivers.len());
        assert!(blocked > 50 && added > 50, "the test must exercise both sums: {blocked} shadowed, {added} lit");
        assert!(skipping <= 2, "{device:?}: {skipping} receivers where the tree skips a blocker");
    }
}

/// The fast kernel (`fast.wgsl`) and its twin agree at every receiver, on the GPU and on the
/// CPU backend, with the VALs grouped as the fast pass groups them: lamps in groups of 4 (so
/// that the plate's receivers sum some groups as one and open others) and the box's re-emitters
/// in groups of 8; every ray cast, and the faint members on their group's shared ray. The
/// kernel decides a group's reach and cone with the GPU's `length` and `sqrt`, which may round
/// a receiver exactly at a threshold the other way: the sums then differ by the aggregate's
/// error, under 5 %; at most 1 % of the receivers may.
#[test]
fn mr_differential_fast_gpu_matches_twin() {
    use relume::gpu::differential::groups::group_vals;
    use relume::gpu::differential::twin::ContentSphere;
    let gpu = gpu();
    let (scene, gpu_scene) = gpu_box(&gpu, 0.7);
    let (vals, real_count, receivers) = lit_plate(&scene);
    let occluders = scene_occluders(&gpu_scene);
    let bounds = relume::mr::differential::bounds(occluders.positions.iter().copied());
    let content = ContentSphere::around(bounds);
    let mut grouped = group_vals(&vals[..real_count], real_count, (4, 4), relume::gpu::differential::groups::REACH);
    let emitter_groups = group_vals(&vals[real_count..], 0, (8, 8), relume::gpu::differential::groups::REACH);
    let shift = grouped.vals.len() as u32;
    grouped.vals.extend(&emitter_groups.vals);
    grouped.groups.extend(emitter_groups.groups.iter().map(|g| relume::gpu::differential::groups::ValGroup {
        first: g.first + shift,
        representative: g.representative + shift,
        ..*g
    }));
    let twins = |share| -> Vec<_> {
        receivers.iter().map(|r| twin::receiver_light_fast(r, &grouped, &content, share, &occluders)).collect()
    };
    // Every ray cast, then the faint members (a share of 2 % of the estimated irradiance: a
    // lamp's average share is 1/64) on their group's shared ray.
    let (all_rays, shared) = (twins(0.0), twins(0.02));
    let (mut summed, mut blocked) = (0, 0);
    for (r, fast) in receivers.iter().zip(&all_rays) {
        let exact = twin::receiver_light(r, &vals, real_count, &occluders);
        let tol = 1e-4 * exact.unoccluded.max_element() + 1e-6;
        summed += usize::from((fast.unoccluded - exact.unoccluded).abs().max_element() > tol);
        blocked += usize::from(exact.blocked.x > 0.0);
    }
    let differ = |a: &relume::gpu::differential::ReceiverLight, b: &relume::gpu::differential::ReceiverLight| {
        (a.blocked - b.blocked).abs().max_element() + (a.added - b.added).abs().max_element() > 0.0
    };
    let by_shared = all_rays.iter().zip(&shared).filter(|(a, b)| differ(a, b)).count();
    eprintln!(
        "{} receivers: {summed} sum some lamp group as one, {blocked} shadowed, {by_shared} changed by shared rays",
        receivers.len()
    );
    assert!(summed > 100 && blocked > 50, "the test must exercise both paths: {summed} summed, {blocked} shadowed");
    assert!(by_shared > 20, "the test must exercise the shared rays: {by_shared} receivers changed by them");
    for (share, twins) in [(0.0, &all_rays), (0.02, &shared)] {
        for device in [DifferentialDevice::Gpu, DifferentialDevice::Cpu] {
            let mut pass = Differential::on(&gpu, &gpu_scene, device).unwrap();
            let sums = Sums::Fast { grouped: &grouped, content: &content, ray_share: share };
            let (light, rounds) = pass.run(&gpu, &gpu_scene, &receivers, sums).unwrap();
            let mut off = 0;
            for (r, (got, want)) in receivers.iter().zip(light.iter().zip(twins)) {
                let scale = (want.unoccluded + want.added).max_element();
                let tol = 1e-4 * scale + 1e-6;
                let worst = [(got.unoccluded, want.unoccluded), (got.blocked, want.blocked), (got.added, want.added)]
                    .iter()
                    .map(|(g, w)| (*g - *w).abs().max_element())
                    .fold(0.0f32, f32::max);
                if worst > tol {
                    off += 1;
                    assert!(
                        worst <= 0.05 * scale,
                        "{device:?}, share {share}, at {}: {got:?} vs twin {want:?}",
                        r.position
                    );
                }
            }
            eprintln!("{device:?}, share {share}: {rounds} rounds, {off} receivers off the twin by over 1e-4");
            assert!(off * 100 <= receivers.len(), "{device:?}, share {share}: {off} receivers off the twin");
        }
    }
}

/// A real plate (albedo 0.5, its camera radiance the exact reference without the box) under a
/// virtual black box, lit by 64 VALs above: the composite `L + rho dE / pi`, with `rho`
/// estimated from `L` and the receivers' irradiance, equals the exact reference rendered with the
/// box in the scene. Both sum the same VALs with the same disc form factor and cast shadow rays
/// through different traversals of different trees (obvhs's any-hit on plate + box, the GPU's
/// stackless one on the box alone), so they differ by float rounding: 1e-4 relative. Where no
/// plate-to-VAL segment crosses the box the composite is the camera radiance exactly.
#[test]
fn mr_differential_plate_darkens_as_exact_predicts() {
    let gpu = gpu();
    let (_, gpu_scene) = gpu_box(&gpu, 0.0);
    let vals = lights_above();
    let receivers = plate_receivers();
    // On this machine's CPU adapter `new` picks the CPU backend; `mr_differential_gpu_matches_twin`
    // holds the GPU pass to the same sums.
    let mut pass = Differential::new(&gpu, &gpu_scene).unwrap();
    let (light, _) =
        pass.run(&gpu, &gpu_scene, &receivers, Sums::Exact { vals: &vals, real_count: vals.len() }).unwrap();

    // The exact reference of the plate alone and of the plate with the box.
    let plate_positions = vec![
        Vec3::new(-2.0, -2.0, 0.0),
        Vec3::new(2.0, -2.0, 0.0),
        Vec3::new(2.0, 2.0, 0.0),
        Vec3::new(-2.0, 2.0, 0.0),
    ];
    let plate_triangles = vec![[0, 1, 2], [0, 2, 3]];
    let Occluders { positions: box_positions, triangles: box_triangles, .. } = scene_occluders(&gpu_scene);
    let mut positions = plate_positions.clone();
    positions.extend(&box_positions);
    let mut triangles = plate_triangles.clone();
    triangles.extend(box_triangles.iter().map(|t| t.map(|i| i + 4)));
    let without = TraceBvh::build(&plate_positions, &plate_triangles);
    let with = TraceBvh::build(&positions, &triangles);
    let surface = Material { diffuse: Vec3::splat(0.5), specular: Vec3::ZERO, exponent: 1.0, diffuse_texture: None };
    let eye = Vec3::new(0.0, -2.0, 1.0);
    let hits: Vec<Option<exact_cpu::Receiver>> =
        receivers.iter().map(|r| Some(exact_cpu::Receiver::new(r.position, r.normal, surface, eye))).collect();
    let n = receivers.len() as u32;
    let render = |bvh: &TraceBvh| {
        let scene = ExactScene { bvh, vals: &vals, glossy: false, blockers_from: 0.0 };
        exact_cpu::render(&scene, &Receivers::Hits(&hits), n, 1, ValSampling::All).image
    };
    let (camera, reference) = (render(&without), render(&with));

    let (mut darkened, mut untouched) = (0, 0);
    for (i, (r, l)) in receivers.iter().zip(&light).enumerate() {
        let (before, after) = (camera.rgb(i), reference.rgb(i));
        let composite = relit_radiance(before, l);
        let tol = 1e-4 * before.max_element() + 1e-9;
        assert!(
            (composite - after).abs().max_element() <= tol,
            "at {}: composite {composite} vs exact {after}",
            r.position
        );
        if after == before {
            assert_eq!(l.blocked, Vec3::ZERO, "at {}", r.position);
            assert_eq!(composite, before, "nothing may change where the box cannot reach ({})", r.position);
            untouched += 1;
        } else if after.x < 0.9 * before.x {
            darkened += 1;
        }
    }
    let centre = receivers.iter().position(|r| r.position.truncate().length() < 1e-3).expect("a centre receiver");
    eprintln!(
        "{darkened} receivers darkened by over 10%, {untouched} untouched; centre {} -> {}",
        camera.rgb(centre),
        reference.rgb(centre)
    );
    assert!(darkened >= 20 && untouched >= 100, "{darkened} darkened, {untouched} untouched");
    assert!(reference.rgb(centre).x < 0.5 * camera.rgb(centre).x, "the box must shade the plate under it");
}

/// What one light estimate makes of the plate beside a resting white box: the relative error
/// of its composite against the truth's, `sqrt(sum |L'_est - L'_true|² / sum |L - L'_true|²)`
/// over the visible receivers (outside the box's footprint), the receivers it darkens by over
/// 10 % (green channel) and its darkest `L' / L - 1`.
#[derive(Debug)]
struct PlateFigures {
    error: f32,
    darkened: usize,
    darkest: f32,
}

/// The plate-and-box world of [`mr_auto_distribution_against_known_light`]: a real plate
/// (z = 0), a virtual white box (albedo 0.8, 0.2 m wide and tall) resting on it,
/// and the shadow rays' BVH of the box.
struct RestingBox {
    occluders: Occluders,
    emitters: Vec<relume::mr::differential::Emitter>,
}

fn resting_box() -> RestingBox {
    use relume::mr::differential::Emitter;
    let (lo, hi) = (Vec3::new(-0.1, -0.1, 0.0), Vec3::new(0.1, 0.1, 0.2));
    let positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let triangles: Vec<[u32; 3]> = quads.iter().flat_map(|[a, b, c, d]| [[*a, *b, *c], [*a, *c, *d]]).collect();
    // 4 x 4 re-emitters on each face but the bottom (it lies on the plate).
    let mut emitters = Vec::new();
    let centre = (lo + hi) * 0.5;
    for normal in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z] {
        let (u, v) = (normal.any_orthonormal_pair().0, normal.any_orthonormal_pair().1);
        for k in 0..16 {
            let (a, b) = (((k % 4) as f32 + 0.5) / 4.0 - 0.5, ((k / 4) as f32 + 0.5) / 4.0 - 0.5);
            let position = centre + normal * 0.1 + (u * a + v * b) * 0.2;
            emitters.push(Emitter { position, normal, area: 0.04 / 16.0, albedo: Vec3::splat(0.8) });
        }
    }
    RestingBox { occluders: Occluders::new(positions, triangles), emitters }
}

impl RestingBox {
    /// Each receiver's light with the box re-emitting what `vals` give its faces (no
    /// occlusion: the box is convex and the plate is below every face that takes part).
    fn light(&self, receivers: &[Receiver], vals: &[Val]) -> Vec<relume::gpu::differential::ReceiverLight> {
        let gathered: Vec<Vec3> = self
            .emitters
            .iter()
            .map(|e| vals.iter().map(|v| relume::twin::val_irradiance(e.position, e.normal, v)).sum())
            .collect();
        let mut all = vals.to_vec();
        all.extend(relume::mr::differential::emitter_vals(&self.emitters, &gathered));
        receivers.iter().map(|r| twin::receiver_light(r, &all, vals.len(), &self.occluders)).collect()
    }
}

/// Ground truth for the `auto` environment's distribution: a real plate under a
/// virtual white box, lit by light the camera never sees, known here. The camera sees the
/// plate alone (its VALs: radiance `rho E / pi`), so `auto` fills the upper cells (16 rows,
/// fine enough that the grid's own quadrature error does not hide the distribution's) and
/// sets their level from the plate's brightness; each distribution's composite is compared
/// with the truth's (the differential pass's sums under the true light). Two lights: 64
/// ceiling lamps 1 m above (light from above, as in an office) and a uniform sky (uniform's
/// own assumption); two plates: albedo 0.5 and a white one (the only plate the albedo <= 1
/// level gets right). Figures are printed (`-- --nocapture`) and quoted in the README; the
/// asserts hold what they showed: overcast nearer the lamps' truth on both plates, uniform
/// nearer the uniform sky's on the white plate; and with the plate's albedo known
/// (`settings.environment.albedo`), the uniform estimate of the uniform sky at its true
/// radiance, which on the grey plate more than halves the error.
#[test]
fn mr_auto_distribution_against_known_light() {
    const ROWS: u32 = 16;
    use relume::mr::differential::ReceiverGrid;
    use relume::mr::environment::{DirectionGrid, EnvironmentDistribution, auto_estimate};
    use relume::twin::val_irradiance;
    let scene = resting_box();
    let receivers = plate_receivers();
    let visible: Vec<bool> = receivers.iter().map(|r| r.position.x.abs().max(r.position.y.abs()) > 0.101).collect();
    let centre = Vec3::new(0.0, 0.0, 0.1);
    let sky = DirectionGrid::new(16, Vec3::Z);
    let upper: Vec<Vec3> =
        (0..sky.cells()).map(|i| if sky.cell(i).0.z > 0.0 { Vec3::ONE } else { Vec3::ZERO }).collect();
    let truths: [(&str, Vec<Val>); 2] = [("ceiling lamps", lights_above()), ("uniform sky", sky.vals(centre, &upper))];
    let cases = [0.5f32, 1.0].into_iter().flat_map(|albedo| truths.iter().map(move |(n, l)| (albedo, *n, l)));
    for (plate_albedo, name, lamps) in cases {
        let e_plate = |p: Vec3| -> Vec3 { lamps.iter().map(|v| val_irradiance(p, Vec3::Z, v)).sum() };
        // The plate the camera sees, 5 cm patches over 3 x 3 m.
        let plate: Vec<Val> = (0..60 * 60)
            .map(|i| {
                let position = Vec3::new(-1.475 + 0.05 * (i % 60) as f32, -1.475 + 0.05 * (i / 60) as f32, 0.0);
                let area = 0.0025;
                Val { position, normal: Vec3::Z, area, flux: plate_albedo * e_plate(position) * area }
            })
            .collect();
        let camera: Vec<Vec3> =
            receivers.iter().map(|r| plate_albedo * e_plate(r.position) / std::f32::consts::PI).collect();
        let mut true_vals = lamps.clone();
        true_vals.extend(&plate);
        let truth: Vec<Vec3> = scene
            .light(&receivers, &true_vals)
            .iter()
            .zip(&camera)
            .map(|(l, c)| *c + plate_albedo * l.change() / std::f32::consts::PI)
            .collect();
        let figures = |composite: &[Vec3]| {
            let (mut err, mut change, mut darkened, mut darkest) = (0.0f32, 0.0f32, 0, 0.0f32);
            for i in (0..receivers.len()).filter(|i| visible[*i]) {
                err += (composite[i] - truth[i]).length_squared();
                change += (camera[i] - truth[i]).length_squared();
                let net = composite[i].y / camera[i].y - 1.0;
                darkened += usize::from(net < -0.1);
                darkest = darkest.min(net);
            }
            PlateFigures { error: (err / change).sqrt(), darkened, darkest }
        };
        let exact = figures(&truth);
        let name = format!("plate albedo {plate_albedo}, {name}");
        eprintln!("{name}: truth darkens {} receivers by over 10 %, darkest {:.3}", exact.darkened, exact.darkest);
        let grid = DirectionGrid::new(ROWS, Vec3::Z);
        let mean = camera.iter().sum::<Vec3>() / camera.len() as f32;
        let radiance_grid =
            ReceiverGrid { receivers: receivers.clone(), radiance: camera.clone(), ..Default::default() };
        let estimate_with = |d: EnvironmentDistribution, albedo: Option<f32>| {
            let estimate = auto_estimate(&grid, d, centre, &plate, Some(&radiance_grid), mean, albedo);
            let mut vals = plate.clone();
            vals.extend(grid.vals(centre, &estimate.radiance));
            let composite: Vec<Vec3> =
                scene.light(&receivers, &vals).iter().zip(&camera).map(|(l, c)| relit_radiance(*c, l)).collect();
            let f = figures(&composite);
            eprintln!(
                "{name}, {d:?} estimate, albedo {albedo:?} (level {:.3}, up {}): {f:?}",
                estimate.level, estimate.up
            );
            (f, estimate.level)
        };
        let [uniform, overcast] =
            [EnvironmentDistribution::Uniform, EnvironmentDistribution::Overcast].map(|d| estimate_with(d, None).0);
        // The plate's albedo known (`settings.environment.albedo`): the level calibrated to it.
        let [uniform_known, overcast_known] = [EnvironmentDistribution::Uniform, EnvironmentDistribution::Overcast]
            .map(|d| estimate_with(d, Some(plate_albedo)));
        // Under the uniform sky (radiance 1 above the horizon) the uniform model is the truth's:
        // with the albedo known its level is the sky's radiance, and on the grey plate, where the
        // albedo <= 1 level is half of it, the composite comes much nearer the truth.
        if !name.ends_with("lamps") {
            let (known, level) = &uniform_known;
            assert!((*level - Vec3::ONE).abs().max_element() < 0.01, "{name}: level {level}");
            if plate_albedo < 1.0 {
                assert!(known.error < 0.5 * uniform.error, "{name}: {known:?} vs {uniform:?}");
            }
        }
        eprintln!("{name}: known albedo: uniform {uniform_known:?}, overcast {overcast_known:?}");
        if name.ends_with("lamps") {
            assert!(overcast.error < uniform.error, "{name}: {overcast:?} vs {uniform:?}");
        } else if plate_albedo == 1.0 {
            assert!(uniform.error < overcast.error, "{name}: {uniform:?} vs {overcast:?}");
        }
    }
}

/// The fast pass against the exact one, each replayed by its own `MrRenderer` on the same
/// frames of `recording` with `scene` (its `settings.mr.differential_method` set to each): per
/// frame, the change of irradiance over the receivers within 10 % rel RMSE and the darkest
/// visible net change (the contact shadow) within `darkest_tolerance` of the exact one's.
fn fast_against_exact(
    name: &str,
    darkest_tolerance: f32,
    scene: &Scene,
    environment: Option<relume::mr::environment::Environment>,
    recording: &relume::rgbd::recording::Recording,
    frames: &[usize],
) {
    use relume::mr::differential::Agreement;
    use relume::mr::{MrOptions, MrRenderer};
    use relume::scene::settings::DifferentialMethod;
    let gpu = gpu();
    let k = recording.intrinsics();
    // The receivers are the depth frame's; the output size only sets the composite's.
    let options = MrOptions { width: k.width / 4, height: k.height / 4, exposure: 1.0, accumulate: None };
    let renderer = |method| {
        let mut scene = scene.clone();
        scene.settings.mr.differential_method = Some(method);
        MrRenderer::new(&gpu, &scene, options).unwrap()
    };
    let (mut exact, mut fast) = (renderer(DifferentialMethod::Exact), renderer(DifferentialMethod::Fast));
    if let Some(environment) = environment {
        exact.set_environment(environment.clone());
        fast.set_environment(environment);
    }
    for &i in frames {
        let frame = recording.frame(i).unwrap();
        let (e, f) = (exact.render_frame(&gpu, &frame).unwrap(), fast.render_frame(&gpu, &frame).unwrap());
        let (de, df) = (e.differential.expect("exact pass ran"), f.differential.expect("fast pass ran"));
        assert_eq!(de.grid.receivers, df.grid.receivers, "{name} frame {i}: the same receivers");
        let a = Agreement::of(&de.light, &df.light, &de.visible);
        eprintln!(
            "{name} frame {i}: {} receivers, fast computed {} ({} interpolated): {a:?}",
            de.light.len(),
            df.counts.computed,
            df.counts.interpolated
        );
        assert!(de.light.len() >= 100, "{name} frame {i}: too few receivers to tell ({})", de.light.len());
        assert!(a.darkest_exact < -0.1, "{name} frame {i}: no contact shadow to compare ({a:?})");
        assert!(a.change_rel_rmse <= 0.10, "{name} frame {i}: change of irradiance off by {a:?}");
        assert!(a.darkest_rel_error() <= darkest_tolerance, "{name} frame {i}: darkest value off by {a:?}");
    }
}

/// The default job's scene on the bundled TUM recording (with its `auto` environment, as
/// `relume replay` reads it), its first, middle and last frames.
#[test]
fn mr_differential_fast_against_exact_on_tum() {
    let scene = super::load_scene("mr_bunny_differential");
    let path = super::fixture("scenes/mr_bunny_differential.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let settings = relume::scene::SceneDescription::from_json_str(&text).unwrap().settings.environment;
    let environment = relume::mr::environment::Environment::from_settings(&settings, path.parent().unwrap()).unwrap();
    let recording = relume::rgbd::recording::Recording::open(
        &super::fixture("recordings/tum_fr1_xyz"),
        &relume::rgbd::recording::RecordingOptions::default(),
    )
    .unwrap();
    fast_against_exact("tum", 0.10, &scene, Some(environment), &recording, &[0, 18, 36]);
}

/// A synthetic closed-loop recording (`relume record-synthetic`: the Cornell room of
/// `cornell_bunny_small.json` without the bunny, lit by its spot light) replayed with the bunny
/// as virtual content, the differential pass on, every frame, held to the targets (10 %).
/// Measured on frame 0: the darkest value -0.8191 against the exact -0.8190 (with the groups'
/// reach at 4 radii instead of 6 it was -0.734, 10.4 % off; docs/measurements/differential.md).
#[test]
fn mr_differential_fast_against_exact_on_synthetic() {
    use relume::mr::synthetic::{SyntheticOptions, record};
    let text = std::fs::read_to_string(super::fixture("scenes/cornell_bunny_small.json")).unwrap();
    let fixture: serde_json::Value = serde_json::from_str(&text).unwrap();
    let with_meshes = |indices: &[usize]| {
        let mut v = fixture.clone();
        v["meshes"] = serde_json::Value::Array(indices.iter().map(|&i| v["meshes"][i].clone()).collect());
        v
    };
    let scene_of = |v: &serde_json::Value| Scene::from_json_str(&v.to_string(), &super::fixture("scenes")).unwrap();
    let gpu = gpu();
    let dir = super::scratch("mr_differential_fast_synthetic");
    let options = SyntheticOptions {
        out: dir.clone(),
        frames: 3,
        width: 192,
        height: 192,
        arc_deg: 60.0,
        turn_deg: 0.0,
        radiance_scale: None,
    };
    let metadata = record(&gpu, &scene_of(&with_meshes(&[0])), &options).unwrap();
    let mut bunny = with_meshes(&[1]);
    bunny.as_object_mut().unwrap().remove("light");
    bunny["settings"]["rgbd"] = serde_json::json!({ "grid_step": 4, "radiance_scale": metadata.radiance_scale });
    bunny["settings"]["mr"] = serde_json::json!({ "differential": true, "receiver_step": 2 });
    let recording =
        relume::rgbd::recording::Recording::open(&dir, &relume::rgbd::recording::RecordingOptions::default()).unwrap();
    fast_against_exact("synthetic", 0.10, &scene_of(&bunny), None, &recording, &[0, 1, 2]);
}
