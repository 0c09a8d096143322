//! Light sources: the spot light's reflective shadow map (RSM) becomes VALs and its direct
//! light; an RGB-D frame becomes VALs.

pub mod bounce;
pub mod direct;
pub mod many;
pub mod rgbd;
pub mod rsm;
pub mod spot;
