//! The hand-mirrored `#[repr(C)]` structs match the WGSL structs, field by field (naga parses
//! the shaders; no drift like kajiya's HLSL/Rust copies), every pass's declared bindings and
//! workgroup size are what its WGSL uses, and every shader validates.

use relume::gpu::raw::*;
use relume::gpu::shader;
use std::mem::{offset_of, size_of};

fn module() -> naga::Module {
    module_of("gather")
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
    let clustering = module_of("clustering");
    use relume::gpu::visibility::clusters::{RawCluster, RawClusterSums};
    check!(clustering, "Cluster", RawCluster, [position, count, normal, radius]);
    check!(clustering, "ClusterSums", RawClusterSums, [offset, count, normal, offset_sq]);
    let many = module_of("lights_direct");
    use relume::gpu::lights::many::RawManyLight;
    check!(many, "ManyLight", RawManyLight, [position, range, direction, inner_angle, intensity, outer_angle]);
    use relume::gpu::lights::light_rsms::{RASTER_STAGE, RawRsmView, VALS_STAGE};
    for module in [module_of(VALS_STAGE), module_of(RASTER_STAGE)] {
        check!(
            module,
            "RsmView",
            RawRsmView,
            [
                world_to_clip,
                position,
                resolution,
                direction,
                tan_half,
                intensity,
                inner_angle,
                origin,
                first_texel,
                outer_angle,
                omega_scale,
                range,
                _pad0,
                _pad1
            ]
        );
    }
    check!(m, "SparsePoint", RawSparsePoint, [position, occluder_radius, normal, exponent, geometric, pad]);
    use relume::gpu::visibility::disks::{RawDiscGroup, RawOccluder};
    let occlusion = module_of("occlusion");
    check!(occlusion, "Occluder", RawOccluder, [position, radius, normal, index]);
    check!(occlusion, "DiscGroup", RawDiscGroup, [centre, radius, largest_disc]);
    check!(m, "Gathered", RawGathered, [irradiance, weight, position, _pad1, second_moment, _pad2]);
    check!(m, "PointLight", RawPointLight, [position, _pad0, intensity, bound]);
    use relume::gpu::lights::bounce::{POINTS_STAGE, RawBouncePoint};
    check!(module_of(POINTS_STAGE), "BouncePoint", RawBouncePoint, [triangle, u, v, area]);
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
    use relume::gpu::lights::rgbd::{RawIntrinsics, RawRgbdParams, RawRgbdSettings};
    let m = module_of("rgbd");
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

/// The kind of a group(0) global as the pass declarations name it.
fn slot_of(module: &naga::Module, global: &naga::GlobalVariable) -> relume::gpu::pass::Slot {
    use relume::gpu::pass::Slot;
    match (global.space, &module.types[global.ty].inner) {
        (naga::AddressSpace::Storage { access }, _) if access.contains(naga::StorageAccess::STORE) => {
            Slot::StorageReadWrite
        }
        (naga::AddressSpace::Storage { .. }, _) => Slot::Storage,
        (
            naga::AddressSpace::Handle,
            naga::TypeInner::Image { class: naga::ImageClass::Sampled { kind: naga::ScalarKind::Uint, .. }, .. },
        ) => Slot::TextureUint,
        (
            naga::AddressSpace::Handle,
            naga::TypeInner::Image {
                class: naga::ImageClass::Sampled { kind: naga::ScalarKind::Float, multi: false },
                ..
            },
        ) => Slot::DepthAsFloat,
        (space, ty) => panic!("{:?}: no slot for {space:?} {ty:?}", global.name),
    }
}

/// Every entry point of every pass uses exactly the group(0) bindings its `PassDesc` declares
/// for it (names, kinds and binding indices, in order), and runs the declared workgroup size:
/// the Rust side binds by these names, so a renamed, moved or retyped WGSL binding fails here.
#[test]
fn pass_declarations_match_wgsl() {
    for pass in relume::gpu::passes() {
        for textured in [false, true] {
            let source = (pass.default_source)(textured);
            let module = naga::front::wgsl::parse_str(&source)
                .unwrap_or_else(|e| panic!("{}: {}", pass.label, e.emit_to_string(&source)));
            let info =
                naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
                    .validate(&module)
                    .unwrap_or_else(|e| panic!("{}: {e:?}", pass.label));
            assert_eq!(
                module.entry_points.len(),
                pass.entries.len(),
                "{}: entry points declared vs in the WGSL",
                pass.label
            );
            for entry in pass.entries {
                let (index, point) = module
                    .entry_points
                    .iter()
                    .enumerate()
                    .find(|(_, e)| e.name == entry.name)
                    .unwrap_or_else(|| panic!("{}: no entry point {}", pass.label, entry.name));
                let uses = info.get_entry_point(index);
                let mut used: Vec<(u32, String, relume::gpu::pass::Slot)> = module
                    .global_variables
                    .iter()
                    .filter(|(handle, _)| !uses[*handle].is_empty())
                    .filter_map(|(_, g)| {
                        let b = g.binding.as_ref().filter(|b| b.group == 0)?;
                        Some((b.binding, g.name.clone().unwrap_or_default(), slot_of(&module, g)))
                    })
                    .collect();
                used.sort_by_key(|u| u.0);
                let declared: Vec<(u32, String, relume::gpu::pass::Slot)> =
                    entry.uses(pass).into_iter().map(|(i, b)| (i, b.name.to_owned(), b.slot)).collect();
                assert_eq!(used, declared, "{}.{}: group(0) bindings", pass.label, entry.name);
                assert_eq!(point.workgroup_size, pass.workgroup, "{}.{}: workgroup size", pass.label, entry.name);
            }
        }
    }
}

#[test]
fn mr_differential_structs_match_wgsl() {
    use relume::gpu::differential::{RawDifferentialParams, RawReceiver, RawReceiverLight};
    let m = module_of("differential");
    check!(m, "DifferentialParams", RawDifferentialParams, [receiver_count, real_count, val_count, _pad0]);
    check!(m, "Receiver", RawReceiver, [position, _pad0, normal, _pad1]);
    check!(m, "ReceiverLight", RawReceiverLight, [unoccluded, blocked, added]);
}

#[test]
fn mr_differential_fast_structs_match_wgsl() {
    use relume::gpu::differential::{RawFastParams, RawReceiver, RawReceiverLight, RawValGroup};
    let m = module_of("differential_fast");
    check!(m, "FastParams", RawFastParams, [receiver_count, group_count, real_groups, ray_share, content]);
    check!(m, "Receiver", RawReceiver, [position, _pad0, normal, _pad1]);
    check!(m, "ReceiverLight", RawReceiverLight, [unoccluded, blocked, added]);
    check!(
        m,
        "ValGroup",
        RawValGroup,
        [position, area, normal, radius, flux, reach, first, count, representative, shadow_reach]
    );
}
