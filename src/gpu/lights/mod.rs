//! Light sources: the spot light's reflective shadow map (RSM) becomes VALs and its direct
//! light; the scene's `lights` make direct light and, through their own RSMs, VALs; an RGB-D
//! frame becomes VALs.

pub mod bounce;
pub mod compact;
pub mod direct;
pub mod light_rsms;
pub mod many;
pub mod rgbd;
pub mod rsm;
pub mod spot;
