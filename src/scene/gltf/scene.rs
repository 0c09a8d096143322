//! A whole scene from one glTF file: its meshes, its `KHR_lights_punctual` light and its
//! camera, with relume's settings beside them.

use super::*;

/// Lumens per watt at 555 nm, the definition of the candela: a glTF light's intensity (cd for
/// spot lights) divided by this is relume's radiant intensity, W/sr.
pub const LUMENS_PER_WATT: f32 = 683.0;

/// A whole scene from one glTF file: its meshes (as one relume mesh), its
/// `KHR_lights_punctual` spot or point light (at most one) and its camera (the first perspective camera
/// in node order), with the relume settings that glTF has no place for.
///
/// ```json
/// {"gltf": "cornell_box.glb", "sparse_points": 512, "width": 64, "height": 64,
///  "skip_groups": ["light"], "settings": {"tuning": {"rsm_resolution": 32}}}
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
pub(super) const POINT_CONE_MARGIN: f32 = 1.01;

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
