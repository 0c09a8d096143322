//! The paper's Table 1 (Lensing & Broll, AMD Radeon 7870, 1920x1080): 200k and 730k
//! triangles; 4k and 16k sparse points; 16k, 64k and 512k VALs; three modes (diffuse only,
//! diffuse and glossy, diffuse and glossy and occlusion).
//!
//! The scenes are built from a Cornell-box-like scene file: its first mesh (the room) stays,
//! and its other meshes (the bunny) are replicated in a grid on the floor, as many copies as
//! bring their triangles nearest the target (the Stanford bunny's 69,451: 3 and 11 copies).
//! The glossy modes need a glossy material in the scene (`cornell_bunny_small.json` has one;
//! `glossy_active` in the results says whether the glossy stages ran). The sparse points are
//! shared equally by all meshes. No references are rendered: the paper's table is timing only,
//! and a brute force at 512k VALs and 1080p takes hours on lavapipe.

use super::{Config, Job};
use crate::scene::{Occlusion, ScaleDescription, Scene, SceneDescription};
use std::path::Path;

/// (name, triangles) of the paper's two scenes.
pub const TRIANGLE_TARGETS: [(&str, usize); 2] = [("200k", 200_000), ("730k", 730_000)];
/// Sparse points in the whole scene.
pub const SPARSE_TOTALS: [u32; 2] = [4096, 16_384];
/// RSM sides for 16k, 64k and 512k VALs (724² = 524,176).
pub const RSM_RESOLUTIONS: [u32; 3] = [128, 256, 724];
/// (name, glossy, occlusion) of the paper's three columns per light count.
pub const MODES: [(&str, bool, Occlusion); 3] =
    [("diffuse", false, Occlusion::Off), ("glossy", true, Occlusion::Off), ("occlusion", true, Occlusion::Disks)];
pub const RESOLUTION: (u32, u32) = (1920, 1080);

/// The paper's frames per second (their Table 1, "our new approach"), in the order of
/// [`TRIANGLE_TARGETS`] x [`SPARSE_TOTALS`] x [`RSM_RESOLUTIONS`] x [`MODES`].
pub const PAPER_FPS: [[[[u32; 3]; 3]; 2]; 2] = [
    [[[126, 89, 66], [70, 46, 38], [25, 16, 14]], [[69, 45, 32], [24, 15, 12], [7, 4, 4]]],
    [[[73, 51, 39], [40, 27, 23], [15, 9, 9]], [[53, 36, 23], [22, 14, 12], [7, 4, 4]]],
];

/// The paper's FPS for a configuration of job `variant` with `sparse_points` in all, when it
/// is one of Table 1's.
pub fn paper_fps(variant: &str, config: &Config, sparse_points: usize) -> Option<u32> {
    let scene = TRIANGLE_TARGETS.iter().position(|(name, _)| variant == format!("table1_{name}"))?;
    // 4,096 or 16,384 shared by the meshes, rounded down per mesh.
    let sparse =
        SPARSE_TOTALS.iter().position(|&t| sparse_points <= t as usize && sparse_points * 10 >= t as usize * 9)?;
    let rsm = RSM_RESOLUTIONS.iter().position(|&r| r == config.rsm_resolution)?;
    let mode =
        MODES.iter().position(|&(_, glossy, occlusion)| (glossy, occlusion) == (config.glossy, config.occlusion))?;
    ((config.width, config.height) == RESOLUTION).then_some(PAPER_FPS[scene][sparse][rsm][mode])
}

/// The scenes and configurations. `quick`: the 200k scene only, R = 8, 64 sparse points,
/// 32x32 (checks the machinery in seconds).
pub fn jobs(description: &SceneDescription, scene: &Scene, quick: bool) -> Vec<Job> {
    let objects: usize = scene.meshes.iter().skip(1).map(|m| m.triangles.len()).sum();
    let targets: &[(&str, usize)] = if quick { &TRIANGLE_TARGETS[..1] } else { &TRIANGLE_TARGETS };
    targets
        .iter()
        .map(|&(name, target)| {
            // The room's share depends on the sparse spacing (it is subdivided to it): left out.
            let copies = if objects == 0 { 1 } else { (target as f64 / objects as f64).round() as usize };
            let d = replicate(description, copies.max(1));
            let meshes = d.meshes.len() as u32;
            let mut configs = Vec::new();
            let sparse_totals: &[u32] = if quick { &[64] } else { &SPARSE_TOTALS };
            let rsm: &[u32] = if quick { &[8] } else { &RSM_RESOLUTIONS };
            let (width, height) = if quick { (32, 32) } else { RESOLUTION };
            for &total in sparse_totals {
                for &rsm_resolution in rsm {
                    for &(_, glossy, occlusion) in &MODES {
                        configs.push(Config {
                            sparse_points_per_mesh: Some((total / meshes).max(1)),
                            ..Config::new(rsm_resolution, occlusion, glossy, width, height)
                        });
                    }
                }
            }
            Job { variant: format!("table1_{name}"), description: d, configs }
        })
        .collect()
}

/// `description` with its file paths (OBJ, textures) made absolute from `base_dir`, to be
/// written anywhere.
pub fn with_absolute_paths(description: &SceneDescription, base_dir: &Path) -> SceneDescription {
    let absolute = |p: &str| {
        let base = std::path::absolute(base_dir).unwrap_or_else(|_| base_dir.to_path_buf());
        base.join(p).to_string_lossy().into_owned()
    };
    let mut d = description.clone();
    for m in &mut d.meshes {
        if m.obj_text.is_none() {
            m.obj = absolute(&m.obj);
        }
        for material in m.material.iter_mut().chain(m.materials.values_mut()) {
            if let Some(t) = &mut material.diffuse_texture {
                *t = absolute(t);
            }
        }
    }
    d
}

/// `description` with every mesh after the first replicated `copies` times in a square grid
/// on the room's floor (x and z in [-0.7, 0.7] m around the original's position), scaled down
/// so that neighbours do not overlap much.
pub fn replicate(description: &SceneDescription, copies: usize) -> SceneDescription {
    let mut d = description.clone();
    if copies <= 1 || d.meshes.len() < 2 {
        return d;
    }
    let objects: Vec<_> = d.meshes.drain(1..).collect();
    let side = (copies as f64).sqrt().ceil() as usize;
    let cell = 1.4 / side as f32;
    let shrink = (2.0 / side as f32).min(1.0);
    for i in 0..copies {
        let (gx, gz) = ((i % side) as f32, (i / side) as f32);
        for mesh in &objects {
            let mut m = mesh.clone();
            m.transform.translation[0] = f64::from(-0.7 + cell * (gx + 0.5));
            m.transform.translation[2] = f64::from(-0.7 + cell * (gz + 0.5));
            m.transform.scale = match m.transform.scale {
                ScaleDescription::Uniform(s) => ScaleDescription::Uniform(s * shrink),
                ScaleDescription::PerAxis(s) => ScaleDescription::PerAxis(s.map(|v| v * shrink)),
            };
            d.meshes.push(m);
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replicate_copies_every_object_into_a_grid() {
        let text = r#"{
            "meshes": [{"obj": "room.obj", "sparse_points": 8}, {"obj": "bunny.obj", "sparse_points": 8,
                "transform": {"translation": [0.3, -0.1, 0.2], "scale": 3}}],
            "camera": {"position": [0, 1, 3], "target": [0, 1, 0], "fov_y_deg": 40, "width": 8, "height": 8}
        }"#;
        let d = SceneDescription::from_json_str(text).unwrap();
        let r = replicate(&d, 10);
        assert_eq!(r.meshes.len(), 11);
        assert_eq!(r.meshes[0], d.meshes[0]);
        let positions: Vec<[f64; 3]> = r.meshes[1..].iter().map(|m| m.transform.translation).collect();
        for (i, p) in positions.iter().enumerate() {
            assert_eq!(p[1], -0.1, "height kept");
            assert!(p[0].abs() <= 0.7 && p[2].abs() <= 0.7, "{p:?}");
            assert!(positions[..i].iter().all(|q| q != p), "distinct cells");
        }
        assert_eq!(r.meshes[1].transform.scale, ScaleDescription::Uniform(1.5));
        assert_eq!(replicate(&d, 1), d);
    }

    #[test]
    fn paper_fps_finds_table_1_cells() {
        let config =
            Config { sparse_points_per_mesh: Some(341), ..Config::new(256, Occlusion::Disks, true, 1920, 1080) };
        assert_eq!(paper_fps("table1_730k", &config, 4092), Some(23));
        assert_eq!(
            paper_fps("table1_200k", &Config { glossy: false, occlusion: Occlusion::Off, ..config }, 16_384),
            Some(24)
        );
        assert_eq!(paper_fps("scene", &config, 4092), None);
        assert_eq!(paper_fps("table1_730k", &Config { width: 32, ..config }, 4092), None);
    }
}
