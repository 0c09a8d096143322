//! WGSL assembly: the constants the shaders share with Rust are generated from the Rust
//! definitions and prepended, followed by `common.wgsl`, `scene.wgsl` and the pass's own file.

use crate::twin;

/// Threads per workgroup of the 1-D passes.
pub const WORKGROUP_SIZE: u32 = 64;
/// Workgroup of the passes over an image (pixels, RSM texels, RGB-D grid cells).
pub const IMAGE_TILE: [u32; 3] = [8, 8, 1];
/// VALs per workgroup-memory tile in the gather and the brute force (also their workgroup size).
pub const TILE_SIZE: u32 = 64;
/// Padding value of a vertex's neighbour list.
pub const NO_NEIGHBOUR: u32 = u32::MAX;
/// Light distance written where an RSM texel sees nothing (m).
pub const NO_SURFACE_DISTANCE: f32 = 3.0e38;
/// Shadow-map depth bias in RSM texel footprints.
pub const SHADOW_BIAS_TEXELS: f32 = 1.5;
/// Exact visibility: shadow rays start and end this far off the surfaces along their normals
/// (m); defined beside its CPU twin, `twin::exact_cpu`.
pub use crate::twin::exact_cpu::RAY_OFFSET;

const COMMON: &str = include_str!("common.wgsl");
/// VAL tiles in workgroup memory and per-dispatch VAL ranges, for the passes that loop over
/// every VAL (the gather, the brute force): prepend to the pass's own WGSL.
pub const VAL_TILES: &str = include_str!("val_tiles.wgsl");
const SCENE: &str = include_str!("scene.wgsl");
const SCENE_TEXTURES: &str = include_str!("scene_textures.wgsl");
const SCENE_UNTEXTURED: &str = include_str!("scene_untextured.wgsl");

fn header(tile_size: u32) -> String {
    format!(
        "const WORKGROUP_SIZE: u32 = {WORKGROUP_SIZE}u;\n\
         const TILE_SIZE: u32 = {tile_size}u;\n\
         const NO_NEIGHBOUR: u32 = {NO_NEIGHBOUR}u;\n\
         const NO_SURFACE_DISTANCE: f32 = {NO_SURFACE_DISTANCE:e};\n\
         const SHADOW_BIAS_TEXELS: f32 = {SHADOW_BIAS_TEXELS:e};\n\
         const RAY_OFFSET: f32 = {RAY_OFFSET:e};\n\
         const RAY_PARALLEL_EPSILON: f32 = {:e};\n\
         const COINCIDENT_DISTANCE_SQ: f32 = {:e};\n\
         const GATHER_EPSILON: f32 = {:e};\n\
         const MIN_LIGHT_DISTANCE: f32 = {:e};\n\
         const MIN_RENORMALISE_COSINE: f32 = {:e};\n\
         const MIN_GLOSSY_RESPONSE: f32 = {:e};\n\
         const NEAR_FIELD_INNER: f32 = {:e};\n",
        twin::bvh::RAY_PARALLEL_EPSILON,
        twin::COINCIDENT_DISTANCE_SQ,
        twin::GATHER_EPSILON,
        twin::MIN_LIGHT_DISTANCE,
        twin::MIN_RENORMALISE_COSINE,
        twin::MIN_GLOSSY_RESPONSE,
        twin::NEAR_FIELD_INNER,
    )
}

/// The full WGSL source of a pass whose own file is `pass`; `textured` scenes bind the texture
/// array, others have no texture binding at all.
pub fn source(pass: &str, textured: bool) -> String {
    source_with_tile_size(pass, textured, TILE_SIZE)
}

/// [`source`] with another `TILE_SIZE` (the bench's gather variants).
pub fn source_with_tile_size(pass: &str, textured: bool, tile_size: u32) -> String {
    let textures = if textured { SCENE_TEXTURES } else { SCENE_UNTEXTURED };
    format!("{}\n{COMMON}\n{textures}\n{SCENE}\n{pass}", header(tile_size))
}

/// Every shader's complete source, by pass label: the compute passes of
/// [`crate::gpu::PASSES`] at their default parameters and the rasters (visibility, cluster shadow maps) (for the
/// layout and compilation tests).
pub fn all_sources(textured: bool) -> Vec<(&'static str, String)> {
    crate::gpu::PASSES
        .iter()
        .map(|p| (p.label, (p.default_source)(textured)))
        .chain([
            ("visibility", crate::gpu::raster::source(textured)),
            (crate::gpu::lights::light_rsms::RASTER_STAGE, crate::gpu::lights::light_rsms::raster_source(textured)),
            (
                crate::gpu::visibility::clusters::SHADOW_MAPS_STAGE,
                crate::gpu::visibility::clusters::default_shadow_maps_source(textured),
            ),
        ])
        .collect()
}
