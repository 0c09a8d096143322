use super::*;
use crate::twin::bvh::Bvh;
use crate::twin::shade_brute_force;
use glam::Vec2;

/// A 4 m x 4 m floor (y = 0, two triangles) under a 1 m x 1 m occluder quad at y = 0.5, lit
/// by 300 VALs facing down between y = 1 and 1.5 with random colours.
struct Room {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    /// The GPU layout's tree, for `Bvh::occluded` (the twin of `bvh.wgsl`).
    bvh: Bvh,
    trace: TraceBvh,
    vals: Vec<Val>,
}

const SURFACE: Material =
    Material { diffuse: Vec3::new(0.6, 0.5, 0.4), specular: Vec3::splat(0.3), exponent: 12.0, diffuse_texture: None };
const EYE: Vec3 = Vec3::new(0.0, 2.5, 3.0);

fn room() -> Room {
    let positions = vec![
        Vec3::new(-2.0, 0.0, -2.0),
        Vec3::new(2.0, 0.0, -2.0),
        Vec3::new(2.0, 0.0, 2.0),
        Vec3::new(-2.0, 0.0, 2.0),
        Vec3::new(-0.5, 0.5, -0.5),
        Vec3::new(0.5, 0.5, -0.5),
        Vec3::new(0.5, 0.5, 0.5),
        Vec3::new(-0.5, 0.5, 0.5),
    ];
    let triangles = vec![[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]];
    let bvh = Bvh::build(&positions, &triangles);
    let trace = TraceBvh::build(&positions, &triangles);
    let vals = vals_above(1, 300, 1.5, 1.0..1.5, 1e-3);
    Room { positions, triangles, bvh, trace, vals }
}

/// `n` VALs of `area` facing down, spread uniformly over `-half_width..half_width` in x and
/// z at `heights`, with random flux (seeded by `seed`).
fn vals_above(seed: u64, n: usize, half_width: f32, heights: std::ops::Range<f32>, area: f32) -> Vec<Val> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut random = |range: std::ops::Range<f32>| rng.random_range(range);
    (0..n)
        .map(|_| {
            let (x, y, z) = (random(-half_width..half_width), random(heights.clone()), random(-half_width..half_width));
            let flux = Vec3::new(random(0.0..1.0), random(0.0..1.0), random(0.0..1.0));
            Val { position: Vec3::new(x, y, z), normal: Vec3::NEG_Y, area, flux }
        })
        .collect()
}

/// Floor receivers along a line through the occluder's shadow: lit, penumbra and umbra.
fn floor_receivers() -> Vec<Option<Receiver>> {
    (0..8).map(|i| Some(Receiver::new(Vec3::new(-1.8 + 0.45 * i as f32, 0.0, 0.1), Vec3::Y, SURFACE, EYE))).collect()
}

/// `blockers_from`: the room's occluder lies 0.5 m or more along every floor receiver's
/// shadow rays, so ignoring blockers within 0.3 m changes nothing (to float rounding),
/// within 3 m (past the occluder on every ray: at most 1.9 m along the longest) leaves every
/// receiver unoccluded, the brute force over every VAL; and the occluder must shadow some
/// receivers at 0 for either to mean anything.
#[test]
fn blockers_from_ignores_only_the_blockers_that_near() {
    let room = room();
    let hits = floor_receivers();
    let image = |blockers_from| {
        let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from };
        render(&scene, &Receivers::Hits(&hits), hits.len() as u32, 1, ValSampling::All).image
    };
    let (every, near_left_out, none) = (image(0.0), image(0.3), image(3.0));
    let mut shadowed = 0;
    for (i, r) in hits.iter().enumerate() {
        let r = r.unwrap();
        let unoccluded = shade_brute_force(r.position, r.normal, &r.surface, EYE, &room.vals, true);
        let (a, b, c) = (every.rgb(i), near_left_out.rgb(i), none.rgb(i));
        assert!((a - b).abs().max_element() <= 1e-5 * a.max_element(), "receiver {i}: {a} vs {b}");
        assert!((c - unoccluded).abs().max_element() <= 1e-5 * unoccluded.max_element(), "receiver {i}: {c}");
        shadowed += usize::from(a.element_sum() < 0.9 * unoccluded.element_sum());
    }
    assert!(shadowed >= 2, "the occluder must shadow some receivers, shadowed {shadowed}");
}

/// Every VAL at the centre: the brute-force twin over the VALs the GPU layout's traversal
/// (`Bvh::occluded`, twin of `bvh.wgsl`) finds visible, to float rounding (1e-5 relative),
/// and noise-free; the occluder must darken some receivers for the test to mean anything.
#[test]
fn every_val_equals_brute_force_over_visible_vals() {
    let room = room();
    let hits = floor_receivers();
    let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from: 0.0 };
    let out = render(&scene, &Receivers::Hits(&hits), hits.len() as u32, 1, ValSampling::All);
    let mut shadowed = 0;
    for (i, r) in hits.iter().enumerate() {
        let r = r.unwrap();
        let origin = r.position + r.normal * RAY_OFFSET;
        let visible: Vec<Val> = room
            .vals
            .iter()
            .filter(|v| {
                !room.bvh.occluded(&room.positions, &room.triangles, origin, v.position + v.normal * RAY_OFFSET)
            })
            .copied()
            .collect();
        let want = shade_brute_force(r.position, r.normal, &r.surface, EYE, &visible, true);
        let unoccluded = shade_brute_force(r.position, r.normal, &r.surface, EYE, &room.vals, true);
        shadowed += usize::from(want.element_sum() < 0.9 * unoccluded.element_sum());
        let got = out.image.rgb(i);
        assert!((got - want).abs().max_element() <= 1e-5 * want.max_element(), "receiver {i}: {got} vs {want}");
        assert_eq!(out.image.pixels[i][3], 1.0);
    }
    assert!(shadowed >= 2, "the occluder must shadow some receivers, shadowed {shadowed}");
    assert!(out.variance.unwrap().iter().all(|v| *v == Vec3::ZERO), "the full sum has no noise");
    assert!(out.shadow_rays > 0 && out.shadow_rays <= (hits.len() * room.vals.len()) as u64);
}

/// The shadow-ray traversal changes the cost, never the image: with 4,000 VALs packed over
/// the occluder (so a floor receiver's neighbouring VALs are ~0.01 rad apart and full packets
/// form) the packets and the single rays give the same pixels, bit for bit, and cast the
/// same rays, for the full sum, a stride and the importance estimate.
#[test]
fn packets_and_single_rays_give_the_same_image() {
    let mut room = room();
    room.vals = vals_above(4, 4000, 0.6, 1.0..1.1, 1e-4);
    let hits = floor_receivers();
    let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from: 0.0 };
    let n = hits.len() as u32;
    for sampling in [ValSampling::All, ValSampling::Stride(3), ValSampling::Importance { samples: 64, seed: 2 }] {
        let render = |t| render_with(&scene, &Receivers::Hits(&hits), n, 1, sampling, Some(t));
        let (single, packets) = (render(ShadowTraversal::Single), render(ShadowTraversal::Packets));
        assert_eq!(single.image.pixels, packets.image.pixels, "{sampling:?}");
        assert_eq!(single.shadow_rays, packets.shadow_rays, "{sampling:?}");
        assert_eq!(packets.traversal, ShadowTraversal::Packets);
    }
    let lit = render(&scene, &Receivers::Hits(&hits), n, 1, ValSampling::All).image;
    let darkest = (0..hits.len()).map(|i| lit.rgb(i).x).fold(f32::INFINITY, f32::min);
    let brightest = (0..hits.len()).map(|i| lit.rgb(i).x).fold(0.0, f32::max);
    assert!(darkest < 0.5 * brightest, "the occluder must shadow part of the line: {darkest} vs {brightest}");
}

/// Importance sampling is unbiased and its noise estimate is right: over 200 independent
/// seeds (16 draws each) the mean estimate at every receiver and channel lies within 4
/// standard errors of the full sum (a z-test; standard error from the spread over seeds;
/// with 24 z-values a false failure has probability ~1e-3), and the mean of the two-halves
/// variance estimate matches the variance observed across seeds within [0.6, 1.6] (each
/// side has ~10 % relative noise at 200 seeds, so that is a ~4-sigma band).
#[test]
fn importance_estimate_mean_over_seeds_converges_to_the_full_sum() {
    let room = room();
    let hits = floor_receivers();
    let scene = ExactScene { bvh: &room.trace, vals: &room.vals, glossy: true, blockers_from: 0.0 };
    let n = hits.len() as u32;
    let full = render(&scene, &Receivers::Hits(&hits), n, 1, ValSampling::All).image;
    let seeds = 200;
    let runs: Vec<ExactImage> = (0..seeds)
        .map(|seed| render(&scene, &Receivers::Hits(&hits), n, 1, ValSampling::Importance { samples: 16, seed }))
        .collect();
    for i in 0..hits.len() {
        let values: Vec<Vec3> = runs.iter().map(|r| r.image.rgb(i)).collect();
        let mean = values.iter().sum::<Vec3>() / seeds as f32;
        let spread = values.iter().map(|v| (*v - mean) * (*v - mean)).sum::<Vec3>() / (seeds - 1) as f32;
        let estimated = runs.iter().map(|r| r.variance.as_ref().unwrap()[i]).sum::<Vec3>() / seeds as f32;
        let want = full.rgb(i);
        for c in 0..3 {
            if spread[c] == 0.0 {
                assert!(
                    (mean[c] - want[c]).abs() <= 1e-5 * want[c].abs().max(1e-12),
                    "receiver {i}: noiseless yet off"
                );
                continue;
            }
            let z = (mean[c] - want[c]) / (spread[c] / seeds as f32).sqrt();
            assert!(z.abs() < 4.0, "receiver {i} channel {c}: mean {} vs full {}, z = {z}", mean[c], want[c]);
            let ratio = estimated[c] / spread[c];
            assert!((0.6..1.6).contains(&ratio), "receiver {i} channel {c}: half-split variance / observed {ratio}");
        }
    }
    assert!(runs[0].shadow_rays <= 16 * n as u64, "one shadow ray per draw at most");
}

/// Shading and geometric normals (docs/design.md §3), in closed form: a receiver on a floor
/// (y = 0, geometric normal +Y) whose shading normal is bent by 60 and by 90 degrees toward a
/// Lambertian wall (x = 1, y and z in [-1, 1], facing -X, radiance `L_e`) that reaches below
/// the floor. The irradiance is `L_e` times the integral over the wall of
/// `cos_wall max(0, n_s . w) / d²` over the part above the floor only: light from below the
/// geometric surface does not count, though the bent shading normal faces it. That integral
/// by midpoint quadrature (600 x 300 cells on the upper half) must equal the brute force's
/// sum over the wall as 40 x 40 VALs (no visibility) and the exact reference's (shadow rays
/// through the floor, from the receiver pushed along its geometric normal) within 1 %; a
/// receiver that took the lower half too, as the shading normal alone would, is 20-100 % over.
#[test]
fn bent_shading_normals_take_light_from_above_the_geometric_surface_only() {
    let l_e = 2.0f32;
    let n = 40;
    let side = 2.0 / n as f32;
    let vals: Vec<Val> = (0..n * n)
        .map(|k| {
            let (i, j) = ((k % n) as f32, (k / n) as f32);
            Val {
                position: Vec3::new(1.0, -1.0 + (j + 0.5) * side, -1.0 + (i + 0.5) * side),
                normal: Vec3::NEG_X,
                area: side * side,
                flux: Vec3::splat(std::f32::consts::PI * l_e * side * side),
            }
        })
        .collect();
    let positions = vec![
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(4.0, 0.0, -4.0),
        Vec3::new(4.0, 0.0, 4.0),
        Vec3::new(-4.0, 0.0, 4.0),
    ];
    let trace = TraceBvh::build(&positions, &[[0, 2, 1], [0, 3, 2]]);
    let matte = Material { diffuse: Vec3::splat(0.5), specular: Vec3::ZERO, exponent: 1.0, diffuse_texture: None };
    let eye = Vec3::new(-1.0, 2.0, 0.3);
    for degrees in [60.0f32, 90.0] {
        let bent = Vec3::new(degrees.to_radians().sin(), degrees.to_radians().cos(), 0.0);
        // The quadrature, in f64: the wall's upper half, where d is at least 1 m.
        let (cells_z, cells_y) = (600, 300);
        let (dz, dy) = (2.0 / cells_z as f64, 1.0 / cells_y as f64);
        let mut above = 0.0f64;
        let mut below = 0.0f64;
        for iy in 0..2 * cells_y {
            for iz in 0..cells_z {
                let y = -1.0 + (iy as f64 + 0.5) * dy;
                let z = -1.0 + (iz as f64 + 0.5) * dz;
                let (vx, vy, vz) = (1.0f64, y, z);
                let d2 = vx * vx + vy * vy + vz * vz;
                let d = d2.sqrt();
                let cos_wall = vx / d;
                let cos_shading = ((bent.x as f64) * vx + (bent.y as f64) * vy) / d;
                let term = l_e as f64 * cos_wall * cos_shading.max(0.0) / d2 * dy * dz;
                if y > 0.0 { above += term } else { below += term }
            }
        }
        let want = 0.5 / std::f64::consts::PI * above;
        let r = Receiver::sided(Vec3::ZERO, bent, Vec3::Y, matte, eye);
        let brute = crate::twin::shade_brute_force_sided(r.position, r.normal, r.geometric, &matte, eye, &vals, false);
        let scene = ExactScene { bvh: &trace, vals: &vals, glossy: false, blockers_from: 0.0 };
        let exact = render(&scene, &Receivers::Hits(&[Some(r)]), 1, 1, ValSampling::All).image.rgb(0);
        for (name, got) in [("brute force", brute), ("exact", exact)] {
            let ratio = got.x as f64 / want;
            assert!((ratio - 1.0).abs() < 0.01, "{degrees} degrees, {name}: {} vs quadrature {want}", got.x);
        }
        // The test can fail: the shading normal alone (the flat surface's sum, `n_g = n_s`)
        // adds the lower half.
        assert!(below > 0.2 * above, "{degrees} degrees: the lower half must matter ({below} vs {above})");
        let unsided = crate::twin::shade_brute_force(r.position, r.normal, &matte, eye, &vals, false);
        assert!(unsided.x as f64 > 1.15 * want, "{degrees} degrees: {} vs {want}", unsided.x);
    }
}

/// Primary rays: at one sample per pixel through the pixel centre (the analytic ray-plane
/// intersection, to 1e-4 m), and with 256 jittered samples a pixel the floor's edge halves is
/// half covered (alpha 0.5 within 4 standard deviations of a binomial, 4 * 0.031).
#[test]
fn traced_receivers_sample_the_pixel_centre_or_its_area() {
    let room = room();
    let (w, h) = (32, 32);
    let world_to_clip = glam::camera::rh::proj::directx::perspective(1.0, 1.0, 0.01, 20.0)
        * glam::camera::rh::view::look_at_mat4(EYE, Vec3::ZERO, Vec3::Y);
    let camera = CameraRays::new(world_to_clip, w, h);
    let surface = |t: u32, b: Vec2| {
        let [p0, p1, p2] = room.triangles[t as usize].map(|i| room.positions[i as usize]);
        let n = (p1 - p0).cross(p2 - p0).normalize();
        Receiver::new(crate::twin::barycentric(b, p0, p1, p2), n, SURFACE, EYE)
    };
    let no_vals = ExactScene { bvh: &room.trace, vals: &[], glossy: true, blockers_from: 0.0 };
    for (x, y) in [(3u32, 30u32), (16, 16), (28, 25)] {
        let (o, d) = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
        let sampling = PixelSampling { spp: 1, seed: 0 };
        let r = pixel_receivers(
            &Receivers::Traced { camera: &camera, sampling, surface: &surface },
            &room.trace,
            (y * w + x) as usize,
            w,
        );
        let [Some(r)] = r[..] else { panic!("pixel ({x}, {y}) must see the room: {r:?}") };
        let t_floor = -o.y / d.y;
        let t_box = (0.5 - o.y) / d.y;
        let on_box = (o + d * t_box).abs().max_element() <= 0.5 && (o + d * t_box).y > 0.4;
        let want = if on_box { o + d * t_box } else { o + d * t_floor };
        assert!((r.position - want).length() < 1e-4, "pixel ({x}, {y}): {} vs {want}", r.position);
    }
    // The floor's far edge (z = -2) crosses some column: find a pixel whose centre sees the
    // floor and whose upper neighbour does not, then place a camera that halves it.
    let edge_camera = CameraRays::new(world_to_clip, w, h);
    let sampling = PixelSampling { spp: 256, seed: 3 };
    let receivers = Receivers::Traced { camera: &edge_camera, sampling, surface: &surface };
    let out = render(&no_vals, &receivers, w, h, ValSampling::All);
    let column = 16;
    let alphas: Vec<f32> = (0..h).map(|y| out.image.pixels[(y * w + column) as usize][3]).collect();
    let partial: Vec<f32> = alphas.iter().copied().filter(|a| *a > 0.0 && *a < 1.0).collect();
    assert!(!partial.is_empty(), "the edge must cut a pixel: {alphas:?}");
    // Where the edge crosses the pixel (sub-pixel row): from where the centre ray meets z = -2.
    let y_edge = (0..h * 64)
        .map(|k| k as f32 / 64.0)
        .find(|&y| {
            let (o, d) = edge_camera.ray(column as f32 + 0.5, y);
            let t = -o.y / d.y;
            t > 0.0 && (o + d * t).z >= -2.0
        })
        .unwrap();
    let row = y_edge.floor() as u32;
    let expected = 1.0 - (y_edge - row as f32);
    let alpha = alphas[row as usize];
    assert!(
        (alpha - expected).abs() < 4.0 * (expected * (1.0 - expected) / 256.0).sqrt() + 0.02,
        "row {row}: alpha {alpha} vs {expected}"
    );
}
