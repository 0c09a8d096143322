//! The frame is the list of techniques the request needs: a component left out runs none of
//! its stages, and what is computed does not depend on what else was asked for.

use crate::{gpu, load_test_room};
use relume::renderer::{Components, Method, Renderer, stage};

fn stage_names(frame: &relume::renderer::Rendered) -> Vec<&str> {
    frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect()
}

/// A direct-only frame records no gather, occlusion, renormalise, interpolate or shade stage
/// (and no brute force), and its direct image is the full frame's direct image. The RSM runs
/// (it is the direct light's shadow map). The two direct images are compared exactly: the
/// direct pass reads the light-distance map, which each RSM texel writes alone, so the atomic
/// VAL order that varies between frames cannot reach it.
#[test]
fn a_direct_only_frame_runs_no_indirect_stage() {
    let gpu = gpu();
    let mut scene = load_test_room();
    scene.settings.visibility.mode = relume::scene::Occlusion::Disks;
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    for method in [Method::Sparse, Method::BruteForce] {
        let direct = renderer.render_components(&gpu, method, 32, 24, Components::DIRECT).unwrap();
        let names = stage_names(&direct);
        assert_eq!(names, [stage::RSM_RASTER, stage::RSM_VALS, stage::VISIBILITY, stage::DIRECT], "{method:?}");
        assert!(direct.indirect_stages.is_empty());
        assert!(direct.indirect.pixels.iter().all(|p| p[..3] == [0.0; 3]), "no indirect light computed");
        let full = renderer.render(&gpu, method, 32, 24).unwrap();
        let indirect = match method {
            Method::Sparse => {
                vec![stage::GATHER, stage::OCCLUSION, stage::RENORMALISE, stage::INTERPOLATE, stage::SHADE]
            }
            _ => vec![stage::BRUTE_FORCE],
        };
        assert_eq!(full.indirect_stages, indirect);
        assert!(indirect.iter().all(|s| stage_names(&full).contains(s)));
        assert_eq!(
            full.direct.pixels, direct.direct.pixels,
            "{method:?}: the direct light does not depend on the rest"
        );
        assert_eq!(
            full.indirect.pixels.iter().map(|p| p[3]).collect::<Vec<_>>(),
            direct.indirect.pixels.iter().map(|p| p[3]).collect::<Vec<_>>(),
            "coverage"
        );
    }
    // An indirect-only frame has no direct stage.
    let indirect = renderer.render_components(&gpu, Method::Sparse, 32, 24, Components::INDIRECT).unwrap();
    assert!(!stage_names(&indirect).contains(&stage::DIRECT));
    assert!(indirect.direct.pixels.iter().all(|p| p[..3] == [0.0; 3]));
}

/// Changing a setting rebuilds only the technique built for it: the sparse frame after a
/// round trip through other settings equals the first one.
#[test]
fn settings_round_trips_give_the_same_frame() {
    let gpu = gpu();
    let scene = load_test_room();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.set_occlusion(relume::scene::Occlusion::Off, scene.settings.visibility.rule);
    let first = renderer.render(&gpu, Method::Sparse, 24, 24).unwrap();
    assert!(!stage_names(&first).contains(&stage::OCCLUSION));
    renderer.set_occlusion(relume::scene::Occlusion::Disks, scene.settings.visibility.rule);
    let disks = renderer.render(&gpu, Method::Sparse, 24, 24).unwrap();
    assert!(stage_names(&disks).contains(&stage::OCCLUSION));
    renderer.set_glossy(false);
    renderer.render(&gpu, Method::Sparse, 24, 24).unwrap();
    renderer.set_glossy(true);
    renderer.set_occlusion(relume::scene::Occlusion::Off, scene.settings.visibility.rule);
    let again = renderer.render(&gpu, Method::Sparse, 24, 24).unwrap();
    // Same techniques, same inputs; only the RSM's atomic VAL order may differ, which moves the
    // gather's float sums in their last bits: 1e-4 relative.
    let err = relume::image::relative_rmse(&again.indirect, &first.indirect);
    assert!(err < 1e-4, "rel RMSE {err}");
    assert_eq!(stage_names(&again), stage_names(&first));
}
