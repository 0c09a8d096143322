//! OBJ and MTL loading with tobj: all groups of one OBJ merged into one indexed triangle mesh,
//! identical vertices welded, and every triangle's material resolved (MTL, then JSON
//! overrides) into a per-mesh table, its diffuse texture (`map_Kd`, or the JSON
//! `diffuse_texture`) loaded into the scene's texture table.
//!
//! tobj reports errors without a line number and accepts a few things relume must not (NaN
//! coordinates, face indices it only checks at the end of a group, short `Kd` lines it panics
//! on), so a light pre-scan of the text checks those first and names the file and line.

use std::cell::RefCell;
use std::collections::{BTreeSet, HashMap};
use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use super::description::{MaterialDescription, MeshDescription, key_path};
use super::hash::fast_hash_map;
use super::texture::{Textures, parse_map_statement};
use super::{Material, SceneError};

/// One mesh file (OBJ here, glTF in `super::gltf`) as a single mesh, before normals,
/// subdivision and sparse points.
#[derive(Clone, Debug)]
pub(crate) struct LoadedMesh {
    /// The mesh file as opened (`base_dir` joined with the scene's path).
    pub file: PathBuf,
    /// Model-space positions, welded.
    pub positions: Vec<Vec3>,
    /// The file's normals, one per vertex, when every loaded face has them.
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates, one per vertex; zero for vertices of faces without `vt`.
    pub texcoords: Vec<Vec2>,
    /// Counter-clockwise triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle, index into `materials`.
    pub triangle_materials: Vec<u32>,
    /// This mesh's materials, one per material name used (plus the default when some faces
    /// have none), overrides applied; texture indices are into the scene's table.
    pub materials: Vec<Material>,
}

/// A problem at a place in a file, before it is tied to a scene field.
struct FileError {
    file: PathBuf,
    line: Option<usize>,
    message: String,
}

impl FileError {
    fn into_scene_error(self, field: &str) -> SceneError {
        SceneError::Obj { field: field.to_owned(), file: self.file, line: self.line, message: self.message }
    }
}

/// Loads the OBJ of mesh `field` (e.g. `meshes[0]`), relative to `base_dir` (the scene file's
/// directory); the textures of the materials its triangles use are added to `textures`.
pub(crate) fn load(
    description: &MeshDescription,
    field: &str,
    base_dir: &Path,
    textures: &mut Textures,
) -> Result<LoadedMesh, SceneError> {
    let obj_field = format!("{field}.obj");
    let file = base_dir.join(&description.obj);
    let file_error = |line: Option<usize>, message: String| SceneError::Obj {
        field: obj_field.clone(),
        file: file.clone(),
        line,
        message,
    };
    let bytes = match &description.obj_text {
        Some(text) => std::borrow::Cow::Borrowed(text.as_bytes()),
        None => {
            std::borrow::Cow::Owned(std::fs::read(&file).map_err(|e| file_error(None, format!("cannot read: {e}")))?)
        }
    };
    let text = String::from_utf8_lossy(&bytes);
    let scan = prescan_obj(&text).map_err(|(line, message)| file_error(Some(line), message))?;
    if description.obj_text.is_some()
        && let Some(line) = text.split('\n').position(|l| l.split_whitespace().next() == Some("mtllib"))
    {
        // Inline text comes from a client: it may not name files to read.
        return Err(SceneError::Obj {
            field: format!("{field}.obj_text"),
            file: file.clone(),
            line: Some(line + 1),
            message: "inline OBJ text may not load MTL files (`mtllib`); give its materials with \
                      the mesh's `material`"
                .to_owned(),
        });
    }

    // tobj asks for each `mtllib`; load it relative to the OBJ and remember where each material
    // is defined (for messages) and the first error (tobj would drop it).
    let obj_dir = file.parent().unwrap_or_else(|| Path::new("."));
    let mtl_files: RefCell<Vec<MtlFile>> = RefCell::new(Vec::new());
    let mtl_error: RefCell<Option<FileError>> = RefCell::new(None);
    let material_loader = |relative: &Path| -> tobj::MTLLoadResult {
        let path = obj_dir.join(relative);
        match load_mtl(&path) {
            Ok((loaded, mtl)) => {
                mtl_files.borrow_mut().push(mtl);
                loaded
            }
            Err(error) => {
                mtl_error.borrow_mut().get_or_insert(error);
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    };
    let mut reader = Cursor::new(text.as_bytes());
    let result = tobj::load_obj_buf(&mut reader, &tobj::GPU_LOAD_OPTIONS, material_loader);
    if let Some(error) = mtl_error.into_inner() {
        return Err(error.into_scene_error(&obj_field));
    }
    let (models, tobj_materials) = result.map_err(|e| {
        let line = line_of_last_read(text.as_bytes(), reader.position());
        file_error(Some(line), format!("cannot parse: {e}"))
    })?;
    // tobj only returns an error here when an MTL failed, which was reported above.
    let tobj_materials = tobj_materials.unwrap_or_default();
    let mtl_files = mtl_files.into_inner();

    check_skip_groups(description, field, &file, &scan, &models)?;
    check_material_overrides(description, field, &file, &tobj_materials)?;
    let mut warned = BTreeSet::new();
    for (name, line) in &scan.usemtl {
        if !tobj_materials.iter().any(|m| &m.name == name) && warned.insert(name) {
            tracing::warn!(
                file = %file.display(),
                line,
                "usemtl `{name}` names no material of the OBJ's MTL files; \
                 its faces get the default material"
            );
        }
    }

    let mut merged = Merged::default();
    let mut resolver = MaterialResolver {
        description,
        field,
        base_dir,
        tobj_materials: &tobj_materials,
        mtl_files: &mtl_files,
        textures,
        by_name: HashMap::new(),
        materials: Vec::new(),
    };
    let skip: BTreeSet<&str> = description.skip_groups.iter().map(String::as_str).collect();
    for model in models.iter().filter(|m| !skip.contains(m.name.as_str())) {
        if model.mesh.indices.is_empty() {
            continue;
        }
        let material = resolver.resolve(model.mesh.material_id)?;
        let texcoords = merged
            .append(&model.mesh, material)
            .map_err(|message| file_error(None, format!("group `{}`: {message}", model.name)))?;
        let textured = resolver.materials[material as usize].diffuse_texture.is_some();
        if textured && texcoords != Texcoords::All {
            tracing::warn!(
                file = %file.display(),
                "group `{}` has a textured material but {} of its faces lack texture \
                 coordinates (`vt`); they sample the texture at (0, 0)",
                model.name,
                if texcoords == Texcoords::None { "all" } else { "some" }
            );
        }
    }
    if merged.triangles.is_empty() {
        let after = if skip.is_empty() { "" } else { " after skip_groups" };
        return Err(file_error(None, format!("no triangles to load{after}")));
    }
    Ok(merged.into_mesh(file, resolver.materials))
}

/// What the pre-scan learned besides "no errors".
#[derive(Debug, Default)]
struct ObjScan {
    /// Names of `g`/`o` statements, as tobj names its models.
    groups: Vec<String>,
    /// `usemtl` names and their lines.
    usemtl: Vec<(String, usize)>,
}

/// Checks what tobj does not: finite coordinates, and face indices that refer to elements
/// defined above them. Errors are (1-based line, message).
fn prescan_obj(text: &str) -> Result<ObjScan, (usize, String)> {
    let mut scan = ObjScan::default();
    let (mut positions, mut texcoords, mut normals) = (0usize, 0usize, 0usize);
    for (index, raw) in text.split('\n').enumerate() {
        let line_number = index + 1;
        let line = raw.strip_suffix('\r').unwrap_or(raw);
        let mut words = line.split_whitespace();
        let fail = |message: String| (line_number, message);
        match words.next() {
            Some("v") => {
                let values: Vec<&str> = words.collect();
                check_numbers(&values, 3, "vertex position").map_err(fail)?;
                if values.len() == 4 {
                    // x y z w: tobj divides by w.
                    match values[3].parse::<f32>() {
                        Ok(w) if w.is_finite() && w != 0.0 => {}
                        _ => {
                            return Err(fail(format!(
                                "vertex weight w must be a finite nonzero number, got `{}`",
                                values[3]
                            )));
                        }
                    }
                }
                positions += 1;
            }
            Some("vn") => {
                let values: Vec<&str> = words.collect();
                check_numbers(&values, 3, "normal").map_err(fail)?;
                normals += 1;
            }
            Some("vt") => {
                let values: Vec<&str> = words.collect();
                check_numbers(&values, 2, "`vt`").map_err(fail)?;
                texcoords += 1;
            }
            Some("f") => {
                for vertex in words {
                    check_face_vertex(vertex, positions, texcoords, normals).map_err(fail)?;
                }
            }
            Some("g" | "o") => {
                let first = line.chars().next().map_or(1, char::len_utf8);
                let name = line[first..].trim();
                let name = if name.is_empty() { "unnamed_object" } else { name };
                scan.groups.push(name.to_owned());
            }
            Some("usemtl") => {
                let name = line.split_once(' ').map_or("", |(_, rest)| rest).trim();
                scan.usemtl.push((name.to_owned(), line_number));
            }
            _ => {}
        }
    }
    Ok(scan)
}

/// The first `count` of `values` must be finite numbers.
fn check_numbers(values: &[&str], count: usize, what: &str) -> Result<(), String> {
    if values.len() < count {
        return Err(format!("{what} has {} coordinates, expected {count}", values.len()));
    }
    for value in &values[..count] {
        match value.parse::<f32>() {
            Ok(x) if x.is_finite() => {}
            Ok(_) => return Err(format!("{what} coordinate `{value}` is not finite")),
            Err(_) => return Err(format!("{what} coordinate `{value}` is not a number")),
        }
    }
    Ok(())
}

/// Checks one `v`, `v/vt`, `v//vn` or `v/vt/vn` face vertex against the element counts so far.
fn check_face_vertex(vertex: &str, positions: usize, texcoords: usize, normals: usize) -> Result<(), String> {
    let parts: Vec<&str> = vertex.split('/').collect();
    if parts.len() > 3 || parts[0].is_empty() {
        return Err(format!("malformed face vertex `{vertex}`"));
    }
    let kinds = [("vertex", positions), ("texture coordinate", texcoords), ("normal", normals)];
    for (part, (kind, count)) in parts.iter().zip(kinds) {
        if part.is_empty() {
            continue;
        }
        let index: i64 = part.parse().map_err(|_| format!("malformed face vertex `{vertex}`"))?;
        // 1..=count counts from the start, -count..=-1 back from the last one defined.
        if index == 0 || index.unsigned_abs() > count as u64 {
            return Err(format!(
                "face {kind} index {index} is out of range: {count} {kind}s are defined above \
                 this line (OBJ indices start at 1, negative ones count back)"
            ));
        }
    }
    Ok(())
}

/// The 1-based line of the last line a line reader read, after it consumed `consumed` bytes.
fn line_of_last_read(text: &[u8], consumed: u64) -> usize {
    let mut end = usize::try_from(consumed).unwrap_or(usize::MAX).min(text.len());
    if end > 0 && text[end - 1] == b'\n' {
        end -= 1;
    }
    text[..end].iter().filter(|&&b| b == b'\n').count() + 1
}

/// One MTL file: its path, the line of each `newmtl`, and the line of each `map_Kd` with the
/// material it belongs to.
#[derive(Debug)]
struct MtlFile {
    path: PathBuf,
    definitions: Vec<(String, usize)>,
    diffuse_maps: Vec<(String, usize)>,
}

impl MtlFile {
    fn line_of(&self, name: &str) -> Option<usize> {
        Self::last_line(&self.definitions, name)
    }

    fn map_kd_line_of(&self, name: &str) -> Option<usize> {
        Self::last_line(&self.diffuse_maps, name)
    }

    fn last_line(lines: &[(String, usize)], name: &str) -> Option<usize> {
        lines.iter().rev().find(|(n, _)| n == name).map(|&(_, line)| line)
    }
}

/// Reads and parses one MTL file; the tobj result is always `Ok` (errors are [`FileError`]s).
fn load_mtl(path: &Path) -> Result<(tobj::MTLLoadResult, MtlFile), FileError> {
    let error = |line: Option<usize>, message: String| FileError { file: path.to_path_buf(), line, message };
    let bytes = std::fs::read(path).map_err(|e| error(None, format!("cannot read: {e}")))?;
    let text = String::from_utf8_lossy(&bytes);
    let mut definitions: Vec<(String, usize)> = Vec::new();
    let mut diffuse_maps = Vec::new();
    for (index, raw) in text.split('\n').enumerate() {
        let line = raw.trim();
        let mut words = line.split_whitespace();
        match words.next() {
            Some("newmtl") => {
                definitions.push((line["newmtl".len()..].trim().to_owned(), index + 1));
            }
            Some("map_Kd") => {
                if let Some((name, _)) = definitions.last() {
                    diffuse_maps.push((name.clone(), index + 1));
                }
            }
            // tobj panics on fewer than three numbers.
            Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) if words.clone().count() < 3 => {
                return Err(error(Some(index + 1), format!("`{key}` needs three numbers (r g b)")));
            }
            _ => {}
        }
    }
    let mut reader = Cursor::new(text.as_bytes());
    let parsed = tobj::load_mtl_buf(&mut reader).map_err(|e| {
        let line = line_of_last_read(text.as_bytes(), reader.position());
        error(Some(line), format!("cannot parse: {e}"))
    })?;
    Ok((Ok(parsed), MtlFile { path: path.to_path_buf(), definitions, diffuse_maps }))
}

fn check_skip_groups(
    description: &MeshDescription,
    field: &str,
    file: &Path,
    scan: &ObjScan,
    models: &[tobj::Model],
) -> Result<(), SceneError> {
    let known: BTreeSet<&str> =
        scan.groups.iter().map(String::as_str).chain(models.iter().map(|m| m.name.as_str())).collect();
    for (i, name) in description.skip_groups.iter().enumerate() {
        if !known.contains(name.as_str()) {
            return Err(SceneError::Obj {
                field: format!("{field}.skip_groups[{i}]"),
                file: file.to_path_buf(),
                line: None,
                message: format!("no group or object named `{name}` (the file has: {})", list(known.iter())),
            });
        }
    }
    Ok(())
}

fn check_material_overrides(
    description: &MeshDescription,
    field: &str,
    file: &Path,
    tobj_materials: &[tobj::Material],
) -> Result<(), SceneError> {
    let known: BTreeSet<&str> = tobj_materials.iter().map(|m| m.name.as_str()).collect();
    for name in description.materials.keys() {
        if !known.contains(name.as_str()) {
            return Err(SceneError::Obj {
                field: key_path(&format!("{field}.materials"), name),
                file: file.to_path_buf(),
                line: None,
                message: format!(
                    "no material named `{name}` in the OBJ's MTL files (they define: {})",
                    list(known.iter())
                ),
            });
        }
    }
    Ok(())
}

/// Converts a JSON material (validated already), loading its texture relative to the scene
/// file's directory `base_dir`; `field` is the material's path.
pub(crate) fn json_material(
    json: &MaterialDescription,
    field: &str,
    base_dir: &Path,
    textures: &mut Textures,
) -> Result<Material, SceneError> {
    let mut material = json.to_material();
    if let Some(texture) = &json.diffuse_texture {
        let path = base_dir.join(texture);
        let index = textures.load(&path).map_err(|message| SceneError::Obj {
            field: format!("{field}.diffuse_texture"),
            file: path.clone(),
            line: None,
            message,
        })?;
        material.diffuse_texture = Some(index);
    }
    Ok(material)
}

/// `a, b, c`, or `nothing`.
pub(crate) fn list<'a>(names: impl Iterator<Item = &'a &'a str>) -> String {
    let names: Vec<&str> = names.copied().collect();
    if names.is_empty() { "nothing".to_owned() } else { names.join(", ") }
}

/// Builds the per-mesh material table on demand, one entry per material name used, loading
/// the textures of those materials.
struct MaterialResolver<'a> {
    description: &'a MeshDescription,
    field: &'a str,
    /// The scene file's directory, which JSON texture paths are relative to.
    base_dir: &'a Path,
    tobj_materials: &'a [tobj::Material],
    mtl_files: &'a [MtlFile],
    textures: &'a mut Textures,
    /// Material name (`None`: faces without a material) to index into `materials`.
    by_name: HashMap<Option<String>, u32>,
    materials: Vec<Material>,
}

impl MaterialResolver<'_> {
    /// The local index of the material with tobj id `id`.
    fn resolve(&mut self, id: Option<usize>) -> Result<u32, SceneError> {
        let source = id.and_then(|id| self.tobj_materials.get(id));
        let name = source.map(|m| m.name.clone());
        if let Some(&index) = self.by_name.get(&name) {
            return Ok(index);
        }
        let description = self.description;
        let by_name_override = name.as_ref().and_then(|name| Some((name, description.materials.get(name)?)));
        let material = match (by_name_override, &description.material, source) {
            (Some((name, json)), _, _) => {
                self.convert_json(json, &key_path(&format!("{}.materials", self.field), name))?
            }
            (None, Some(json), _) => self.convert_json(json, &format!("{}.material", self.field))?,
            (None, None, Some(mtl)) => self.convert_mtl(mtl)?,
            (None, None, None) => Material::DEFAULT,
        };
        let index = u32::try_from(self.materials.len()).unwrap_or(u32::MAX);
        self.materials.push(material);
        self.by_name.insert(name, index);
        Ok(index)
    }

    fn convert_json(&mut self, json: &MaterialDescription, field: &str) -> Result<Material, SceneError> {
        json_material(json, field, self.base_dir, self.textures)
    }

    /// Converts an MTL material: `Kd` to diffuse, `Ks` to specular, `Ns` to exponent, `map_Kd`
    /// (relative to the MTL file's directory) to the diffuse texture; values out of range are
    /// clamped and `Kd + Ks > 1` is scaled down to 1, each with a warning.
    fn convert_mtl(&mut self, mtl: &tobj::Material) -> Result<Material, SceneError> {
        let file = self.mtl_files.iter().rev().find(|f| f.line_of(&mtl.name).is_some());
        let (path, line) = file.map_or((PathBuf::new(), None), |f| (f.path.clone(), f.line_of(&mtl.name)));
        let name = &mtl.name;
        let warn = |what: &str| {
            tracing::warn!(
                file = %path.display(),
                line,
                material = %name,
                "{what}"
            );
        };
        let diffuse = mtl.diffuse.map_or(Material::DEFAULT.diffuse, Vec3::from_array);
        let specular = mtl.specular.map_or(Material::DEFAULT.specular, Vec3::from_array);
        let exponent = mtl.shininess.unwrap_or(Material::DEFAULT.exponent);
        if !diffuse.is_finite() || !specular.is_finite() || !exponent.is_finite() {
            return Err(SceneError::Obj {
                field: format!("{}.obj", self.field),
                file: path,
                line,
                message: format!(
                    "material `{name}` has a non-finite Kd, Ks or Ns \
                     (Kd {diffuse}, Ks {specular}, Ns {exponent})"
                ),
            });
        }
        let mut material = Material {
            diffuse: diffuse.clamp(Vec3::ZERO, Vec3::ONE),
            specular: specular.clamp(Vec3::ZERO, Vec3::ONE),
            exponent: exponent.clamp(0.0, Material::MAX_EXPONENT),
            diffuse_texture: None,
        };
        if material.diffuse != diffuse || material.specular != specular {
            warn(&format!(
                "Kd {diffuse} / Ks {specular} outside [0, 1]: clamped to Kd {} / Ks {}",
                material.diffuse, material.specular
            ));
        }
        if material.exponent != exponent {
            warn(&format!("Ns {exponent} outside [0, {}]: clamped to {}", Material::MAX_EXPONENT, material.exponent));
        }
        let sum = material.diffuse + material.specular;
        if sum.max_element() > 1.0 {
            let scale = Vec3::ONE / sum.max(Vec3::ONE);
            let before = material;
            material.diffuse *= scale;
            material.specular *= scale;
            warn(&format!(
                "Kd + Ks = {sum} exceeds 1 (not energy conserving): scaled down to Kd {} / Ks {} \
                 (was Kd {} / Ks {})",
                material.diffuse, material.specular, before.diffuse, before.specular
            ));
        }
        if mtl.emissive.is_some_and(|ke| ke.iter().any(|&c| c > 0.0)) {
            warn("Ke (emission) ignored: relume's only emitter is the spot light");
        }
        if let Some(statement) = &mtl.diffuse_texture {
            let map_line = file.and_then(|f| f.map_kd_line_of(name)).or(line);
            let error = |message: String| SceneError::Obj {
                field: format!("{}.obj", self.field),
                file: path.clone(),
                line: map_line,
                message: format!("material `{name}`: map_Kd {message}"),
            };
            let (relative, options) = parse_map_statement(statement);
            if relative.is_empty() {
                return Err(error(format!("`{statement}` names no file")));
            }
            if !options.is_empty() {
                warn(&format!("map_Kd options `{options}` ignored"));
            }
            let mtl_dir = path.parent().unwrap_or_else(|| Path::new("."));
            let index = self
                .textures
                .load(&mtl_dir.join(&relative))
                .map_err(|message| error(format!("`{relative}`: {message}")))?;
            material.diffuse_texture = Some(index);
        }
        Ok(material)
    }
}

/// Which faces of a group have texture coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Texcoords {
    All,
    Some,
    None,
}

/// The groups of an OBJ (or the primitives of a glTF, `super::gltf`) concatenated.
#[derive(Default)]
pub(crate) struct Merged {
    pub positions: Vec<Vec3>,
    /// Zero for vertices of groups without normals.
    pub normals: Vec<Vec3>,
    /// Zero for vertices of groups without texture coordinates.
    pub texcoords: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
    pub triangle_materials: Vec<u32>,
    pub faces_with_normals: usize,
    pub faces_without_normals: usize,
}

impl Merged {
    /// The welded mesh of `file`: the file's normals when every face has them, else none (they
    /// are computed, with a warning when only some faces had them).
    pub(crate) fn into_mesh(self, file: PathBuf, materials: Vec<Material>) -> LoadedMesh {
        let normals = match (self.faces_with_normals, self.faces_without_normals) {
            (0, _) => None,
            (_, 0) => Some(self.normals),
            (with, without) => {
                tracing::warn!(
                    file = %file.display(),
                    "{with} faces have normals and {without} do not; computing all normals"
                );
                None
            }
        };
        weld(self.positions, normals, self.texcoords, self.triangles, self.triangle_materials)
            .into_mesh(file, materials)
    }

    /// Appends a group's vertices and triangles; says which of its faces have texture
    /// coordinates.
    fn append(&mut self, mesh: &tobj::Mesh, material: u32) -> Result<Texcoords, String> {
        let base = self.positions.len();
        let count = mesh.positions.len() / 3;
        if base + count >= u32::MAX as usize {
            return Err("more than 2^32 vertices".to_owned());
        }
        self.positions.extend(mesh.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        if let Some(bad) = self.positions[base..].iter().find(|p| !p.is_finite()) {
            return Err(format!("vertex position {bad} is not finite"));
        }
        let has_normals = mesh.normals.len() == mesh.positions.len();
        if has_normals {
            self.normals.extend(mesh.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2])));
        } else {
            self.normals.resize(self.positions.len(), Vec3::ZERO);
        }
        // tobj gives texture coordinates only for the vertices that have them, so they can be
        // matched to vertices only when all or none do.
        let texcoords = match mesh.texcoords.len() {
            0 => Texcoords::None,
            n if n == 2 * count => Texcoords::All,
            _ => Texcoords::Some,
        };
        if texcoords == Texcoords::All {
            self.texcoords.extend(mesh.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], t[1])));
            if let Some(bad) = self.texcoords[base..].iter().find(|t| !t.is_finite()) {
                return Err(format!("texture coordinate {bad} is not finite"));
            }
        } else {
            self.texcoords.resize(self.positions.len(), Vec2::ZERO);
        }
        let faces = mesh.indices.len() / 3;
        if has_normals {
            self.faces_with_normals += faces;
        } else {
            self.faces_without_normals += faces;
        }
        for corners in mesh.indices.chunks_exact(3) {
            if let Some(&bad) = corners.iter().find(|&&i| i as usize >= count) {
                return Err(format!("face index {bad} out of range ({count} vertices)"));
            }
            // base + count < u32::MAX, checked above.
            let offset = base as u32;
            self.triangles.push([corners[0] + offset, corners[1] + offset, corners[2] + offset]);
            self.triangle_materials.push(material);
        }
        Ok(texcoords)
    }
}

/// Welded geometry.
struct Welded {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    texcoords: Vec<Vec2>,
    triangles: Vec<[u32; 3]>,
    triangle_materials: Vec<u32>,
}

/// Merges vertices with bit-identical position, texture coordinates and (when there are
/// normals) normal, so that groups sharing positions share vertices while UV seams and hard
/// edges stay split; drops triangles with two corners at one position.
fn weld(
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    texcoords: Vec<Vec2>,
    triangles: Vec<[u32; 3]>,
    triangle_materials: Vec<u32>,
) -> Welded {
    // `+ 0.0` turns -0.0 into 0.0 so that the two compare equal as bits.
    let bits = |v: Vec3| (v + Vec3::ZERO).to_array().map(f32::to_bits);
    let bits2 = |v: Vec2| (v + Vec2::ZERO).to_array().map(f32::to_bits);
    type Key = ([u32; 3], [u32; 3], [u32; 2]);
    let mut map = fast_hash_map::<Key, u32>(positions.len());
    let mut remap = Vec::with_capacity(positions.len());
    let mut welded_positions = Vec::with_capacity(positions.len());
    let mut welded_normals = Vec::with_capacity(positions.len());
    let mut welded_texcoords = Vec::with_capacity(positions.len());
    for (i, (&p, &uv)) in positions.iter().zip(&texcoords).enumerate() {
        let n = normals.as_ref().map_or(Vec3::ZERO, |n| n[i]);
        let next = welded_positions.len() as u32;
        let index = *map.entry((bits(p), bits(n), bits2(uv))).or_insert(next);
        if index == next {
            welded_positions.push(p);
            welded_normals.push(n);
            welded_texcoords.push(uv);
        }
        remap.push(index);
    }
    let mut welded_triangles = Vec::with_capacity(triangles.len());
    let mut welded_materials = Vec::with_capacity(triangles.len());
    for (triangle, material) in triangles.iter().zip(triangle_materials) {
        let corners = triangle.map(|v| remap[v as usize]);
        // Positions are finite, so `==` is bit equality up to the sign of zero.
        let [a, b, c] = corners.map(|v| welded_positions[v as usize]);
        if a != b && b != c && c != a {
            welded_triangles.push(corners);
            welded_materials.push(material);
        }
    }
    let dropped = triangles.len() - welded_triangles.len();
    if dropped > 0 {
        tracing::debug!("dropped {dropped} triangles with two corners at one position");
    }
    Welded {
        positions: welded_positions,
        normals: normals.map(|_| welded_normals),
        texcoords: welded_texcoords,
        triangles: welded_triangles,
        triangle_materials: welded_materials,
    }
}

impl Welded {
    /// The mesh of `file` with this geometry and its `materials`.
    pub(crate) fn into_mesh(self, file: PathBuf, materials: Vec<Material>) -> LoadedMesh {
        LoadedMesh {
            file,
            positions: self.positions,
            normals: self.normals,
            texcoords: self.texcoords,
            triangles: self.triangles,
            triangle_materials: self.triangle_materials,
            materials,
        }
    }
}

#[cfg(test)]
mod tests;
