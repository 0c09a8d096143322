use super::rsm::*;
use super::*;
use crate::scene::SpotLight;
use proptest::prelude::*;

fn fibonacci_sphere(n: usize) -> Vec<Vec3> {
    let golden = PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect()
}

/// On the axis of a parallel disc the approximation is exact: F = r^2 / (d^2 + r^2).
#[test]
fn disc_form_factor_is_exact_on_axis() {
    for (d, r) in [(1.0f32, 0.1f32), (0.5, 0.5), (2.0, 3.0), (1e-3, 1.0)] {
        let a = PI * r * r;
        let g = val_geometry(Vec3::ZERO, Vec3::Y, Vec3::new(0.0, d, 0.0), -Vec3::Y, a);
        let f = g.weight * g.cos_receiver * a;
        let exact = r * r / (d * d + r * r);
        assert!((f - exact).abs() <= 1e-5 * exact, "d={d} r={r}: {f} vs {exact}");
    }
}

/// The differential passes' form factor without a square root is `val_geometry`'s `weight *
/// cos_receiver` to rounding (of the largest form factor at that distance), for VALs around a
/// receiver facing every way, and 0 exactly where that is (behind the receiver, facing away,
/// coincident).
#[test]
fn form_factor_without_a_square_root_is_val_geometrys() {
    let (x, n_x) = (Vec3::new(0.2, -0.1, 0.3), Vec3::new(0.3, 0.9, -0.2).normalize());
    let (mut lit, mut unlit) = (0, 0);
    let directions = fibonacci_sphere(500);
    for (i, p) in directions.iter().enumerate() {
        let position = x + *p * (0.01 + 0.5 * (i % 7) as f32);
        let normal = directions[(i * 37) % 500];
        let area = [0.0, 1e-4, 0.02, -0.01][i % 4];
        let g = val_geometry(x, n_x, position, normal, area);
        let (want, got) = (g.weight * g.cos_receiver, val_form_factor(x, n_x, position, normal, area));
        // Rounding is relative to the largest form factor at that distance (both cosines 1): a
        // grazing cosine is a difference of larger terms in either form.
        let scale = 1.0 / (PI * (position - x).length_squared() + area.max(0.0));
        assert!((got - want).abs() <= 1e-6 * scale, "VAL {i}: {got} against {want}");
        assert_eq!(got > 0.0, want > 0.0, "VAL {i}");
        if got > 0.0 { lit += 1 } else { unlit += 1 }
    }
    assert!(lit > 50 && unlit > 50, "both sides exercised: {lit} lit, {unlit} not");
    assert_eq!(val_form_factor(x, n_x, x, -n_x, 0.01), 0.0, "coincident");
}

/// Off axis, against a numerical integral of cos cos / (pi s^2) over a tilted disc: the
/// point-to-disc approximation's error is of order (r/d)^2, so it must fall as the disc moves
/// away: below (r/d)^2 at every distance and below 0.5 % at 16 radii.
#[test]
fn disc_form_factor_matches_numerical_integration_off_axis() {
    let r = 0.1f32;
    let normal = Vec3::new(-0.3, -1.0, -0.2).normalize();
    let (t, b) = (any_perpendicular(normal), normal.cross(any_perpendicular(normal)));
    let direction = Vec3::new(0.25, 0.3, 0.1).normalize();
    for radii in [4.0f32, 8.0, 16.0] {
        let d = radii * r;
        let centre = direction * d;
        let (nr, nphi) = (200, 400);
        let mut integral = 0.0f64;
        for i in 0..nr {
            let rho = (i as f32 + 0.5) / nr as f32 * r;
            for j in 0..nphi {
                let phi = (j as f32 + 0.5) / nphi as f32 * 2.0 * PI;
                let v = centre + (t * phi.cos() + b * phi.sin()) * rho;
                let s2 = v.length_squared();
                let w = v / s2.sqrt();
                let da = rho * (r / nr as f32) * (2.0 * PI / nphi as f32);
                integral += (Vec3::Y.dot(w).max(0.0) * (-normal.dot(w)).max(0.0) / (PI * s2) * da) as f64;
            }
        }
        let g = val_geometry(Vec3::ZERO, Vec3::Y, centre, normal, PI * r * r);
        let approx = (g.weight * g.cos_receiver * PI * r * r) as f64;
        let err = (approx - integral).abs() / integral;
        let bound = if radii >= 16.0 { 0.005 } else { 1.0 / (radii * radii) as f64 };
        assert!(err <= bound, "{radii} radii: {approx} vs {integral} ({:.2} %)", err * 100.0);
    }
}

/// White furnace: a receiver at the centre of a sphere tiled by inward-facing Lambertian discs
/// of radiance L receives E = pi L from the hemisphere it faces (1 % with 20k discs: the
/// tiling error of Fibonacci discs).
#[test]
fn furnace_sphere_of_vals_gives_pi_l() {
    let n = 20_000;
    let radius = 2.0;
    let area = 4.0 * PI * radius * radius / n as f32;
    let radiance = Vec3::new(1.0, 0.5, 0.25);
    let vals: Vec<Val> = fibonacci_sphere(n)
        .into_iter()
        .map(|d| Val { position: d * radius, normal: -d, area, flux: PI * radiance * area })
        .collect();
    let e: Vec3 = vals.iter().map(|v| val_irradiance(Vec3::ZERO, Vec3::Y, v)).sum();
    let expected = PI * radiance;
    assert!((e - expected).abs().max_element() <= 0.01 * expected.max_element(), "{e} vs {expected}");
}

fn random_vals(seed: u64, n: usize) -> Vec<Val> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let p = Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(0.2..2.0), rng.random_range(-1.0..1.0));
            let nrm = Vec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..-0.1), rng.random_range(-1.0..1.0))
                .normalize();
            Val {
                position: p,
                normal: nrm,
                area: rng.random_range(0.0..0.01),
                flux: Vec3::new(rng.random_range(0.0..1.0), rng.random_range(0.0..1.0), rng.random_range(0.0..1.0)),
            }
        })
        .collect()
}

/// Renormalised lights reproduce what was gathered at the sparse point itself.
#[test]
fn renormalisation_reproduces_gathered_light_at_the_point() {
    let vals = random_vals(7, 300);
    let (x, n, eye) = (Vec3::new(0.1, 0.0, -0.2), Vec3::Y, Vec3::new(0.5, 1.5, 3.0));
    for k in [0.0f32, 1.0, 10.0, 100.0] {
        let g = gather_point(x, n, k, eye, &vals);
        let surface = Material { diffuse: Vec3::ONE, specular: Vec3::ONE, exponent: k, diffuse_texture: None };
        let d = renormalise_diffuse(x, n, g.irradiance, g.diffuse_position);
        let l = point_light_radiance(x, n, &surface, eye, &d, false);
        let want = g.irradiance / PI;
        assert!((l - want).abs().max_element() <= 1e-4 * want.max_element(), "k={k}: {l} vs {want}");
        let s = renormalise_glossy(x, n, k, eye, g.glossy_irradiance, g.glossy_position);
        let l = point_light_radiance(x, n, &surface, eye, &s, true);
        let want = g.glossy_irradiance * phong_normalisation(k);
        assert!((l - want).abs().max_element() <= 1e-3 * want.max_element().max(1e-12), "k={k}: {l} vs {want}");
    }
}

/// `glossy_interpolation: "radiance"` at a sparse point gives what its (unbounded) renormalised
/// glossy light gives there (both are the gathered glossy radiance), and the brute force's glossy
/// lobe; averaging equal sums returns them; a point facing away from the eye adds nothing.
#[test]
fn glossy_radiance_interpolation_reproduces_the_gathered_lobe() {
    let vals = random_vals(11, 300);
    let (x, n, eye) = (Vec3::new(-0.2, 0.0, 0.1), Vec3::Y, Vec3::new(0.4, 1.2, 2.5));
    for k in [1.0f32, 10.0, 100.0, 1000.0] {
        let s = Material { diffuse: Vec3::ZERO, specular: Vec3::splat(0.4), exponent: k, diffuse_texture: None };
        let g = gather_point(x, n, k, eye, &vals);
        let toward = glossy_toward_eye(x, n, eye, g.glossy_irradiance);
        let interpolated = interpolate_radiance(&[0.2, 0.5, 0.3], &[toward; 3]);
        let got = glossy_from_radiance(&s, interpolated);
        let brute = shade_brute_force(x, n, &s, eye, &vals, true);
        assert!((got - brute).abs().max_element() <= 1e-4 * brute.max_element().max(1e-12), "k={k}: {got} vs {brute}");
        let light = renormalise_glossy(x, n, k, eye, g.glossy_irradiance, g.glossy_position);
        let via_light = point_light_radiance(x, n, &s, eye, &light, true);
        assert!(
            (got - via_light).abs().max_element() <= 1e-3 * got.max_element().max(1e-12),
            "k={k}: {got} vs {via_light}"
        );
    }
    assert_eq!(glossy_toward_eye(Vec3::ZERO, Vec3::Y, Vec3::new(0.0, -1.0, 2.0), Vec3::ONE), Vec3::ZERO);
    assert_eq!(interpolate_radiance(&[0.0, 0.0], &[Vec3::ONE, Vec3::ONE]), Vec3::ZERO);
}

/// Brute force and the sparse chain agree exactly when the receiver is the sparse point.
#[test]
fn brute_force_equals_gather_at_the_point() {
    let vals = random_vals(3, 200);
    let (x, n, eye) = (Vec3::ZERO, Vec3::Y, Vec3::new(0.0, 2.0, 2.0));
    let s = Material { diffuse: Vec3::splat(0.5), specular: Vec3::splat(0.3), exponent: 20.0, diffuse_texture: None };
    let g = gather_point(x, n, s.exponent, eye, &vals);
    let brute = shade_brute_force(x, n, &s, eye, &vals, true);
    let via_gather = s.diffuse / PI * g.irradiance + s.specular * phong_normalisation(s.exponent) * g.glossy_irradiance;
    assert!((brute - via_gather).abs().max_element() <= 1e-5 * brute.max_element());
}

/// A vertex whose neighbours lie on a perpendicular surface weighs them as in the unturned
/// scene (cosine exactly 0) when a turn leaves their cosines a few 1e-8 either side of 0:
/// nothing, and the fallback picks the same neighbour.
#[test]
fn perpendicular_neighbours_weigh_nothing_however_the_scene_is_turned() {
    for kernel in [InterpolationKernel::Paper, InterpolationKernel::Smooth] {
        let offsets = [Vec3::X * 0.1, Vec3::Z * 0.2, Vec3::X * 0.3];
        let square = interpolation_weights(kernel, Vec3::Y, &offsets, &[Vec3::X, Vec3::X, -Vec3::Y]);
        assert_eq!(square, vec![1.0, 0.0, 0.0]);
        let tilted = |e: f32| (Vec3::X + Vec3::Y * e).normalize();
        let turned = interpolation_weights(kernel, Vec3::Y, &offsets, &[tilted(3e-8), tilted(-3e-8), -Vec3::Y]);
        assert_eq!(turned, square);
        // Neighbours that do face the vertex weigh as before.
        let facing = interpolation_weights(kernel, Vec3::Y, &offsets, &[Vec3::Y, Vec3::X, Vec3::Y]);
        assert!(facing[0] > 0.0 && facing[1] == 0.0);
    }
}

/// A light of negligible weight (a neighbour at the support radius, weight 0 in one turn of
/// the scene and 1e-17 in another) lends the result no bound.
#[test]
fn a_negligible_weight_lends_no_bound() {
    let light = |bound: f32| PointLight { position: Vec3::ZERO, intensity: Vec3::ONE, bound };
    let lights = [light(0.05), light(0.12)];
    for w in [0.0, 1e-17, 1e-5] {
        assert_eq!(interpolate_lights(&[1.0, w], &lights, LightBound::Gathered).bound, 0.05, "weight {w}");
    }
    assert_eq!(interpolate_lights(&[1.0, 1e-3], &lights, LightBound::Gathered).bound, 0.12);
}

#[test]
fn interpolation_weights_fall_back_to_nearest_compatible() {
    for kernel in [InterpolationKernel::Paper, InterpolationKernel::Smooth] {
        let at = |ds: &[f32]| ds.iter().map(|&d| Vec3::X * d).collect::<Vec<_>>();
        // All neighbours equally far: every spatial factor is 0.
        let w = interpolation_weights(kernel, Vec3::Y, &at(&[1.0, 1.0, 1.0]), &[-Vec3::Y, Vec3::Y, Vec3::Y]);
        assert_eq!(w, vec![0.0, 1.0, 0.0]);
        // All facing away: the nearest gets it.
        let w = interpolation_weights(kernel, Vec3::Y, &at(&[0.1, 0.2]), &[-Vec3::Y, -Vec3::Y]);
        assert_eq!(w, vec![1.0, 0.0]);
        // Coincident points (d_max = 0) are weighted by normals alone.
        let w = interpolation_weights(kernel, Vec3::Y, &at(&[0.0, 0.0]), &[Vec3::Y, Vec3::Y]);
        assert_eq!(w, vec![1.0, 1.0]);
    }
}

#[test]
fn phong_lobe_is_defined_everywhere() {
    assert_eq!(phong_lobe(0.0, 0.0), 1.0);
    assert_eq!(phong_lobe(-0.5, 3.0), 0.0);
    assert_eq!(phong_lobe(1.0, 1e4), 1.0);
    assert!((phong_lobe(0.5, 2.0) - 0.25).abs() < 1e-6);
    assert!(phong_lobe(0.999, 1e4).is_finite());
}

#[test]
fn gather_lobe_is_phong_lobe_down_to_its_cutoff() {
    assert_eq!(gather_lobe(0.0, 0.0), 1.0);
    assert_eq!(gather_lobe(-0.5, 0.0), 1.0);
    assert_eq!(gather_lobe(-0.5, 3.0), 0.0);
    assert_eq!(gather_lobe(0.0, 3.0), 0.0);
    assert_eq!(gather_lobe(1.0, 1e4), 1.0);
    let cutoff = GATHER_LOBE_CUTOFF_LOG2.exp2();
    for k in [0.5f32, 1.0, 10.0, 30.0, 60.0, 1e3, 1e4] {
        for i in 1..=1000 {
            let c = i as f32 / 1000.0;
            let (exact, gathered) = (phong_lobe(c, k), gather_lobe(c, k));
            if gathered == 0.0 {
                assert!(exact < 2.0 * cutoff, "k {k} c {c}: left out {exact}");
            } else {
                assert_eq!(gathered, exact, "k {k} c {c}");
            }
        }
    }
    // A lobe just above the cutoff is kept, one just below is not.
    assert!(gather_lobe(0.5, 63.9) > 0.0);
    assert_eq!(gather_lobe(0.5, 64.1), 0.0);
}

#[test]
fn spot_cone_flux_matches_closed_form_for_a_hard_edge() {
    let spot = SpotLight {
        position: Vec3::ZERO,
        direction: -Vec3::Y,
        inner_angle: 0.5,
        outer_angle: 0.5,
        intensity: Vec3::ONE,
        up: Vec3::Z,
    };
    let got = spot_cone_flux(&spot, 10_000).x;
    let want = 2.0 * PI * (1.0 - 0.5f32.cos());
    assert!((got - want).abs() < 1e-3 * want, "{got} vs {want}");
}

/// The CPU RSM of a spot aimed at an infinite plane: the sum of VAL flux equals the albedo times
/// the flux in the cone (0.5 % at R = 256: texel quadrature of the cone's edge).
#[test]
fn rsm_flux_sums_to_cone_flux_on_a_plane() {
    let spot = SpotLight {
        position: Vec3::new(0.0, 2.0, 0.0),
        direction: -Vec3::Y,
        inner_angle: 20f32.to_radians(),
        outer_angle: 35f32.to_radians(),
        intensity: Vec3::new(3.0, 2.0, 1.0),
        up: Vec3::new(1.0, 0.0, 1.0).normalize(),
    };
    let rho = Vec3::new(0.8, 0.5, 0.2);
    let r = 256;
    let mut total = Vec3::ZERO;
    for iy in 0..r {
        for ix in 0..r {
            let ndc = rsm_texel_ndc(ix, iy, r);
            // Light looks down -Y, its grid turned 45° about the axis by `up`.
            let dir = rsm_texel_direction(ndc, &spot);
            let y = spot.position + dir * (2.0 / dir.y.abs());
            total += rsm_texel_val(ndc, r, &spot, y, Vec3::Y, rho).flux;
        }
    }
    let want = rho * spot_cone_flux(&spot, 10_000);
    assert!((total - want).abs().max_element() <= 0.005 * want.max_element(), "{total} vs {want}");
}

/// The twin's texel directions are the RSM raster's: projected through the light's view and
/// square perspective (as `SpotVals::light_to_clip`), they land on the texel centres they came
/// from, for the default up and a tilted one.
#[test]
fn rsm_texel_directions_project_to_their_texels() {
    let direction = Vec3::new(-1.6, -0.3, -0.8).normalize();
    for up in [SpotLight::default_up(direction), Vec3::new(0.3, 0.2, 1.0).normalize()] {
        let spot = SpotLight {
            position: Vec3::new(1.0, 2.0, 3.0),
            direction,
            inner_angle: 0.2,
            outer_angle: 0.4,
            intensity: Vec3::ONE,
            up,
        };
        let clip = glam::camera::rh::proj::directx::perspective(2.0 * spot.outer_angle, 1.0, 0.1, 10.0)
            * spot.world_to_light();
        for (ix, iy) in [(0, 0), (3, 7), (15, 15), (9, 2)] {
            let ndc = rsm_texel_ndc(ix, iy, 16);
            let p = clip.project_point3(spot.position + rsm_texel_direction(ndc, &spot));
            assert!(p.truncate().abs_diff_eq(ndc, 1e-5), "up {up}: texel ({ix}, {iy}) at {p}, not {ndc}");
        }
    }
}

fn finite_non_negative(v: Vec3) -> bool {
    v.is_finite() && v.min_element() >= 0.0
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// docs/design.md §4 step 2 extremes: k in [0, 1e4], distances 1e-6..1e4 m, zero area, zero
    /// flux, VALs behind the receiver. Every output finite and non-negative.
    #[test]
    fn renormalisation_is_finite_and_non_negative(
        log_d in -6.0f32..4.0,
        dir in prop::array::uniform3(-1.0f32..1.0),
        vnorm in prop::array::uniform3(-1.0f32..1.0),
        k in prop_oneof![Just(0.0f32), Just(1e4f32), 0.0f32..1e4],
        area in prop_oneof![Just(0.0f32), 0.0f32..1.0],
        flux in prop_oneof![Just(0.0f32), 0.0f32..1e3],
        eye_dir in prop::array::uniform3(-1.0f32..1.0),
    ) {
        let dir = Vec3::from(dir).normalize_or(Vec3::Y);
        let d = 10f32.powf(log_d);
        let val = Val { position: dir * d, normal: Vec3::from(vnorm).normalize_or(-Vec3::Y), area, flux: Vec3::splat(flux) };
        let eye = Vec3::from(eye_dir).normalize_or(Vec3::Y) * 3.0;
        let g = gather_point(Vec3::ZERO, Vec3::Y, k, eye, &[val]);
        prop_assert!(finite_non_negative(g.irradiance) && finite_non_negative(g.glossy_irradiance));
        prop_assert!(g.diffuse_position.is_finite() && g.glossy_position.is_finite());
        let ld = renormalise_diffuse(Vec3::ZERO, Vec3::Y, g.irradiance, g.diffuse_position);
        let ls = renormalise_glossy(Vec3::ZERO, Vec3::Y, k, eye, g.glossy_irradiance, g.glossy_position);
        for l in [ld, ls] {
            prop_assert!(l.position.is_finite() && finite_non_negative(l.intensity), "{l:?}");
        }
        // Applied at a nearby pixel, the lights stay finite too.
        let s = Material { diffuse: Vec3::ONE, specular: Vec3::ONE, exponent: k, diffuse_texture: None };
        let p = Vec3::new(1e-3, 0.0, 0.0);
        prop_assert!(finite_non_negative(shade_sparse(p, Vec3::Y, &s, eye, &ld, Some(&ls))));
        prop_assert!(finite_non_negative(shade_brute_force(p, Vec3::Y, &s, eye, &[val], true)));
    }

    /// Every VAL behind the receiver: no light, and the lights are still defined.
    #[test]
    fn vals_behind_give_zero(n in 1usize..50, seed in 0u64..1000) {
        let vals: Vec<Val> = random_vals(seed, n).into_iter().map(|mut v| { v.position.y = -v.position.y; v }).collect();
        let g = gather_point(Vec3::ZERO, Vec3::Y, 10.0, Vec3::Y, &vals);
        prop_assert_eq!(g.irradiance, Vec3::ZERO);
        let l = renormalise_diffuse(Vec3::ZERO, Vec3::Y, g.irradiance, g.diffuse_position);
        prop_assert!(l.position.is_finite());
        prop_assert_eq!(l.intensity, Vec3::ZERO);
    }

    /// docs/design.md §4 step 4 extremes: weights are finite, non-negative and never all zero.
    #[test]
    fn interpolation_weights_are_usable(
        offsets in prop::collection::vec(prop::array::uniform3(-1e4f32..1e4), 1..=8),
        ns in prop::collection::vec(prop::array::uniform3(-1.0f32..1.0), 8),
        smooth in any::<bool>(),
    ) {
        let mut offsets: Vec<Vec3> = offsets.into_iter().map(Vec3::from).collect();
        offsets.sort_by(|a, b| a.length().total_cmp(&b.length()));
        let ns: Vec<Vec3> = ns.into_iter().take(offsets.len()).map(|n| Vec3::from(n).normalize_or(Vec3::X)).collect();
        let kernel = if smooth { InterpolationKernel::Smooth } else { InterpolationKernel::Paper };
        let w = interpolation_weights(kernel, Vec3::Y, &offsets, &ns);
        prop_assert!(w.iter().all(|w| w.is_finite() && *w >= 0.0));
        prop_assert!(w.iter().sum::<f32>() > 0.0);
    }
}

/// A flat wall (z = 0, normal +z) with sparse points on a jittered unit grid, each carrying a
/// renormalised light from a gather of its own random VALs, and the irradiance luminance that
/// a receiver at `(x, y)` gets from the light interpolated over its `k` nearest points with
/// `kernel` (unbounded: the bound is tested in `bound_light_caps_only_what_the_gather_did_not_see`).
struct Wall {
    points: Vec<Vec3>,
    lights: Vec<PointLight>,
}

impl Wall {
    fn new(side: usize, seed: u64) -> Wall {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut points = Vec::new();
        let mut lights = Vec::new();
        for i in 0..side {
            for j in 0..side {
                let jitter = Vec3::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3), 0.0);
                let x = Vec3::new(i as f32, j as f32, 0.0) + jitter;
                // VALs above the wall, facing it, in a different place for every point: the
                // averaged positions and intensities differ from point to point.
                let vals: Vec<Val> = (0..4)
                    .map(|_| Val {
                        position: x + Vec3::new(rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0), 1.5),
                        normal: -Vec3::Z,
                        area: 0.01,
                        flux: Vec3::splat(rng.random_range(0.5..3.0)),
                    })
                    .collect();
                let g = gather_point(x, Vec3::Z, 0.0, x + Vec3::Z, &vals);
                lights.push(renormalise_diffuse(x, Vec3::Z, g.irradiance, g.diffuse_position));
                points.push(x);
            }
        }
        Wall { points, lights }
    }

    fn irradiance(&self, receiver: Vec3, k: usize, weigh: impl Fn(&[Vec3], &[Vec3]) -> Vec<f32>) -> f32 {
        let mut order: Vec<usize> = (0..self.points.len()).collect();
        order.sort_by(|&a, &b| {
            let (da, db) = (self.points[a].distance(receiver), self.points[b].distance(receiver));
            da.total_cmp(&db).then(a.cmp(&b))
        });
        order.truncate(k);
        let offsets: Vec<Vec3> = order.iter().map(|&i| self.points[i] - receiver).collect();
        let w = weigh(&offsets, &vec![Vec3::Z; k]);
        let lights: Vec<PointLight> = order.iter().map(|&i| self.lights[i]).collect();
        let light = interpolate_lights(&w, &lights, LightBound::Off);
        let v = light.position - receiver;
        luminance(light.intensity) * Vec3::Z.dot(v.normalize()).max(0.0) / v.length_squared()
    }

    /// Irradiance along the line y = 5.3 from `x0`, `count` steps of `step` spacings.
    fn line(
        &self,
        k: usize,
        x0: f32,
        step: f32,
        count: usize,
        weigh: impl Fn(&[Vec3], &[Vec3]) -> Vec<f32>,
    ) -> Vec<f32> {
        (0..=count).map(|i| self.irradiance(Vec3::new(x0 + i as f32 * step, 5.3, 0.0), k, &weigh)).collect()
    }

    /// The largest step of the irradiance, relative to its mean, along x = 3..8 (dozens of
    /// neighbour-set boundaries) in steps of 1e-3 spacings, and the largest step again in
    /// steps of 1e-4 over the 1e-3 step where it occurred. A continuous light's largest step
    /// shrinks about tenfold with the step; a jump does not shrink.
    fn largest_step(&self, k: usize, weigh: impl Fn(&[Vec3], &[Vec3]) -> Vec<f32> + Copy) -> (f32, f32) {
        let coarse = self.line(k, 3.0, 1e-3, 5000, weigh);
        let mean = coarse.iter().sum::<f32>() / coarse.len() as f32;
        let (at, step) = coarse
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .enumerate()
            .fold((0, 0.0f32), |best, (i, d)| if d > best.1 { (i, d) } else { best });
        let fine = self.line(k, 3.0 + at as f32 * 1e-3, 1e-4, 10, weigh);
        let fine_step = fine.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f32::max);
        (step / mean, fine_step / mean)
    }
}

/// A receiver moving along a flat wall across neighbour-set boundaries gets
/// continuously varying light. Tolerance: a largest step of at most 5 % of the mean per 1e-3
/// spacings (the light varies by a few times its mean per spacing where few neighbours
/// share it), and refining that step tenfold must shrink it at least threefold (a jump does
/// not shrink). Equal weights over the k nearest (a kernel that is not zero at the edge of its
/// support) must fail the refinement, so this test can fail. The paper's `1 - d / d_max` is
/// continuous too (a point enters or leaves the set at `d = d_max`, weight 0).
#[test]
fn smooth_interpolation_is_continuous_along_a_wall() {
    let wall = Wall::new(12, 21);
    for k in [4, 8, 16] {
        for kernel in [InterpolationKernel::Smooth, InterpolationKernel::Paper] {
            let (coarse, fine) = wall.largest_step(k, |o, n| interpolation_weights(kernel, Vec3::Z, o, n));
            eprintln!("k {k} {kernel:?}: largest step {coarse:.2e}, refined {fine:.2e}");
            assert!(coarse < 5e-2, "k {k} {kernel:?}: the light steps by {coarse} of the mean");
            assert!(fine < coarse / 3.0, "k {k} {kernel:?}: a jump: {coarse} at 1e-3, {fine} at 1e-4");
        }
        let (coarse, fine) = wall.largest_step(k, |o, _| vec![1.0; o.len()]);
        eprintln!("k {k} equal weights: largest step {coarse:.2e}, refined {fine:.2e}");
        assert!(fine > coarse / 3.0, "k {k}: equal weights must jump: {coarse} at 1e-3, {fine} at 1e-4");
    }
}

/// The smooth kernel gives no weight to points behind the vertex's tangent
/// plane by more than `PLANE_FALLOFF` of the support radius, even when they face the same way
/// (a thin slab's parallel faces, a pillar's neighbouring face seen from its corner), and full
/// weight to points on the plane.
#[test]
fn smooth_kernel_ignores_points_behind_the_surface() {
    let offsets = [Vec3::new(0.2, 0.0, 0.0), Vec3::new(0.0, 0.5, -0.4), Vec3::new(-1.0, 0.0, 0.0)];
    let normals = [Vec3::Z; 3];
    let w = interpolation_weights(InterpolationKernel::Smooth, Vec3::Z, &offsets, &normals);
    assert!(w[0] > 0.9, "{w:?}");
    assert_eq!(w[1], 0.0, "{w:?}");
    assert_eq!(w[2], 0.0, "the farthest point is the support radius: {w:?}");
    let paper = interpolation_weights(InterpolationKernel::Paper, Vec3::Z, &offsets, &normals);
    assert!(paper[1] > 0.0, "the paper's weights do not see the plane: {paper:?}");
}

/// The smooth kernel follows a curved surface as its normals describe it: on a cylinder of
/// radius 0.3 m (a round pillar), a vertex's neighbours 20 to 50 degrees around the curve, with
/// the cylinder's normals, lie on the smooth surface through both points, so each weighs exactly
/// the radial kernel times its facing, though the 40-degree one lies deeper behind the vertex's
/// tangent plane than `PLANE_FALLOFF` of the support radius (which took all its weight: the
/// facet look); the same point on a parallel surface (the vertex's own normal) weighs nothing.
#[test]
fn smooth_kernel_follows_curved_surfaces() {
    let r = 0.3f32;
    let at = |deg: f32| {
        let a = deg.to_radians();
        (Vec3::new(r * a.cos(), r * a.sin(), 0.0), Vec3::new(a.cos(), a.sin(), 0.0))
    };
    let (v, n_v) = at(0.0);
    let angles = [20.0f32, -30.0, 40.0, -50.0];
    let offsets: Vec<Vec3> = angles.iter().map(|&a| at(a).0 - v).collect();
    let normals: Vec<Vec3> = angles.iter().map(|&a| at(a).1).collect();
    let d_max = offsets.iter().map(|o| o.length()).fold(0.0f32, f32::max);
    let w = interpolation_weights(InterpolationKernel::Smooth, n_v, &offsets, &normals);
    for k in 0..3 {
        let q = 1.0 - offsets[k].length_squared() / (d_max * d_max);
        let want = q * q * facing(n_v, normals[k]);
        assert!(want > 0.05 && (w[k] - want).abs() < 1e-5, "point {k}: {} vs {want}", w[k]);
    }
    assert!(n_v.dot(offsets[2]) < -PLANE_FALLOFF * d_max, "the 40-degree point lies behind the tangent plane");
    assert_eq!(smooth_weight(n_v, n_v, offsets[2], d_max), 0.0, "a parallel surface behind weighs nothing");
}

/// Bounded renormalisation: a light that would deliver more irradiance than its bound is scaled to the
/// bound exactly; one within it, or unbounded, is untouched; and a renormalised light applied
/// at its own sparse point is within its bound (it reproduces the gathered irradiance).
#[test]
fn bound_light_caps_only_what_the_gather_did_not_see() {
    let close = PointLight { position: Vec3::new(0.0, 0.0, 0.01), intensity: Vec3::ONE, bound: 2.0 };
    let bounded = bound_light(Vec3::ZERO, Vec3::Z, &close);
    let delivered = luminance(bounded.intensity) / 0.01f32.powi(2);
    assert!((delivered - 2.0).abs() < 1e-4, "{delivered}");
    let far = PointLight { position: Vec3::new(0.0, 0.0, 10.0), ..close };
    assert_eq!(bound_light(Vec3::ZERO, Vec3::Z, &far), far);
    let unbounded = PointLight { bound: 0.0, ..close };
    assert_eq!(bound_light(Vec3::ZERO, Vec3::Z, &unbounded), unbounded);

    for seed in 0..20 {
        let vals = random_vals(seed, 30);
        let g = gather_point(Vec3::ZERO, Vec3::Y, 0.0, Vec3::Y, &vals);
        let light = renormalise_diffuse(Vec3::ZERO, Vec3::Y, g.irradiance, g.diffuse_position);
        let applied = bound_light(Vec3::ZERO, Vec3::Y, &light);
        assert!((applied.intensity - light.intensity).abs().max_element() <= 1e-4 * light.intensity.max_element());
    }
}
