use super::super::test_util::TempDir;
use super::*;

fn mesh(obj: &str) -> MeshDescription {
    MeshDescription {
        obj: obj.to_owned(),
        obj_text: None,
        gltf: None,
        transform: Default::default(),
        sparse_points: 16,
        material: None,
        materials: Default::default(),
        skip_groups: Vec::new(),
    }
}

fn load_text(dir: &TempDir, obj: &str, description: &MeshDescription) -> Result<LoadedMesh, SceneError> {
    dir.write(&description.obj, obj);
    load(description, "meshes[0]", dir.path(), &mut Textures::default())
}

const QUAD_MTL: &str = "\
mtllib quad.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
g first
usemtl shiny
f 1 2 3
g second
usemtl matte
f 1 3 4
";

#[test]
fn groups_merge_with_materials_and_welding() {
    let dir = TempDir::new("obj-merge");
    dir.write("quad.mtl", "newmtl shiny\nKd 0.2 0.2 0.2\nKs 0.5 0.5 0.5\nNs 40\nnewmtl matte\nKd 0.8 0.1 0.1\n");
    let loaded = load_text(&dir, QUAD_MTL, &mesh("quad.obj")).expect("loads");
    // Two groups with 3 vertices each, welded to the quad's 4.
    assert_eq!(loaded.positions.len(), 4);
    assert_eq!(loaded.triangles.len(), 2);
    assert!(loaded.normals.is_none());
    assert_eq!(loaded.materials.len(), 2);
    let shiny = loaded.materials[loaded.triangle_materials[0] as usize];
    let matte = loaded.materials[loaded.triangle_materials[1] as usize];
    assert_eq!(shiny.specular, Vec3::splat(0.5));
    assert_eq!(shiny.exponent, 40.0);
    assert_eq!(matte.diffuse, Vec3::new(0.8, 0.1, 0.1));
    assert_eq!(matte.specular, Vec3::ZERO);
    assert_eq!(matte.exponent, Material::DEFAULT.exponent);
}

#[test]
fn inline_text_loads_without_a_file_and_may_not_load_mtl_files() {
    let dir = TempDir::new("obj-inline");
    let inline =
        MeshDescription { obj_text: Some("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n".to_owned()), ..mesh("uploaded.obj") };
    let loaded = load(&inline, "meshes[0]", dir.path(), &mut Textures::default()).expect("loads");
    assert_eq!(loaded.triangles.len(), 1);
    assert_eq!(loaded.materials, vec![Material::DEFAULT]);

    // The MTL exists next to where the file would be, and is still not read.
    dir.write("quad.mtl", "newmtl shiny\nKd 0.2 0.2 0.2\n");
    let inline = MeshDescription { obj_text: Some(QUAD_MTL.to_owned()), ..mesh("quad.obj") };
    let message =
        load(&inline, "meshes[0]", dir.path(), &mut Textures::default()).expect_err("mtllib refused").to_string();
    assert!(message.starts_with("meshes[0].obj_text: "), "{message}");
    assert!(message.contains("quad.obj:1"), "{message}");
    assert!(message.contains("mtllib"), "{message}");
}

#[test]
fn mtl_energy_excess_is_clamped() {
    let dir = TempDir::new("obj-clamp");
    dir.write("quad.mtl", "newmtl shiny\nKd 0.8 0.5 1.5\nKs 0.8 0.2 0\nNs 50000\nnewmtl matte\nKd 0.8 0.1 0.1\n");
    let loaded = load_text(&dir, QUAD_MTL, &mesh("quad.obj")).expect("loads");
    let shiny = loaded.materials[loaded.triangle_materials[0] as usize];
    // Red: 0.8 + 0.8 scaled to 0.5 + 0.5; green 0.5 + 0.2 untouched; blue Kd clamped to 1.
    assert!(shiny.diffuse.abs_diff_eq(Vec3::new(0.5, 0.5, 1.0), 1e-6), "{shiny:?}");
    assert!(shiny.specular.abs_diff_eq(Vec3::new(0.5, 0.2, 0.0), 1e-6), "{shiny:?}");
    assert_eq!(shiny.exponent, Material::MAX_EXPONENT);
    let sum = shiny.diffuse + shiny.specular;
    assert!(sum.max_element() <= 1.0 + 1e-6);
}

#[test]
fn texcoords_are_read_and_uv_seams_are_not_welded() {
    let dir = TempDir::new("obj-uv");
    // Two groups sharing the edge 2-3 in position; the second group's faces use other
    // texture coordinates at vertex 3 (a UV seam there) and the same ones at vertex 2.
    let obj = "\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\n\
vt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\nvt 0.9 0.9\nvt 1 0\n\
g a\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n\
g b\nf 2/2 5/6 3/5\n";
    let loaded = load_text(&dir, obj, &mesh("uv.obj")).expect("loads");
    // 5 positions; vertex 3 (1, 1, 0) appears with uv (0.5, 1) and (0.9, 0.9).
    assert_eq!(loaded.positions.len(), 6);
    assert_eq!(loaded.texcoords.len(), 6);
    let expected = [
        ([0.0, 0.0, 0.0], [0.0, 0.0]),
        ([1.0, 0.0, 0.0], [0.5, 0.0]),
        ([1.0, 1.0, 0.0], [0.5, 1.0]),
        ([0.0, 1.0, 0.0], [0.0, 1.0]),
        ([2.0, 0.0, 0.0], [1.0, 0.0]),
        ([1.0, 1.0, 0.0], [0.9, 0.9]),
    ]
    .map(|(p, t)| (Vec3::from_array(p), Vec2::from_array(t)));
    for (position, texcoord) in expected {
        let found =
            loaded.positions.iter().zip(&loaded.texcoords).filter(|&(&p, &t)| p == position && t == texcoord).count();
        assert_eq!(found, 1, "vertex {position} with uv {texcoord}");
    }
    // Every corner keeps the texture coordinates of its face vertex.
    let corner = |t: usize, k: usize| loaded.texcoords[loaded.triangles[t][k] as usize];
    assert_eq!(corner(2, 2), Vec2::new(0.9, 0.9));
    assert_eq!(corner(0, 2), Vec2::new(0.5, 1.0));
    // The shared vertex 2 (same position and uv in both groups) is welded.
    assert_eq!(loaded.triangles[0][1], loaded.triangles[2][0]);
}

#[test]
fn faces_without_texcoords_get_zeros() {
    let dir = TempDir::new("obj-no-uv");
    // Group a has texture coordinates, b none, c only on one of its faces.
    let obj = "\
v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0.25 0.75\n\
g a\nf 1/1 2/1 3/1\n\
g b\nf 2 4 3\n\
g c\nf 1/1 2/1 4/1\nf 1 4 3\n";
    let loaded = load_text(&dir, obj, &mesh("mixed.obj")).expect("loads");
    let corners = |t: usize| loaded.triangles[t].map(|v| loaded.texcoords[v as usize]);
    assert_eq!(corners(0), [Vec2::new(0.25, 0.75); 3]);
    assert_eq!(corners(1), [Vec2::ZERO; 3]);
    assert_eq!(corners(2), [Vec2::ZERO; 3], "a group with only some texcoords gets none");
    assert_eq!(corners(3), [Vec2::ZERO; 3]);

    let message = load_text(&dir, "v 0 0 0\nvt 0 nan\n", &mesh("nan.obj")).expect_err("NaN uv").to_string();
    assert!(message.contains("nan.obj:2: `vt` coordinate `nan` is not finite"), "{message}");
    let message = load_text(&dir, "v 0 0 0\nvt 0.5\n", &mesh("short.obj")).expect_err("short uv").to_string();
    assert!(message.contains("short.obj:2: `vt` has 1 coordinates, expected 2"), "{message}");
}

#[test]
fn welding_drops_triangles_with_two_corners_at_one_position() {
    // Vertices 1 and 3 share a position but not texture coordinates.
    let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::X];
    let texcoords = vec![Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE];
    let welded = weld(positions, None, texcoords, vec![[0, 1, 2], [0, 1, 3], [3, 2, 0]], vec![0, 1, 2]);
    assert_eq!(welded.positions.len(), 4);
    assert_eq!(welded.triangles, vec![[0, 1, 2], [3, 2, 0]]);
    assert_eq!(welded.triangle_materials, vec![0, 2]);
}

#[test]
fn json_overrides_replace_mtl_materials() {
    let dir = TempDir::new("obj-override");
    dir.write("quad.mtl", "newmtl shiny\nKd 0.2 0.2 0.2\nnewmtl matte\nKd 0.8 0.1 0.1\n");
    let mut description = mesh("quad.obj");
    let green = super::super::MaterialDescription { diffuse: [0.1, 0.9, 0.1], ..Default::default() };
    description.materials.insert("matte".to_owned(), green.clone());
    description.material = Some(super::super::MaterialDescription { diffuse: [0.3, 0.3, 0.3], ..Default::default() });
    let loaded = load_text(&dir, QUAD_MTL, &description).expect("loads");
    assert_eq!(loaded.materials[loaded.triangle_materials[0] as usize].diffuse, Vec3::splat(0.3));
    assert_eq!(loaded.materials[loaded.triangle_materials[1] as usize].diffuse, Vec3::new(0.1, 0.9, 0.1));

    description.materials.insert("chrome".to_owned(), green);
    let message = load_text(&dir, QUAD_MTL, &description).expect_err("unknown").to_string();
    assert!(message.starts_with("meshes[0].materials.chrome:"), "{message}");
    assert!(message.contains("matte, shiny"), "{message}");
}

#[test]
fn skip_groups_drop_faces_and_unknown_groups_are_errors() {
    let dir = TempDir::new("obj-skip");
    dir.write("quad.mtl", "newmtl shiny\nKd 0.2 0.2 0.2\nnewmtl matte\nKd 0.8 0.1 0.1\n");
    let mut description = mesh("quad.obj");
    description.skip_groups = vec!["second".to_owned()];
    let loaded = load_text(&dir, QUAD_MTL, &description).expect("loads");
    assert_eq!(loaded.triangles.len(), 1);
    assert_eq!(loaded.materials.len(), 1);

    description.skip_groups = vec!["second".to_owned(), "first".to_owned()];
    let message = load_text(&dir, QUAD_MTL, &description).expect_err("empty").to_string();
    assert!(message.contains("no triangles to load after skip_groups"), "{message}");

    description.skip_groups = vec!["third".to_owned()];
    let message = load_text(&dir, QUAD_MTL, &description).expect_err("unknown").to_string();
    assert!(message.starts_with("meshes[0].skip_groups[0]:"), "{message}");
    assert!(message.contains("first, second"), "{message}");
}

#[test]
fn obj_without_mtl_gets_the_default_material() {
    let dir = TempDir::new("obj-default");
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 2\nf 1//1 2//1 3//1\n";
    let loaded = load_text(&dir, obj, &mesh("tri.obj")).expect("loads");
    assert_eq!(loaded.materials, vec![Material::DEFAULT]);
    assert_eq!(loaded.triangle_materials, vec![0]);
    // Normals are kept as given (normalised later).
    assert_eq!(loaded.normals, Some(vec![Vec3::new(0.0, 0.0, 2.0); 3]));
}

#[test]
fn crlf_files_load() {
    let dir = TempDir::new("obj-crlf");
    dir.write("quad.mtl", &"newmtl shiny\nKd 0.2 0.2 0.2\nnewmtl matte\nKd 0.8 0.1 0.1\n".replace('\n', "\r\n"));
    let obj = QUAD_MTL.replace('\n', "\r\n");
    let mut description = mesh("quad.obj");
    description.skip_groups = vec!["first".to_owned()];
    let loaded = load_text(&dir, &obj, &description).expect("loads");
    assert_eq!(loaded.triangles.len(), 1);
    assert_eq!(loaded.materials[0].diffuse, Vec3::new(0.8, 0.1, 0.1));
}

#[test]
fn bad_files_name_the_file_and_line() {
    let dir = TempDir::new("obj-errors");
    let cases = [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", ":4: face vertex index 4 is out of range"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", ":4: face vertex index 0 is out of range"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", ":4: face vertex index -4"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/1 3/1\n", ":4: face texture coordinate index 1"),
        ("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", ":2: vertex position coordinate `nan` is not finite"),
        ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", ":2: vertex position has 2 coordinates"),
        ("v 0 0 0\r\nv 1 0 0\r\nvn 0 inf 0\r\n", ":3: normal coordinate `inf` is not finite"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", ":4: malformed face vertex `x`"),
        ("# nothing\n", "no triangles to load"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "no triangles to load"),
    ];
    for (obj, expected) in cases {
        let message = load_text(&dir, obj, &mesh("bad.obj")).expect_err(obj).to_string();
        assert!(message.starts_with("meshes[0].obj: "), "{message}");
        assert!(message.contains("bad.obj"), "{message}");
        assert!(message.contains(expected), "{obj:?}: got `{message}`, expected `{expected}`");
    }
}

#[test]
fn bad_mtl_files_name_the_file_and_line() {
    let dir = TempDir::new("mtl-errors");
    let cases = [
        ("newmtl shiny\nKd 0.5\n", "quad.mtl:2: `Kd` needs three numbers"),
        ("newmtl shiny\nKd 0.5 x 0.5\n", "quad.mtl:2: cannot parse"),
        ("newmtl shiny\nKd 0.5 NaN 0.5\nnewmtl matte\n", "quad.mtl:1: material `shiny` has a non-finite"),
    ];
    for (mtl, expected) in cases {
        dir.write("quad.mtl", mtl);
        let message = load_text(&dir, QUAD_MTL, &mesh("quad.obj")).expect_err(mtl).to_string();
        assert!(message.contains(expected), "{mtl:?}: got `{message}`, expected `{expected}`");
    }
    std::fs::remove_file(dir.path().join("quad.mtl")).expect("remove");
    let message = load_text(&dir, QUAD_MTL, &mesh("quad.obj")).expect_err("missing MTL").to_string();
    assert!(message.contains("quad.mtl: cannot read"), "{message}");
}

#[test]
fn line_of_last_read_counts_lines() {
    let text = b"a\nbb\nccc";
    assert_eq!(line_of_last_read(text, 2), 1);
    assert_eq!(line_of_last_read(text, 5), 2);
    assert_eq!(line_of_last_read(text, 8), 3);
    assert_eq!(line_of_last_read(b"", 0), 1);
}
