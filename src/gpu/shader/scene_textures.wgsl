// Included only for scenes with diffuse textures (`src/gpu/shader.rs`): every texture is a layer
// of one sRGB array (the GPU decodes to linear before filtering), sampled bilinearly with
// repeat addressing. Rust twin: `twin::sample_bilinear`.

@group(1) @binding(5) var diffuse_textures: texture_2d_array<f32>;
@group(1) @binding(6) var diffuse_sampler: sampler;

fn diffuse_albedo(material: Material, st: vec2<f32>) -> vec3<f32> {
    if material.diffuse_texture < 0 {
        return material.diffuse;
    }
    return material.diffuse * textureSampleLevel(diffuse_textures, diffuse_sampler, st, material.diffuse_texture, 0.0).rgb;
}
