//! Every GPU pass against its CPU twin in `relume::twin`, on the same inputs: each pass's
//! input is read back from the GPU, fed to the twin, and the outputs compared.
//!
//! Tolerances: lavapipe evaluates `inverseSqrt`, `exp2`/`log2` and `acos` with a few ulp of
//! error and may contract multiply-adds, so quantities agree to ~1e-5 relative; we allow 1e-3 of
//! the largest value of the compared buffer (plus a tiny absolute floor for zeros), which is
//! still far below anything visible and far below the sparse method's own error.

use super::{assert_close, gpu, load_scene, load_test_room};
use glam::{Mat4, Vec3};
use relume::gpu::raw::RawPointLight;
use relume::gpu::visibility::disks::twin::Combine;
use relume::renderer::{Method, Renderer};
use relume::twin::near_field::{NearPixel, near_field_terms};
use relume::twin::{self, PointLight, Val};

const REL: f32 = 1e-3;

fn max_of(v: impl Iterator<Item = Vec3>) -> f32 {
    v.map(|x| x.max_element()).fold(0.0, f32::max)
}

fn light(r: &RawPointLight) -> PointLight {
    r.into()
}

#[test]
fn sparse_pipeline_matches_cpu_twins() {
    let gpu = gpu();
    let mut scene = load_test_room();
    // The paper's glossy chain (renormalised glossy lights, interpolated per vertex); the
    // default, the interpolated glossy radiance, is `glossy_radiance_interpolation_matches_cpu_twins`.
    scene.settings.sparse.glossy_interpolation = relume::scene::GlossyInterpolation::Lights;
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    assert!(renderer.glossy(), "the small fixture has glossy materials");
    let (w, h) = (48, 40);
    let frame = renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let vals: Vec<Val> = renderer.read_vals(&gpu).unwrap();
    assert!(vals.len() > 100, "the spot must produce VALs, got {}", vals.len());
    let mid = renderer.read_sparse_intermediates(&gpu).unwrap();
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();

    // Step 1: gather.
    assert_gather_matches_twin(flat, &mid, eye, &vals);

    // Step 2: renormalisation, from the GPU's own gathered values.
    let mut cpu_sparse = (Vec::new(), Vec::new());
    for (i, p) in flat.sparse_points.iter().enumerate() {
        let (x, n) = (Vec3::from(p.position), Vec3::from(p.normal));
        let (gd, gg) = (&mid.gathered_diffuse[i], &mid.gathered_glossy[i]);
        cpu_sparse.0.push(twin::renormalise_diffuse(x, n, gd.irradiance.into(), gd.position.into()));
        let glossy = twin::renormalise_glossy(x, n, p.exponent, eye, gg.irradiance.into(), gg.position.into());
        cpu_sparse.1.push(twin::with_bound(glossy, gd.irradiance.into()));
    }
    for (cpu, gpu_lights, what) in
        [(&cpu_sparse.0, &mid.sparse_diffuse, "I_d"), (&cpu_sparse.1, &mid.sparse_glossy, "I_s")]
    {
        let scale = max_of(cpu.iter().map(|l| l.intensity));
        for (i, (c, g)) in cpu.iter().zip(gpu_lights).enumerate() {
            let g = light(g);
            assert_close(g.intensity, c.intensity, REL, scale, 1e-9, &format!("{what} at sparse point {i}"));
            let bound_scale = cpu.iter().map(|l| l.bound).fold(0.0, f32::max);
            assert!(
                (g.bound - c.bound).abs() <= REL * bound_scale + 1e-9,
                "{what} bound at {i}: {} vs {}",
                g.bound,
                c.bound
            );
            if c.intensity.max_element() > 1e-3 * scale {
                assert_close(g.position, c.position, 1e-3, 1.0, 1e-4, &format!("{what} position at {i}"));
            }
        }
    }

    // Step 4: interpolation, from the GPU's own sparse lights.
    assert_interpolation_matches_twin(flat, &mid, scene.settings.sparse, eye, None);

    // Step 5: per-pixel shading, from the GPU's visibility buffer and vertex lights.
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let expected = sparse_shading_twin(flat, (&flat.indices, &flat.triangle_materials), &hits, &mid, eye);
    let scale = max_of(expected.iter().flatten().copied());
    assert!(scale > 0.0, "some pixel must receive indirect light");
    for (i, e) in expected.iter().enumerate() {
        assert_eq!(e.is_some(), frame.indirect.covered(i), "coverage of pixel {i}");
        if let Some(e) = e {
            assert_close(frame.indirect.rgb(i), *e, REL, scale, 1e-9, &format!("indirect pixel {i}"));
        }
    }

    // Direct light: wherever the shadow test passes, the GPU equals the twin.
    let spot = renderer.spot().unwrap();
    let direct = super::per_hit(flat, &hits, |p, n, surface| twin::rsm::direct_radiance(p, n, surface, eye, &spot));
    let scale = max_of(direct.iter().flatten().copied());
    let mut lit = 0;
    for (i, want) in direct.iter().enumerate() {
        let got = frame.direct.rgb(i);
        if let (Some(want), true) = (want, got.max_element() > 0.0) {
            lit += 1;
            assert_close(got, *want, REL, scale, 1e-9, &format!("direct pixel {i}"));
        }
    }
    assert!(lit > 20, "the spot must light some visible pixels directly, lit {lit}");
}

/// `glossy_interpolation: "radiance"`: the interpolation averages the GPU's gathered glossy
/// sums (`twin::interpolate_radiance`) and the pixels apply them through their own lobe factor
/// (`twin::glossy_from_radiance`), with no glossy point light anywhere (the glossy light
/// buffers do not exist); the image differs from the paper's glossy lights only where the
/// glossy lobe is. Same tolerances as the rest of this file.
#[test]
fn glossy_radiance_interpolation_matches_cpu_twins() {
    use relume::scene::GlossyInterpolation;
    let gpu = gpu();
    let mut scene = load_test_room();
    let (w, h) = (48, 40);
    scene.settings.sparse.glossy_interpolation = GlossyInterpolation::Lights;
    let lights = Renderer::new(&gpu, &scene).unwrap().render(&gpu, Method::Sparse, w, h).unwrap();
    scene.settings.sparse.glossy_interpolation = GlossyInterpolation::Radiance;
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let mid = renderer.read_sparse_intermediates(&gpu).unwrap();
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    assert!(mid.sparse_glossy.is_empty() && mid.vertex_glossy.is_empty(), "no glossy point lights");
    // The gather sums the lobe without its mean position (`GatherLobes::GlossyRadiance`).
    assert_gather_matches_twin(flat, &mid, eye, &renderer.read_vals(&gpu).unwrap());
    assert!(mid.gathered_glossy.iter().all(|g| g.weight == 0.0), "no glossy mean position is summed");
    assert_eq!(mid.vertex_glossy_radiance.len(), flat.vertices.len());
    assert!(mid.vertex_glossy_radiance.iter().any(|g| g[0] > 0.0), "some vertex must see glossy light");
    assert_interpolation_matches_twin(flat, &mid, scene.settings.sparse, eye, None);
    let scale = assert_pixels_match_twin(&gpu, &renderer, &frame, &mid);
    let changed = (0..lights.indirect.pixels.len())
        .filter(|&i| (lights.indirect.rgb(i) - frame.indirect.rgb(i)).abs().max_element() > REL * scale)
        .count();
    assert!(changed > 0, "the glossy lobe must be carried differently");
}

/// The camera's simplified copy of the meshes (the frame budget's cheapest rung): the camera
/// draws under half the triangles, the interpolation lights their vertices (matching its
/// twin) and no other, every covered pixel is the CPU twin's shading decoded on the simplified
/// triangles from the GPU's per-vertex light, the image stays close to the full meshes' (under
/// 2 % of the pixels change coverage, the mean change under 5 % of the brightest), the frame
/// has its error estimate, and `None` and the other methods draw the full meshes.
#[test]
fn the_cameras_simplified_copy_matches_cpu_twins() {
    use relume::renderer::budget::{CAMERA_LOD_ERROR, CAMERA_LOD_RATIO};
    let gpu = gpu();
    let scene = load_test_room();
    let (w, h) = (96, 80);
    // A fresh renderer's first frame draws the copy: a vertex it does not use keeps the light
    // buffers' zeros.
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.set_camera_lod(&gpu, Some((CAMERA_LOD_RATIO, CAMERA_LOD_ERROR))).unwrap();
    renderer.set_error_estimate(Some(relume::renderer::estimate::PER_FRAME));
    let frame = renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let lod = renderer.camera_lod_drawn().expect("a sparse frame draws the simplified copy").clone();
    let all = renderer.scene.flat.triangle_count();
    assert!(lod.count() * 2 < all, "{} of {all} triangles drawn", lod.count());
    let mid = renderer.read_sparse_intermediates(&gpu).unwrap();
    let scale = assert_pixels_match_twin(&gpu, &renderer, &frame, &mid);
    // The interpolation lit the vertices of the simplified triangles, and only those.
    let used = lod.vertices();
    let eye = renderer.view().eye();
    assert_interpolation_matches_twin(&renderer.scene.flat, &mid, scene.settings.sparse, eye, Some(&used));
    let lit = |v: usize| mid.vertex_diffuse[v].intensity.iter().any(|&c| c != 0.0);
    let unused = (0..mid.vertex_diffuse.len()).filter(|v| used.binary_search(&(*v as u32)).is_err());
    assert_eq!(unused.filter(|&v| lit(v)).count(), 0, "a vertex the copy does not use was lit");
    assert!(used.iter().filter(|&&v| lit(v as usize)).count() * 2 > used.len(), "most used vertices are lit");
    let estimate = frame.error_estimate.expect("an estimate of the simplified frame");
    assert!(estimate.rel_rmse.is_finite() && estimate.rel_rmse > 0.0, "{estimate:?}");

    renderer.set_camera_lod(&gpu, None).unwrap();
    let full = renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    assert!(renderer.camera_lod_drawn().is_none());
    let pixels = full.indirect.pixels.len();
    let coverage_changed = (0..pixels).filter(|&i| full.indirect.covered(i) != frame.indirect.covered(i)).count();
    assert!(coverage_changed * 50 < pixels, "{coverage_changed} of {pixels} pixels changed coverage");
    let both: Vec<usize> = (0..pixels).filter(|&i| full.indirect.covered(i) && frame.indirect.covered(i)).collect();
    let mean_change =
        both.iter().map(|&i| (full.indirect.rgb(i) - frame.indirect.rgb(i)).abs().max_element()).sum::<f32>()
            / both.len() as f32;
    eprintln!(
        "simplified copy: {} of {all} triangles, {} of {} vertices, {coverage_changed} of {pixels} pixels changed \
         coverage, mean change {mean_change} of {scale}, error estimate {:.4}",
        lod.count(),
        used.len(),
        mid.vertex_diffuse.len(),
        estimate.rel_rmse
    );
    assert!(mean_change < 0.05 * scale, "mean change {mean_change} of {scale}");
    // The brute force decodes the camera's pixels on the full meshes: it draws them.
    renderer.set_camera_lod(&gpu, Some((CAMERA_LOD_RATIO, CAMERA_LOD_ERROR))).unwrap();
    renderer.set_error_estimate(None);
    renderer.render(&gpu, Method::BruteForce, w, h).unwrap();
    assert!(renderer.camera_lod_drawn().is_none(), "the brute force draws the full meshes");
}

/// Every covered pixel of `frame`'s indirect light against [`sparse_shading_twin`] at the
/// renderer's camera view, from the GPU's own intermediates; returns the scale (the brightest
/// expected pixel).
fn assert_pixels_match_twin(
    gpu: &relume::gpu::Gpu,
    renderer: &Renderer,
    frame: &relume::renderer::Rendered,
    mid: &relume::renderer::SparseIntermediates,
) -> f32 {
    let hits = renderer.camera_view().unwrap().read(gpu).unwrap();
    let flat = &renderer.scene.flat;
    // The triangles the camera drew: the scene's, or their simplified copy.
    let triangles = match renderer.camera_lod_drawn() {
        Some(t) => (&t.indices[..], &t.materials[..]),
        None => (&flat.indices[..], &flat.triangle_materials[..]),
    };
    let expected = sparse_shading_twin(flat, triangles, &hits, mid, renderer.view().eye());
    let scale = max_of(expected.iter().flatten().copied());
    for (i, e) in expected.iter().enumerate() {
        if let Some(e) = e {
            assert_close(frame.indirect.rgb(i), *e, REL, scale, 1e-9, &format!("indirect pixel {i}"));
        }
    }
    scale
}

/// `twin::shade_sparse` at every pixel of `hits`, from the GPU's vertex lights in `mid`;
/// `triangles` (corner indices, materials) are those `hits` name.
fn sparse_shading_twin(
    flat: &relume::gpu::scene::FlatScene,
    (indices, materials): (&[u32], &[u32]),
    hits: &[Option<relume::gpu::raster::Hit>],
    mid: &relume::renderer::SparseIntermediates,
    eye: Vec3,
) -> Vec<Option<Vec3>> {
    let vd: Vec<PointLight> = mid.vertex_diffuse.iter().map(light).collect();
    let vs: Vec<PointLight> = mid.vertex_glossy.iter().map(light).collect();
    let vg: Vec<Vec3> = mid.vertex_glossy_radiance.iter().map(|g| Vec3::from_slice(&g[..3])).collect();
    let mut expected = Vec::new();
    for hit in hits {
        expected.push(hit.map(|h| {
            let (p, n, surface) = flat.surface_on(indices, materials, h.triangle, h.barycentrics);
            let t = 3 * h.triangle as usize;
            let corners = [0, 1, 2].map(|k| indices[t + k] as usize);
            let lerp = |l: &[PointLight]| PointLight {
                position: twin::barycentric(
                    h.barycentrics,
                    l[corners[0]].position,
                    l[corners[1]].position,
                    l[corners[2]].position,
                ),
                intensity: twin::barycentric(
                    h.barycentrics,
                    l[corners[0]].intensity,
                    l[corners[1]].intensity,
                    l[corners[2]].intensity,
                ),
                bound: twin::barycentric(
                    h.barycentrics,
                    Vec3::splat(l[corners[0]].bound),
                    Vec3::splat(l[corners[1]].bound),
                    Vec3::splat(l[corners[2]].bound),
                )
                .x,
            };
            if vg.is_empty() {
                twin::shade_sparse(p, n, &surface, eye, &lerp(&vd), Some(&lerp(&vs)))
            } else {
                // `glossy_interpolation: "radiance"`: the diffuse light, and the corners'
                // glossy sums interpolated through the pixel's lobe factor.
                let g = twin::barycentric(h.barycentrics, vg[corners[0]], vg[corners[1]], vg[corners[2]]);
                twin::shade_sparse(p, n, &surface, eye, &lerp(&vd), None) + twin::glossy_from_radiance(&surface, g)
            }
        }));
    }
    expected
}

/// Past llvmpipe's loop limit the gather runs in VAL ranges, one dispatch each, merged: with
/// more VALs than one invocation may loop over (an RSM of 300², ~70k VALs), every sparse point
/// must still receive all of them. Before the ranges, the GPU silently summed the first ~63k.
#[test]
fn gather_takes_every_val_past_the_cpu_loop_limit() {
    let gpu = gpu();
    let mut scene = load_test_room();
    scene.settings.rsm_resolution = 300;
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let vals: Vec<Val> = renderer.read_vals(&gpu).unwrap();
    assert!(
        vals.len() as u32 > relume::gpu::Gpu::CPU_MAX_GATHERED_VALS,
        "the RSM must exceed one invocation's loop budget: {} VALs",
        vals.len()
    );
    let mid = renderer.read_sparse_intermediates(&gpu).unwrap();
    assert_gather_matches_twin(&renderer.scene.flat, &mid, renderer.view().eye(), &vals);
}

/// The gather with 1, 5 and 7 sparse points per invocation (CPU adapters take
/// `gather::CPU_RECEIVERS`, 8, which every other gather test here runs; 5 and 7 leave the last
/// invocation's slots partly past the last of the 768 points), and with one point shared by 8
/// and 16 invocations (GPUs' `gather::GPU_LANES`), against `twin::gather_point`, both lobes.
/// Same tolerances as the rest of this file.
#[test]
fn gather_variants_match_cpu_twin() {
    use relume::gpu::raw::RawGathered;
    use relume::gpu::sparse::gather::{Gather, GatherInput, GatherLobes};
    use relume::gpu::timing::Recorder;
    let gpu = gpu();
    let scene = load_test_room();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let vals = renderer.read_vals(&gpu).unwrap();
    let n = renderer.scene.flat.sparse_points.len();
    assert!(renderer.glossy() && !n.is_multiple_of(5) && !n.is_multiple_of(7), "{n} points");
    for (receivers, lanes) in [(1, 1), (5, 1), (7, 1), (1, 8), (1, 16)] {
        let gathered = relume::gpu::Lobes::new::<RawGathered>(&gpu, "test.gathered", n, true).unwrap();
        let mut pass =
            Gather::variant(&gpu, &renderer.scene, GatherLobes::GlossyLights, 64, (receivers, lanes)).unwrap();
        pass.fit(&gpu, &renderer.scene, renderer.val_capacity()).unwrap();
        let mut rec = Recorder::new(&gpu, "test.gather", 1);
        let input = GatherInput { scene: &renderer.scene, vals: &renderer.vals, gathered: &gathered, groups: None };
        rec.stage("gather", |e, s| pass.record(&gpu, e, &input, s)).unwrap();
        rec.finish().unwrap();
        let mid = relume::renderer::SparseIntermediates {
            gathered_diffuse: gpu.read_buffer(&gathered.diffuse, n).unwrap(),
            gathered_glossy: gpu.read_buffer(gathered.glossy.as_ref().unwrap(), n).unwrap(),
            ..Default::default()
        };
        // A variant gathers the lobe at every point, those on diffuse materials too.
        let flat = relume::gpu::scene::FlatScene {
            glossy_points: renderer.scene.flat.base_sparse_count(),
            ..renderer.scene.flat.clone()
        };
        assert_gather_matches_twin(&flat, &mid, renderer.view().eye(), &vals);
    }
}

/// The renderer's gather with the GPUs' kernel (`gather::GPU_LANES` invocations per sparse
/// point, forced on this CPU adapter through `Gpu::gather_lanes`) gives the frame that the CPU
/// adapters' kernel (8 points per invocation) gives, the same pairs summed in another order: on
/// the glossy open room at `accurate`, whose gathers run through the clusters' table and at the
/// adaptive candidates the frame chooses (the grouped and the chosen passes), and at `balanced`.
#[test]
fn the_gpus_gather_renders_the_frame_of_the_cpu_adapters_gather() {
    use relume::scene::Scene;
    use relume::scene::settings::Quality;
    let path = super::fixture("scenes/cornell_glossy_open.json");
    let mut lanes = gpu();
    lanes.gather_lanes = Some(relume::gpu::sparse::gather::GPU_LANES);
    for quality in [Quality::Balanced, Quality::Accurate] {
        let scene = Scene::load_at(&path, Some(quality)).unwrap();
        let render = |gpu: &relume::gpu::Gpu| {
            let mut renderer = Renderer::new(gpu, &scene).unwrap();
            renderer.render(gpu, Method::Sparse, 32, 64).unwrap().indirect
        };
        let (cpu_kernel, gpu_kernel) = (render(&gpu()), render(&lanes));
        let largest = cpu_kernel.pixels.iter().flat_map(|p| p[..3].iter().copied()).fold(0.0f32, f32::max);
        let rel_rmse = relume::image::relative_rmse(&gpu_kernel, &cpu_kernel);
        assert!(largest > 0.0 && rel_rmse < 1e-4, "{quality:?}: rel RMSE {rel_rmse} between the kernels' frames");
    }
}

/// The GPU's gathered light (diffuse and glossy irradiance, mean diffuse VAL position) at every
/// sparse point against `twin::gather_point` over `vals`.
fn assert_gather_matches_twin(
    flat: &relume::gpu::scene::FlatScene,
    mid: &relume::renderer::SparseIntermediates,
    eye: Vec3,
    vals: &[Val],
) {
    assert_far_field_gather_matches_twin(flat, mid, eye, vals, 0.0);
}

/// [`assert_gather_matches_twin`] with the near field at `near_radius` left out
/// (`twin::gather_far_field`).
fn assert_far_field_gather_matches_twin(
    flat: &relume::gpu::scene::FlatScene,
    mid: &relume::renderer::SparseIntermediates,
    eye: Vec3,
    vals: &[Val],
    near_radius: f32,
) {
    let cpu: Vec<twin::Gathered> = flat
        .sparse_points
        .iter()
        .map(|p| twin::gather_far_field(p.position.into(), p.normal.into(), p.exponent, eye, vals, near_radius))
        .collect();
    let scale_e = max_of(cpu.iter().map(|g| g.irradiance));
    let scale_g = max_of(cpu.iter().map(|g| g.glossy_irradiance));
    assert!(scale_e > 0.0 && scale_g > 0.0);
    let base = flat.base_sparse_count() as usize;
    for (i, c) in cpu.iter().enumerate() {
        if i >= base && mid.adaptive_chosen[i - base] == 0 {
            continue; // An adaptive candidate not gathered this frame.
        }
        let (gd, gg) = (&mid.gathered_diffuse[i], &mid.gathered_glossy[i]);
        assert_close(gd.irradiance.into(), c.irradiance, REL, scale_e, 1e-9, &format!("E at sparse point {i}"));
        // Points on a material without a glossy lobe (after `glossy_points`, before the
        // candidates) gather none.
        let g = if (flat.glossy_points as usize..base).contains(&i) { Vec3::ZERO } else { c.glossy_irradiance };
        assert_close(gg.irradiance.into(), g, REL, scale_g, 1e-9, &format!("G at sparse point {i}"));
        if c.irradiance.max_element() > 1e-3 * scale_e {
            assert_close(gd.position.into(), c.diffuse_position, 1e-3, 1.0, 1e-4, &format!("l'_d at {i}"));
        }
    }
}

/// The near field (`settings.sparse.near_field`): the gather leaves each VAL's near-field share
/// out (`twin::gather_far_field`), and every pixel gets the sparse shading of its vertex lights
/// plus the near VALs' light found through the hashed grid, which must equal
/// `twin::shade_near_field` over every VAL (the grid may only skip VALs beyond the radius).
/// Same tolerances as the rest of this file.
#[test]
fn near_field_matches_cpu_twins() {
    near_field_matches_twins(None, 1.5, (40, 32), 1);
}

/// As [`near_field_matches_cpu_twins`], interleaved over blocks of 4 x 4 pixels: each pixel's
/// subset of the near VALs, then the filter over its block
/// (`twin::near_field::{near_field_terms, filter}`), the close share added by each pixel, the
/// redo of the pixels the filter leaves. The image's sides are no multiple of the block's or of a
/// workgroup's, so that the sub-images the shade walks end inside both; the radius of 4
/// spacings puts VALs within the close radius (1 spacing) of pixels.
#[test]
fn interleaved_near_field_matches_cpu_twins() {
    near_field_matches_twins(None, 4.0, (35, 30), 4);
}

/// As [`near_field_matches_cpu_twins`] with ~70k VALs and a radius of 8 spacings, so that many
/// pixels have more near VALs than one invocation may loop over on a CPU adapter (the VAL
/// ranges of the per-pixel pass).
#[test]
fn near_field_takes_every_near_val_past_the_cpu_loop_limit() {
    near_field_matches_twins(Some(300), 8.0, (10, 8), 1);
}

fn near_field_matches_twins(rsm_resolution: Option<u32>, near_field: f32, (w, h): (u32, u32), side: u32) {
    let gpu = gpu();
    let mut scene = load_test_room();
    scene.settings.sparse.near_field = near_field;
    scene.settings.sparse.near_field_interleave = side;
    if let Some(r) = rsm_resolution {
        scene.settings.rsm_resolution = r;
    }
    let radius = near_field * scene.sparse_spacing();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let stages: Vec<&str> = frame.timings.stages.iter().map(|(s, _)| s.as_str()).collect();
    assert!(stages.contains(&"near_field_grid") && stages.contains(&"near_field"), "{stages:?}");
    let vals: Vec<Val> = renderer.read_vals(&gpu).unwrap();
    let mid = renderer.read_sparse_intermediates(&gpu).unwrap();
    let (flat, eye) = (&renderer.scene.flat, renderer.view().eye());
    assert_far_field_gather_matches_twin(flat, &mid, eye, &vals, radius);
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let sparse = sparse_shading_twin(flat, (&flat.indices, &flat.triangle_materials), &hits, &mid, eye);
    let centres = vertex_centres(flat, scene.settings.sparse.kernel);
    let subsets = side * side;
    // The receiver at a hit and its near-field centre (its triangle's corners' centres).
    let receiver_at = |triangle: u32, b: glam::Vec2| {
        let c = [0, 1, 2].map(|k| centres[flat.indices[3 * triangle as usize + k] as usize]);
        (flat.receiver_at(triangle, b, eye), twin::barycentric(b, c[0], c[1], c[2]))
    };
    let receivers: Vec<Option<(NearPixel, relume::scene::Material)>> = hits
        .iter()
        .enumerate()
        .map(|(i, hit)| {
            hit.map(|h| {
                let (r, centre) = receiver_at(h.triangle, h.barycentrics);
                let subset = twin::near_field::pixel_subset(i as u32 % w, i as u32 / w, side);
                let receiver = (r.position, r.normal, r.geometric);
                let exponent = r.surface.exponent;
                let parts = near_field_terms(receiver, exponent, eye, centre, &vals, (subset, subsets), true, radius);
                (NearPixel { parts, position: r.position, normal: r.geometric }, r.surface)
            })
        })
        .collect();
    let pixels: Vec<Option<NearPixel>> = receivers.iter().map(|r| r.as_ref().map(|(p, _)| *p)).collect();
    // Interleaved, the close share the shade adds itself must show at the tolerance below.
    let close = receivers.iter().flatten().map(|(p, m)| p.parts.close.radiance(m, true));
    let close = max_of(close);
    // A pixel the filter leaves to the redo: every near VAL at the pixel.
    let whole = |i: usize| {
        let h = hits[i].expect("the filter hands on covered pixels only");
        let (r, centre) = receiver_at(h.triangle, h.barycentrics);
        let receiver = (r.position, r.normal, r.geometric);
        twin::near_field::terms_over(receiver, r.surface.exponent, eye, centre, &vals, true, radius)
    };
    let redone = std::cell::Cell::new(0);
    let filtered = twin::near_field::filter(&pixels, w, side, radius, |i| {
        redone.set(redone.get() + 1);
        whole(i)
    });
    if side > 1 {
        // The test room has corners and image edges: the redo must be exercised.
        assert!(redone.get() > 0, "no pixel left to the redo");
    }
    let near: Vec<Option<Vec3>> = filtered
        .iter()
        .zip(&receivers)
        .map(|(f, r)| f.zip(r.as_ref()).map(|(f, (_, m))| f.radiance(m, true)))
        .collect();
    if side == 1 {
        // Not interleaved, the terms are the sum over every VAL.
        for (i, hit) in hits.iter().enumerate() {
            let Some(h) = hit else { continue };
            let (r, centre) = receiver_at(h.triangle, h.barycentrics);
            let all =
                twin::shade_near_field(r.position, r.normal, r.geometric, &r.surface, eye, centre, &vals, true, radius);
            let n = near[i].unwrap();
            assert!((all - n).abs().max_element() <= 1e-4 * all.max_element() + 1e-12, "pixel {i}: {all} vs {n}");
        }
    }
    let mut most_near = 0;
    if rsm_resolution.is_some() {
        for hit in hits.iter().flatten() {
            let (p, _, _) = flat.surface_at(hit.triangle, hit.barycentrics);
            most_near = most_near.max(vals.iter().filter(|v| v.position.distance(p) < radius).count());
        }
        assert!(most_near as u32 > relume::gpu::LLVMPIPE_LOOP_LIMIT / 3, "{most_near} near VALs at most");
    }
    let expected: Vec<Option<Vec3>> = sparse.iter().zip(&near).map(|(s, n)| s.zip(*n).map(|(s, n)| s + n)).collect();
    let scale = max_of(near.iter().flatten().copied());
    assert!(scale > 0.0, "some pixel must have a VAL within the radius");
    let scale = max_of(expected.iter().flatten().copied());
    if side > 1 {
        assert!(close > 10.0 * REL * scale, "close share at most {close} against {scale}: not tested");
    }
    for (i, e) in expected.iter().enumerate() {
        assert_eq!(e.is_some(), frame.indirect.covered(i), "coverage of pixel {i}");
        if let Some(e) = e {
            assert_close(frame.indirect.rgb(i), *e, REL, scale, 1e-9, &format!("sparse + near-field pixel {i}"));
        }
    }
}

/// Every vertex's near-field centre (`twin::near_field::vertex_centre` over its sparse
/// neighbours, as the GPU's `centres` takes them).
fn vertex_centres(flat: &relume::gpu::scene::FlatScene, kernel: relume::scene::InterpolationKernel) -> Vec<Vec3> {
    let k = flat.neighbours as usize;
    flat.vertices
        .iter()
        .enumerate()
        .map(|(v, vertex)| {
            let neighbours: Vec<(Vec3, Vec3)> = flat.vertex_neighbours[v * k..(v + 1) * k]
                .iter()
                .take_while(|&&i| i != u32::MAX)
                .map(|&i| {
                    (flat.sparse_points[i as usize].position.into(), flat.sparse_points[i as usize].normal.into())
                })
                .collect();
            twin::near_field::vertex_centre(kernel, vertex.position.into(), vertex.normal.into(), &neighbours)
        })
        .collect()
}

#[test]
fn brute_force_matches_cpu_twin() {
    brute_force_matches_twin(None, (32, 24));
}

/// As [`gather_takes_every_val_past_the_cpu_loop_limit`], for the brute force: ~70k VALs, more
/// than one invocation may loop over on a CPU adapter, all of them at every pixel.
#[test]
fn brute_force_takes_every_val_past_the_cpu_loop_limit() {
    brute_force_matches_twin(Some(300), (10, 8));
}

fn brute_force_matches_twin(rsm_resolution: Option<u32>, (w, h): (u32, u32)) {
    let gpu = gpu();
    let mut scene = load_test_room();
    if let Some(r) = rsm_resolution {
        scene.settings.rsm_resolution = r;
    }
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::BruteForce, w, h).unwrap();
    let vals = renderer.read_vals(&gpu).unwrap();
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    let expected = super::per_receiver(flat, &hits, eye, |r| {
        twin::shade_brute_force_sided(r.position, r.normal, r.geometric, &r.surface, eye, &vals, renderer.glossy())
    });
    if rsm_resolution.is_some() {
        assert!(vals.len() as u32 > relume::gpu::Gpu::CPU_MAX_GATHERED_VALS, "{} VALs", vals.len());
    }
    let scale = max_of(expected.iter().flatten().copied());
    assert!(scale > 0.0);
    for (i, e) in expected.iter().enumerate() {
        assert_eq!(e.is_some(), frame.indirect.covered(i));
        if let Some(e) = e {
            assert_close(frame.indirect.rgb(i), *e, REL, scale, 1e-9, &format!("brute-force pixel {i}"));
        }
    }
}

#[test]
fn rsm_vals_match_cpu_twin() {
    let gpu = gpu();
    let scene = load_test_room();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let gpu_vals = renderer.read_vals(&gpu).unwrap();
    let hits = renderer.rsm_view().unwrap().read(&gpu).unwrap();
    let r = renderer.rsm_view().unwrap().width;
    let flat = &renderer.scene.flat;
    let spot = renderer.spot().unwrap();
    let mut cpu_vals = Vec::new();
    for (t, hit) in hits.iter().enumerate() {
        if let Some(h) = hit {
            let (y, n, surface) = flat.surface_at(h.triangle, h.barycentrics);
            let ndc = twin::rsm::rsm_texel_ndc(t as u32 % r, t as u32 / r, r);
            let v = twin::rsm::rsm_texel_val(ndc, r, &spot, y, n, surface.diffuse);
            if v.flux.max_element() > 0.0 {
                cpu_vals.push(v);
            }
        }
    }
    assert_eq!(gpu_vals.len(), cpu_vals.len(), "VAL count");
    assert_eq!(unmatched_vals(&cpu_vals, &gpu_vals), 0, "a CPU VAL has no GPU VAL at its position");
}

/// Each of `expected` against the VAL of `actual` at its position (the GPU appends in no fixed
/// order: matched by position), flux, area and normal; the count of those with none there.
fn unmatched_vals(expected: &[Val], actual: &[Val]) -> usize {
    let positions: Vec<[f32; 3]> = actual.iter().map(|v| v.position.to_array()).collect();
    let tree: kiddo::ImmutableKdTree<f32, 3> = kiddo::ImmutableKdTree::new_from_slice(&positions).unwrap();
    let scale = max_of(expected.iter().map(|v| v.flux));
    let mut unmatched = 0;
    for e in expected {
        let nearest = tree.query(&e.position.to_array()).nearest_one::<kiddo::SquaredEuclidean<f32>>().execute();
        if nearest.distance >= 1e-8 {
            unmatched += 1;
            continue;
        }
        let a = actual[nearest.item as usize];
        assert_close(a.flux, e.flux, REL, scale, 1e-12, "VAL flux");
        assert!((a.area - e.area).abs() <= 1e-3 * e.area + 1e-12, "VAL area {} vs {}", a.area, e.area);
        assert_close(a.normal, e.normal, 1e-3, 1.0, 0.0, "VAL normal");
    }
    unmatched
}

/// The spot light's VALs traced through the BVH (`twin::rsm::traced_vals`, what the error
/// estimate sums over at the reference's RSM side) are the GPU RSM's at the same side: nearly
/// every texel makes the same VAL (a ray and the raster may disagree on a texel whose centre
/// lies on an edge between triangles), and the light they carry is the same.
#[test]
fn traced_rsm_vals_are_the_rasterised_ones() {
    let gpu = gpu();
    let scene = load_test_room();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let gpu_vals = renderer.read_vals(&gpu).unwrap();
    let r = renderer.rsm_view().unwrap().width;
    let flat = &renderer.scene.flat;
    let traced = twin::rsm::traced_vals(flat, &flat.trace_bvh(), &renderer.spot().unwrap(), r);
    assert!(traced.len() > 500, "{} traced VALs", traced.len());
    let off = (traced.len() as f64 - gpu_vals.len() as f64).abs() / gpu_vals.len() as f64;
    assert!(off < 0.005, "{} traced VALs, {} rasterised", traced.len(), gpu_vals.len());
    let unmatched = unmatched_vals(&traced, &gpu_vals);
    assert!(unmatched * 200 <= traced.len(), "{unmatched} of {} traced VALs have no rasterised twin", traced.len());
    let flux = |v: &[Val]| v.iter().map(|v| v.flux).sum::<Vec3>();
    assert_close(flux(&traced), flux(&gpu_vals), 5e-3, flux(&gpu_vals).max_element(), 0.0, "total flux");
}

/// A frame whose VALs are coarser than the `reference` level's (a level with a smaller RSM)
/// has an error the frame's own VALs cannot show: here the exact method itself at an 8x8 RSM,
/// against the exact method at the reference's 32x32, where every bit of the error is the VALs'
/// coarseness. The per-frame estimate sums over the reference's VALs, traced, and finds that
/// error within the 1.5x the levels hold it to; summed over the frame's own VALs it would read
/// about nothing.
#[test]
fn the_estimate_of_coarse_vals_sums_over_the_references() {
    let gpu = gpu();
    let fine = load_test_room();
    assert_eq!(fine.settings.reference_rsm_resolution, 32, "the fixture pins its RSM");
    let mut coarse = fine.clone();
    coarse.settings.rsm_resolution = 8;
    let (w, h) = (64, 64);
    let reference = Renderer::new(&gpu, &fine).unwrap().render(&gpu, Method::Exact, w, h).unwrap();
    let mut renderer = Renderer::new(&gpu, &coarse).unwrap();
    assert_eq!(renderer.reference_spot().map(|(_, side)| side), Some(32));
    renderer.set_error_estimate(Some(relume::renderer::estimate::EstimateOptions::default()));
    let frame = renderer.render(&gpu, Method::Exact, w, h).unwrap();
    let measured = relume::image::relative_rmse(&frame.indirect, &reference.indirect);
    let estimate = frame.error_estimate.expect("an estimate");
    assert_eq!(estimate.reference_rsm_resolution, Some(32), "{estimate:?}");
    assert!(estimate.reference_vals > 4 * frame.val_count, "{estimate:?}, {} frame VALs", frame.val_count);
    assert!(measured > 0.02, "the coarse VALs must make an error to find: {measured}");
    let ratio = estimate.rel_rmse / measured;
    assert!((1.0 / 1.5..=1.5).contains(&ratio), "estimate {} against {measured}", estimate.rel_rmse);
}

/// docs/design.md §4 step 2 extremes on the GPU: Phong exponents 0 and 1e4 (the glossy divisions),
/// an intense light, a surface right against the spot; every pixel finite and non-negative.
#[test]
fn extreme_materials_render_finite_and_non_negative() {
    let scene_dir = super::fixture("scenes");
    let json = std::fs::read_to_string(scene_dir.join("cornell_bunny_small.json"))
        .unwrap()
        .replace("\"exponent\": 30", "\"exponent\": 10000")
        .replace("\"exponent\": 20", "\"exponent\": 0")
        .replace("[10, 10, 10]", "[1e6, 1e6, 1e6]")
        .replace("[0.6, 1.6, 0.6]", "[-0.999, 1.0, 0.0]");
    let plain = relume::scene::Scene::from_json_str(&json, &scene_dir).unwrap();
    // The same with the most adaptive points (candidates placed at load).
    let mut adaptive: serde_json::Value = serde_json::from_str(&json).unwrap();
    adaptive["settings"]["tuning"]["sparse"] = serde_json::json!({"adaptive": 1.0});
    let adaptive = relume::scene::Scene::from_json_str(&adaptive.to_string(), &scene_dir).unwrap();
    let gpu = gpu();
    // Both ways of carrying the glossy lobe: the paper's lights, and the interpolated radiance.
    let glossy_forms = [relume::scene::GlossyInterpolation::Lights, relume::scene::GlossyInterpolation::Radiance];
    for (mut scene, glossy) in [plain, adaptive].into_iter().flat_map(|s| glossy_forms.map(|g| (s.clone(), g))) {
        scene.settings.sparse.glossy_interpolation = glossy;
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        for method in [Method::Sparse, Method::BruteForce] {
            let f = renderer.render(&gpu, method, 24, 24).unwrap();
            for img in [&f.indirect, &f.direct] {
                for (i, p) in img.pixels.iter().enumerate() {
                    assert!(p.iter().all(|c| c.is_finite() && *c >= 0.0), "{glossy:?} {method:?} pixel {i}: {p:?}");
                }
            }
        }
        let mid = renderer.read_sparse_intermediates(&gpu).unwrap();
        let lights = mid.sparse_diffuse.iter().chain(&mid.sparse_glossy).chain(&mid.vertex_diffuse);
        for l in lights.chain(&mid.vertex_glossy) {
            let l = light(l);
            assert!(l.position.is_finite() && l.intensity.is_finite() && l.intensity.min_element() >= 0.0, "{l:?}");
        }
        for g in &mid.vertex_glossy_radiance {
            assert!(g.iter().all(|c| c.is_finite() && *c >= 0.0), "glossy radiance {g:?}");
        }
    }
}

/// The occlusion pass against `gpu::visibility::disks::twin` for both combination rules: the GPU's
/// gathered irradiance after occlusion equals the CPU gather times the CPU visibility of the
/// GPU's own light sphere, over every disc (same 1e-3 tolerance as the other twins). The pass
/// skips groups of discs that cannot occlude a workgroup's receivers, so this also checks that
/// none it skips would have. Then, with the bunny moved (`Renderer::place_meshes`), again: the
/// discs' order and groups follow the sparse points.
#[test]
fn occlusion_matches_cpu_twin() {
    let dir = super::fixture("scenes");
    let base = super::test_room_text();
    for (rule, combine) in [("sum", Combine::Sum), ("product", Combine::Product)] {
        let json = base
            .replace("\"visibility\": \"off\"", &format!("\"visibility\": \"disks\", \"occlusion_rule\": \"{rule}\""));
        assert_ne!(json, base);
        let scene = relume::scene::Scene::from_json_str(&json, &dir).unwrap();
        let gpu = gpu();
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        check_occlusion(&gpu, &mut renderer, combine, rule);
        if combine == Combine::Product {
            let mut placement = renderer.placement().to_vec();
            placement[1] = Mat4::from_translation(Vec3::new(0.15, 0.0, -0.1)) * placement[1];
            renderer.place_meshes(&gpu, &scene, &placement);
            check_occlusion(&gpu, &mut renderer, combine, "product, the bunny moved");
        }
    }
}

fn check_occlusion(gpu: &relume::gpu::Gpu, renderer: &mut Renderer, combine: Combine, what: &str) {
    use relume::gpu::visibility::disks::twin::{Disc, light_sphere, visibility};
    let frame = renderer.render(gpu, Method::Sparse, 16, 16).unwrap();
    assert!(frame.timings.stages.iter().any(|(n, _)| n == "occlusion"));
    let vals = renderer.read_vals(gpu).unwrap();
    let mid = renderer.read_sparse_intermediates(gpu).unwrap();
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    let discs: Vec<Disc> = flat
        .sparse_points
        .iter()
        .map(|p| Disc { position: p.position.into(), normal: p.normal.into(), radius: p.occluder_radius })
        .collect();
    let mut expected = Vec::new();
    let mut occluded = 0;
    for (i, p) in flat.sparse_points.iter().enumerate() {
        let (x, n) = (Vec3::from(p.position), Vec3::from(p.normal));
        let g = twin::gather_point(x, n, p.exponent, eye, &vals);
        let gd = &mid.gathered_diffuse[i];
        let sphere = light_sphere(gd.position.into(), gd.second_moment.into());
        let others: Vec<Disc> = discs.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, d)| *d).collect();
        let v = visibility(x, n, &sphere, &others, combine);
        occluded += usize::from(v < 0.9);
        expected.push(g.irradiance * v);
    }
    assert!(occluded > 10, "{what}: some sparse points must be occluded, got {occluded}");
    let scale = max_of(expected.iter().copied());
    for (i, e) in expected.iter().enumerate() {
        assert_close(mid.gathered_diffuse[i].irradiance.into(), *e, REL, scale, 1e-9, &format!("{what}: E at {i}"));
    }
}

/// The exact-visibility reference against its CPU twin: per pixel, the brute-force sum over the
/// same VAL subsample (every `stride`-th, flux x `stride`, in the GPU's own VAL order) of the
/// VALs that the BVH twin finds unoccluded. A shadow ray through a shared triangle edge may be
/// decided differently by the two float pipelines, so up to 1 % of pixels may differ beyond the
/// tolerance (none did when this was written).
/// With every VAL (stride 1) many pixels need more loop iterations than llvmpipe allows one
/// invocation (65,535, all loops together); before the pass ran in rounds those pixels kept only
/// the VALs before the cut, 46 of 400 pixels differed here, and the big images showed blocks.
/// Occlusion only removes light: the exact image is darker than the plain brute force.
#[test]
fn exact_visibility_matches_cpu_twin() {
    for stride in [1, 4] {
        exact_matches_cpu_twin("cornell_bunny_small", stride, (20, 16));
    }
}

/// The README's scene, where the blocks showed (545 of 992 pixels differed before the rounds).
#[test]
fn exact_visibility_matches_cpu_twin_on_cornell_bunny() {
    exact_matches_cpu_twin("cornell_bunny", 16, (32, 32));
}

/// The CPU exact reference (`twin::exact_cpu`: rayon, obvhs's traversal) against the GPU
/// exact pass (obvhs's tree flattened for `bvh.wgsl`), every VAL, pixel by pixel on the same
/// visibility buffer. Tolerance: the twins' 1e-3 of the largest pixel (the two sum the same
/// terms in different orders, lavapipe with a few ulp per operation), and up to 1 % of pixels may
/// differ beyond it, for a shadow ray through a shared triangle edge that the two float pipelines
/// decide differently (as in [`exact_visibility_matches_cpu_twin`]).
#[test]
fn cpu_exact_reference_matches_gpu_exact() {
    use relume::bench::compare::{ExactOptions, ReferenceDevice, exact_reference};
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &load_test_room()).unwrap();
    let (w, h) = (20, 16);
    let options = ExactOptions::every_val;
    let on_gpu = exact_reference(&gpu, &mut renderer, w, h, &options(ReferenceDevice::Gpu)).unwrap();
    let on_cpu = exact_reference(&gpu, &mut renderer, w, h, &options(ReferenceDevice::Cpu)).unwrap();
    assert_eq!((on_gpu.device, on_cpu.device), (ReferenceDevice::Gpu, ReferenceDevice::Cpu));
    let scale = max_of((0..on_cpu.indirect().pixels.len()).map(|i| on_cpu.indirect().rgb(i)));
    assert!(scale > 0.0);
    let mut differing = 0;
    for i in 0..on_cpu.indirect().pixels.len() {
        assert_eq!(on_cpu.indirect().covered(i), on_gpu.indirect().covered(i), "coverage of pixel {i}");
        let (c, g) = (on_cpu.indirect().rgb(i), on_gpu.indirect().rgb(i));
        let bad = (c - g).abs().max_element() > REL * scale + 1e-9;
        if bad && differing < 5 {
            eprintln!("pixel {i}: GPU {g} CPU {c}");
        }
        differing += usize::from(bad);
    }
    let covered = on_cpu.indirect().coverage();
    assert!(differing * 100 <= covered, "{differing} of {covered} pixels differ");
    // The CPU reference's frame ran no indirect technique of the GPU: its indirect stage is the
    // CPU's own.
    let stages: Vec<&str> = on_cpu.frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect();
    assert!(stages.contains(&"exact_cpu") && !stages.contains(&"gather") && !stages.contains(&"exact"), "{stages:?}");
    let rays = on_cpu.shadow_rays.unwrap();
    assert!(rays > 0 && rays <= covered as u64 * on_cpu.frame.val_count as u64, "{rays} shadow rays");
    for r in [&on_cpu, &on_gpu] {
        assert!(r.variance.as_ref().unwrap().iter().all(|v| *v == Vec3::ZERO), "every VAL: no noise");
    }
}

/// The GPU estimator (`gpu/references/estimator.wgsl`: the brute force's sum as the total,
/// then a systematic walk over the VALs and a shadow ray per draw) against its CPU twin
/// (`twin::exact_cpu`, `ValSampling::Systematic`, the same draws from the same hash), on the
/// same visibility buffer and VAL list, with few and with many draws. The two totals are sums
/// of the same terms in different orders, so a threshold near a VAL's edge of the running sum
/// may fall on the next VAL on one side: up to 2 % of pixels may differ beyond the twins' 1e-3
/// of the largest pixel. The estimate must also be near the exact image (many draws), darker
/// than the unoccluded one, and its draws must be what makes it differ from the exact image
/// (few draws are further from it than many).
#[test]
fn gpu_estimator_matches_cpu_twin() {
    let errors = estimator_matches_cpu_twin("cornell_bunny_small", (24, 20), &[4, 64], true);
    eprintln!("estimator against exact: rel RMSE {errors:?} at 4 and 64 draws");
    assert!(errors[1] < 0.15, "64 draws: {} from exact", errors[1]);
    assert!(errors[0] > errors[1], "more draws, closer to exact: {errors:?}");
}

/// The same on the README's scene, 16,384 VALs: where the exact pass, run in 8x8 workgroups on
/// llvmpipe, showed wrong blocks (its nested loops; the estimator's one flat loop runs in 8x8
/// workgroups everywhere).
#[test]
fn gpu_estimator_matches_cpu_twin_on_cornell_bunny() {
    // The twin is the check here: no exact image to measure the estimate's error against.
    estimator_matches_cpu_twin("cornell_bunny", (40, 40), &[16], false);
}

/// [`gpu_estimator_matches_cpu_twin`]'s comparison on `scene` at each count of draws; with
/// `exact`, the GPU estimate's rel RMSE against the GPU's exact image at each.
fn estimator_matches_cpu_twin(scene: &str, (w, h): (u32, u32), draws: &[u32], exact: bool) -> Vec<f64> {
    use relume::twin::exact_cpu::{self as cpu, Receivers, ValSampling};
    let gpu = gpu();
    let scene = load_scene(scene);
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let exact = exact.then(|| renderer.render(&gpu, Method::Exact, w, h).unwrap().indirect);
    let brute = renderer.render(&gpu, Method::BruteForce, w, h).unwrap().indirect;
    let mut errors = Vec::new();
    for &samples in draws {
        renderer.set_estimator(samples, 7);
        let on_gpu = renderer.render(&gpu, Method::Estimator, w, h).unwrap();
        assert_eq!(on_gpu.indirect_stages, ["brute_force", "estimator"]);
        let vals = renderer.read_vals(&gpu).unwrap();
        let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
        let flat = &renderer.scene.flat;
        let eye = renderer.view().eye();
        let receivers: Vec<_> =
            hits.iter().map(|h| h.map(|h| flat.receiver_at(h.triangle, h.barycentrics, eye))).collect();
        let bvh = flat.trace_bvh();
        let cpu_scene = cpu::ExactScene { bvh: &bvh, vals: &vals, glossy: renderer.glossy(), blockers_from: 0.0 };
        let sampling = ValSampling::Systematic { samples, seed: 7 };
        let on_cpu = cpu::render(&cpu_scene, &Receivers::Hits(&receivers), w, h, sampling).image;
        assert_estimator_twins(&on_cpu, &on_gpu.indirect, &format!("{samples} draws"));
        if let Some(exact) = &exact {
            errors.push(relume::image::relative_rmse(&on_gpu.indirect, exact));
        }
        let energy = |image: &relume::image::LinearImage| {
            (0..image.pixels.len()).map(|i| image.rgb(i).element_sum()).sum::<f32>()
        };
        assert!(energy(&on_gpu.indirect) < 0.97 * energy(&brute), "{samples} draws: occlusion removes light");
    }
    errors
}

/// The estimator's CPU twin against its GPU pass, as [`gpu_estimator_matches_cpu_twin`] allows:
/// the same coverage, and at most 2 % of pixels beyond 1e-3 of the largest.
fn assert_estimator_twins(on_cpu: &relume::image::LinearImage, on_gpu: &relume::image::LinearImage, label: &str) {
    let scale = max_of((0..on_cpu.pixels.len()).map(|i| on_cpu.rgb(i)));
    assert!(scale > 0.0);
    let mut differing = 0;
    for i in 0..on_cpu.pixels.len() {
        assert_eq!(on_cpu.covered(i), on_gpu.covered(i), "coverage of pixel {i}");
        let (c, g) = (on_cpu.rgb(i), on_gpu.rgb(i));
        let bad = (c - g).abs().max_element() > REL * scale + 1e-9;
        if bad && differing < 5 {
            eprintln!("{label}, pixel {i}: GPU {g} CPU {c}");
        }
        differing += usize::from(bad);
    }
    let covered = on_cpu.coverage();
    assert!(differing * 50 <= covered, "{label}: {differing} of {covered} pixels differ from the twin");
}

/// The level technique `"estimator"` as `relume render`, the service and the levels bench run
/// it (`bench::compare::exact_reference` with `ExactOptions::estimator_on`): on the CPU its
/// twin's systematic draws, on the GPU the estimator pass, both with the renderer's draws and
/// seed, so the same image; and an estimate, not the sum over every VAL.
#[test]
fn the_estimator_technique_runs_its_twin_on_the_cpu() {
    use relume::bench::compare::{ExactOptions, ReferenceDevice, exact_reference};
    let gpu = gpu();
    let scene = load_scene("cornell_bunny_small");
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.set_estimator(16, 7);
    let (w, h) = (24, 20);
    let mut on = |options: ExactOptions| exact_reference(&gpu, &mut renderer, w, h, &options).unwrap();
    let on_cpu = on(ExactOptions::estimator_on(ReferenceDevice::Cpu));
    let on_gpu = on(ExactOptions::estimator_on(ReferenceDevice::Gpu));
    let exact = on(ExactOptions::every_val(ReferenceDevice::Cpu));
    assert_eq!(on_cpu.frame.indirect_stages, [relume::twin::exact_cpu::STAGE]);
    assert_eq!(on_gpu.frame.indirect_stages, ["brute_force", "estimator"]);
    assert_estimator_twins(on_cpu.indirect(), on_gpu.indirect(), "16 draws");
    let error = relume::image::relative_rmse(on_cpu.indirect(), exact.indirect());
    assert!(error > 1e-3 && error < 0.5, "16 draws against every VAL: {error}");
}

/// Primary rays through pixel centres in the obvhs BVH (the CPU reference's receivers with
/// `--spp`) see what the rasteriser's visibility buffer sees: on at least 97 % of pixels both
/// miss, or both hit the same surface point to 0.1 pixel on screen and 0.2 % of the distance in
/// depth (which triangle may differ: the subdivided walls put many shared edges in a pixel, and
/// the rasteriser snaps vertices to its sub-pixel grid, which moved points by ~1/40 pixel here).
/// The rest are silhouette pixels, where a centre on an edge goes either way.
#[test]
fn traced_pixel_centres_match_the_visibility_buffer() {
    use relume::twin::bvh::TraceBvh;
    use relume::twin::exact_cpu::CameraRays;
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &load_test_room()).unwrap();
    let (w, h) = (48, 40);
    renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let flat = &renderer.scene.flat;
    let positions: Vec<Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let bvh = TraceBvh::build(&positions, &triangles);
    let world_to_clip = renderer.camera_to_clip(w, h);
    let camera = CameraRays::new(world_to_clip, w, h);
    let on_screen = |p: Vec3| {
        let ndc = world_to_clip.project_point3(p);
        glam::Vec2::new((ndc.x + 1.0) * 0.5 * w as f32, (1.0 - ndc.y) * 0.5 * h as f32)
    };
    let mut same = 0;
    for (i, hit) in hits.iter().enumerate() {
        let (x, y) = ((i as u32 % w) as f32 + 0.5, (i as u32 / w) as f32 + 0.5);
        let (origin, direction) = camera.ray(x, y);
        let traced = bvh.closest_hit(origin, direction);
        match (hit, traced) {
            (Some(g), Some(c)) => {
                let (pg, _, _) = flat.surface_at(g.triangle, g.barycentrics);
                let (pc, _, _) = flat.surface_at(c.triangle, c.barycentrics);
                let offset = (on_screen(pg) - on_screen(pc)).length();
                let depth = (pg.distance(origin) - pc.distance(origin)).abs();
                same += usize::from(offset < 0.1 && depth < 2e-3 * c.t);
            }
            (None, None) => same += 1,
            _ => {}
        }
    }
    assert!(same * 100 >= hits.len() * 97, "{same} of {} pixels agree", hits.len());
}

fn exact_matches_cpu_twin(scene: &str, stride: u32, (w, h): (u32, u32)) {
    use relume::gpu::shader::RAY_OFFSET;
    use relume::twin::bvh::Bvh;
    let gpu = gpu();
    let scene = load_scene(scene);
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.set_exact_val_stride(stride);
    let exact = renderer.render(&gpu, Method::Exact, w, h).unwrap();
    if stride == 1 {
        assert!(exact.exact_rounds > 1, "every VAL must need more than one round, took {}", exact.exact_rounds);
    }
    let vals = renderer.read_vals(&gpu).unwrap();
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    let positions: Vec<Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let bvh = Bvh::build(&positions, &triangles);
    let subsample: Vec<Val> = vals
        .iter()
        .step_by(stride as usize)
        .take(vals.len() / stride as usize)
        .map(|v| Val { flux: v.flux * stride as f32, ..*v })
        .collect();
    let expected = super::per_receiver(flat, &hits, eye, |r| {
        let origin = r.position + r.geometric * RAY_OFFSET;
        let visible: Vec<Val> = subsample
            .iter()
            .filter(|v| !bvh.occluded(&positions, &triangles, origin, v.position + v.normal * RAY_OFFSET))
            .copied()
            .collect();
        twin::shade_brute_force_sided(r.position, r.normal, r.geometric, &r.surface, eye, &visible, renderer.glossy())
    });
    // The occluders must take a visible share of the light of the same VALs. The VAL buffer's
    // order comes from atomic appends, so which VALs a stride keeps changes from run to run: the
    // unoccluded sum is the twin's over the same subsample, not the brute-force frame over every
    // VAL (against which a 1-in-16 subsample's own noise alone moved the ratio 0.90-0.96).
    let unoccluded = super::per_receiver(flat, &hits, eye, |r| {
        twin::shade_brute_force_sided(r.position, r.normal, r.geometric, &r.surface, eye, &subsample, renderer.glossy())
    });
    let scale = max_of(expected.iter().flatten().copied());
    let mut differing = 0;
    for (i, e) in expected.iter().enumerate() {
        if let Some(e) = e {
            let got = exact.indirect.rgb(i);
            let bad = (got - *e).abs().max_element() > REL * scale + 1e-9;
            if bad && differing < 5 {
                eprintln!("pixel {i}: GPU {got} CPU {e} unoccluded {:?}", unoccluded[i]);
            }
            differing += usize::from(bad);
        }
    }
    let covered = exact.indirect.coverage();
    assert!(differing * 100 <= covered, "stride {stride}: {differing} of {covered} pixels differ from the twin");
    let sum = |pixels: &[Option<Vec3>]| pixels.iter().flatten().map(|c| c.element_sum()).sum::<f32>();
    let sum_exact: f32 = (0..exact.indirect.pixels.len()).map(|i| exact.indirect.rgb(i).element_sum()).sum();
    let sum_unoccluded = sum(&unoccluded);
    eprintln!("stride {stride}: exact {sum_exact}, unoccluded {sum_unoccluded}, twin {}", sum(&expected));
    assert!(sum_exact < 0.95 * sum_unoccluded, "exact {sum_exact} vs unoccluded {sum_unoccluded}");
}

/// The GPU's per-vertex lights against `twin::interpolate_lights` over each vertex's
/// `flat.neighbours` sparse points, from the GPU's own sparse lights.
fn assert_interpolation_matches_twin(
    flat: &relume::gpu::scene::FlatScene,
    mid: &relume::renderer::SparseIntermediates,
    shading: relume::scene::SparseShading,
    eye: Vec3,
    only: Option<&[u32]>,
) {
    let sparse_d: Vec<PointLight> = mid.sparse_diffuse.iter().map(light).collect();
    let sparse_s: Vec<PointLight> = mid.sparse_glossy.iter().map(light).collect();
    let scale = max_of(sparse_d.iter().map(|l| l.intensity));
    let radiance_scale = max_of(mid.gathered_glossy.iter().map(|g| Vec3::from(g.irradiance)));
    let k = flat.neighbours as usize;
    let base = flat.base_sparse_count() as usize;
    for (v, ids) in flat.vertex_neighbours.chunks_exact(k).enumerate() {
        if only.is_some_and(|only| only.binary_search(&(v as u32)).is_err()) {
            continue;
        }
        let vertex = flat.vertices[v];
        let mut ids: Vec<usize> = ids.iter().take_while(|&&i| i != u32::MAX).map(|&i| i as usize).collect();
        let sp = |i: usize| flat.sparse_points[i];
        let offsets_of = |ids: &[usize]| -> Vec<Vec3> {
            ids.iter().map(|&i| Vec3::from(sp(i).position) - Vec3::from(vertex.position)).collect()
        };
        let normals_of = |ids: &[usize]| -> Vec<Vec3> { ids.iter().map(|&i| sp(i).normal.into()).collect() };
        let offsets = offsets_of(&ids);
        let mut w = twin::interpolation_weights(shading.kernel, vertex.normal.into(), &offsets, &normals_of(&ids));
        if flat.candidates > 0 {
            // Adaptive candidates: the chosen ones among the vertex's nearest join its points.
            let row = &flat.vertex_candidates[v * k..(v + 1) * k];
            let candidates: Vec<usize> = row.iter().take_while(|&&i| i != u32::MAX).map(|&i| i as usize).collect();
            let chosen: Vec<bool> = candidates.iter().map(|&i| mid.adaptive_chosen[i - base] != 0).collect();
            let cw = twin::adaptive::candidate_weights(
                shading.kernel,
                vertex.normal.into(),
                &offsets,
                &offsets_of(&candidates),
                &normals_of(&candidates),
                &chosen,
            );
            for (i, cw) in candidates.into_iter().zip(cw).filter(|(_, cw)| *cw > 0.0) {
                ids.push(i);
                w.push(cw);
            }
        }
        let d = twin::interpolate_lights(&w, &ids.iter().map(|&i| sparse_d[i]).collect::<Vec<_>>(), shading.bound);
        assert_close(
            light(&mid.vertex_diffuse[v]).intensity,
            d.intensity,
            REL,
            scale,
            1e-9,
            &format!("vertex {v} I_d"),
        );
        if mid.vertex_glossy_radiance.is_empty() {
            let s = twin::interpolate_lights(&w, &ids.iter().map(|&i| sparse_s[i]).collect::<Vec<_>>(), shading.bound);
            assert_close(
                light(&mid.vertex_glossy[v]).position,
                s.position,
                1e-3,
                1.0,
                1e-4,
                &format!("vertex {v} l_s"),
            );
        } else {
            // `glossy_interpolation: "radiance"`: the GPU's gathered glossy sums averaged.
            let g: Vec<Vec3> = ids
                .iter()
                .map(|&i| {
                    let p = sp(i);
                    twin::glossy_toward_eye(
                        p.position.into(),
                        p.normal.into(),
                        eye,
                        mid.gathered_glossy[i].irradiance.into(),
                    )
                })
                .collect();
            let want = twin::interpolate_radiance(&w, &g);
            let got = Vec3::from_slice(&mid.vertex_glossy_radiance[v][..3]);
            assert_close(got, want, REL, radiance_scale, 1e-9, &format!("vertex {v} glossy radiance"));
        }
        let gpu_bound = light(&mid.vertex_diffuse[v]).bound;
        assert!((gpu_bound - d.bound).abs() <= 1e-5 * d.bound.max(1.0), "vertex {v} bound: {gpu_bound} vs {}", d.bound);
    }
}

/// Adaptive sparse points (`settings.sparse.adaptive` 0.5: up to half the points' count more
/// each frame, from twice the points' count of candidates): the GPU's scores against `twin::adaptive::candidate_score` from
/// its own gathered sums, its choice against `twin::adaptive::select` of its scores, the chosen
/// candidates' gather against `twin::gather_point`, the vertices' interpolation (chosen
/// candidates weighed in) and the pixels against the twins. A second frame of the same view
/// scores the chosen ones `HYSTERESIS` times higher and keeps every one of them. Same
/// tolerances as the rest of this file; the choice may differ from the twin's only for a score
/// within float rounding of a bin edge (CPU and GPU `log2` differ in the last bits), which the
/// test allows for 2 candidates of 768.
#[test]
fn adaptive_points_match_cpu_twins() {
    use twin::adaptive::{HYSTERESIS, candidate_score, scored_light, select};
    let gpu = gpu();
    let dir = super::fixture("scenes");
    let text = super::test_room_text();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["settings"]["tuning"]["sparse"] = serde_json::json!({"adaptive": 0.5});
    let scene = relume::scene::Scene::from_json_str(&json.to_string(), &dir).unwrap();
    let (w, h) = (48, 40);
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let mid = renderer.read_sparse_intermediates(&gpu).unwrap();
    let flat = &renderer.scene.flat.clone();
    let (base, k) = (flat.base_sparse_count() as usize, flat.neighbours as usize);
    assert_eq!((base, flat.candidates, flat.adaptive_budget), (768, 1536, 384));
    let eye = renderer.view().eye();
    let light_at = |mid: &relume::renderer::SparseIntermediates, i: usize| {
        let g = twin::Gathered {
            irradiance: mid.gathered_diffuse[i].irradiance.into(),
            glossy_irradiance: mid.gathered_glossy[i].irradiance.into(),
            ..Default::default()
        };
        scored_light(&g, true)
    };
    let twin_scores = |mid: &relume::renderer::SparseIntermediates, before: &[u32]| -> Vec<f32> {
        (0..flat.candidates as usize)
            .map(|c| {
                let p = flat.sparse_points[base + c];
                let ids: Vec<usize> = flat.candidate_neighbours[c * k..(c + 1) * k]
                    .iter()
                    .take_while(|&&i| i != u32::MAX)
                    .map(|&i| i as usize)
                    .collect();
                let offsets: Vec<Vec3> =
                    ids.iter().map(|&i| Vec3::from(flat.sparse_points[i].position) - Vec3::from(p.position)).collect();
                let normals: Vec<Vec3> = ids.iter().map(|&i| flat.sparse_points[i].normal.into()).collect();
                let w = twin::interpolation_weights(scene.settings.sparse.kernel, p.normal.into(), &offsets, &normals);
                let y: Vec<f32> = ids.iter().map(|&i| light_at(mid, i)).collect();
                candidate_score(&w, &y, before.get(c).is_some_and(|&b| b != 0))
            })
            .collect()
    };
    let check_scores = |mid: &relume::renderer::SparseIntermediates, before: &[u32]| {
        let want = twin_scores(mid, before);
        let scale = want.iter().copied().fold(0.0, f32::max);
        assert!(scale > 0.0);
        for (c, (&got, &want)) in mid.adaptive_scores.iter().zip(&want).enumerate() {
            assert!((got - want).abs() <= REL * scale, "candidate {c}: score {got} vs twin {want}");
        }
        let twin_choice = select(&mid.adaptive_scores, flat.adaptive_budget);
        let differ = twin_choice.iter().zip(&mid.adaptive_chosen).filter(|(t, g)| **t != (**g != 0)).count();
        assert!(differ <= 2, "{differ} candidates chosen differently from the twin");
        let n = mid.adaptive_chosen.iter().filter(|&&c| c != 0).count() as u32;
        assert!(n > flat.adaptive_budget / 2 && n <= flat.adaptive_budget, "{n} chosen of {}", flat.adaptive_budget);
    };
    check_scores(&mid, &[]);
    assert_gather_matches_twin(flat, &mid, eye, &renderer.read_vals(&gpu).unwrap());
    assert_interpolation_matches_twin(flat, &mid, scene.settings.sparse, eye, None);
    assert_pixels_match_twin(&gpu, &renderer, &frame, &mid);
    // The next frame: the chosen score HYSTERESIS times higher and all stay chosen.
    let before = mid.adaptive_chosen.clone();
    renderer.render(&gpu, Method::Sparse, w, h).unwrap();
    let next = renderer.read_sparse_intermediates(&gpu).unwrap();
    check_scores(&next, &before);
    for (c, (&b, &n)) in before.iter().zip(&next.adaptive_chosen).enumerate() {
        assert!(b == 0 || n != 0, "candidate {c} was dropped in a frame with the same light");
        if b != 0 {
            // The gathered sums differ between frames by float rounding (the RSM's atomic
            // append orders the VALs differently), so the factor holds to the file's REL.
            let (got, want) = (next.adaptive_scores[c], HYSTERESIS * mid.adaptive_scores[c]);
            assert!(
                (got - want).abs() <= REL * want,
                "candidate {c}: score {got}, {HYSTERESIS} x {}",
                mid.adaptive_scores[c]
            );
        }
    }
}

/// The interpolation with 4 and 16 neighbours per vertex (`settings.interpolation_neighbours`)
/// against its twin, and the image changes with the count.
#[test]
fn interpolation_takes_the_scene_neighbour_count() {
    let gpu = gpu();
    let dir = super::fixture("scenes");
    let text = super::test_room_text();
    let mut images = Vec::new();
    for k in [4, 16] {
        let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
        json["settings"]["tuning"]["interpolation_neighbours"] = k.into();
        let scene = relume::scene::Scene::from_json_str(&json.to_string(), &dir).unwrap();
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let frame = renderer.render(&gpu, Method::Sparse, 24, 20).unwrap();
        let flat = &renderer.scene.flat;
        assert_eq!((flat.neighbours, flat.vertex_neighbours.len()), (k, k as usize * flat.vertices.len()));
        assert_interpolation_matches_twin(
            flat,
            &renderer.read_sparse_intermediates(&gpu).unwrap(),
            scene.settings.sparse,
            renderer.view().eye(),
            None,
        );
        images.push(frame.indirect.pixels);
    }
    assert_ne!(images[0], images[1], "4 and 16 neighbours interpolate differently");
}
