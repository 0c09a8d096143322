//! MCAP recordings: the TUM fixture re-packed as a ROS 2 bag (colour `rgb8` and depth `16UC1`
//! `sensor_msgs/msg/Image`, `CameraInfo`, the ground truth as `/tf` plus a static optical-frame
//! link on `/tf_static`) must read and replay exactly as the TUM folder does; malformed bags are
//! errors naming the record and field; arbitrary bytes never panic.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

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

/// `relume replay` of the bag writes the same images as that of the folder. The inputs are
/// equal bit for bit (the test above); what is left is the GPU's own run-to-run variation
/// (float atomics and reductions whose order is not fixed): irradiance changes within 1e-6 and
/// 8-bit pixels at most one level apart, on at most 0.5 % of the pixels.
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
    for (a, b) in mcap.irradiance_change.iter().zip(&tum.irradiance_change) {
        assert!((a - b).abs() <= 1e-6, "irradiance change {a} vs {b}");
    }
    for i in 0..4 {
        for kind in ["composited", "indirect"] {
            let file = format!("{kind}/{i:04}.png");
            let a = image::open(mcap_out.join(&file)).unwrap().into_rgb8();
            let b = image::open(tum_out.join(&file)).unwrap().into_rgb8();
            assert_eq!(a.dimensions(), b.dimensions());
            let mut differing = 0;
            for (p, q) in a.pixels().zip(b.pixels()) {
                let most = p.0.iter().zip(q.0).map(|(x, y)| x.abs_diff(y)).max().unwrap_or(0);
                assert!(most <= 1, "{file}: pixels {p:?} and {q:?} differ by {most} levels");
                differing += usize::from(most > 0);
            }
            assert!(differing * 200 <= (a.width() * a.height()) as usize, "{file}: {differing} pixels differ");
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
