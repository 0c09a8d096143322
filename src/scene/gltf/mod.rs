//! glTF 2.0 (`.gltf` with its buffers, or one `.glb`) with the `gltf` crate: a mesh entry's
//! `gltf` file, or a whole scene ([`GltfSceneDescription`]: meshes, the `KHR_lights_punctual`
//! spot or point light and the camera of one file, with relume's settings beside it).
//!
//! - **Meshes.** Every mesh of the file's default scene (else its first), each node's world
//!   transform baked into the positions (normals by the inverse transpose, winding flipped under
//!   a mirroring transform), become one relume mesh in the glTF's frame (+Y up, metres, as
//!   relume's). Only `TRIANGLES` primitives; texture coordinate set 0, flipped to relume's `vt`
//!   convention (`v = 1 - v_gltf`). Vertices are kept in order of first use, as the OBJ loader
//!   keeps them, and then welded by the same code.
//! - **Materials** ([`phong_from_pbr`]): `pbrMetallicRoughness`, with `KHR_materials_specular`
//!   and `KHR_materials_ior`, to the normalised Phong model; `baseColorTexture` multiplies the
//!   diffuse albedo as `map_Kd` does. A primitive without a material gets
//!   [`Material::DEFAULT`], as an OBJ face without one does.
//! - **Bounds.** The file and every buffer it uses count towards [`MAX_GLTF_BYTES`], checked
//!   before reading; every accessor's type, count and extent is checked against its buffer
//!   view, and the triangles of every primitive instance against the scene's triangle limit,
//!   before any vertex is read. External URIs must stay inside the glTF file's directory.
//!
//! Every error names the scene field (`meshes[0].gltf`), the file, and the glTF object and
//! field (`accessors[3].componentType`).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt;
use std::io::Read as _;
use std::path::{Component, Path, PathBuf};

use base64::Engine as _;
use glam::{Mat3, Mat4, Vec2, Vec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};
use serde::{Deserialize, Serialize};

use super::description::{
    CameraDescription, LightDescription, MAX_IMAGE_SIDE, MAX_OUTER_ANGLE_DEG, MaterialDescription, MeshDescription,
    SceneDescription, SettingsDescription, int_in, key_path, parse_json,
};
use super::obj::{LoadedMesh, Merged, json_material, list};
use super::texture::Textures;
use super::{MAX_TRIANGLES_PER_MESH, Material, SceneError, TriangleBudget};

mod material;
mod scene;
#[cfg(test)]
mod tests;

pub use material::{Pbr, phong_from_pbr};
pub use scene::{GltfSceneDescription, LUMENS_PER_WATT};

/// Most bytes of one glTF file and all the buffers its meshes and textures use, together.
/// Checked before anything is read.
pub const MAX_GLTF_BYTES: u64 = 1 << 30;

/// Where errors point: the scene field that named the file, and the file.
struct At {
    field: String,
    file: PathBuf,
}

impl At {
    fn error(&self, message: impl Into<String>) -> SceneError {
        SceneError::Obj { field: self.field.clone(), file: self.file.clone(), line: None, message: message.into() }
    }
}

/// `nodes[3] (`lamp`)`, or `nodes[3]` for a node without a name.
struct NodeName<'a, 'b>(&'b gltf::Node<'a>);

impl fmt::Display for NodeName<'_, '_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0.name() {
            Some(name) => write!(f, "nodes[{}] (`{name}`)", self.0.index()),
            None => write!(f, "nodes[{}]", self.0.index()),
        }
    }
}

/// Reads and parses (with the `gltf` crate's validation) the file, after checking its size.
fn open(file: &Path, at: &At) -> Result<gltf::Gltf, SceneError> {
    let size = std::fs::metadata(file).map_err(|e| at.error(format!("cannot read: {e}")))?.len();
    if size > MAX_GLTF_BYTES {
        return Err(at.error(format!("the file is {size} bytes, over the limit of {MAX_GLTF_BYTES}")));
    }
    let bytes = std::fs::read(file).map_err(|e| at.error(format!("cannot read: {e}")))?;
    let invalid = |error: &gltf::Error| at.error(format!("not a valid glTF 2.0 file: {}", gltf_error(error)));
    let gltf = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| invalid(&e))?;
    // gltf-json 1.4.1's validation indexes the accessors with a primitive's POSITION before
    // checking it (a panic that fuzzing found): check it first.
    let root = gltf.document.as_json();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let position = gltf::json::validation::Checked::Valid(gltf::json::mesh::Semantic::Positions);
            if let Some(index) = primitive.attributes.get(&position)
                && index.value() >= root.accessors.len()
            {
                return Err(at.error(format!(
                    "meshes[{m}].primitives[{p}].attributes.POSITION: accessors[{}] does not exist (the file has {})",
                    index.value(),
                    root.accessors.len()
                )));
            }
        }
    }
    use gltf::json::validation::Validate as _;
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |path, error| errors.push((path(), error)));
    if errors.is_empty() { Ok(gltf) } else { Err(invalid(&gltf::Error::Validation(errors))) }
}

/// The `gltf` crate's error, with the JSON path of each validation failure (the first few).
fn gltf_error(error: &gltf::Error) -> String {
    match error {
        gltf::Error::Validation(errors) => {
            let mut parts: Vec<String> = errors.iter().take(4).map(|(path, e)| format!("{path}: {e}")).collect();
            if errors.len() > 4 {
                parts.push(format!("and {} more", errors.len() - 4));
            }
            parts.join("; ")
        }
        other => other.to_string(),
    }
}

/// The nodes of the default scene (else the first) that are not skipped, depth first in
/// document order, each with its world transform. A node reached twice (a cycle, or a node
/// with two parents) is an error, so a hostile file cannot loop.
fn instances<'a>(
    document: &'a gltf::Gltf,
    skip: &BTreeSet<&str>,
    at: &At,
) -> Result<Vec<(gltf::Node<'a>, Mat4)>, SceneError> {
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or_else(|| at.error("scenes: the file has no scene"))?;
    let mut reached = vec![false; document.nodes().len()];
    let mut stack: Vec<(gltf::Node<'a>, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    stack.reverse();
    let mut out = Vec::new();
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut reached[node.index()], true) {
            return Err(at.error(format!(
                "{}: reached twice from scenes[{}]; the node hierarchy must be a set of trees",
                NodeName(&node),
                scene.index()
            )));
        }
        if node.name().is_some_and(|name| skip.contains(name)) {
            continue;
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(at.error(format!(
                "{}: its transform (matrix, or translation / rotation / scale) is not finite in the world",
                NodeName(&node)
            )));
        }
        stack.extend(node.children().collect::<Vec<_>>().into_iter().rev().map(|child| (child, world)));
        out.push((node, world));
    }
    Ok(out)
}

/// What an accessor may hold: its component types and its element type.
struct Expect {
    what: &'static str,
    types: &'static [DataType],
    dimensions: Dimensions,
}

const POSITION: Expect = Expect { what: "POSITION", types: &[DataType::F32], dimensions: Dimensions::Vec3 };
const NORMAL: Expect = Expect { what: "NORMAL", types: &[DataType::F32], dimensions: Dimensions::Vec3 };
const TEXCOORD: Expect =
    Expect { what: "TEXCOORD_0", types: &[DataType::F32, DataType::U8, DataType::U16], dimensions: Dimensions::Vec2 };
const INDICES: Expect =
    Expect { what: "indices", types: &[DataType::U8, DataType::U16, DataType::U32], dimensions: Dimensions::Scalar };

/// Checks that reading `accessor` as `expect` stays inside its buffer view and buffer (the
/// `gltf` crate's reader assumes it), with at most `max_count` elements.
fn check_accessor(accessor: &gltf::Accessor, expect: &Expect, max_count: usize, at: &At) -> Result<(), SceneError> {
    let name = format!("accessors[{}] ({})", accessor.index(), expect.what);
    if accessor.sparse().is_some() {
        return Err(at.error(format!("{name}.sparse: sparse accessors are not supported")));
    }
    if !expect.types.contains(&accessor.data_type()) {
        return Err(at.error(format!(
            "{name}.componentType: must be one of {:?}, got {:?}",
            expect.types,
            accessor.data_type()
        )));
    }
    if accessor.dimensions() != expect.dimensions {
        return Err(at.error(format!("{name}.type: must be {:?}, got {:?}", expect.dimensions, accessor.dimensions())));
    }
    let count = accessor.count();
    if count == 0 || count > max_count {
        return Err(at.error(format!("{name}.count: must be in 1..={max_count}, got {count}")));
    }
    let Some(view) = accessor.view() else {
        return Err(at.error(format!("{name}.bufferView: missing (an accessor of zeros has no surface)")));
    };
    let size = accessor.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(at.error(format!(
            "bufferViews[{}].byteStride: {stride} is smaller than the {size}-byte elements of {name}",
            view.index()
        )));
    }
    let end =
        stride.checked_mul(count - 1).and_then(|n| n.checked_add(size)).and_then(|n| n.checked_add(accessor.offset()));
    if end.is_none_or(|end| end > view.length()) {
        return Err(at.error(format!(
            "{name}: byteOffset {} + {count} elements of {size} bytes every {stride} bytes end past \
             bufferViews[{}].byteLength {}",
            accessor.offset(),
            view.index(),
            view.length()
        )));
    }
    check_view(&view, at)
}

/// A buffer view must lie inside its buffer's declared length (the loaded data is checked
/// against that length).
fn check_view(view: &gltf::buffer::View, at: &At) -> Result<(), SceneError> {
    let end = view.offset().checked_add(view.length());
    if end.is_none_or(|end| end > view.buffer().length()) {
        return Err(at.error(format!(
            "bufferViews[{}]: byteOffset {} + byteLength {} ends past buffers[{}].byteLength {}",
            view.index(),
            view.offset(),
            view.length(),
            view.buffer().index(),
            view.buffer().length()
        )));
    }
    Ok(())
}

/// The data of the buffers in `needed` (`None` for the others), after checking that the file
/// and those buffers stay within [`MAX_GLTF_BYTES`] together, and that each has its declared
/// `byteLength`.
fn load_buffers(
    gltf: &gltf::Gltf,
    blob: Option<Vec<u8>>,
    needed: &BTreeSet<usize>,
    at: &At,
) -> Result<Vec<Option<Vec<u8>>>, SceneError> {
    let mut total = std::fs::metadata(&at.file).map_or(0, |m| m.len());
    let dir = at.file.parent().unwrap_or_else(|| Path::new("."));
    let mut out = Vec::new();
    for buffer in gltf.buffers() {
        let index = buffer.index();
        if !needed.contains(&index) {
            out.push(None);
            continue;
        }
        let length = buffer.length();
        total = total.saturating_add(length as u64);
        if total > MAX_GLTF_BYTES {
            return Err(at.error(format!(
                "buffers[{index}].byteLength: {length} bytes take the file and its buffers over the \
                 limit of {MAX_GLTF_BYTES} bytes"
            )));
        }
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => {
                blob.clone().ok_or_else(|| at.error(format!("buffers[{index}]: no uri and no GLB binary chunk")))?
            }
            gltf::buffer::Source::Uri(uri) => Uri::resolve(uri, dir)
                .and_then(|uri| uri.read(length))
                .map_err(|m| at.error(format!("buffers[{index}].uri: {m}")))?,
        };
        if data.len() < length {
            return Err(
                at.error(format!("buffers[{index}].byteLength: declares {length} bytes, the data has {}", data.len()))
            );
        }
        out.push(Some(data));
    }
    Ok(out)
}

/// What a buffer's or image's `uri` names.
enum Uri {
    /// A base64 `data:` URI, decoded.
    Data(Vec<u8>),
    /// A file relative to the glTF file's directory.
    File(PathBuf),
}

impl Uri {
    /// Decodes a `data:` URI, or resolves a relative one against `dir`; a path may not climb
    /// out of `dir` (no absolute paths, no `..`, no other scheme).
    fn resolve(uri: &str, dir: &Path) -> Result<Uri, String> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (_, payload) = rest.split_once(";base64,").ok_or("a data URI must be base64 (`data:...;base64,`)")?;
            return base64::engine::general_purpose::STANDARD
                .decode(payload)
                .map(Uri::Data)
                .map_err(|e| format!("invalid base64 in the data URI: {e}"));
        }
        let decoded = percent_encoding::percent_decode_str(uri)
            .decode_utf8()
            .map_err(|_| format!("`{uri}` is not UTF-8 once percent-decoded"))?;
        let relative = Path::new(decoded.as_ref());
        let confined =
            !uri.contains(':') && relative.components().all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
        if !confined {
            return Err(format!(
                "`{uri}` is not a relative path inside the glTF file's directory (no scheme, no `..`, \
                 not absolute)"
            ));
        }
        Ok(Uri::File(dir.join(relative)))
    }

    /// The bytes, at most `max_bytes` of a file.
    fn read(self, max_bytes: usize) -> Result<Vec<u8>, String> {
        match self {
            Uri::Data(bytes) => Ok(bytes),
            Uri::File(path) => {
                let error = |e: std::io::Error| format!("cannot read {}: {e}", path.display());
                let mut data = Vec::new();
                std::fs::File::open(&path)
                    .map_err(error)?
                    .take(max_bytes as u64)
                    .read_to_end(&mut data)
                    .map_err(error)?;
                Ok(data)
            }
        }
    }
}

/// Loads the glTF of mesh `field` (e.g. `meshes[0]`), relative to `base_dir`: every triangle
/// of its default scene as one mesh. Textures of the materials used go into `textures`.
pub(crate) fn load(
    description: &MeshDescription,
    field: &str,
    base_dir: &Path,
    budget: &TriangleBudget,
    textures: &mut Textures,
) -> Result<LoadedMesh, SceneError> {
    let relative = description.gltf.as_deref().unwrap_or_default();
    let at = At { field: format!("{field}.gltf"), file: base_dir.join(relative) };
    let mut gltf = open(&at.file, &at)?;
    let blob = gltf.blob.take();
    check_names(description, field, &gltf, &at)?;
    let skip: BTreeSet<&str> = description.skip_groups.iter().map(String::as_str).collect();
    let nodes = instances(&gltf, &skip, &at)?;

    // Every primitive instance, checked and counted before any buffer is read.
    let mut plan = Vec::new();
    let mut triangles = 0usize;
    let max_vertices = 3 * MAX_TRIANGLES_PER_MESH;
    let mut needed = BTreeSet::new();
    for (node, world) in &nodes {
        let Some(mesh) = node.mesh() else { continue };
        for primitive in mesh.primitives() {
            let name = format!("meshes[{}].primitives[{}]", mesh.index(), primitive.index());
            if primitive.mode() != Mode::Triangles {
                return Err(at.error(format!(
                    "{name}.mode: relume reads TRIANGLES (4) only, got {:?}; export triangles",
                    primitive.mode()
                )));
            }
            let positions = primitive
                .get(&Semantic::Positions)
                .ok_or_else(|| at.error(format!("{name}.attributes: no POSITION")))?;
            check_accessor(&positions, &POSITION, max_vertices, &at)?;
            let mut accessors = vec![positions.clone()];
            let corners = match primitive.indices() {
                Some(indices) => {
                    check_accessor(&indices, &INDICES, 3 * budget.total.min(MAX_TRIANGLES_PER_MESH), &at)?;
                    accessors.push(indices.clone());
                    indices.count()
                }
                None => positions.count(),
            };
            if corners % 3 != 0 {
                return Err(at.error(format!("{name}: {corners} corners is not a whole number of triangles")));
            }
            for (semantic, expect) in [(Semantic::Normals, &NORMAL), (Semantic::TexCoords(0), &TEXCOORD)] {
                if let Some(accessor) = primitive.get(&semantic) {
                    check_accessor(&accessor, expect, max_vertices, &at)?;
                    if accessor.count() != positions.count() {
                        return Err(at.error(format!(
                            "{name}.attributes.{}: accessors[{}] has {} elements, POSITION has {}",
                            expect.what,
                            accessor.index(),
                            accessor.count(),
                            positions.count()
                        )));
                    }
                    accessors.push(accessor);
                }
            }
            triangles += corners / 3;
            if triangles > budget.left {
                let what = format!("the glTF has at least {triangles} triangles (node instances counted),");
                return Err(budget.exceeded(at.field.clone(), &what));
            }
            needed.extend(accessors.iter().filter_map(|a| a.view()).map(|v| v.buffer().index()));
            plan.push((node.clone(), *world, mesh.index(), primitive));
        }
    }
    if plan.is_empty() {
        let after = if skip.is_empty() { "" } else { " after skip_groups" };
        return Err(at.error(format!("no triangles to load{after}")));
    }
    for (_, _, _, primitive) in &plan {
        let texture = primitive.material().pbr_metallic_roughness().base_color_texture();
        if let Some(gltf::image::Source::View { view, .. }) = texture.map(|t| t.texture().source().source()) {
            check_view(&view, &at)?;
            needed.insert(view.buffer().index());
        }
    }
    let buffers = load_buffers(&gltf, blob, &needed, &at)?;

    let mut resolver = Resolver {
        description,
        field,
        base_dir,
        at: &at,
        buffers: &buffers,
        textures,
        by_index: HashMap::new(),
        materials: Vec::new(),
    };
    let mut merged = Merged::default();
    for (node, world, mesh, primitive) in &plan {
        let name = format!("{} meshes[{mesh}].primitives[{}]", NodeName(node), primitive.index());
        let material = resolver.resolve(&primitive.material())?;
        let reader = primitive.reader(|buffer| buffers.get(buffer.index()).and_then(|b| b.as_deref()));
        let read_error = |what: &str| at.error(format!("{name}: cannot read {what}"));
        let positions: Vec<Vec3> =
            reader.read_positions().ok_or_else(|| read_error("POSITION"))?.map(Vec3::from).collect();
        if let Some(bad) = positions.iter().find(|p| !p.is_finite()) {
            return Err(at.error(format!("{name}: POSITION {bad} is not finite")));
        }
        let indices: Vec<u32> = match reader.read_indices() {
            Some(indices) => indices.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
            return Err(at.error(format!("{name}: index {bad} is out of range ({} vertices)", positions.len())));
        }
        let normals: Option<Vec<Vec3>> = reader.read_normals().map(|n| n.map(Vec3::from).collect());
        let texcoords: Option<Vec<Vec2>> =
            reader.read_tex_coords(0).map(|t| t.into_f32().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect());
        if let Some(bad) = texcoords.iter().flatten().find(|t| !t.is_finite()) {
            return Err(at.error(format!("{name}: TEXCOORD_0 {bad} is not finite")));
        }
        merged.append_primitive(Primitive { world: *world, positions, normals, texcoords, indices, material });
    }
    Ok(merged.into_mesh(at.file.clone(), resolver.materials))
}

/// `skip_groups` must name nodes and `materials` glTF materials of the file.
fn check_names(description: &MeshDescription, field: &str, gltf: &gltf::Gltf, at: &At) -> Result<(), SceneError> {
    let nodes: BTreeSet<&str> = gltf.nodes().filter_map(|n| n.name()).collect();
    for (i, name) in description.skip_groups.iter().enumerate() {
        if !nodes.contains(name.as_str()) {
            return Err(SceneError::Obj {
                field: format!("{field}.skip_groups[{i}]"),
                file: at.file.clone(),
                line: None,
                message: format!("no node named `{name}` (the file has: {})", list(nodes.iter())),
            });
        }
    }
    let materials: BTreeSet<&str> = gltf.materials().filter_map(|m| m.name()).collect();
    for name in description.materials.keys() {
        if !materials.contains(name.as_str()) {
            return Err(SceneError::Obj {
                field: key_path(&format!("{field}.materials"), name),
                file: at.file.clone(),
                line: None,
                message: format!("no material named `{name}` (the file has: {})", list(materials.iter())),
            });
        }
    }
    Ok(())
}

/// One primitive instance, read.
struct Primitive {
    world: Mat4,
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    texcoords: Option<Vec<Vec2>>,
    indices: Vec<u32>,
    material: u32,
}

/// The primitive instances are concatenated in world (the glTF scene's) space.
impl Merged {
    /// Appends the vertices the primitive's triangles use, in order of first use (as the OBJ
    /// loader orders them), transformed to world space.
    fn append_primitive(&mut self, p: Primitive) {
        let normal_matrix = Mat3::from_mat4(p.world).inverse().transpose();
        let mirrored = Mat3::from_mat4(p.world).determinant() < 0.0;
        let mut remap = vec![u32::MAX; p.positions.len()];
        let mut corner = |v: u32| -> u32 {
            let slot = &mut remap[v as usize];
            if *slot == u32::MAX {
                *slot = self.positions.len() as u32;
                let v = v as usize;
                self.positions.push(p.world.transform_point3(p.positions[v]));
                let normal = p.normals.as_ref().map_or(Vec3::ZERO, |n| (normal_matrix * n[v]).normalize_or_zero());
                self.normals.push(normal);
                self.texcoords.push(p.texcoords.as_ref().map_or(Vec2::ZERO, |t| t[v]));
            }
            *slot
        };
        let mut triangles = Vec::with_capacity(p.indices.len() / 3);
        for t in p.indices.chunks_exact(3) {
            let [a, b, c] = [corner(t[0]), corner(t[1]), corner(t[2])];
            triangles.push(if mirrored { [a, c, b] } else { [a, b, c] });
        }
        if p.normals.is_some() {
            self.faces_with_normals += triangles.len();
        } else {
            self.faces_without_normals += triangles.len();
        }
        self.triangle_materials.extend(std::iter::repeat_n(p.material, triangles.len()));
        self.triangles.extend(triangles);
    }
}

/// The mesh's material table, one entry per glTF material used (in order of first use), with
/// the scene's overrides, loading base colour textures.
struct Resolver<'a> {
    description: &'a MeshDescription,
    field: &'a str,
    base_dir: &'a Path,
    at: &'a At,
    buffers: &'a [Option<Vec<u8>>],
    textures: &'a mut Textures,
    /// glTF material index (`None`: the default material) to index into `materials`.
    by_index: HashMap<Option<usize>, u32>,
    materials: Vec<Material>,
}

impl Resolver<'_> {
    fn resolve(&mut self, material: &gltf::Material) -> Result<u32, SceneError> {
        if let Some(&index) = self.by_index.get(&material.index()) {
            return Ok(index);
        }
        let description = self.description;
        let by_name = material.name().and_then(|name| Some((name, description.materials.get(name)?)));
        let converted = match (by_name, &description.material, material.index()) {
            (Some((name, json)), _, _) => {
                let field = key_path(&format!("{}.materials", self.field), name);
                json_material(json, &field, self.base_dir, self.textures)?
            }
            (None, Some(json), _) => {
                json_material(json, &format!("{}.material", self.field), self.base_dir, self.textures)?
            }
            (None, None, Some(_)) => self.convert(material)?,
            (None, None, None) => Material::DEFAULT,
        };
        let index = self.materials.len() as u32;
        self.materials.push(converted);
        self.by_index.insert(material.index(), index);
        Ok(index)
    }

    /// A glTF material through [`phong_from_pbr`], with its base colour texture.
    fn convert(&mut self, material: &gltf::Material) -> Result<Material, SceneError> {
        let index = material.index().unwrap_or_default();
        let pbr = material.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        let specular = material.specular();
        let ior = material.ior().unwrap_or(1.5);
        if !(ior.is_finite() && ior >= 1.0) {
            return Err(self.at.error(format!(
                "materials[{index}].extensions.KHR_materials_ior.ior: must be a finite number >= 1, got {ior}"
            )));
        }
        let mut converted = phong_from_pbr(Pbr {
            base_color: Vec3::new(r, g, b),
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            specular: specular.as_ref().map_or(1.0, |s| s.specular_factor()),
            specular_color: specular.as_ref().map_or(Vec3::ONE, |s| Vec3::from(s.specular_color_factor())),
            ior,
        });
        let ignored: Vec<&str> = [
            (pbr.metallic_roughness_texture().is_some(), "metallicRoughnessTexture (the factors are used)"),
            (material.normal_texture().is_some(), "normalTexture"),
            (material.emissive_texture().is_some() || material.emissive_factor() != [0.0; 3], "emission"),
            (material.alpha_mode() != gltf::material::AlphaMode::Opaque, "alphaMode (rendered opaque)"),
        ]
        .into_iter()
        .filter_map(|(present, what)| present.then_some(what))
        .collect();
        if !ignored.is_empty() {
            tracing::warn!(file = %self.at.file.display(), material = index, "glTF material: ignored {}", ignored.join(", "));
        }
        if let Some(info) = pbr.base_color_texture() {
            if info.tex_coord() != 0 {
                tracing::warn!(
                    material = index,
                    "baseColorTexture uses TEXCOORD_{}; relume reads TEXCOORD_0",
                    info.tex_coord()
                );
            }
            let image = info.texture().source();
            let image_field =
                format!("materials[{index}].pbrMetallicRoughness.baseColorTexture: images[{}]", image.index());
            let key = self.key(image.index());
            let loaded = match image.source() {
                gltf::image::Source::Uri { uri, .. } => {
                    Uri::resolve(uri, self.at.file.parent().unwrap_or_else(|| Path::new("."))).and_then(|resolved| {
                        match resolved {
                            Uri::File(path) => self.textures.load(&path),
                            Uri::Data(bytes) => self.textures.load_bytes(key, &bytes),
                        }
                    })
                }
                gltf::image::Source::View { view, .. } => {
                    // The view was checked against its buffer, and the buffer's data against its
                    // declared length, before any data was read.
                    let bytes = self
                        .buffers
                        .get(view.buffer().index())
                        .and_then(|b| b.as_deref())
                        .and_then(|b| b.get(view.offset()..view.offset() + view.length()));
                    match bytes {
                        Some(bytes) => self.textures.load_bytes(key, bytes),
                        None => Err(format!("bufferViews[{}] is not loaded", view.index())),
                    }
                }
            };
            converted.diffuse_texture =
                Some(loaded.map_err(|message| self.at.error(format!("{image_field}: {message}")))?);
        }
        Ok(converted)
    }

    /// The texture table's key of an image embedded in the file.
    fn key(&self, image: usize) -> PathBuf {
        PathBuf::from(format!("{}#images[{image}]", self.at.file.display()))
    }
}
