//! The range checks every part of a scene file shares: each names the field it checks.

use super::SceneError;
use super::description::MAX_COORDINATE_M;

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
