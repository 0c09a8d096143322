// One view of a light's RSM (`twin::light_rsms::RsmView`, Rust `RawRsmView`): shared by the
// lights' RSM raster (`light_rsms_raster.wgsl`) and their VAL pass (`light_rsms.wgsl`).
struct RsmView {
    world_to_clip: mat4x4<f32>,
    position: vec3<f32>,
    // Texels per side.
    resolution: u32,
    direction: vec3<f32>,
    // Half-extent of the image on the unit-distance plane.
    tan_half: f32,
    // W/sr, RGB.
    intensity: vec3<f32>,
    inner_angle: f32,
    // Top-left texel of the view in the atlas.
    origin: vec2<u32>,
    // Index of the view's first texel in the VAL pass's flat texel range.
    first_texel: u32,
    outer_angle: f32,
    // `twin::light_rsms::view_omega_scale`.
    omega_scale: f32,
    // Point light's range (m); 0: none.
    range: f32,
    _pad0: u32,
    _pad1: u32,
}
