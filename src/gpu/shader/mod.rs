//! WGSL assembly: the constants the shaders share with Rust are generated from the Rust
//! definitions and prepended, followed by `common.wgsl`, `scene.wgsl` and the pass's own file,
//! all through [`Wgsl`] (`compose.rs`), the one way sources are put together.

mod compose;

pub use compose::Wgsl;

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
/// `progress` and `status` (bindings 6 and 7) and `end_round`, for the passes run in rounds
/// (the exact reference, the differential passes; [`crate::gpu::rounds_done`]): prepend to the
/// pass's own WGSL.
pub const ROUNDS: &str = include_str!("rounds.wgsl");
const SCENE: &str = include_str!("scene.wgsl");
const SCENE_TEXTURES: &str = include_str!("scene_textures.wgsl");
const SCENE_UNTEXTURED: &str = include_str!("scene_untextured.wgsl");

/// The constants every shader shares with Rust, `TILE_SIZE` as given.
fn header(tile_size: u32) -> Wgsl {
    Wgsl::new()
        .u32("WORKGROUP_SIZE", WORKGROUP_SIZE)
        .u32("TILE_SIZE", tile_size)
        .u32("NO_NEIGHBOUR", NO_NEIGHBOUR)
        .f32("NO_SURFACE_DISTANCE", NO_SURFACE_DISTANCE)
        .f32("SHADOW_BIAS_TEXELS", SHADOW_BIAS_TEXELS)
        .f32("RAY_OFFSET", RAY_OFFSET)
        .f32("RAY_PARALLEL_EPSILON", twin::bvh::RAY_PARALLEL_EPSILON)
        .f32("COINCIDENT_DISTANCE_SQ", twin::COINCIDENT_DISTANCE_SQ)
        .f32("GATHER_EPSILON", twin::GATHER_EPSILON)
        .f32("MIN_LIGHT_DISTANCE", twin::MIN_LIGHT_DISTANCE)
        .f32("MIN_RENORMALISE_COSINE", twin::MIN_RENORMALISE_COSINE)
        .f32("MIN_GLOSSY_RESPONSE", twin::MIN_GLOSSY_RESPONSE)
        .f32("NEAR_FIELD_INNER", twin::NEAR_FIELD_INNER)
}

/// The full WGSL source of a pass whose own file is `pass`; `textured` scenes bind the texture
/// array, others have no texture binding at all.
pub fn source(pass: &str, textured: bool) -> String {
    source_with_tile_size(pass, textured, TILE_SIZE)
}

/// [`source`] with another `TILE_SIZE` (the bench's gather variants).
pub fn source_with_tile_size(pass: &str, textured: bool, tile_size: u32) -> String {
    prelude(Wgsl::new(), textured, tile_size).include(pass).finish()
}

/// `first` (e.g. a pass's workgroup sizes), then the shared constants, `common.wgsl` and the
/// scene's bindings (`textured` or not): what every pass's own WGSL follows.
pub fn prelude(first: Wgsl, textured: bool, tile_size: u32) -> Wgsl {
    let textures = if textured { SCENE_TEXTURES } else { SCENE_UNTEXTURED };
    first.include(&header(tile_size).finish()).include(COMMON).include(textures).include(SCENE)
}

/// Every shader's complete source, by pass label: the compute passes of
/// [`crate::gpu::passes`] at their default parameters and the rasters (visibility, cluster shadow maps) (for the
/// layout and compilation tests).
pub fn all_sources(textured: bool) -> Vec<(&'static str, String)> {
    crate::gpu::passes()
        .into_iter()
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
