// Included for scenes without textures: no texture binding exists.

fn diffuse_albedo(material: Material, st: vec2<f32>) -> vec3<f32> {
    return material.diffuse;
}
