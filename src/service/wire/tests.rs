use super::proto::envelope::Body;
use super::*;

fn limits() -> Limits {
    Limits::default()
}

/// A 4 x 3 frame: colour (x, y, 7), depth 1 + x / 10 m, camera 2 m up the z axis.
fn frame() -> proto::RgbdFrame {
    let (w, h) = (4u32, 3u32);
    let mut rgb = Vec::new();
    let mut depth = Vec::new();
    for y in 0..h {
        for x in 0..w {
            rgb.extend_from_slice(&[x as u8, y as u8, 7]);
            depth.extend_from_slice(&(1000 + 100 * x as u16).to_le_bytes());
        }
    }
    proto::RgbdFrame {
        frame_id: 42,
        timestamp: 1.5,
        intrinsics: Some(proto::Intrinsics { width: w, height: h, fx: 5.0, fy: 5.0, cx: 1.5, cy: 1.0 }),
        color: Some(proto::Color { data: Some(proto::color::Data::Rgb8(rgb)) }),
        depth: Some(proto::Depth {
            data: Some(proto::depth::Data::U16(proto::DepthU16 { data: depth, units_per_metre: 1000.0 })),
        }),
        camera_to_world: Some(proto::Pose {
            transform: Some(proto::pose::Transform::TranslationRotation(proto::TranslationRotation {
                translation: Some(proto::Vec3 { x: 0.0, y: 0.0, z: 2.0 }),
                rotation: Some(proto::Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }),
            })),
            translation_f64: None,
        }),
    }
}

fn envelope(body: Body) -> Vec<u8> {
    proto::Envelope { version: PROTOCOL_VERSION, body: Some(body) }.encode_to_vec()
}

fn decode_frame_err(edit: impl FnOnce(&mut proto::RgbdFrame)) -> WireError {
    let mut f = frame();
    edit(&mut f);
    decode(&envelope(Body::RgbdFrame(f)), &limits()).expect_err("refused")
}

#[test]
fn a_valid_frame_decodes_to_metres_and_a_pose() {
    let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(frame())), &limits()).expect("valid") else {
        panic!("not a frame");
    };
    assert_eq!(m.frame_id, 42);
    assert_eq!(m.frame.timestamp, 1.5);
    assert_eq!(m.frame.intrinsics, Intrinsics { width: 4, height: 3, fx: 5.0, fy: 5.0, cx: 1.5, cy: 1.0 });
    assert_eq!(m.frame.color[4 + 2], [2, 1, 7]);
    assert_eq!(m.frame.depth.len(), 12);
    assert!((m.frame.depth[3] - 1.3).abs() < 1e-6, "{}", m.frame.depth[3]);
    assert!(m.frame.camera_to_world.translation.abs_diff_eq(DVec3::new(0.0, 0.0, 2.0), 0.0));
}

#[test]
fn encoded_frames_decode_to_the_same_frame() {
    let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(frame())), &limits()).expect("valid") else {
        panic!("not a frame");
    };
    let mut original = m.frame;
    original.depth[0] = f32::NAN;
    original.depth[1] = 0.0;
    // 100 km out with a sub-millimetre part: the f64 translation comes back exactly.
    original.camera_to_world = DAffine3::from_rotation_translation(
        glam::DQuat::from_rotation_y(0.7),
        DVec3::new(100e3 + 1e-4, 2.0, -70e3 - 3e-4),
    );
    let ClientMessage::Frame(again) = decode(&encode_rgbd_frame(9, &original), &limits()).expect("valid") else {
        panic!("not a frame");
    };
    assert_eq!(again.frame_id, 9);
    assert_eq!(again.frame.color, original.color);
    assert!(again.frame.depth[0].is_nan());
    assert_eq!(again.frame.depth[1..], original.depth[1..]);
    assert!(again.frame.camera_to_world.matrix3.abs_diff_eq(original.camera_to_world.matrix3, 1e-6));
    assert_eq!(again.frame.camera_to_world.translation, original.camera_to_world.translation);
}

#[test]
fn byte_lengths_are_checked_against_the_intrinsics() {
    let e = decode_frame_err(|f| {
        if let Some(proto::color::Data::Rgb8(rgb)) = &mut f.color.as_mut().unwrap().data {
            rgb.pop();
        }
    });
    assert_eq!(e.code, ErrorCode::InvalidField);
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.color.rgb8"));
    assert_eq!(e.frame_id, Some(42));
    assert!(e.message.contains("expected 4 x 3 x 3 = 36 bytes"), "{}", e.message);

    let e = decode_frame_err(|f| {
        f.depth = Some(proto::Depth { data: Some(proto::depth::Data::F32Metres(vec![0; 47])) });
    });
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.depth.f32_metres"));
    let e = decode_frame_err(|f| {
        if let Some(proto::depth::Data::U16(d)) = &mut f.depth.as_mut().unwrap().data {
            d.units_per_metre = 0.0;
        }
    });
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.depth.u16.units_per_metre"));
    let e = decode_frame_err(|f| f.color = None);
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.color"));
}

#[test]
fn f32_depth_keeps_nan_and_maps_infinities_to_missing() {
    let mut f = frame();
    let values = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1.0, 0.0, 2.5];
    let bytes: Vec<u8> = (0..12).flat_map(|i| values[i % values.len()].to_le_bytes()).collect();
    f.depth = Some(proto::Depth { data: Some(proto::depth::Data::F32Metres(bytes)) });
    let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("valid") else {
        panic!("not a frame");
    };
    assert!(m.frame.depth[..3].iter().all(|d| d.is_nan()));
    assert_eq!(m.frame.depth[3..6], [-1.0, 0.0, 2.5]);
}

#[test]
fn png_colour_must_have_the_intrinsics_size() {
    let png = |w: u32, h: u32| {
        let mut bytes = Vec::new();
        image::RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, 9]))
            .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
            .expect("encode");
        bytes
    };
    let mut f = frame();
    f.color = Some(proto::Color { data: Some(proto::color::Data::Png(png(4, 3))) });
    let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("valid") else {
        panic!("not a frame");
    };
    assert_eq!(m.frame.color[4 + 3], [3, 1, 9]);
    let e = decode_frame_err(|f| f.color = Some(proto::Color { data: Some(proto::color::Data::Png(png(3, 4))) }));
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.color.png"));
    assert!(e.message.contains("3 x 4"), "{}", e.message);
    let e = decode_frame_err(|f| f.color = Some(proto::Color { data: Some(proto::color::Data::Png(vec![1, 2])) }));
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.color.png"));
}

#[test]
fn poses_must_be_finite_unit_and_rigid() {
    let tr = |x: f32, w: f32| proto::Pose {
        transform: Some(proto::pose::Transform::TranslationRotation(proto::TranslationRotation {
            translation: Some(proto::Vec3 { x: 0.0, y: 0.0, z: 0.0 }),
            rotation: Some(proto::Quaternion { x, y: 0.0, z: 0.0, w }),
        })),
        translation_f64: None,
    };
    let field = "rgbd_frame.camera_to_world.translation_rotation.rotation";
    let e = decode_frame_err(|f| f.camera_to_world = Some(tr(f32::NAN, 1.0)));
    assert_eq!(e.field.as_deref(), Some(field));
    let e = decode_frame_err(|f| f.camera_to_world = Some(tr(0.0, 1.1)));
    assert_eq!(e.field.as_deref(), Some(field));
    assert!(e.message.contains("unit quaternion"), "{}", e.message);
    // Within the tolerance: renormalised.
    let mut f = frame();
    f.camera_to_world = Some(tr(0.0, 1.0005));
    decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("nearly unit is fine");

    let matrix = |m: Mat4| proto::Pose {
        transform: Some(proto::pose::Transform::Matrix(proto::Matrix4 { column_major: m.to_cols_array().to_vec() })),
        translation_f64: None,
    };
    let field = "rgbd_frame.camera_to_world.matrix.column_major";
    for bad in [
        Mat4::from_scale(Vec3::splat(2.0)),
        Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0)),
        Mat4::from_cols_array(&[1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]),
    ] {
        let e = decode_frame_err(|f| f.camera_to_world = Some(matrix(bad)));
        assert_eq!(e.field.as_deref(), Some(field), "{bad}");
        assert!(e.message.contains("rigid"), "{}", e.message);
    }
    let e = decode_frame_err(|f| {
        f.camera_to_world = Some(proto::Pose {
            transform: Some(proto::pose::Transform::Matrix(proto::Matrix4 { column_major: vec![1.0; 12] })),
            translation_f64: None,
        })
    });
    assert!(e.message.contains("16 numbers"), "{}", e.message);
    let mut nan = Mat4::IDENTITY.to_cols_array();
    nan[13] = f32::NAN;
    let e = decode_frame_err(|f| f.camera_to_world = Some(matrix(Mat4::from_cols_array(&nan))));
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.camera_to_world.matrix.column_major[13]"));
    let mut f = frame();
    f.camera_to_world = Some(matrix(Mat4::from_rotation_translation(Quat::from_rotation_x(1.0), Vec3::ONE)));
    decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("a rigid matrix");
}

#[test]
fn a_double_translation_replaces_the_float_one() {
    let far = DVec3::new(100e3 + 2e-4, -3.0, 70e3 - 1e-4);
    let mut f = frame();
    f.camera_to_world.as_mut().unwrap().translation_f64 = Some(proto::DVec3 { x: far.x, y: far.y, z: far.z });
    let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("valid") else {
        panic!("not a frame");
    };
    assert_eq!(m.frame.camera_to_world.translation, far);
    let bad = [
        (proto::DVec3 { x: f64::NAN, y: 0.0, z: 0.0 }, "x"),
        (proto::DVec3 { x: 0.0, y: 2e7, z: 0.0 }, "y"),
        (proto::DVec3 { x: 0.0, y: 0.0, z: f64::NEG_INFINITY }, "z"),
    ];
    for (t, axis) in bad {
        let e = decode_frame_err(|f| f.camera_to_world.as_mut().unwrap().translation_f64 = Some(t));
        assert_eq!(e.field.as_deref(), Some(format!("rgbd_frame.camera_to_world.translation_f64.{axis}").as_str()));
    }
    // The transform is still required and checked.
    let e = decode_frame_err(|f| f.camera_to_world.as_mut().unwrap().transform = None);
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.camera_to_world"));
}

#[test]
fn intrinsics_and_limits_name_the_field_and_setting() {
    let e = decode_frame_err(|f| f.intrinsics.as_mut().unwrap().fx = f32::INFINITY);
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.intrinsics.fx"));
    let e = decode_frame_err(|f| f.intrinsics.as_mut().unwrap().cy = f32::NAN);
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.intrinsics.cy"));
    let e = decode_frame_err(|f| f.intrinsics.as_mut().unwrap().width = 5000);
    assert_eq!(e.code, ErrorCode::LimitExceeded);
    assert_eq!(e.limit, Some(limit::MAX_FRAME_SIDE));
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.intrinsics.width"));
    let e = decode_frame_err(|f| f.timestamp = f64::NAN);
    assert_eq!(e.field.as_deref(), Some("rgbd_frame.timestamp"));

    let small = Limits { max_message_bytes: 10, ..limits() };
    let e = decode(&envelope(Body::RgbdFrame(frame())), &small).expect_err("too big");
    assert_eq!((e.code, e.limit), (ErrorCode::LimitExceeded, Some(limit::MAX_MESSAGE_BYTES)));

    let tum = Intrinsics::TUM;
    let settings = RgbdSettings::default();
    check_frame_vals(&tum, &settings, &limits()).expect("80 x 60 VALs");
    let few = Limits { max_vals: 4799, ..limits() };
    let e = check_frame_vals(&tum, &settings, &few).expect_err("4800 > 4799");
    assert_eq!(e.limit, Some(limit::MAX_VALS));
}

#[test]
fn envelopes_are_checked_before_bodies() {
    let e = decode(&[0xff, 0xff, 0xff], &limits()).expect_err("garbage");
    assert_eq!(e.code, ErrorCode::Malformed);
    let e = decode(&[], &limits()).expect_err("empty");
    assert_eq!((e.code, e.field.as_deref()), (ErrorCode::Malformed, None));
    let e = decode(&proto::Envelope { version: 0, body: Some(Body::RgbdFrame(frame())) }.encode_to_vec(), &limits())
        .expect_err("version 0");
    assert_eq!((e.code, e.field.as_deref()), (ErrorCode::UnsupportedVersion, Some("version")));
    let e = decode(&proto::Envelope { version: 1, body: None }.encode_to_vec(), &limits()).expect_err("no body");
    assert_eq!((e.code, e.field.as_deref()), (ErrorCode::Malformed, Some("body")));
    let bytes = proto::Envelope { version: 2, body: Some(Body::RgbdFrame(frame())) }.encode_to_vec();
    assert_eq!(decode(&bytes, &limits()).expect_err("v2").code, ErrorCode::UnsupportedVersion);
    let bytes = envelope(Body::SettingsAck(proto::SettingsAck::default()));
    assert_eq!(decode(&bytes, &limits()).expect_err("server body").code, ErrorCode::UnexpectedMessage);
}

/// The bytes the viewer's encoder (protobuf.js in src/service/viewer/proto.js) writes for
/// one Control; tests/e2e/viewer.test.mjs checks that the page writes exactly these.
const VIEWER_CONTROL: [u8; 23] = [8, 1, 26, 19, 8, 172, 2, 42, 4, 16, 3, 32, 1, 50, 2, 8, 12, 58, 4, 8, 2, 16, 0];
/// Another: a request id of 0 and `Quality.component` left out (no presence, default
/// value), floats, and `glossy` alone; also checked by tests/e2e/viewer.test.mjs.
const VIEWER_CONTROL_FLOATS: [u8; 28] =
    [8, 1, 26, 24, 42, 9, 16, 1, 29, 0, 0, 0, 63, 32, 2, 50, 7, 8, 4, 37, 0, 0, 32, 64, 58, 2, 16, 1];

#[test]
fn the_viewers_control_bytes_are_prosts_and_decode() {
    let control = proto::Control {
        request_id: 300,
        quality: Some(proto::Quality { component: 3, format: 1, ..Default::default() }),
        rgbd: Some(proto::RgbdSettings { grid_step: Some(12), ..Default::default() }),
        render: Some(proto::RenderSettings { occlusion: Some(2), glossy: Some(false), ..Default::default() }),
        ..Default::default()
    };
    assert_eq!(envelope(Body::Control(control.clone())), VIEWER_CONTROL);
    let floats = proto::Control {
        request_id: 0,
        quality: Some(proto::Quality { component: 1, exposure: Some(0.5), format: 2, ..Default::default() }),
        rgbd: Some(proto::RgbdSettings { grid_step: Some(4), radiance_scale: Some(2.5), ..Default::default() }),
        render: Some(proto::RenderSettings { occlusion: None, glossy: Some(true), ..Default::default() }),
        ..Default::default()
    };
    assert_eq!(envelope(Body::Control(floats)), VIEWER_CONTROL_FLOATS);
    let ClientMessage::Control(c) = decode(&VIEWER_CONTROL, &limits()).expect("valid") else { panic!("control") };
    assert_eq!(c.request_id, 300);
    assert_eq!(c.quality.expect("quality").component, Component::Indirect);
    assert_eq!(c.rgbd.expect("rgbd").grid_step, Some(12));
    assert_eq!(
        c.render,
        Some(RenderSettingsPatch {
            occlusion: Some(Some(Occlusion::Disks)),
            glossy: Some(false),
            ..Default::default()
        })
    );

    let unset = proto::Control {
        render: Some(proto::RenderSettings { occlusion: Some(0), glossy: None, ..Default::default() }),
        ..control.clone()
    };
    let ClientMessage::Control(c) = decode(&envelope(Body::Control(unset)), &limits()).expect("valid") else {
        panic!("control")
    };
    assert_eq!(
        c.render,
        Some(RenderSettingsPatch { occlusion: Some(None), glossy: None, ..Default::default() }),
        "0: the scene's"
    );
    let bad = proto::Control {
        render: Some(proto::RenderSettings { occlusion: Some(7), glossy: None, ..Default::default() }),
        ..control
    };
    let e = decode(&envelope(Body::Control(bad)), &limits()).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.render.occlusion"));
}

#[test]
fn control_messages_validate_each_part() {
    let control = |edit: &dyn Fn(&mut proto::Control)| {
        let mut c = proto::Control { request_id: 7, ..Default::default() };
        edit(&mut c);
        decode(&envelope(Body::Control(c)), &limits())
    };
    let camera = proto::Camera {
        position: Some(proto::Vec3 { x: 0.0, y: 1.0, z: 3.0 }),
        target: Some(proto::Vec3 { x: 0.0, y: 1.0, z: 0.0 }),
        up: None,
        fov_y_deg: 40.0,
        width: 64,
        height: 48,
    };
    let ok = control(&|c| {
        c.camera = Some(camera);
        c.model_transforms = vec![proto::ModelTransform {
            mesh_index: 1,
            translation: Some(proto::Vec3 { x: 1.0, y: 0.0, z: 0.0 }),
            rotation_deg: Some(proto::Vec3 { x: 0.0, y: 90.0, z: 0.0 }),
            scale: None,
        }];
        c.quality = Some(proto::Quality { method: 2, component: 3, exposure: Some(2.0), format: 2 });
        c.rgbd = Some(proto::RgbdSettings { grid_step: Some(4), ..Default::default() });
    })
    .expect("valid");
    let ClientMessage::Control(ok) = ok else { panic!("not a control") };
    assert_eq!(ok.request_id, 7);
    assert_eq!(ok.camera.expect("camera").up, [0.0, 1.0, 0.0]);
    assert_eq!(ok.model_transforms[0].0, 1);
    let quality = ok.quality.expect("quality");
    assert_eq!((quality.method, quality.component), (Method::BruteForce, Component::Indirect));
    assert_eq!(quality.format, StreamImageFormat::Rgba8);
    let rgbd = ok.rgbd.expect("rgbd").apply(&RgbdSettings::default(), "control.rgbd").expect("valid");
    assert_eq!(rgbd.grid_step, 4);

    let e = control(&|c| c.camera = Some(proto::Camera { fov_y_deg: f32::NAN, ..camera })).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.camera.fov_y_deg"));
    assert_eq!(e.request_id, Some(7));
    let e = control(&|c| c.camera = Some(proto::Camera { width: 100_000, ..camera })).unwrap_err();
    assert_eq!(e.limit, Some(limit::MAX_FRAME_SIDE));
    let e = control(&|c| c.camera = Some(proto::Camera { target: None, ..camera })).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.camera.target"));
    let e = control(&|c| {
        c.model_transforms = vec![proto::ModelTransform {
            mesh_index: 0,
            translation: Some(proto::Vec3::default()),
            rotation_deg: Some(proto::Vec3::default()),
            scale: Some(proto::Vec3 { x: 1.0, y: 0.0, z: 1.0 }),
        }]
    })
    .unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.model_transforms[0].scale[1]"));
    let ism = control(&|c| c.quality = Some(proto::Quality { method: 3, ..Default::default() })).expect("valid");
    let ClientMessage::Control(ism) = ism else { panic!("not a control") };
    assert_eq!(ism.quality.expect("quality").method, Method::BruteForceIsm);
    let e = control(&|c| c.quality = Some(proto::Quality { method: 9, ..Default::default() })).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.quality.method"));
    let e = RgbdSettingsPatch { min_depth: Some(20.0), ..Default::default() }
        .apply(&RgbdSettings::default(), "control.rgbd")
        .unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.rgbd.max_depth"));
    // The scene file's bounds: a grid step of 100 is refused, as in a scene file.
    let e = RgbdSettingsPatch { grid_step: Some(100), ..Default::default() }
        .apply(&RgbdSettings::default(), "control.rgbd")
        .unwrap_err();
    assert_eq!((e.code, e.field.as_deref()), (ErrorCode::InvalidField, Some("control.rgbd.grid_step")));
    assert_eq!(e.message, "control.rgbd.grid_step: must be in 1..=64, got 100");
    let e = RgbdSettingsPatch { min_depth: Some(0.0), ..Default::default() }
        .apply(&RgbdSettings::default(), "control.rgbd")
        .unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.rgbd.min_depth"));
}

#[test]
fn server_messages_encode_as_version_1_envelopes() {
    let frame = RenderedFrame {
        frame_id: 3,
        timestamp: 0.25,
        width: 2,
        height: 1,
        image: FrameImage::Rgba8(vec![1; 8]),
        timings: vec![("gather".to_owned(), 1.5)],
        val_count: 100,
        dropped_frames: 2,
        error_estimate: None,
        quality: crate::scene::Quality::Fast,
        parameters: vec![("vals_step".to_owned(), "2".to_owned())],
        budget_ms: Some(40.0),
    };
    let envelope = proto::Envelope::decode(encode(ServerMessage::Frame(frame)).as_slice()).expect("decodes");
    assert_eq!(envelope.version, PROTOCOL_VERSION);
    let Some(Body::RenderedFrame(f)) = envelope.body else { panic!("not a frame") };
    assert_eq!((f.frame_id, f.width, f.val_count, f.dropped_frames), (3, 2, 100, 2));
    assert_eq!((f.quality(), f.budget_ms, f.error_estimate), (proto::QualityLevel::Fast, 40.0, None));
    assert_eq!((f.parameters[0].name.as_str(), f.parameters[0].value.as_str()), ("vals_step", "2"));
    assert_eq!(f.timings[0].stage, "gather");
    assert_eq!(f.image, Some(proto::rendered_frame::Image::Rgba8(vec![1; 8])));

    let error = WireError::limit(limit::MAX_VALS, Some("rgbd_frame.intrinsics".to_owned()), "too many").with_frame(5);
    let envelope = proto::Envelope::decode(encode(ServerMessage::Error(error)).as_slice()).expect("decodes");
    let Some(Body::Error(e)) = envelope.body else { panic!("not an error") };
    assert_eq!(e.code(), ErrorCode::LimitExceeded);
    assert_eq!((e.limit.as_str(), e.field.as_str()), ("max_vals", "rgbd_frame.intrinsics"));
    assert_eq!((e.frame_id, e.request_id), (Some(5), None));

    let ack = SettingsAck { request_id: 8, applied: vec!["camera".to_owned()] };
    let envelope = proto::Envelope::decode(encode(ServerMessage::Ack(ack)).as_slice()).expect("decodes");
    let Some(Body::SettingsAck(a)) = envelope.body else { panic!("not an ack") };
    assert_eq!((a.request_id, a.applied), (8, vec!["camera".to_owned()]));
}

/// The JSON names of a protobuf enum's values but `UNSPECIFIED` (0), in the protobuf's order:
/// each value decodes to a value of the scene file's type (`from_proto`) which encodes back to it
/// (`to_proto`), and its protobuf name (`proto_name`) is `prefix` and the JSON name in capitals.
fn proto_json_names<E, S>(
    prefix: &str,
    proto_name: fn(&E) -> &'static str,
    from_proto: impl Fn(E) -> Option<S>,
    to_proto: impl Fn(S) -> E,
) -> Vec<String>
where
    E: TryFrom<i32> + Copy + PartialEq + std::fmt::Debug,
    S: serde::Serialize + Copy,
{
    let mut names = Vec::new();
    for value in 1..64 {
        let Ok(proto) = E::try_from(value) else { continue };
        let scene = from_proto(proto).unwrap_or_else(|| panic!("{proto:?} has no value in the scene file"));
        assert_eq!(to_proto(scene), proto);
        let name = serde_json::to_value(scene).unwrap().as_str().expect("a JSON name").to_owned();
        assert_eq!(proto_name(&proto), format!("{prefix}{}", name.to_uppercase()));
        names.push(name);
    }
    names
}

/// The names the OpenAPI document's `schema` enum lists, in its order.
fn openapi_enum(schema: &str) -> Vec<String> {
    let openapi: serde_json::Value =
        serde_json::from_str(include_str!("../../../proto/openapi.json")).expect("the OpenAPI document");
    let values = openapi["components"]["schemas"][schema]["enum"].as_array();
    let values = values.unwrap_or_else(|| panic!("no {schema} enum in the OpenAPI document"));
    values.iter().map(|v| v.as_str().expect("a name").to_owned()).collect()
}

/// The protobuf schema, the scene file's JSON names and the OpenAPI document list the same
/// visibility modes: every protobuf value but `UNSPECIFIED` is a mode, and back; its name is the
/// JSON name; the registry and the OpenAPI document's `Occlusion` schema list exactly those names.
#[test]
fn visibility_modes_agree_between_proto_json_and_openapi() {
    let to_proto = |mode| occlusion_to_proto(mode).expect("every mode has a protobuf value");
    let json_names = proto_json_names("OCCLUSION_", proto::Occlusion::as_str_name, occlusion_from_proto, to_proto);
    let registry: Vec<&str> = Occlusion::ALL.iter().map(|m| m.name()).collect();
    assert_eq!(json_names, registry, "relume.proto's Occlusion values and the registry of modes differ");
    assert_eq!(openapi_enum("Occlusion"), json_names);
}

/// The protobuf schema, the scene file's JSON names and the OpenAPI document list the same
/// quality levels: every protobuf value but `UNSPECIFIED` is a level, and back; its name is
/// the JSON name; `Quality::ALL` and the OpenAPI document's `QualityLevel` schema list exactly
/// those names, cheapest first.
#[test]
fn quality_levels_agree_between_proto_json_and_openapi() {
    let json_names =
        proto_json_names("QUALITY_LEVEL_", proto::QualityLevel::as_str_name, quality_from_proto, quality_to_proto);
    let all: Vec<&str> = crate::scene::Quality::ALL.iter().map(|q| q.name()).collect();
    assert_eq!(json_names, all);
    assert_eq!(openapi_enum("QualityLevel"), json_names);
}

/// A control message's level and budget: a level, back to the scene's (0), a budget, no
/// budget (0), and the one check of a budget's range naming the field.
#[test]
fn control_messages_carry_a_level_and_a_budget() {
    let control = |quality: Option<i32>, budget_ms: Option<f32>| {
        let render = proto::RenderSettings { quality, budget_ms, ..Default::default() };
        decode(&envelope(Body::Control(proto::Control { render: Some(render), ..Default::default() })), &limits())
    };
    let render = |m: Result<ClientMessage, WireError>| match m.expect("valid") {
        ClientMessage::Control(c) => c.render.expect("render"),
        ClientMessage::Frame(_) => panic!("a control message"),
    };
    let fast = render(control(Some(proto::QualityLevel::Fast as i32), Some(25.0)));
    assert_eq!((fast.quality, fast.budget_ms), (Some(Some(crate::scene::Quality::Fast)), Some(Some(25.0))));
    let back = render(control(Some(0), Some(0.0)));
    assert_eq!((back.quality, back.budget_ms), (Some(None), Some(None)));
    let e = control(Some(9), None).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("control.render.quality"));
    for bad in [-1.0, 0.01, f32::NAN, 1e9] {
        let e = control(None, Some(bad)).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.render.budget_ms"), "{bad}");
        assert_eq!(e.code, ErrorCode::InvalidField);
    }
}
