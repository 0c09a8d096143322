//! Loading whole scenes: meshes, transforms, materials and textures.

use super::test_util::{TempDir, scene_json, scene_json_with};
use super::*;
use glam::{DAffine3, DMat4, DVec3, Mat4, Vec2, Vec3};
use std::path::Path;

const CUBE_OBJ: &str = "\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";

#[test]
fn loads_a_scene_end_to_end() {
    let dir = TempDir::new("end-to-end");
    dir.write("cube.obj", CUBE_OBJ);
    let json = scene_json(
        r#""obj": "cube.obj", "sparse_points": 64,
           "transform": {"translation": [1, 2, 3], "scale": 2},
           "material": {"diffuse": [0.2, 0.3, 0.4], "specular": [0.5, 0.5, 0.5], "exponent": 30}"#,
    );
    let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
    assert_eq!(scene.meshes.len(), 1);
    let mesh = &scene.meshes[0];
    assert_eq!(mesh.name, "cube");
    assert_eq!(scene.sparse_point_count(), 64);
    assert_eq!(mesh.normals.len(), mesh.positions.len());
    assert_eq!(mesh.triangle_materials.len(), mesh.triangles.len());
    assert_eq!(mesh.sparse.vertex_neighbours.len(), mesh.positions.len() * DEFAULT_NEIGHBOURS as usize);
    assert_eq!(scene.materials.len(), 1);
    assert_eq!(scene.materials[0].exponent, 30.0);
    assert!(scene.needs_glossy());
    // World transform: the model-space corner (1, 1, 1) lands at 2 * (1, 1, 1) + (1, 2, 3),
    // in user coordinates (local + origin).
    let world = mesh.world_positions();
    let user = |p: &Vec3| p.as_dvec3() + scene.origin;
    assert!(world.iter().any(|p| user(p).abs_diff_eq(DVec3::new(3.0, 4.0, 5.0), 1e-5)));
    for n in mesh.world_normals() {
        assert!((n.length() - 1.0).abs() < 1e-5);
    }
    let radii = mesh.world_occluder_radii();
    for (world, model) in radii.iter().zip(&mesh.sparse.occluder_radii) {
        assert!((world - 2.0 * model).abs() < 1e-5);
    }
}

/// A scene 100 km out keeps its millimetres: the floating origin is the meshes' centre,
/// and the local positions are the user's minus it, exact to f32 at the scene's size
/// (the user-space f32 spacing there is 7.8 mm).
#[test]
fn far_scenes_are_local_to_their_centre() {
    let dir = TempDir::new("far_scene");
    dir.write("cube.obj", CUBE_OBJ);
    let far = r#""obj": "cube.obj", "sparse_points": 8,
                 "transform": {"translation": [100000.001, -70000.002, 30000.003]}"#;
    let json = scene_json(far).replace(
        r#""camera": {"position": [0, 1, 3.5], "target": [0, 1, 0]"#,
        r#""camera": {"position": [100000.501, -69999.502, 30003.503], "target": [100000.501, -69999.502, 30000.503]"#,
    );
    let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
    let user = DVec3::new(100000.001, -70000.002, 30000.003);
    assert!(scene.origin.abs_diff_eq(user + DVec3::splat(0.5), 1e-9), "origin {}", scene.origin);
    let local = scene.meshes[0].world_positions();
    for (p, model) in local.iter().zip(&scene.meshes[0].positions) {
        assert!(p.abs_diff_eq(*model - Vec3::splat(0.5), 1e-7), "{p} for model {model}");
    }
    assert!(scene.camera.position.abs_diff_eq(Vec3::new(0.0, 0.0, 3.0), 1e-6), "{}", scene.camera.position);
    let moved = DMat4::from_translation(user + DVec3::X);
    assert!(
        scene.mesh_to_world(0, Some(moved)).transform_point3(Vec3::ZERO).abs_diff_eq(Vec3::new(0.5, -0.5, -0.5), 1e-7)
    );
    // A pose's sub-millimetre survives: f32 would round 100 km to 7.8 mm steps.
    let at = DVec3::new(100000.0012, -70000.0007, 30000.0003);
    let pose = DAffine3::from_rotation_translation(glam::DQuat::from_rotation_y(0.3), at);
    let local = scene.local_pose(&pose);
    assert!(Vec3::from(local.translation).abs_diff_eq((at - scene.origin).as_vec3(), 1e-7));
    assert!(local.matrix3.abs_diff_eq(glam::Mat3A::from_rotation_y(0.3), 1e-7));

    let too_far = scene_json(r#""obj": "cube.obj", "sparse_points": 8, "transform": {"translation": [2e7, 0, 0]}"#);
    let message = Scene::from_json_str(&too_far, dir.path()).expect_err("too far").to_string();
    assert!(message.contains("meshes[0].transform.translation[0]"), "{message}");
}

fn mesh_of(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
    let n = positions.len();
    Mesh {
        name: "test".to_owned(),
        model_to_world: Mat4::IDENTITY,
        positions,
        normals: vec![Vec3::Y; n],
        texcoords: vec![Vec2::ZERO; n],
        triangle_materials: vec![0; triangles.len()],
        triangles,
        sparse: SparsePoints::default(),
    }
}

/// A unit cube, counter-clockwise seen from outside.
fn cube() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let p = (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32)).collect();
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let t = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    (p, t)
}

/// A convex object and a convex room cannot occlude themselves; two boxes side by side
/// (one mesh) can.
#[test]
fn self_occlusion_test_tells_convex_from_concave() {
    let (p, t) = cube();
    assert!(!mesh_of(p.clone(), t.clone()).may_occlude_itself(), "cube seen from outside");
    let inward: Vec<[u32; 3]> = t.iter().map(|&[a, b, c]| [a, c, b]).collect();
    assert!(!mesh_of(p.clone(), inward).may_occlude_itself(), "room seen from inside");
    let mut p2 = p.clone();
    p2.extend(p.iter().map(|v| *v + Vec3::new(3.0, 0.0, 0.0)));
    let mut t2 = t.clone();
    t2.extend(t.iter().map(|f| f.map(|i| i + 8)));
    assert!(mesh_of(p2, t2).may_occlude_itself(), "two boxes");
}

#[test]
fn world_normals_use_the_inverse_transpose() {
    let n = Vec3::new(1.0, 1.0, 0.0).normalize();
    let mesh = Mesh {
        name: "plane".to_owned(),
        model_to_world: Mat4::from_scale(Vec3::new(1.0, 2.0, 1.0)),
        positions: vec![Vec3::ZERO, Vec3::Z, Vec3::new(1.0, -1.0, 0.0)],
        normals: vec![n; 3],
        texcoords: vec![Vec2::ZERO; 3],
        triangles: vec![[0, 1, 2]],
        triangle_materials: vec![0],
        sparse: SparsePoints {
            positions: vec![Vec3::new(0.5, -0.5, 0.0)],
            normals: vec![n],
            occluder_radii: vec![0.25],
            ..Default::default()
        },
    };
    // The plane x + y = 0 stretched by 2 along y is x + y / 2 = 0: normal (1, 1/2, 0).
    let expected = Vec3::new(1.0, 0.5, 0.0).normalize();
    for world in mesh.world_normals().into_iter().chain(mesh.sparse_world_normals()) {
        assert!(world.abs_diff_eq(expected, 1e-6), "{world}");
    }
    let world = mesh.world_positions();
    let edge = world[2] - world[0];
    assert!(edge.dot(expected).abs() < 1e-6, "the normal stays perpendicular to the surface");
    assert_eq!(mesh.sparse_world_positions(), vec![Vec3::new(0.5, -1.0, 0.0)]);
    assert_eq!(mesh.world_occluder_radii(), vec![0.5]);
}

#[test]
fn glossy_needs_the_setting_and_a_glossy_material() {
    let dir = TempDir::new("glossy");
    dir.write("cube.obj", CUBE_OBJ);
    let diffuse_only = scene_json(r#""obj": "cube.obj", "sparse_points": 8"#);
    let scene = Scene::from_json_str(&diffuse_only, dir.path()).expect("scene loads");
    assert!(!scene.needs_glossy());
    assert_eq!(scene.materials, vec![Material::DEFAULT]);

    let glossy_mesh = r#""obj": "cube.obj", "sparse_points": 8, "material": {"specular": [0, 0.1, 0]}"#;
    let scene = Scene::from_json_str(&scene_json(glossy_mesh), dir.path()).expect("loads");
    assert!(scene.needs_glossy());
    let glossy_off = scene_json_with(glossy_mesh, r#", "settings": {"glossy": false}"#);
    let scene = Scene::from_json_str(&glossy_off, dir.path()).expect("scene loads");
    assert!(!scene.settings.glossy);
    assert!(!scene.needs_glossy());
}

#[test]
fn load_reads_relative_to_the_scene_file() {
    let dir = TempDir::new("load");
    std::fs::create_dir_all(dir.path().join("meshes")).expect("mkdir");
    dir.write("meshes/cube.obj", CUBE_OBJ);
    let scene_path = dir.write("scene.json", &scene_json(r#""obj": "meshes/cube.obj", "sparse_points": 16"#));
    let scene = Scene::load(&scene_path).expect("scene loads");
    assert_eq!(scene.triangle_count(), scene.meshes[0].triangles.len());
    assert_eq!(scene.vertex_count(), scene.meshes[0].positions.len());

    let missing = Scene::load(&dir.path().join("nope.json")).expect_err("missing file");
    assert!(missing.to_string().contains("nope.json"), "{missing}");
}

#[test]
fn missing_obj_names_the_field_and_file() {
    let dir = TempDir::new("missing-obj");
    let json = scene_json(r#""obj": "does-not-exist.obj", "sparse_points": 8"#);
    let error = Scene::from_json_str(&json, dir.path()).expect_err("missing OBJ");
    let message = error.to_string();
    assert!(message.contains("meshes[0].obj"), "{message}");
    assert!(message.contains("does-not-exist.obj"), "{message}");
}

/// A 2 x 1 quad in z = 0 whose texture coordinates are `uv = (x / 2, y)`, split into two
/// groups with materials `left` and `right` (defined in `quad.mtl`).
const TEXTURED_QUAD_OBJ: &str = "\
mtllib quad.mtl
v 0 0 0\nv 1 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 0 1 0
vt 0 0\nvt 0.5 0\nvt 1 0\nvt 1 1\nvt 0.5 1\nvt 0 1
g left
usemtl left
f 1/1 2/2 5/5 6/6
g right
usemtl right
f 2/2 3/3 4/4 5/5
";

/// Writes a `width` x `height` RGBA PNG whose texel (x, y) is `[x, y, 7, 200]`.
fn write_rgba_png(dir: &TempDir, name: &str, width: u32, height: u32) -> std::path::PathBuf {
    let path = dir.path().join(name);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).expect("mkdir");
    }
    image::RgbaImage::from_fn(width, height, |x, y| image::Rgba([x as u8, y as u8, 7, 200]))
        .save(&path)
        .expect("write PNG");
    path
}

/// Asserts that every vertex's texture coordinates are `uv(position)`.
fn assert_uv_is(mesh: &Mesh, uv: impl Fn(Vec3) -> Vec2) {
    assert_eq!(mesh.texcoords.len(), mesh.positions.len());
    for (p, t) in mesh.positions.iter().zip(&mesh.texcoords) {
        assert!(t.abs_diff_eq(uv(*p), 1e-5), "vertex at {p} has uv {t}, expected {}", uv(*p));
    }
}

#[test]
fn map_kd_textures_load_with_their_texcoords() {
    let dir = TempDir::new("map-kd");
    write_rgba_png(&dir, "textures/bricks.png", 3, 2);
    let rgb = dir.path().join("plain.png");
    image::RgbImage::from_pixel(1, 1, image::Rgb([10, 20, 30])).save(&rgb).expect("write PNG");
    dir.write(
        "quad.mtl",
        "newmtl left\nKd 0.5 0.5 0.5\nmap_Kd textures/bricks.png\n\
         newmtl right\nKd 1 1 1\nmap_Kd -s 1 1 1 plain.png\n",
    );
    dir.write("quad.obj", TEXTURED_QUAD_OBJ);
    let json = scene_json(r#""obj": "quad.obj", "sparse_points": 4"#);
    let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");

    assert_eq!(scene.textures.len(), 2);
    let bricks = &scene.textures[0];
    assert_eq!(bricks.path, dir.path().join("textures/bricks.png"));
    assert_eq!((bricks.width, bricks.height), (3, 2));
    assert_eq!(bricks.rgba8.len(), 3 * 2 * 4);
    // Row-major from the top row: texel (x = 2, y = 1) starts at byte 4 * (1 * 3 + 2).
    assert_eq!(&bricks.rgba8[..4], &[0, 0, 7, 200]);
    assert_eq!(&bricks.rgba8[20..24], &[2, 1, 7, 200]);
    let plain = &scene.textures[1];
    assert_eq!(plain.rgba8, vec![10, 20, 30, 255], "alpha 255 when the file has none");

    let mesh = &scene.meshes[0];
    for (t, &m) in mesh.triangle_materials.iter().enumerate() {
        let material = scene.materials[m as usize];
        let centre = mesh.triangles[t].iter().map(|&v| mesh.positions[v as usize]).sum::<Vec3>() / 3.0;
        if centre.x < 1.0 {
            assert_eq!(material.diffuse_texture, Some(0));
            assert_eq!(material.diffuse, Vec3::splat(0.5));
        } else {
            assert_eq!(material.diffuse_texture, Some(1));
        }
    }
    assert_uv_is(mesh, |p| Vec2::new(p.x / 2.0, p.y));
    // The shared edge x = 1 has the same texture coordinates on both sides: welded.
    assert_eq!(mesh.positions.iter().filter(|p| p.x == 1.0 && p.y == 0.0).count(), 1);
}

#[test]
fn materials_sharing_a_png_share_one_texture() {
    let dir = TempDir::new("shared-texture");
    write_rgba_png(&dir, "tex/shared.png", 2, 2);
    std::fs::create_dir_all(dir.path().join("mtl")).expect("mkdir");
    // Two spellings of one file.
    dir.write("mtl/quad.mtl", "newmtl left\nmap_Kd ../tex/shared.png\nnewmtl right\nmap_Kd ../tex/./shared.png\n");
    dir.write("quad.obj", &TEXTURED_QUAD_OBJ.replace("mtllib quad.mtl", "mtllib mtl/quad.mtl"));
    // Two meshes, and a JSON material with the same file: still one texture.
    let mesh = r#"{"obj": "quad.obj", "sparse_points": 4}"#;
    let json_mesh = r#"{"obj": "quad.obj", "sparse_points": 4,
                        "material": {"diffuse_texture": "tex/shared.png"}}"#;
    let json = format!(r#"{{"meshes": [{mesh}, {mesh}, {json_mesh}], {}}}"#, super::test_util::LIGHT_AND_CAMERA);
    let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(scene.textures[0].path, dir.path().join("mtl/../tex/shared.png"));
    // One entry per (mesh, material name), as without textures.
    assert_eq!(scene.materials.len(), 6);
    assert!(scene.materials.iter().all(|m| m.diffuse_texture == Some(0)));
}

#[test]
fn missing_textures_name_the_mtl_and_the_texture() {
    let dir = TempDir::new("missing-texture");
    dir.write("quad.mtl", "newmtl left\nKd 1 1 1\n\nmap_Kd textures/nope.png\nnewmtl right\n");
    dir.write("quad.obj", TEXTURED_QUAD_OBJ);
    let json = scene_json(r#""obj": "quad.obj", "sparse_points": 4"#);
    let message = Scene::from_json_str(&json, dir.path()).expect_err("missing texture").to_string();
    assert!(message.starts_with("meshes[0].obj: "), "{message}");
    assert!(message.contains("quad.mtl:4: material `left`: map_Kd"), "{message}");
    assert!(message.contains("textures/nope.png"), "{message}");

    // An unreadable one (not an image) is an error too.
    std::fs::create_dir_all(dir.path().join("textures")).expect("mkdir");
    dir.write("textures/nope.png", "not a PNG");
    let message = Scene::from_json_str(&json, dir.path()).expect_err("bad texture").to_string();
    assert!(message.contains("nope.png"), "{message}");
    assert!(message.contains("not an image file"), "{message}");

    // A JSON material's missing texture names the field and the file.
    let json = scene_json(r#""obj": "quad.obj", "sparse_points": 4, "material": {"diffuse_texture": "gone.png"}"#);
    let message = Scene::from_json_str(&json, dir.path()).expect_err("missing JSON texture").to_string();
    assert!(message.starts_with("meshes[0].material.diffuse_texture: "), "{message}");
    assert!(message.contains("gone.png"), "{message}");
}

#[test]
fn subdivision_keeps_texcoords_affine_in_position() {
    let dir = TempDir::new("subdivide-uv");
    write_rgba_png(&dir, "t.png", 4, 4);
    dir.write("quad.mtl", "newmtl left\nmap_Kd t.png\nnewmtl right\nmap_Kd t.png\n");
    // The quad scaled to 20 x 10 and sheared in uv: uv = (0.1 + 0.04 x - 0.02 y, 0.05 x + 0.1 y).
    let uv = |p: Vec3| Vec2::new(0.1 + 0.04 * p.x - 0.02 * p.y, 0.05 * p.x + 0.1 * p.y);
    let mut obj = String::from("mtllib quad.mtl\n");
    let corners = [[0, 0], [10, 0], [20, 0], [20, 10], [10, 10], [0, 10]];
    for [x, y] in corners {
        obj.push_str(&format!("v {x} {y} 0\n"));
    }
    for [x, y] in corners {
        let t = uv(Vec3::new(x as f32, y as f32, 0.0));
        obj.push_str(&format!("vt {} {}\n", t.x, t.y));
    }
    obj.push_str("usemtl left\nf 1/1 2/2 5/5 6/6\nusemtl right\nf 2/2 3/3 4/4 5/5\n");
    dir.write("quad.obj", &obj);
    let json = scene_json(r#""obj": "quad.obj", "sparse_points": 512"#);
    let scene = Scene::from_json_str(&json, dir.path()).expect("scene loads");
    let mesh = &scene.meshes[0];
    assert!(mesh.triangles.len() > 500, "subdivided: {} triangles", mesh.triangles.len());
    assert_uv_is(mesh, uv);
    assert_eq!(scene.textures.len(), 1);
}

#[test]
fn json_diffuse_texture_replaces_the_mtl_material() {
    let dir = TempDir::new("json-texture");
    write_rgba_png(&dir, "scene-tex/wood.png", 5, 3);
    write_rgba_png(&dir, "mtl-tex.png", 2, 2);
    std::fs::create_dir_all(dir.path().join("meshes")).expect("mkdir");
    dir.write("meshes/quad.mtl", "newmtl left\nmap_Kd ../mtl-tex.png\nnewmtl right\nmap_Kd ../mtl-tex.png\n");
    dir.write("meshes/quad.obj", TEXTURED_QUAD_OBJ);
    let scene_path = dir.write(
        "scene.json",
        &scene_json(
            r#""obj": "meshes/quad.obj", "sparse_points": 4,
               "materials": {"left": {"diffuse": [0.8, 0.8, 0.8], "diffuse_texture": "scene-tex/wood.png"},
                             "right": {"diffuse": [0.2, 0.3, 0.4]}}"#,
        ),
    );
    let scene = Scene::load(&scene_path).expect("scene loads");
    // Only the JSON texture: the MTL materials, and their map_Kd, are replaced.
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(scene.textures[0].path, dir.path().join("scene-tex/wood.png"));
    assert_eq!((scene.textures[0].width, scene.textures[0].height), (5, 3));
    let mut materials = scene.materials.clone();
    materials.sort_by(|a, b| b.diffuse.x.total_cmp(&a.diffuse.x));
    assert_eq!(materials[0].diffuse, Vec3::splat(0.8));
    assert_eq!(materials[0].diffuse_texture, Some(0));
    assert_eq!(materials[1].diffuse_texture, None);
    assert_uv_is(&scene.meshes[0], |p| Vec2::new(p.x / 2.0, p.y));
}

#[test]
fn meshes_without_texcoords_get_zeros() {
    let dir = TempDir::new("no-texcoords");
    dir.write("cube.obj", CUBE_OBJ);
    let scene = Scene::from_json_str(&scene_json(r#""obj": "cube.obj", "sparse_points": 32"#), dir.path())
        .expect("scene loads");
    let mesh = &scene.meshes[0];
    assert_eq!(mesh.texcoords, vec![Vec2::ZERO; mesh.positions.len()]);
    assert!(scene.textures.is_empty());
    assert_eq!(scene.materials[0].diffuse_texture, None);
}

/// The folder of a mesh shipped with the project (`fixtures/meshes/<name>`, else the shared
/// data set next to the checkout); `None`, with a note, when neither exists.
fn mesh_dir(name: &str) -> Option<std::path::PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let found = [root.join("fixtures/meshes").join(name), root.join("../shared/data/meshes").join(name)]
        .into_iter()
        .find(|dir| dir.is_dir());
    if found.is_none() {
        eprintln!("skipping: mesh folder {name} not found");
    }
    found
}

#[test]
fn cornell_box_loads_if_present() {
    let Some(dir) = mesh_dir("cornell_box") else {
        return;
    };
    let dir = dir.as_path();
    let json = scene_json(
        r#""obj": "CornellBox-Original.obj", "sparse_points": 1024,
           "materials": {"tallBox": {"diffuse": [0.5, 0.5, 0.5], "specular": [0.3, 0.3, 0.3], "exponent": 50}}"#,
    );
    let started = std::time::Instant::now();
    let scene = Scene::from_json_str(&json, dir).expect("Cornell box loads");
    let elapsed = started.elapsed();
    assert_eq!(scene.materials.len(), 8, "one entry per named material");
    assert_eq!(scene.sparse_point_count(), 1024);
    assert!(scene.needs_glossy());
    let red = Vec3::new(0.63, 0.065, 0.05);
    assert!(scene.materials.iter().any(|m| m.diffuse == red));
    assert!(elapsed.as_secs_f32() < 10.0, "took {elapsed:?}");

    let skip_light = scene_json(r#""obj": "CornellBox-Original.obj", "sparse_points": 256, "skip_groups": ["light"]"#);
    let scene = Scene::from_json_str(&skip_light, dir).expect("Cornell box loads");
    assert_eq!(scene.materials.len(), 7);
    assert!(!scene.needs_glossy());
}

#[test]
fn bunny_loads_fast_if_present() {
    let Some(dir) = mesh_dir("stanford_bunny") else {
        return;
    };
    let dir = dir.as_path();
    let json = scene_json(r#""obj": "stanford-bunny.obj", "sparse_points": 4096"#);
    let started = std::time::Instant::now();
    let scene = Scene::from_json_str(&json, dir).expect("bunny loads");
    let elapsed = started.elapsed();
    eprintln!(
        "bunny: {} vertices, {} triangles, {} sparse points in {elapsed:?}",
        scene.vertex_count(),
        scene.triangle_count(),
        scene.sparse_point_count()
    );
    assert_eq!(scene.sparse_point_count(), 4096);
    assert!(scene.triangle_count() >= 69_451);
    assert!(elapsed.as_secs_f32() < 20.0, "took {elapsed:?}");
}
