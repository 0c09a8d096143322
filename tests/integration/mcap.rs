//! MCAP recordings: the TUM fixture re-packed as a ROS 2 bag (colour `rgb8` and depth `16UC1`
//! `sensor_msgs/msg/Image`, `CameraInfo`, the ground truth as `/tf` plus a static optical-frame
//! link on `/tf_static`) must read and replay exactly as the TUM folder does; malformed bags are
//! errors naming the record and field; arbitrary bytes never panic.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use glam::{DAffine3, DQuat, DVec3};
use proptest::prelude::*;
use relume::rgbd::recording::{Layout, Recording, RecordingOptions};
use relume::rgbd::rosbag::{self, McapTopics, msg};

use super::{fixture, gpu, scratch};

const COLOUR_TOPIC: &str = "/camera/rgb/image_color";
const DEPTH_TOPIC: &str = "/camera/depth_registered/image_raw";
const INFO_TOPIC: &str = "/camera/depth_registered/camera_info";
const OPTICAL_FRAME: &str = "openni_rgb_optical_frame";

/// Writes MCAP files of ROS 2 messages.
struct Bag {
    writer: mcap::Writer<BufWriter<std::fs::File>>,
    channels: BTreeMap<String, u16>,
    sequence: u32,
}

impl Bag {
    fn create(path: &Path) -> Bag {
        let file = BufWriter::new(std::fs::File::create(path).unwrap());
        Bag { writer: mcap::Writer::new(file).unwrap(), channels: BTreeMap::new(), sequence: 0 }
    }

    fn write<T: serde::Serialize>(&mut self, topic: &str, schema: &str, stamp: msg::Time, message: &T) {
        let channel = match self.channels.get(topic) {
            Some(&id) => id,
            None => {
                let schema_id = self.writer.add_schema(schema, "ros2msg", b"").unwrap();
                let id = self.writer.add_channel(schema_id, topic, "cdr", &BTreeMap::new()).unwrap();
                self.channels.insert(topic.to_owned(), id);
                id
            }
        };
        self.sequence += 1;
        let time = (stamp.seconds() * 1e9) as u64;
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: self.sequence,
            log_time: time,
            publish_time: time,
        };
        self.writer.write_to_known_channel(&header, &msg::encode(message).unwrap()).unwrap();
    }

    fn finish(mut self) {
        self.writer.finish().unwrap();
    }
}

fn header(seconds: f64, frame_id: &str) -> msg::Header {
    msg::Header { stamp: msg::Time::from_seconds(seconds), frame_id: frame_id.to_owned() }
}

/// `timestamp rest...` lines of a TUM text file.
fn tum_lines(file: &Path) -> Vec<(f64, Vec<String>)> {
    std::fs::read_to_string(file)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let mut fields = l.split_whitespace().map(str::to_owned);
            (fields.next().unwrap().parse().unwrap(), fields.collect())
        })
        .collect()
}

fn image_message(
    seconds: f64,
    encoding: &str,
    width: u32,
    height: u32,
    bpp: u32,
    data: Vec<u8>,
) -> msg::Image<'static> {
    msg::Image {
        header: header(seconds, OPTICAL_FRAME),
        height,
        width,
        encoding: encoding.to_owned(),
        is_bigendian: 0,
        step: width * bpp,
        data: data.into(),
    }
}

/// The TUM fixture as an MCAP file at `path`: every colour and depth image of `rgb.txt` and
/// `depth.txt` at its timestamp (depth raw, 5000 units per metre as in TUM), the camera info of
/// TUM's registered depth, and every ground-truth sample as `world -> openni_camera` on `/tf`
/// with an identity `openni_camera -> openni_rgb_optical_frame` on `/tf_static`.
fn write_tum_as_mcap(path: &Path) {
    let dir = fixture("recordings/tum_fr1_xyz");
    let mut bag = Bag::create(path);
    let k = relume::rgbd::Intrinsics::TUM;
    let info = msg::CameraInfo {
        header: header(0.0, OPTICAL_FRAME),
        height: k.height,
        width: k.width,
        distortion_model: "plumb_bob".to_owned(),
        d: vec![0.0; 5],
        k: [k.fx as f64, 0.0, k.cx as f64, 0.0, k.fy as f64, k.cy as f64, 0.0, 0.0, 1.0],
        ..Default::default()
    };
    bag.write(INFO_TOPIC, rosbag::CAMERA_INFO, info.header.stamp, &info);
    let link = msg::TfMessage {
        transforms: vec![msg::TransformStamped {
            header: header(0.0, "openni_camera"),
            child_frame_id: OPTICAL_FRAME.to_owned(),
            transform: msg::Transform {
                rotation: msg::Quaternion { w: 1.0, ..Default::default() },
                ..Default::default()
            },
        }],
    };
    bag.write(rosbag::TF_STATIC_TOPIC, rosbag::TF_MESSAGE, msg::Time::default(), &link);
    for (t, fields) in tum_lines(&dir.join("groundtruth.txt")) {
        let v: Vec<f64> = fields.iter().map(|f| f.parse().unwrap()).collect();
        let tf = msg::TfMessage {
            transforms: vec![msg::TransformStamped {
                header: header(t, "world"),
                child_frame_id: "openni_camera".to_owned(),
                transform: msg::Transform {
                    translation: msg::Vector3 { x: v[0], y: v[1], z: v[2] },
                    rotation: msg::Quaternion { x: v[3], y: v[4], z: v[5], w: v[6] },
                },
            }],
        };
        bag.write("/tf", rosbag::TF_MESSAGE, msg::Time::from_seconds(t), &tf);
    }
    for (t, fields) in tum_lines(&dir.join("rgb.txt")) {
        let rgb = image::open(dir.join(&fields[0])).unwrap().into_rgb8();
        let (w, h) = rgb.dimensions();
        bag.write(
            COLOUR_TOPIC,
            rosbag::IMAGE,
            msg::Time::from_seconds(t),
            &image_message(t, "rgb8", w, h, 3, rgb.into_raw()),
        );
    }
    for (t, fields) in tum_lines(&dir.join("depth.txt")) {
        let depth = image::open(dir.join(&fields[0])).unwrap().into_luma16();
        let (w, h) = depth.dimensions();
        let bytes: Vec<u8> = depth.into_raw().iter().flat_map(|v| v.to_le_bytes()).collect();
        bag.write(DEPTH_TOPIC, rosbag::IMAGE, msg::Time::from_seconds(t), &image_message(t, "16UC1", w, h, 2, bytes));
    }
    bag.finish();
}

/// The re-packed fixture in a scratch directory of its own (`test` names it: tests run in
/// parallel).
fn tum_mcap(test: &str) -> PathBuf {
    let path = scratch(&format!("mcap_tum_{test}")).join("tum_fr1_xyz.mcap");
    write_tum_as_mcap(&path);
    path
}

/// The options that read the re-packed depth as TUM's (5000 units per metre, not ROS's 1000).
fn tum_scale() -> RecordingOptions {
    RecordingOptions { depth_scale: Some(relume::rgbd::recording::TUM_DEPTH_SCALE), ..Default::default() }
}

#[test]
fn mcap_of_the_tum_fixture_reads_as_the_tum_folder() {
    let path = tum_mcap("read");
    let mcap = Recording::open(&path, &tum_scale()).unwrap();
    let tum = Recording::open(&fixture("recordings/tum_fr1_xyz"), &RecordingOptions::default()).unwrap();
    assert_eq!(mcap.layout(), Layout::Mcap);
    assert_eq!((mcap.len(), tum.len()), (37, 37));
    assert_eq!(mcap.stats(), tum.stats());
    assert_eq!(mcap.intrinsics(), tum.intrinsics());
    assert!(mcap.has_groundtruth());
    // Stamps go through (sec, nanosec) and back; TUM's 6 decimals survive exactly.
    assert_eq!(mcap.timestamps(), tum.timestamps());
    // The same samples, interpolated the same way, composed with an identity static link.
    assert_eq!(mcap.poses(), tum.poses());
    for i in 0..tum.len() {
        let (a, b) = (mcap.frame(i).unwrap(), tum.frame(i).unwrap());
        assert_eq!(a.color, b.color, "frame {i} colour");
        assert_eq!(a.depth, b.depth, "frame {i} depth");
        assert_eq!((a.timestamp, a.camera_to_world, a.intrinsics), (b.timestamp, b.camera_to_world, b.intrinsics));
    }
}

/// `relume replay` of the bag writes the same images as that of the folder, to the bit: the
/// inputs are equal bit for bit (the test above), and a frame's VALs come in their cells' order
/// (`gpu/lights/compact.rs`), so every sum over them is the same from run to run.
#[test]
fn mcap_replay_equals_the_tum_replay() {
    let gpu = gpu();
    let path = tum_mcap("replay");
    let mut outputs = Vec::new();
    for (name, recording, options) in
        [("mcap", path, tum_scale()), ("tum", fixture("recordings/tum_fr1_xyz"), RecordingOptions::default())]
    {
        let out = scratch(&format!("mcap_replay_{name}"));
        let options = relume::mr::replay::ReplayOptions {
            recording,
            recording_options: options,
            scene: fixture("scenes/mr_bunny.json"),
            out: out.clone(),
            size: Some((160, 120)),
            frames: Some(4),
            accumulate: None,
            exposure: 1.0,
            progress: false,
            budget_ms: None,
        };
        let summary = relume::mr::replay::replay(&gpu, &options).unwrap();
        outputs.push((out, summary));
    }
    let [(mcap_out, mcap), (tum_out, tum)] = &outputs[..] else { unreachable!() };
    assert_eq!(mcap.vals_per_frame, tum.vals_per_frame);
    assert_eq!(mcap.irradiance_change.len(), 3);
    assert_eq!(mcap.irradiance_change, tum.irradiance_change);
    for i in 0..4 {
        for kind in ["composited", "indirect"] {
            let file = format!("{kind}/{i:04}.png");
            let a = image::open(mcap_out.join(&file)).unwrap().into_rgb8();
            let b = image::open(tum_out.join(&file)).unwrap().into_rgb8();
            assert!(a == b, "{file}: the bag's and the folder's replays differ");
        }
    }
}

/// A one-frame bag: 2x1 images `colour` and `depth` (little-endian), camera info, no poses.
fn tiny_bag(
    name: &str,
    colour: (&str, Vec<u8>),
    depth: (&str, Vec<u8>),
    edit: impl FnOnce(&mut msg::Image),
) -> PathBuf {
    let path = scratch(&format!("mcap_{name}")).join("tiny.mcap");
    let mut bag = Bag::create(&path);
    let info = msg::CameraInfo {
        header: header(0.0, "cam"),
        width: 2,
        height: 1,
        k: [2.0, 0.0, 0.5, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0],
        ..Default::default()
    };
    bag.write("/cam/camera_info", rosbag::CAMERA_INFO, msg::Time::default(), &info);
    let bpp = |encoding: &str| match encoding {
        "bgr8" | "rgb8" => 3,
        "mono8" => 1,
        "16UC1" | "mono16" => 2,
        _ => 4,
    };
    let colour = image_message(1.0, colour.0, 2, 1, bpp(colour.0), colour.1);
    let mut depth = image_message(1.0, depth.0, 2, 1, bpp(depth.0), depth.1);
    edit(&mut depth);
    bag.write("/cam/color/image_raw", rosbag::IMAGE, msg::Time::from_seconds(1.0), &colour);
    bag.write("/cam/depth/image_raw", rosbag::IMAGE, msg::Time::from_seconds(1.0), &depth);
    bag.finish();
    path
}

#[test]
fn mcap_encodings_convert_to_rgb_and_metres() {
    let f32s = |v: [f32; 2]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let path = tiny_bag("float", ("bgr8", vec![1, 2, 3, 4, 5, 6]), ("32FC1", f32s([1.5, f32::NAN])), |_| {});
    let recording = Recording::open(&path, &RecordingOptions::default()).unwrap();
    assert!(!recording.has_groundtruth());
    let frame = recording.frame(0).unwrap();
    assert_eq!(frame.color, vec![[3, 2, 1], [6, 5, 4]]);
    assert_eq!(frame.depth, vec![1.5, 0.0], "NaN is no measurement");
    assert_eq!(frame.intrinsics, relume::rgbd::Intrinsics { width: 2, height: 1, fx: 2.0, fy: 2.0, cx: 0.5, cy: 0.0 });

    // 16UC1 is millimetres; rows padded to a step of 8 bytes are read by step.
    let path = tiny_bag("mm", ("mono8", vec![9, 10]), ("16UC1", vec![0xd0, 0x07, 0, 0, 0xaa, 0xbb, 0xcc, 0xdd]), |d| {
        d.step = 8
    });
    let frame = Recording::open(&path, &RecordingOptions::default()).unwrap().frame(0).unwrap();
    assert_eq!(frame.color, vec![[9, 9, 9], [10, 10, 10]]);
    assert_eq!(frame.depth, vec![2.0, 0.0]);
}

#[test]
fn mcap_errors_name_the_record_and_field() {
    let open_err =
        |path: &Path, options: &RecordingOptions| Recording::open(path, options).map(|_| ()).unwrap_err().to_string();
    let rgb = ("rgb8", vec![0; 6]);
    let path = tiny_bag("short", rgb.clone(), ("16UC1", vec![0; 3]), |_| {});
    assert_eq!(
        open_err(&path, &RecordingOptions::default()),
        "tiny.mcap: /cam/depth/image_raw message 0 (sensor_msgs/msg/Image): field `data`: 3 bytes, fewer than the 4 of 1 rows of 4 bytes"
    );
    let path = tiny_bag("encoding", rgb.clone(), ("rgb8", vec![0; 6]), |_| {});
    let error = open_err(&path, &RecordingOptions::default());
    assert!(error.contains("field `encoding`: `rgb8` is not a depth encoding"), "{error}");
    let path = tiny_bag("size", rgb.clone(), ("16UC1", vec![0; 6]), |d| {
        d.width = 3;
        d.step = 6;
    });
    let error = open_err(&path, &RecordingOptions::default());
    assert!(error.ends_with("image is 3x1, intrinsics say 2x1"), "{error}");

    let path = tiny_bag("topics", rgb, ("16UC1", vec![0; 4]), |_| {});
    let topics = |depth: &str| RecordingOptions {
        mcap: McapTopics { depth: Some(depth.to_owned()), ..Default::default() },
        ..Default::default()
    };
    let error = open_err(&path, &topics("/nope"));
    assert!(error.starts_with("tiny.mcap: topics: --depth-topic `/nope` is not in the file"), "{error}");
    let error = open_err(&path, &topics("/cam/camera_info"));
    assert!(error.contains("has schema `sensor_msgs/msg/CameraInfo`, not sensor_msgs/msg/Image"), "{error}");

    let garbage = scratch("mcap_garbage").join("garbage.mcap");
    std::fs::write(&garbage, b"\x89MCAP0\r\nnot really").unwrap();
    let error = open_err(&garbage, &RecordingOptions::default());
    assert!(error.starts_with("garbage.mcap: file: not a valid MCAP file"), "{error}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Arbitrary bytes, and single-byte edits of a valid bag, are an error or a recording
    /// whose frames decode: never a panic.
    #[test]
    fn mcap_reader_never_panics(edits in proptest::collection::vec((any::<proptest::sample::Index>(), any::<u8>()), 0..8),
                                noise in proptest::collection::vec(any::<u8>(), 0..256)) {
        let dir = scratch("mcap_fuzz");
        let bytes = std::fs::read(tiny_bag("fuzz_source", ("rgb8", vec![1; 6]), ("16UC1", vec![2; 4]), |_| {})).unwrap();
        let mut mutated = bytes.clone();
        for (index, value) in &edits {
            let at = index.index(mutated.len());
            mutated[at] = *value;
        }
        for (name, data) in [("mutated.mcap", mutated), ("noise.mcap", noise)] {
            let path = dir.join(name);
            std::fs::write(&path, data).unwrap();
            if let Ok(recording) = Recording::open(&path, &RecordingOptions::default()) {
                for frame in recording.frames() {
                    let _ = frame;
                }
            }
        }
        // CDR decoding of arbitrary bytes as each message type.
        let _ = msg::decode::<msg::Image>(&bytes[..bytes.len().min(64)]);
        let _ = msg::decode::<msg::CameraInfo>(&bytes);
        let _ = msg::decode::<msg::TfMessage>(&bytes);
    }
}

/// The ROS 2 bag that the reference implementation's Python writer made of the first 8 TUM
/// frames (`tools/make_ros2_mcap.py`; its SOURCE.md says how): RealSense topic names, `16UC1`
/// millimetres, camera info, and the pose as `map -> odom -> base_link` on `/tf` below
/// `base_link -> camera_link -> camera_color_frame -> camera_color_optical_frame` on `/tf_static`.
const ROS2_BAG: &str = "recordings/tum_fr1_xyz_ros2/tum_fr1_xyz_ros2.mcap";

/// The ground truth of the TUM folder through the bag's chain of frames, as its SOURCE.md and
/// `tools/make_ros2_mcap.py` state it (written out here, not read from the bag): `map -> odom`
/// (constant) and the static `base_link -> camera_color_optical_frame`. `odom -> base_link` at
/// each ground-truth sample is `odom_from_map * sample * optical_from_base`; at a frame's stamp
/// it is interpolated between the two samples around it (tf2's lookup), then composed back.
fn ground_truth_through_the_chain(groundtruth: &[(f64, Vec<String>)], t: f64) -> DAffine3 {
    let placement = |t: [f64; 3], q: [f64; 4]| {
        DAffine3::from_rotation_translation(DQuat::from_array(q).normalize(), DVec3::from_array(t))
    };
    let about = |axis: DVec3, degrees: f64| DQuat::from_axis_angle(axis, degrees.to_radians()).to_array();
    let map_from_odom = placement([2.0, -1.0, 0.0], about(DVec3::Z, 0.5f64.to_degrees()));
    let base_from_optical = placement([0.20, 0.0, 0.45], about(DVec3::Y, 10.0))
        * placement([-0.0003, 0.0148, 0.0001], [0.0012, -0.0009, 0.0031, 1.0])
        * placement([0.0; 3], [-0.5, 0.5, -0.5, 0.5]);
    let after = groundtruth.partition_point(|(s, _)| *s <= t);
    let odom_from_base = |(_, fields): &(f64, Vec<String>)| {
        let v: Vec<f64> = fields.iter().map(|f| f.parse().unwrap()).collect();
        map_from_odom.inverse() * placement([v[0], v[1], v[2]], [v[3], v[4], v[5], v[6]]) * base_from_optical.inverse()
    };
    let (a, b) = (&groundtruth[after - 1], &groundtruth[after]);
    let s = (t - a.0) / (b.0 - a.0);
    let (_, qa, ta) = odom_from_base(a).to_scale_rotation_translation();
    let (_, qb, tb) = odom_from_base(b).to_scale_rotation_translation();
    let odom_from_base = DAffine3::from_rotation_translation(qa.slerp(qb, s).normalize(), ta.lerp(tb, s));
    map_from_odom * odom_from_base * base_from_optical
}

/// Largest difference of two poses' matrix entries (rotation and translation, m).
fn pose_difference(a: DAffine3, b: DAffine3) -> f64 {
    let rotation = (a.matrix3 - b.matrix3).to_cols_array().iter().fold(0.0f64, |m, x| m.max(x.abs()));
    (a.translation - b.translation).abs().max_element().max(rotation)
}

/// Replayed with no options, it gives TUM's frames: the same stamps, the ground truth through
/// the chain within 1e-6, the colour pixels of the crop the camera info states, and the depth
/// of that crop in whole millimetres (`(raw + 2) / 5` of TUM's 5000 units per metre).
#[test]
fn ros2_bag_of_an_independent_writer_replays_the_tum_frames() {
    let bag = Recording::open(&fixture(ROS2_BAG), &RecordingOptions::default()).unwrap();
    let dir = fixture("recordings/tum_fr1_xyz");
    let tum = Recording::open(&dir, &RecordingOptions::default()).unwrap();
    assert_eq!(bag.layout(), Layout::Mcap);
    assert_eq!(bag.len(), 8, "every depth frame has a colour frame and a pose: {:?}", bag.stats());
    assert!(bag.has_groundtruth());
    assert_eq!(bag.depth_scale(), rosbag::ROS_DEPTH_SCALE);
    // The camera info is TUM's registered camera, cropped: the principal point moves by whole
    // pixels, the focal lengths stay.
    let (k, full) = (*bag.intrinsics(), *tum.intrinsics());
    assert_eq!((k.width, k.height, k.fx, k.fy), (320, 240, full.fx, full.fy));
    let (left, top) = (full.cx - k.cx, full.cy - k.cy);
    assert_eq!((left, top), (160.0, 120.0));
    let (left, top) = (left as usize, top as usize);
    let depth_files: BTreeMap<String, String> = tum_lines(&dir.join("depth.txt"))
        .into_iter()
        .map(|(t, fields)| (format!("{t:.6}"), fields[0].clone()))
        .collect();
    let groundtruth = tum_lines(&dir.join("groundtruth.txt"));

    let (mut through_chain, mut against_tum) = (0.0f64, 0.0f64);
    for i in 0..bag.len() {
        let (a, b) = (bag.frame(i).unwrap(), tum.frame(i).unwrap());
        assert_eq!(a.timestamp, b.timestamp, "frame {i}: stamps are TUM's to the nanosecond");
        through_chain = through_chain
            .max(pose_difference(a.camera_to_world, ground_truth_through_the_chain(&groundtruth, a.timestamp)));
        against_tum = against_tum.max(pose_difference(a.camera_to_world, b.camera_to_world));

        let source = image::open(dir.join(&depth_files[&format!("{:.6}", b.timestamp)])).unwrap().into_luma16();
        let (mut colour_differ, mut depth_differ) = (0, 0);
        for y in 0..k.height as usize {
            for x in 0..k.width as usize {
                let (p, q) = (y * k.width as usize + x, (y + top) * full.width as usize + x + left);
                colour_differ += usize::from(a.color[p] != b.color[q]);
                let raw = source.get_pixel((x + left) as u32, (y + top) as u32).0[0];
                let millimetres = (u32::from(raw) + 2) / 5;
                depth_differ += usize::from(a.depth[p] != millimetres as f32 / 1000.0);
            }
        }
        assert_eq!((colour_differ, depth_differ), (0, 0), "frame {i}: pixels that differ (colour, depth)");
    }
    eprintln!(
        "ROS 2 bag poses: {through_chain:.1e} from the ground truth through the chain, {against_tum:.1e} from the TUM folder's"
    );
    assert!(through_chain <= 1e-6, "poses differ from the ground truth through the chain by {through_chain:e}");
    // The TUM reader interpolates the optical frame's samples, the bag's reader base_link's,
    // 0.5 m away: between 10 ms samples of a turning camera the two paths part by about
    // 1e-6 m (lever arm times the square of the turn).
    assert!(against_tum <= 1e-5, "poses differ from the TUM folder's by {against_tum:e}");
}

/// A copy of the ROS 2 bag without the messages `drop` picks.
fn ros2_bag_without(name: &str, drop: impl Fn(&mcap::Message) -> bool) -> PathBuf {
    let bytes = std::fs::read(fixture(ROS2_BAG)).unwrap();
    let path = scratch(&format!("mcap_ros2_without_{name}")).join("bag.mcap");
    let mut writer = mcap::Writer::new(BufWriter::new(std::fs::File::create(&path).unwrap())).unwrap();
    let mut dropped = 0;
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        if drop(&message) {
            dropped += 1;
        } else {
            writer.write(&message).unwrap();
        }
    }
    writer.finish().unwrap();
    assert!(dropped > 0, "{name}: nothing left out");
    path
}

/// A ROS 2 bag that lacks a topic or a link of the chain is an error that names what is missing.
#[test]
fn ros2_bag_missing_a_topic_or_link_is_an_error_naming_it() {
    let open_err =
        |path: &Path| Recording::open(path, &RecordingOptions::default()).map(|_| ()).unwrap_err().to_string();
    let topic_is = |topic: &'static str| move |m: &mcap::Message| m.channel.topic == topic;

    let error = open_err(&ros2_bag_without("depth", topic_is("/camera/aligned_depth_to_color/image_raw")));
    assert!(error.starts_with("bag.mcap: topics: no depth topic"), "{error}");
    assert!(error.contains("\"/camera/color/image_raw\"") && error.contains("--depth-topic"), "{error}");

    let error = open_err(&ros2_bag_without("camera_info", topic_is("/camera/color/camera_info")));
    assert!(error.starts_with("bag.mcap: topics: no sensor_msgs/msg/CameraInfo topic"), "{error}");
    assert!(error.contains("--intrinsics"), "{error}");
    // Given the intrinsics, it reads.
    let options = RecordingOptions {
        intrinsics: Some(relume::rgbd::Intrinsics {
            width: 320,
            height: 240,
            fx: 525.0,
            fy: 525.0,
            cx: 159.5,
            cy: 119.5,
        }),
        ..Default::default()
    };
    let without_info = ros2_bag_without("camera_info_given", topic_is("/camera/color/camera_info"));
    assert_eq!(Recording::open(&without_info, &options).unwrap().len(), 8);

    let error = open_err(&ros2_bag_without("tf_static", topic_is("/tf_static")));
    assert!(
        error.starts_with(
            "bag.mcap: /tf and /tf_static: no transform places the depth image's frame `camera_color_optical_frame`"
        ),
        "{error}"
    );
    assert!(error.contains("no /tf_static") && error.contains("[\"base_link\", \"odom\"]"), "{error}");

    // odom -> base_link left out of /tf: the static chain stops at base_link, which nothing
    // places under map.
    let error = open_err(&ros2_bag_without("odom_link", |m| {
        m.channel.topic == "/tf"
            && msg::decode::<msg::TfMessage>(&m.data)
                .unwrap()
                .transforms
                .iter()
                .any(|t| t.child_frame_id == "base_link")
    }));
    assert!(error.contains("hangs from `base_link` by static links only (base_link -> camera_link -> camera_color_frame -> camera_color_optical_frame)"), "{error}");
    assert!(error.contains("rooted at [\"map\"]"), "{error}");

    // Without /tf at all the camera stands where /tf_static puts it: every pose the same.
    let still = Recording::open(&ros2_bag_without("tf", topic_is("/tf")), &RecordingOptions::default()).unwrap();
    assert_eq!(still.len(), 8);
    assert!(still.poses().iter().all(|p| *p == still.poses()[0]) && still.poses()[0] != DAffine3::IDENTITY);
}
