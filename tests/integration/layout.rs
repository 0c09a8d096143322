//! The hand-mirrored `#[repr(C)]` structs match the WGSL structs, field by field (naga parses
//! the shaders; no drift like kajiya's HLSL/Rust copies), and every shader validates.

use relume::gpu::raw::*;
use relume::gpu::shader;
use std::mem::{offset_of, size_of};

fn module() -> naga::Module {
    module_of("gather.wgsl")
}

fn module_of(name: &str) -> naga::Module {
    let sources = shader::all_sources(true);
    let (_, source) = sources.iter().find(|(n, _)| *n == name).unwrap_or_else(|| panic!("{name} shader"));
    naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{name} parses: {e}"))
}

fn wgsl_layout(module: &naga::Module, name: &str) -> (u32, Vec<(String, u32)>) {
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("layout");
    for (handle, ty) in module.types.iter() {
        if ty.name.as_deref() == Some(name)
            && let naga::TypeInner::Struct { members, span } = &ty.inner
        {
            let _ = layouter[handle];
            return (*span, members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset)).collect());
        }
    }
    panic!("struct {name} not found in WGSL");
}

macro_rules! check {
    ($module:expr, $wgsl:literal, $rust:ty, [$($field:ident),* $(,)?]) => {{
        let (size, members) = wgsl_layout(&$module, $wgsl);
        assert_eq!(size as usize, size_of::<$rust>(), "size of {}", $wgsl);
        let rust: Vec<(String, u32)> = vec![$((stringify!($field).to_string(), offset_of!($rust, $field) as u32)),*];
        assert_eq!(members, rust, "fields of {}", $wgsl);
    }};
}

#[test]
fn rust_structs_match_wgsl() {
    let m = module();
    check!(m, "Val", RawVal, [position, area, normal, _pad0, flux, _pad1]);
    check!(m, "Vertex", RawVertex, [position, s, normal, t]);
    check!(m, "Material", RawMaterial, [diffuse, exponent, specular, diffuse_texture]);
    check!(m, "SparsePoint", RawSparsePoint, [position, occluder_radius, normal, exponent]);
    check!(m, "Gathered", RawGathered, [irradiance, weight, position, _pad1, second_moment, _pad2]);
    check!(m, "PointLight", RawPointLight, [position, _pad0, intensity, _pad1]);
    check!(
        m,
        "Frame",
        RawFrame,
        [
            world_to_clip,
            light_world_to_clip,
            eye,
            width,
            light_position,
            height,
            light_direction,
            rsm_resolution,
            light_intensity,
            light_inner_angle,
            light_outer_angle,
            sparse_count,
            vertex_count,
            triangle_count,
        ]
    );
}

#[test]
fn rgbd_structs_match_wgsl() {
    use relume::gpu::rgbd::{RawIntrinsics, RawRgbdParams, RawRgbdSettings};
    let m = module_of("rgbd.wgsl");
    check!(m, "Intrinsics", RawIntrinsics, [width, height, fx, fy, cx, cy]);
    check!(
        m,
        "RgbdSettings",
        RawRgbdSettings,
        [grid_step, min_depth, max_depth, radiance_scale, bilateral_radius, bilateral_depth_sigma, min_cosine]
    );
    check!(m, "RgbdParams", RawRgbdParams, [camera_to_world, intrinsics, settings, _pad0, _pad1, _pad2]);
}

#[test]
fn every_shader_validates() {
    for (name, source) in shader::all_sources(false).into_iter().chain(shader::all_sources(true)) {
        let module =
            naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
}
