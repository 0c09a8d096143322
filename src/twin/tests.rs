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

#[test]
fn interpolation_weights_fall_back_to_nearest_compatible() {
    // All neighbours equally far: every spatial factor is 1 - 1 = 0.
    let w = interpolation_weights(Vec3::Y, &[1.0, 1.0, 1.0], &[-Vec3::Y, Vec3::Y, Vec3::Y]);
    assert_eq!(w, vec![0.0, 1.0, 0.0]);
    // All facing away: the nearest gets it.
    let w = interpolation_weights(Vec3::Y, &[0.1, 0.2], &[-Vec3::Y, -Vec3::Y]);
    assert_eq!(w, vec![1.0, 0.0]);
    // Coincident points (d_max = 0) are weighted by normals alone.
    let w = interpolation_weights(Vec3::Y, &[0.0, 0.0], &[Vec3::Y, Vec3::Y]);
    assert_eq!(w, vec![1.0, 1.0]);
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
fn spot_cone_flux_matches_closed_form_for_a_hard_edge() {
    let spot = SpotLight {
        position: Vec3::ZERO,
        direction: -Vec3::Y,
        inner_angle: 0.5,
        outer_angle: 0.5,
        intensity: Vec3::ONE,
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
    };
    let rho = Vec3::new(0.8, 0.5, 0.2);
    let r = 256;
    let mut total = Vec3::ZERO;
    let t = spot.outer_angle.tan();
    for iy in 0..r {
        for ix in 0..r {
            let ndc = rsm_texel_ndc(ix, iy, r);
            // Light looks down -Y; image x = world x, image y = world z (any orthonormal frame).
            let dir = Vec3::new(ndc.x * t, -1.0, ndc.y * t);
            let y = spot.position + dir * (2.0 / dir.y.abs());
            total += rsm_texel_val(ndc, r, &spot, y, Vec3::Y, rho).flux;
        }
    }
    let want = rho * spot_cone_flux(&spot, 10_000);
    assert!((total - want).abs().max_element() <= 0.005 * want.max_element(), "{total} vs {want}");
}

fn finite_non_negative(v: Vec3) -> bool {
    v.is_finite() && v.min_element() >= 0.0
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// DESIGN.md §4 step 2 extremes: k in [0, 1e4], distances 1e-6..1e4 m, zero area, zero
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

    /// DESIGN.md §4 step 4 extremes: weights are finite, non-negative and never all zero.
    #[test]
    fn interpolation_weights_are_usable(
        ds in prop::collection::vec(0.0f32..1e4, 1..=8),
        ns in prop::collection::vec(prop::array::uniform3(-1.0f32..1.0), 8),
    ) {
        let mut ds = ds;
        ds.sort_by(f32::total_cmp);
        let ns: Vec<Vec3> = ns.into_iter().take(ds.len()).map(|n| Vec3::from(n).normalize_or(Vec3::X)).collect();
        let w = interpolation_weights(Vec3::Y, &ds, &ns);
        prop_assert!(w.iter().all(|w| w.is_finite() && *w >= 0.0));
        prop_assert!(w.iter().sum::<f32>() > 0.0);
    }
}
