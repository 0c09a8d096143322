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

/// Most bytes of one glTF file and all the buffers its meshes and textures use, together.
/// Checked before anything is read.
pub const MAX_GLTF_BYTES: u64 = 1 << 30;

/// Lumens per watt at 555 nm, the definition of the candela: a glTF light's intensity (cd for
/// spot lights) divided by this is relume's radiant intensity, W/sr.
pub const LUMENS_PER_WATT: f32 = 683.0;

/// A whole scene from one glTF file: its meshes (as one relume mesh), its
/// `KHR_lights_punctual` spot or point light (at most one) and its camera (the first perspective camera
/// in node order), with the relume settings that glTF has no place for.
///
/// ```json
/// {"gltf": "cornell_box.glb", "sparse_points": 512, "width": 64, "height": 64,
///  "skip_groups": ["light"], "settings": {"rsm_resolution": 32}}
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GltfSceneDescription {
    /// The glTF 2.0 file (`.gltf` or `.glb`), relative to the scene file's directory.
    pub gltf: String,
    /// Sparse shading points of the mesh, in 1..=65536.
    pub sparse_points: u32,
    /// Image width, pixels (glTF cameras have only an aspect ratio).
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Nodes (with their children) not to load. Unknown names are errors.
    #[serde(default)]
    pub skip_groups: Vec<String>,
    /// Replaces every material of the file.
    #[serde(default)]
    pub material: Option<MaterialDescription>,
    /// Replaces glTF materials by name; wins over `material`. Unknown names are errors.
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialDescription>,
    /// Render settings, as in a scene file.
    #[serde(default)]
    pub settings: SettingsDescription,
}

impl GltfSceneDescription {
    /// Whether `text` is a JSON object with a top-level `gltf` field (so it is one of these,
    /// not a [`SceneDescription`]).
    pub fn is_one(text: &str) -> bool {
        serde_json::from_str::<serde_json::Map<String, serde_json::Value>>(text)
            .is_ok_and(|object| object.contains_key("gltf"))
    }

    /// Where a field of the [`SceneDescription`] this stands for
    /// ([`GltfSceneDescription::to_scene_description`]) sits in this form, so that an error
    /// found in that description names what the user wrote: the one mesh's fields are
    /// top-level here (`meshes[0].skip_groups[1]` is `skip_groups[1]`, the mesh itself and its
    /// file `gltf`, all meshes' sparse points `sparse_points`), and the camera's size is
    /// `width` and `height`. Other fields (`settings.*`) are where they were.
    pub fn field_in_form(field: &str) -> String {
        match field {
            "meshes[0]" | "meshes[0].gltf" => "gltf".to_owned(),
            "meshes" => "sparse_points".to_owned(),
            "camera" | "camera.width" => "width".to_owned(),
            "camera.height" => "height".to_owned(),
            _ => field.strip_prefix("meshes[0].").unwrap_or(field).to_owned(),
        }
    }

    /// Parses the JSON, with [`SceneDescription::from_json_str`]'s errors.
    pub fn from_json_str(text: &str) -> Result<GltfSceneDescription, SceneError> {
        parse_json(text)
    }

    /// The scene description this stands for: reads the glTF file's JSON (not its buffers) for
    /// the light and the camera. The mesh is `meshes[0]` of the result, with `gltf` set.
    pub fn to_scene_description(&self, base_dir: &Path) -> Result<SceneDescription, SceneError> {
        let file = base_dir.join(&self.gltf);
        let at = At { field: "gltf".to_owned(), file: file.clone() };
        if self.gltf.trim().is_empty() {
            return Err(SceneError::field("gltf", "must name a glTF file, got an empty string"));
        }
        int_in(self.width, 1, MAX_IMAGE_SIDE, "width")?;
        int_in(self.height, 1, MAX_IMAGE_SIDE, "height")?;
        let document = open(&file, &at)?;
        let skip: BTreeSet<&str> = self.skip_groups.iter().map(String::as_str).collect();
        let nodes = instances(&document, &skip, &at)?;
        let mut light: Option<(usize, LightDescription)> = None;
        let mut camera: Option<CameraDescription> = None;
        for (node, world) in &nodes {
            let name = NodeName(node);
            if let Some(punctual) = node.light() {
                let description = light_description(&punctual, *world, || mesh_bounds(&nodes)).map_err(|message| {
                    at.error(format!(
                        "{name}: its KHR_lights_punctual light (`lights[{}]`): {message}",
                        punctual.index()
                    ))
                })?;
                if let Some((first, _)) = &light {
                    return Err(at.error(format!(
                        "{name}: a second spot light (the first is on nodes[{first}]); a relume scene has one"
                    )));
                }
                light = Some((node.index(), description));
            }
            if let (Some(glcamera), None) = (node.camera(), &camera) {
                let description = camera_description(&glcamera, *world, self.width, self.height)
                    .map_err(|message| at.error(format!("{name}: cameras[{}]: {message}", glcamera.index())))?;
                camera = Some(description);
            }
        }
        let camera = camera.ok_or_else(|| {
            at.error("the default scene has no camera node; add a perspective camera (relume needs one view)")
        })?;
        Ok(SceneDescription {
            meshes: vec![MeshDescription {
                obj: String::new(),
                obj_text: None,
                gltf: Some(self.gltf.clone()),
                transform: Default::default(),
                sparse_points: self.sparse_points,
                material: self.material.clone(),
                materials: self.materials.clone(),
                skip_groups: self.skip_groups.clone(),
            }],
            light: light.map(|(_, l)| l),
            lights: Vec::new(),
            anchor: None,
            camera,
            settings: self.settings.clone(),
        })
    }
}

/// A glTF light as relume's spot light, validated. relume's only emitter is one spot light
/// (docs/design.md §2): a point light outside the meshes' bounding sphere (`bounds`, asked only for
/// a point light) is the spot light that lights every mesh as it would ([`point_as_spot`]);
/// one inside it, and directional lights, are errors.
fn light_description(
    light: &gltf::khr_lights_punctual::Light,
    world: Mat4,
    bounds: impl FnOnce() -> Result<(Vec3, f32), String>,
) -> Result<LightDescription, String> {
    use gltf::khr_lights_punctual::Kind;
    let intensity = Vec3::from(light.color()) * light.intensity() / LUMENS_PER_WATT;
    let position = world.transform_point3(Vec3::ZERO);
    let (inner, outer) = match light.kind() {
        Kind::Spot { inner_cone_angle, outer_cone_angle } => (inner_cone_angle, outer_cone_angle),
        Kind::Point => {
            if light.range().is_some() {
                tracing::warn!("KHR_lights_punctual `range` ignored: relume's lights fall off as 1/d²");
            }
            let description = point_as_spot(position, intensity, bounds()?)?;
            description.validate("light").map_err(|e| e.to_string())?;
            return Ok(description);
        }
        Kind::Directional => {
            return Err("a directional light: relume's scene has one spot light and no directional \
                        lights; make it a spot light or remove it"
                .to_owned());
        }
    };
    if light.range().is_some() {
        tracing::warn!("KHR_lights_punctual `range` ignored: relume's spot light falls off as 1/d²");
    }
    let description = LightDescription {
        position: position.as_dvec3().to_array(),
        direction: world.transform_vector3(Vec3::NEG_Z).normalize_or_zero().to_array(),
        inner_angle_deg: inner.to_degrees(),
        outer_angle_deg: outer.to_degrees(),
        intensity: intensity.to_array(),
        // The node's +Y, as for a camera: the light's frame turns with the node, so a file
        // turned as a whole keeps its RSM grid on the scene.
        up: Some(world.transform_vector3(Vec3::Y).normalize_or_zero().to_array()),
    };
    description.validate("light").map_err(|e| e.to_string())?;
    Ok(description)
}

/// How much wider than the meshes' bounding sphere seen from a point light the cone of the
/// spot light that stands for it is: rounding never leaves geometry on the cone's hard edge.
const POINT_CONE_MARGIN: f32 = 1.01;

/// A point light at `position` as the spot light that lights everything inside the sphere
/// `(centre, radius)` exactly as the point light does: aimed at the centre, its inner and outer
/// half-angles equal (no falloff inside, docs/design.md §2) and the sphere's angular radius from
/// the light (times [`POINT_CONE_MARGIN`]). The same radiant intensity, the same 1/d². An error
/// when the light is inside the sphere or so near that the cone would pass
/// [`MAX_OUTER_ANGLE_DEG`] (one perspective RSM cannot see around a point light).
fn point_as_spot(position: Vec3, intensity: Vec3, (centre, radius): (Vec3, f32)) -> Result<LightDescription, String> {
    let to_centre = centre.as_dvec3() - position.as_dvec3();
    let distance = to_centre.length();
    let needed_deg = if distance > radius as f64 {
        ((radius as f64 / distance).asin().to_degrees() as f32 * POINT_CONE_MARGIN).max(0.01)
    } else {
        f32::INFINITY
    };
    if needed_deg > MAX_OUTER_ANGLE_DEG {
        let (where_, needs) = if needed_deg.is_finite() {
            ("so near", format!("a cone of {needed_deg:.1}° half-angle to reach them all"))
        } else {
            ("inside", "light all around".to_owned())
        };
        return Err(format!(
            "a point light {where_} the meshes' bounding sphere (centre {centre}, radius {radius} m) that it would \
             need {needs}; relume's one emitter is a spot light of at most {MAX_OUTER_ANGLE_DEG}°: move the light \
             further out or make it a spot light"
        ));
    }
    Ok(LightDescription {
        position: position.as_dvec3().to_array(),
        direction: (to_centre / distance).as_vec3().to_array(),
        inner_angle_deg: needed_deg,
        outer_angle_deg: needed_deg,
        intensity: intensity.to_array(),
        up: None,
    })
}

/// The bounding sphere (centre, radius), in the world, of the meshes of `nodes`, from their
/// `POSITION` accessors' `min` and `max` (which glTF requires) and the nodes' world transforms:
/// no buffer is read.
fn mesh_bounds(nodes: &[(gltf::Node, Mat4)]) -> Result<(Vec3, f32), String> {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for (node, world) in nodes {
        let Some(mesh) = node.mesh() else { continue };
        for primitive in mesh.primitives() {
            let Some(positions) = primitive.get(&Semantic::Positions) else { continue };
            let corner = |value: Option<gltf::json::Value>| -> Option<Vec3> {
                let array = value?;
                let array = array.as_array()?;
                let v: Vec<f32> = array.iter().filter_map(|x| x.as_f64()).map(|x| x as f32).collect();
                (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| Vec3::new(v[0], v[1], v[2]))
            };
            let (Some(min), Some(max)) = (corner(positions.min()), corner(positions.max())) else {
                return Err(format!(
                    "accessors[{}] (POSITION of meshes[{}]) has no finite 3-number `min` and `max`, which glTF \
                     requires and a point light needs for the meshes' bounds",
                    positions.index(),
                    mesh.index()
                ));
            };
            for i in 0..8 {
                let p = Vec3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                );
                let p = world.transform_point3(p);
                (lo, hi) = (lo.min(p), hi.max(p));
            }
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return Err("a point light, and no mesh for it to light (its bounds are needed)".to_owned());
    }
    Ok(((lo + hi) * 0.5, (hi - lo).length() * 0.5))
}

/// A glTF perspective camera (looking down its node's -Z, +Y up) as relume's camera.
fn camera_description(
    camera: &gltf::Camera,
    world: Mat4,
    width: u32,
    height: u32,
) -> Result<CameraDescription, String> {
    let gltf::camera::Projection::Perspective(perspective) = camera.projection() else {
        return Err("an orthographic camera: relume renders perspective cameras only".to_owned());
    };
    if let Some(aspect) = perspective.aspect_ratio() {
        let image = width as f32 / height as f32;
        if (aspect / image - 1.0).abs() > 0.01 {
            tracing::warn!(
                "camera aspectRatio {aspect} differs from the scene's width / height = {image}; \
                 the vertical field of view is kept"
            );
        }
    }
    let position = world.transform_point3(Vec3::ZERO);
    let forward = world.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
    let description = CameraDescription {
        // Scene positions are f64 (the floating origin); glTF's node transforms are f32.
        position: position.as_dvec3().to_array(),
        target: (position.as_dvec3() + forward.as_dvec3()).to_array(),
        up: world.transform_vector3(Vec3::Y).normalize_or_zero().to_array(),
        fov_y_deg: perspective.yfov().to_degrees(),
        width,
        height,
    };
    description.validate("camera").map_err(|e| e.to_string())?;
    Ok(description)
}

/// Inputs of [`phong_from_pbr`], as a glTF material gives them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pbr {
    /// `baseColorFactor` (RGB, linear; alpha is ignored).
    pub base_color: Vec3,
    /// `metallicFactor`, in [0, 1].
    pub metallic: f32,
    /// `roughnessFactor` (perceptual roughness), in [0, 1].
    pub roughness: f32,
    /// `KHR_materials_specular.specularFactor` (1 without the extension).
    pub specular: f32,
    /// `KHR_materials_specular.specularColorFactor` (white without the extension).
    pub specular_color: Vec3,
    /// `KHR_materials_ior.ior` (1.5 without the extension), >= 1.
    pub ior: f32,
}

impl Default for Pbr {
    fn default() -> Self {
        Pbr { base_color: Vec3::ONE, metallic: 1.0, roughness: 1.0, specular: 1.0, specular_color: Vec3::ONE, ior: 1.5 }
    }
}

/// The normalised Phong material standing for a metallic-roughness one (README "glTF"):
///
/// - specular albedo `rho_s = mix(F0, baseColor, metallic)`, with the dielectric reflectance
///   at normal incidence `F0 = min(((ior - 1) / (ior + 1))² specularColor, 1) specular`
///   (0.04 for the defaults): the glTF BRDF's Fresnel term at normal incidence, without its
///   rise at grazing angles;
/// - diffuse albedo `rho_d = baseColor (1 - metallic) (1 - rho_s)`, so `rho_d + rho_s <= 1`;
/// - Phong exponent `k = (2 / alpha² - 2) / 4` with `alpha = roughness²`: the Blinn-Phong
///   exponent whose lobe matches GGX of width `alpha` (Walter et al. 2007), divided by 4
///   because relume's lobe is around the reflected direction, where the angle is twice the
///   half-vector's; clamped to [0, [`Material::MAX_EXPONENT`]].
///
/// Inputs are clamped to their ranges first.
pub fn phong_from_pbr(pbr: Pbr) -> Material {
    let unit = |x: f32| if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    let base = pbr.base_color.to_array().map(unit);
    let base = Vec3::from_array(base);
    let (metallic, roughness, specular) = (unit(pbr.metallic), unit(pbr.roughness), unit(pbr.specular));
    let ior = if pbr.ior.is_finite() { pbr.ior.max(1.0) } else { 1.5 };
    let f0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
    let specular_color =
        Vec3::from_array(pbr.specular_color.to_array().map(|c| if c.is_finite() { c.max(0.0) } else { 1.0 }));
    let dielectric = (f0 * specular_color).min(Vec3::ONE) * specular;
    let rho_s = dielectric.lerp(base, metallic);
    let rho_d = base * (1.0 - metallic) * (Vec3::ONE - rho_s);
    let alpha = roughness * roughness;
    let exponent = if alpha <= 0.0 {
        Material::MAX_EXPONENT
    } else {
        ((2.0 / (alpha * alpha) - 2.0) / 4.0).clamp(0.0, Material::MAX_EXPONENT)
    };
    Material { diffuse: rho_d, specular: rho_s, exponent, diffuse_texture: None }
}

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

#[cfg(test)]
mod tests {
    use super::super::test_util::{TempDir, scene_json};
    use super::*;
    use serde_json::{Value, json};

    /// A glTF document around `nodes` with one triangle mesh (positions, indices and texture
    /// coordinates in one base64 buffer), written as `name` (`.gltf`, or `.glb` with the
    /// buffer in the binary chunk); `edit` changes the JSON before it is written.
    fn write(dir: &TempDir, name: &str, nodes: Value, edit: impl FnOnce(&mut Value)) {
        let positions: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let texcoords: [[f32; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 0.25]];
        let mut bin: Vec<u8> = positions.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        bin.extend([0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
        bin.extend(texcoords.iter().flatten().flat_map(|x| x.to_le_bytes()));
        let mut doc = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": (0..nodes.as_array().map_or(0, Vec::len)).collect::<Vec<_>>()}],
            "nodes": nodes,
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 1, "material": 0}]}],
            "materials": [{"name": "red", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0}}],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"},
                {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"}
            ],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 36},
                {"buffer": 0, "byteOffset": 36, "byteLength": 12},
                {"buffer": 0, "byteOffset": 48, "byteLength": 24}
            ],
            "buffers": [{"byteLength": bin.len()}]
        });
        edit(&mut doc);
        let path = dir.path().join(name);
        if name.ends_with(".glb") {
            let extra = doc["buffers"][0]["byteLength"].as_u64().unwrap_or(0) as usize;
            bin.resize(bin.len().max(extra), 0);
            while !bin.len().is_multiple_of(4) {
                bin.push(0);
            }
            let mut text = doc.to_string().into_bytes();
            while !text.len().is_multiple_of(4) {
                text.push(b' ');
            }
            let mut glb = b"glTF".to_vec();
            glb.extend(2u32.to_le_bytes());
            glb.extend(((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
            glb.extend((text.len() as u32).to_le_bytes());
            glb.extend(b"JSON");
            glb.extend(text);
            glb.extend((bin.len() as u32).to_le_bytes());
            glb.extend(b"BIN\0");
            glb.extend(bin);
            std::fs::write(path, glb).expect("write glb");
        } else {
            if doc["buffers"][0].get("uri").is_none() {
                let data = base64::engine::general_purpose::STANDARD.encode(&bin);
                doc["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{data}"));
            }
            std::fs::write(path, doc.to_string()).expect("write gltf");
        }
    }

    fn load_scene(dir: &TempDir, file: &str) -> Result<super::super::Scene, SceneError> {
        let text = scene_json(&format!(r#""gltf": "{file}", "sparse_points": 4"#));
        super::super::Scene::from_json_str(&text, dir.path())
    }

    fn error(dir: &TempDir, file: &str) -> String {
        load_scene(dir, file).map(|_| ()).expect_err("an error").to_string()
    }

    #[test]
    fn pbr_maps_to_energy_conserving_phong() {
        let dielectric = phong_from_pbr(Pbr { base_color: Vec3::splat(0.8), metallic: 0.0, ..Pbr::default() });
        assert!(dielectric.specular.abs_diff_eq(Vec3::splat(0.04), 1e-6), "{dielectric:?}");
        assert!(dielectric.diffuse.abs_diff_eq(Vec3::splat(0.8 * 0.96), 1e-6), "{dielectric:?}");
        assert_eq!(dielectric.exponent, 0.0, "roughness 1 is the widest lobe");
        let gold = Vec3::new(1.0, 0.77, 0.34);
        let metal = phong_from_pbr(Pbr { base_color: gold, roughness: 0.5, ..Pbr::default() });
        assert_eq!(metal.diffuse, Vec3::ZERO);
        assert!(metal.specular.abs_diff_eq(gold, 1e-6));
        // alpha = 0.25: Blinn-Phong 2 / alpha^2 - 2 = 30, over 4 for the reflected lobe.
        assert!((metal.exponent - 7.5).abs() < 1e-4, "{metal:?}");
        assert_eq!(phong_from_pbr(Pbr { roughness: 0.0, ..Pbr::default() }).exponent, Material::MAX_EXPONENT);
        let matte =
            phong_from_pbr(Pbr { base_color: Vec3::splat(0.5), metallic: 0.0, specular: 0.0, ..Pbr::default() });
        assert_eq!((matte.diffuse, matte.specular), (Vec3::splat(0.5), Vec3::ZERO), "specularFactor 0 is Lambertian");
        for i in 0..=10 {
            for j in 0..=10 {
                let (t, u) = (i as f32 / 10.0, j as f32 / 10.0);
                let m = phong_from_pbr(Pbr {
                    base_color: Vec3::new(1.0, t, u),
                    metallic: t,
                    roughness: u,
                    specular_color: Vec3::splat(30.0 * u),
                    ior: 1.0 + 3.0 * t,
                    ..Pbr::default()
                });
                assert!((m.diffuse + m.specular).max_element() <= 1.0 + 1e-6, "{t} {u}: {m:?}");
                assert!(m.diffuse.min_element() >= 0.0 && m.specular.min_element() >= 0.0);
            }
        }
    }

    #[test]
    fn node_transforms_are_baked_and_mirrors_keep_facing() {
        let dir = TempDir::new("gltf-nodes");
        let nodes = json!([
            {"name": "parent", "translation": [10, 0, 0], "children": [1]},
            {"name": "mirrored", "scale": [-2, 2, 2], "mesh": 0}
        ]);
        write(&dir, "t.gltf", nodes, |doc| doc["scenes"][0]["nodes"] = json!([0]));
        let scene = load_scene(&dir, "t.gltf").expect("loads");
        let mesh = &scene.meshes[0];
        let (lo, hi) = mesh.positions.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        assert!(lo.abs_diff_eq(Vec3::new(8.0, 0.0, 0.0), 1e-6) && hi.abs_diff_eq(Vec3::new(10.0, 2.0, 0.0), 1e-6));
        // The file's triangle faces +Z; mirrored in x it still faces +Z once its winding flips.
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            assert!((b - a).cross(c - a).z > 0.0, "winding kept facing +Z: {t:?}");
        }
        assert!(mesh.normals.iter().all(|n| n.abs_diff_eq(Vec3::Z, 1e-6)));
        let material = scene.materials[mesh.triangle_materials[0] as usize];
        assert!(material.diffuse.abs_diff_eq(Vec3::new(0.8, 0.1, 0.1) * 0.96, 1e-6));
        // v flipped to the OBJ convention: the vertex at glTF v = 0.25 has v = 0.75.
        assert!(mesh.texcoords.iter().any(|t| t.abs_diff_eq(Vec2::new(0.0, 0.75), 1e-6)));
    }

    #[test]
    fn embedded_glb_texture_is_loaded() {
        let dir = TempDir::new("gltf-texture");
        let mut png = Vec::new();
        image::RgbaImage::from_pixel(2, 2, image::Rgba([10, 200, 30, 255]))
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .expect("encode PNG");
        let png_len = png.len();
        let nodes = json!([{"mesh": 0}]);
        write(&dir, "t.glb", nodes, |doc| {
            doc["buffers"][0]["byteLength"] = json!(72 + png_len);
            doc["bufferViews"]
                .as_array_mut()
                .expect("views")
                .push(json!({"buffer": 0, "byteOffset": 72, "byteLength": png_len}));
            doc["images"] = json!([{"bufferView": 3, "mimeType": "image/png"}]);
            doc["textures"] = json!([{"source": 0}]);
            doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
        });
        // The PNG goes where the writer zero-filled the declared length.
        let mut bytes = std::fs::read(dir.path().join("t.glb")).expect("read");
        let json_len = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes")) as usize;
        let bin_start = 20 + json_len + 8;
        bytes[bin_start + 72..bin_start + 72 + png_len].copy_from_slice(&png);
        std::fs::write(dir.path().join("t.glb"), bytes).expect("write");
        let scene = load_scene(&dir, "t.glb").expect("loads");
        assert_eq!(scene.textures.len(), 1);
        assert_eq!(&scene.textures[0].rgba8[..4], &[10, 200, 30, 255]);
        assert!(scene.textures[0].path.to_string_lossy().ends_with("t.glb#images[0]"));
        assert_eq!(scene.materials[0].diffuse_texture, Some(0));
    }

    #[test]
    fn malformed_files_name_the_object_and_field() {
        let dir = TempDir::new("gltf-errors");
        let mesh_node = || json!([{"name": "thing", "mesh": 0}]);
        // (file, how to break it, what the error must say)
        type Case<'a> = (&'a str, Box<dyn FnOnce(&mut Value)>, &'a str);
        let cases: Vec<Case> = vec![
            (
                "index.gltf",
                Box::new(|d| d["accessors"][1]["count"] = json!(6)),
                "accessors[1] (indices): byteOffset 0 + 6 elements",
            ),
            (
                "type.gltf",
                Box::new(|d| d["accessors"][0]["componentType"] = json!(5123)),
                "accessors[0] (POSITION).componentType",
            ),
            (
                "mode.gltf",
                Box::new(|d| d["meshes"][0]["primitives"][0]["mode"] = json!(1)),
                "meshes[0].primitives[0].mode",
            ),
            (
                "climb.gltf",
                Box::new(|d| d["buffers"][0]["uri"] = json!("../secret.bin")),
                "buffers[0].uri: `../secret.bin` is not a relative path",
            ),
            (
                "short.gltf",
                Box::new(|d| d["buffers"][0]["byteLength"] = json!(4096)),
                "buffers[0].byteLength: declares 4096 bytes, the data has 72",
            ),
            ("cycle.gltf", Box::new(|d| d["nodes"][0]["children"] = json!([0])), "nodes[0] (`thing`): reached twice"),
            (
                "sparse.gltf",
                Box::new(
                    |d| d["accessors"][0]["sparse"] = json!({"count": 1, "indices": {"bufferView": 1, "componentType": 5125}, "values": {"bufferView": 0}}),
                ),
                "accessors[0] (POSITION).sparse",
            ),
        ];
        for (file, edit, expected) in cases {
            write(&dir, file, mesh_node(), edit);
            let message = error(&dir, file);
            assert!(message.starts_with("meshes[0].gltf: "), "{file}: {message}");
            assert!(message.contains(expected), "{file}: expected `{expected}` in `{message}`");
        }
        // An index past the vertices is found when the indices are read.
        write(&dir, "range.gltf", mesh_node(), |_| {});
        let mut doc: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("range.gltf")).expect("read")).expect("JSON");
        let mut bin = base64::engine::general_purpose::STANDARD
            .decode(doc["buffers"][0]["uri"].as_str().expect("uri").split(',').nth(1).expect("payload"))
            .expect("base64");
        bin[40..44].copy_from_slice(&7u32.to_le_bytes());
        let data = base64::engine::general_purpose::STANDARD.encode(&bin);
        doc["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{data}"));
        std::fs::write(dir.path().join("range.gltf"), doc.to_string()).expect("write");
        let message = error(&dir, "range.gltf");
        assert!(
            message.contains("nodes[0] (`thing`) meshes[0].primitives[0]: index 7 is out of range (3 vertices)"),
            "{message}"
        );

        let text = scene_json(r#""gltf": "range.gltf", "sparse_points": 4, "skip_groups": ["lamp"]"#);
        let message =
            super::super::Scene::from_json_str(&text, dir.path()).map(|_| ()).expect_err("unknown node").to_string();
        assert!(
            message.starts_with("meshes[0].skip_groups[0]: ")
                && message.contains("no node named `lamp` (the file has: thing)"),
            "{message}"
        );
        let message = error(&dir, "missing.gltf");
        assert!(message.starts_with("meshes[0].gltf: ") && message.contains("cannot read"), "{message}");
        std::fs::write(dir.path().join("junk.glb"), b"glTF\x02\0\0\0\xff\xff\xff\xff").expect("write");
        let message = error(&dir, "junk.glb");
        assert!(message.contains("not a valid glTF 2.0 file"), "{message}");
    }

    #[test]
    fn triangles_are_counted_against_the_limit_before_reading() {
        let dir = TempDir::new("gltf-budget");
        // Four instances of the one-triangle mesh; the buffer's data is never read because
        // the count is over before (its uri names a file that does not exist).
        let nodes = json!([{"mesh": 0}, {"mesh": 0}, {"mesh": 0}, {"mesh": 0}]);
        write(&dir, "many.gltf", nodes, |d| d["buffers"][0]["uri"] = json!("absent.bin"));
        let text = scene_json(r#""gltf": "many.gltf", "sparse_points": 4"#);
        let description = SceneDescription::from_json_str(&text).expect("parses");
        let error =
            super::super::Scene::from_description_within(&description, dir.path(), 3).map(|_| ()).expect_err("over");
        assert!(matches!(error, SceneError::TooManyTriangles { limit: 3, .. }), "{error}");
        assert!(error.to_string().contains("at least 4 triangles"), "{error}");
        let message =
            super::super::Scene::from_description_within(&description, dir.path(), 4).map(|_| ()).expect_err("absent");
        assert!(message.to_string().contains("buffers[0].uri: cannot read"), "{message}");
    }

    #[test]
    fn whole_scene_lights_and_cameras_are_checked() {
        let dir = TempDir::new("gltf-scene");
        let scene = |file: &str| {
            let text = format!(r#"{{"gltf": "{file}", "sparse_points": 4, "width": 32, "height": 16}}"#);
            GltfSceneDescription::from_json_str(&text).expect("parses").to_scene_description(dir.path())
        };
        let lights = |kind: &str| {
            let mut light = json!({"type": kind, "intensity": 683, "color": [1, 0.5, 0.5]});
            if kind == "spot" {
                light["spot"] = json!({"outerConeAngle": 0.5});
            }
            json!({"KHR_lights_punctual": {"lights": [light]}})
        };
        let nodes = json!([
            {"mesh": 0},
            {"name": "lamp", "translation": [0, 3, 0], "rotation": [-0.70710677, 0, 0, 0.70710677], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "eye", "translation": [0, 1, 5], "camera": 0}
        ]);
        let camera = json!([{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.1}}]);
        for (file, kind, cameras, expected) in [
            (
                "sun.gltf",
                "directional",
                camera.clone(),
                Some("nodes[1] (`lamp`): its KHR_lights_punctual light (`lights[0]`): a directional light"),
            ),
            (
                "spot.gltf",
                "spot",
                json!([{"type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 9}}]),
                Some("nodes[2] (`eye`): cameras[0]: an orthographic camera"),
            ),
            ("good.gltf", "spot", camera.clone(), None),
        ] {
            write(&dir, file, nodes.clone(), |d| {
                d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
                d["extensions"] = lights(kind);
                d["cameras"] = cameras;
            });
            match (scene(file), expected) {
                (Err(error), Some(expected)) => {
                    let message = error.to_string();
                    assert!(message.starts_with("gltf: ") && message.contains(expected), "{file}: {message}");
                }
                (Ok(description), None) => {
                    let light = description.light.as_ref().expect("the spot light");
                    assert!(glam::DVec3::from(light.position).abs_diff_eq(glam::DVec3::new(0.0, 3.0, 0.0), 1e-6));
                    assert!(Vec3::from(light.direction).abs_diff_eq(Vec3::NEG_Y, 1e-6), "{light:?}");
                    let up = Vec3::from(light.up.expect("the node's +Y"));
                    assert!(up.abs_diff_eq(Vec3::NEG_Z, 1e-6), "the lamp's +Y turned with it: {up}");
                    assert!((light.outer_angle_deg - 0.5f32.to_degrees()).abs() < 1e-4);
                    assert_eq!(light.intensity, [1.0, 0.5, 0.5], "683 cd is 1 W/sr");
                    let camera = &description.camera;
                    assert_eq!(
                        (camera.position, camera.target, camera.width, camera.height),
                        ([0.0, 1.0, 5.0], [0.0, 1.0, 4.0], 32, 16)
                    );
                    assert!((camera.fov_y_deg - 0.7f32.to_degrees()).abs() < 1e-4);
                    assert_eq!(description.meshes[0].gltf.as_deref(), Some(file));
                    description.validate().expect("valid");
                }
                (other, expected) => panic!("{file}: expected {expected:?}, got {other:?}"),
            }
        }
        // A point light outside the meshes' bounds is the spot light aimed at their bounding
        // sphere with no falloff over it: every vertex inside its cone, the same intensity.
        let with_point_light = |d: &mut Value| {
            d["extensionsUsed"] = json!(["KHR_lights_punctual"]);
            d["extensions"] = lights("point");
            d["cameras"] = camera.clone();
        };
        write(&dir, "point.gltf", nodes.clone(), with_point_light);
        let light = scene("point.gltf").expect("a point light outside the meshes").light.expect("a light");
        assert_eq!(light.intensity, [1.0, 0.5, 0.5], "683 cd is 1 W/sr");
        assert_eq!(light.inner_angle_deg, light.outer_angle_deg, "no falloff inside the cone");
        // The triangle (0,0,0) (1,0,0) (0,1,0): bounding sphere centre (0.5, 0.5, 0), radius
        // 0.5·√2, seen from the lamp at (0, 3, 0).
        let (apex, axis) = (glam::DVec3::from(light.position).as_vec3(), Vec3::from(light.direction));
        assert!(apex.abs_diff_eq(Vec3::new(0.0, 3.0, 0.0), 1e-6));
        let centre = Vec3::new(0.5, 0.5, 0.0);
        assert!(axis.abs_diff_eq((centre - apex).normalize(), 1e-6), "aimed at the centre: {axis}");
        let sphere_deg = (0.5f32.sqrt() / (centre - apex).length()).asin().to_degrees();
        assert!((light.outer_angle_deg - sphere_deg * POINT_CONE_MARGIN).abs() < 1e-3, "{light:?}");
        for vertex in [Vec3::ZERO, Vec3::X, Vec3::Y] {
            let angle = (vertex - apex).angle_between(axis).to_degrees();
            assert!(angle < light.outer_angle_deg, "vertex {vertex} at {angle}° outside the cone");
        }
        let mut near = nodes.clone();
        near[1]["translation"] = json!([0.3, 0.3, 0.0]);
        write(&dir, "inside.gltf", near.clone(), with_point_light);
        let message = scene("inside.gltf").expect_err("inside the meshes").to_string();
        assert!(message.contains("a point light inside the meshes' bounding sphere"), "{message}");
        near[1]["translation"] = json!([0.5, 0.5, 0.71]);
        write(&dir, "near.gltf", near, with_point_light);
        let message = scene("near.gltf").expect_err("too near the meshes").to_string();
        assert!(message.contains("so near") && message.contains("make it a spot light"), "{message}");

        write(&dir, "blind.gltf", json!([{"mesh": 0}]), |_| {});
        let message = scene("blind.gltf").expect_err("no camera").to_string();
        assert!(message.contains("no camera node"), "{message}");

        // Errors found once the whole scene is a scene description name the fields as written.
        let text = r#"{"gltf": "good.gltf", "sparse_points": 4, "width": 32, "height": 16, "skip_groups": ["x"]}"#;
        let error = super::super::Scene::from_json_str(text, dir.path()).map(|_| ()).expect_err("no node x");
        assert_eq!(error.field_path(), Some("skip_groups[0]"), "{error}");
        assert!(error.to_string().starts_with("skip_groups[0]: "), "{error}");
        let text = r#"{"gltf": "good.gltf", "sparse_points": 4, "width": 0, "height": 16}"#;
        let error = super::super::Scene::from_json_str(text, dir.path()).map(|_| ()).expect_err("no pixels");
        assert_eq!(error.to_string(), "width: must be in 1..=8192, got 0");
    }
}
