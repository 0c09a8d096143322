//! The range checks every part of a scene file shares: each names the field it checks.

use super::SceneError;
use super::description::{MAX_COORDINATE_M, MAX_SCENE_EXTENT_M, MESH_SCALE_RANGE, MIN_SCENE_EXTENT_M};

pub(crate) fn finite(value: f32, field: &str) -> Result<(), SceneError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(SceneError::field(field, format!("must be a finite number, got {value}")))
    }
}

pub(crate) fn finite3(values: [f32; 3], field: &str) -> Result<(), SceneError> {
    for (i, &value) in values.iter().enumerate() {
        finite(value, &format!("{field}[{i}]"))?;
    }
    Ok(())
}

/// Finite world-space coordinates of magnitude at most [`MAX_COORDINATE_M`].
pub(crate) fn coordinates(values: [f64; 3], field: &str) -> Result<(), SceneError> {
    for (i, &value) in values.iter().enumerate() {
        if !(value.is_finite() && value.abs() <= MAX_COORDINATE_M) {
            return Err(SceneError::field(
                format!("{field}[{i}]"),
                format!("must be a finite number within +-{MAX_COORDINATE_M:e} m, got {value:e}"),
            ));
        }
    }
    Ok(())
}

/// A transform's scale factor: finite, > 0 and within [`MESH_SCALE_RANGE`].
pub(crate) fn scale_factor(value: f32, field: &str) -> Result<(), SceneError> {
    positive(value, field)?;
    let (lo, hi) = MESH_SCALE_RANGE;
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(SceneError::field(field, format!("must be in [{lo:e}, {hi:e}], got {value:e}")))
    }
}

/// The diagonal (m) of a world-space bounding box of meshes (`field`: `meshes` for the whole
/// scene's extent, `meshes[i]` for one mesh's) within [[`MIN_SCENE_EXTENT_M`],
/// [`MAX_SCENE_EXTENT_M`]]: the sizes the renderer resolves.
pub(crate) fn scene_extent(diagonal: f64, field: &str) -> Result<(), SceneError> {
    if (MIN_SCENE_EXTENT_M..=MAX_SCENE_EXTENT_M).contains(&diagonal) {
        Ok(())
    } else {
        Err(SceneError::field(
            field,
            format!(
                "the bounding box of the mesh{} (transforms and the anchor applied) has a diagonal \
                 of {diagonal:.3e} m; the renderer resolves scenes between {MIN_SCENE_EXTENT_M:e} and \
                 {MAX_SCENE_EXTENT_M:e} m",
                if field == "meshes" { "es" } else { "" }
            ),
        ))
    }
}

pub(crate) fn positive(value: f32, field: &str) -> Result<(), SceneError> {
    finite(value, field)?;
    if value > 0.0 { Ok(()) } else { Err(SceneError::field(field, format!("must be > 0, got {value}"))) }
}

pub(crate) fn at_least(value: f32, min: f32, field: &str) -> Result<(), SceneError> {
    finite(value, field)?;
    if value >= min { Ok(()) } else { Err(SceneError::field(field, format!("must be >= {min}, got {value}"))) }
}

pub(crate) fn in_closed(value: f32, lo: f32, hi: f32, field: &str) -> Result<(), SceneError> {
    finite(value, field)?;
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(SceneError::field(field, format!("must be in [{lo}, {hi}], got {value}")))
    }
}

pub(crate) fn unit_interval3(values: [f32; 3], field: &str) -> Result<(), SceneError> {
    for (i, &value) in values.iter().enumerate() {
        in_closed(value, 0.0, 1.0, &format!("{field}[{i}]"))?;
    }
    Ok(())
}

pub(crate) fn int_in(value: u32, lo: u32, hi: u32, field: &str) -> Result<(), SceneError> {
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(SceneError::field(field, format!("must be in {lo}..={hi}, got {value}")))
    }
}
