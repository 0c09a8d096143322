//! Mesh entries of a scene file: the file, its placement and its materials.

use std::collections::BTreeMap;
use std::fmt;

use glam::{DMat4, DQuat, DVec3, EulerRot, Vec3};
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use super::MAX_SPARSE_POINTS;
use super::json::key_path;
use crate::scene::validate::{coordinates, finite3, in_closed, int_in, scale_factor, unit_interval3};
use crate::scene::{Material, SceneError};

/// Largest amount by which `diffuse + specular` may exceed 1 before it counts as an error
/// (absorbs decimal-to-binary rounding of values such as 0.7 + 0.3).
const ENERGY_TOLERANCE: f32 = 1e-6;

/// One mesh entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshDescription {
    /// OBJ file, relative to the scene file's directory. With `obj_text`, only the mesh's name
    /// (its stem) and the name used in messages. Required unless `gltf` is given.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub obj: String,
    /// glTF 2.0 file (`.gltf` or `.glb`) instead of `obj`, relative to the scene file's
    /// directory: every mesh of its default scene, placed by its node transforms, becomes this
    /// one mesh (docs/scene-format.md "glTF"); `skip_groups` names nodes and `materials` glTF materials.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gltf: Option<String>,
    /// The OBJ file's text inline, instead of reading `obj`. It may not load MTL files
    /// (`mtllib`): give its materials with `material`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obj_text: Option<String>,
    /// Model-to-world transform; identity when absent.
    #[serde(default)]
    pub transform: TransformDescription,
    /// Number of sparse shading points on this mesh, in 1..=65536.
    pub sparse_points: u32,
    /// Replaces every material of the mesh (those from the MTL and the default one).
    #[serde(default)]
    pub material: Option<MaterialDescription>,
    /// Replaces MTL materials by name; wins over `material`. Unknown names are errors.
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialDescription>,
    /// OBJ groups/objects (`g`/`o` names), or glTF nodes (with their children), not to load.
    /// Unknown names are errors.
    #[serde(default)]
    pub skip_groups: Vec<String>,
}

/// Scale, then rotation, then translation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TransformDescription {
    /// Translation, m (f64: a mesh may sit far from the origin, see [`MAX_COORDINATE_M`]).
    #[serde(default)]
    pub translation: [f64; 3],
    /// Euler angles about X, then Y, then Z (glam `EulerRot::XYZ`), degrees.
    #[serde(default)]
    pub rotation_deg: [f32; 3],
    /// Uniform or per-axis scale, each in [`super::MESH_SCALE_RANGE`].
    #[serde(default)]
    pub scale: ScaleDescription,
}

impl Default for TransformDescription {
    fn default() -> Self {
        TransformDescription { translation: [0.0; 3], rotation_deg: [0.0; 3], scale: ScaleDescription::default() }
    }
}

/// A scale: a single number, or `[x, y, z]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, utoipa::ToSchema)]
#[serde(untagged)]
pub enum ScaleDescription {
    /// The same factor on every axis.
    Uniform(f32),
    /// One factor per axis.
    PerAxis([f32; 3]),
}

impl Default for ScaleDescription {
    fn default() -> Self {
        ScaleDescription::Uniform(1.0)
    }
}

impl ScaleDescription {
    /// The per-axis factors.
    pub fn to_vec3(self) -> Vec3 {
        match self {
            ScaleDescription::Uniform(s) => Vec3::splat(s),
            ScaleDescription::PerAxis(s) => Vec3::from_array(s),
        }
    }
}

impl<'de> Deserialize<'de> for ScaleDescription {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct ScaleVisitor;

        impl<'de> Visitor<'de> for ScaleVisitor {
            type Value = ScaleDescription;

            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number or an array [x, y, z]")
            }

            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
                Ok(ScaleDescription::Uniform(v as f32))
            }

            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
                Ok(ScaleDescription::Uniform(v as f32))
            }

            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
                Ok(ScaleDescription::Uniform(v as f32))
            }

            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut xyz = [0.0f32; 3];
                for (i, value) in xyz.iter_mut().enumerate() {
                    *value = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<de::IgnoredAny>()?.is_some() {
                    return Err(de::Error::invalid_length(4, &self));
                }
                Ok(ScaleDescription::PerAxis(xyz))
            }
        }

        deserializer.deserialize_any(ScaleVisitor)
    }
}

/// A material. Each channel in [0, 1], `diffuse + specular <= 1` per channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialDescription {
    /// Diffuse albedo `rho_d`, linear RGB; default 0.5 grey.
    #[serde(default = "default_diffuse")]
    pub diffuse: [f32; 3],
    /// Specular albedo `rho_s`, linear RGB; default black.
    #[serde(default)]
    pub specular: [f32; 3],
    /// Phong exponent `k`, in [0, 1e4]; default 1.
    #[serde(default = "default_exponent")]
    pub exponent: f32,
    /// Diffuse texture (PNG or OpenEXR), relative to the scene file's directory; the albedo is
    /// `diffuse` times the texture. Default none (the MTL's `map_Kd` is replaced too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diffuse_texture: Option<String>,
}

fn default_diffuse() -> [f32; 3] {
    Material::DEFAULT.diffuse.to_array()
}

fn default_exponent() -> f32 {
    Material::DEFAULT.exponent
}

impl Default for MaterialDescription {
    fn default() -> Self {
        MaterialDescription {
            diffuse: default_diffuse(),
            specular: [0.0; 3],
            exponent: default_exponent(),
            diffuse_texture: None,
        }
    }
}

impl MaterialDescription {
    /// The material (assumes [`MaterialDescription::validate`] passed), without its texture:
    /// `diffuse_texture` is `None` here and set by the loader, which owns the texture table.
    pub fn to_material(&self) -> Material {
        Material {
            diffuse: Vec3::from_array(self.diffuse),
            specular: Vec3::from_array(self.specular),
            exponent: self.exponent,
            diffuse_texture: None,
        }
    }

    /// Checks ranges and energy conservation; `field` is this material's path.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        unit_interval3(self.diffuse, &format!("{field}.diffuse"))?;
        unit_interval3(self.specular, &format!("{field}.specular"))?;
        in_closed(self.exponent, 0.0, Material::MAX_EXPONENT, &format!("{field}.exponent"))?;
        if self.diffuse_texture.as_ref().is_some_and(|path| path.trim().is_empty()) {
            return Err(SceneError::field(
                format!("{field}.diffuse_texture"),
                "must name an image file, got an empty string",
            ));
        }
        for (channel, name) in ["red", "green", "blue"].iter().enumerate() {
            let (d, s) = (self.diffuse[channel], self.specular[channel]);
            if d + s > 1.0 + ENERGY_TOLERANCE {
                return Err(SceneError::field(
                    format!("{field}.specular[{channel}]"),
                    format!(
                        "diffuse + specular must be <= 1 in every channel (energy conservation), \
                         got {d} + {s} = {} in channel {channel} ({name})",
                        d + s
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl TransformDescription {
    /// The model-to-world matrix: scale, then rotation, then translation, in f64 so that
    /// composing it with an anchor and the scene's origin keeps millimetres at 10,000 km.
    pub fn to_matrix(&self) -> DMat4 {
        let [x, y, z] = self.rotation_deg.map(|d| f64::from(d).to_radians());
        DMat4::from_scale_rotation_translation(
            self.scale.to_vec3().as_dvec3(),
            DQuat::from_euler(EulerRot::XYZ, x, y, z),
            DVec3::from_array(self.translation),
        )
    }

    /// Checks that every number is finite, the translation within [`MAX_COORDINATE_M`] and every
    /// scale factor within [`super::MESH_SCALE_RANGE`]; `field` is this transform's path.
    pub fn validate(&self, field: &str) -> Result<(), SceneError> {
        coordinates(self.translation, &format!("{field}.translation"))?;
        finite3(self.rotation_deg, &format!("{field}.rotation_deg"))?;
        let scale_field = format!("{field}.scale");
        match self.scale {
            ScaleDescription::Uniform(s) => scale_factor(s, &scale_field),
            ScaleDescription::PerAxis(s) => {
                for (i, &value) in s.iter().enumerate() {
                    scale_factor(value, &format!("{scale_field}[{i}]"))?;
                }
                Ok(())
            }
        }
    }
}

impl MeshDescription {
    pub(crate) fn validate(&self, field: &str) -> Result<(), SceneError> {
        match (&self.gltf, self.obj.is_empty()) {
            (None, true) => {
                return Err(SceneError::field(
                    format!("{field}.obj"),
                    "required field is missing: give `obj` (an OBJ file) or `gltf` (a glTF 2.0 file)",
                ));
            }
            (None, false) if self.obj.trim().is_empty() => {
                return Err(SceneError::field(format!("{field}.obj"), "must name an OBJ file, got an empty string"));
            }
            (Some(_), false) => {
                return Err(SceneError::field(format!("{field}.gltf"), "give `obj` or `gltf`, not both"));
            }
            (Some(gltf), true) if gltf.trim().is_empty() => {
                return Err(SceneError::field(format!("{field}.gltf"), "must name a glTF file, got an empty string"));
            }
            (Some(_), true) if self.obj_text.is_some() => {
                return Err(SceneError::field(format!("{field}.obj_text"), "only with `obj`, not with `gltf`"));
            }
            _ => {}
        }
        self.transform.validate(&format!("{field}.transform"))?;
        int_in(self.sparse_points, 1, MAX_SPARSE_POINTS, &format!("{field}.sparse_points"))?;
        if let Some(material) = &self.material {
            material.validate(&format!("{field}.material"))?;
        }
        for (name, material) in &self.materials {
            material.validate(&key_path(&format!("{field}.materials"), name))?;
        }
        Ok(())
    }
}
