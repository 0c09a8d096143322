//! MCAP recordings (Foxglove; ROS 2's default bag format) of ROS 2 messages, CDR-encoded
//! (docs/rgbd.md "Recording layouts"), read with the `mcap` crate and decoded with
//! `cdr-encoding`.
//!
//! What is read:
//!
//! - colour: `sensor_msgs/msg/Image`, encoding `rgb8`, `bgr8`, `rgba8`, `bgra8` or `mono8`;
//! - depth: `sensor_msgs/msg/Image`, `16UC1` / `mono16` (millimetres: [`ROS_DEPTH_SCALE`] units
//!   per metre unless the options give a depth scale; 0 = none) or `32FC1` (metres; NaN = none),
//!   registered to colour (same size as the camera info);
//! - intrinsics: the first `sensor_msgs/msg/CameraInfo` message (`width`, `height`, `k` row-major)
//!   on its topic; without one, the options' intrinsics, else an error (a bag's images need not
//!   be TUM's);
//! - poses: `geometry_msgs/msg/PoseStamped` on a pose topic (the pose of the depth image's
//!   optical frame), or else the `tf2_msgs/msg/TFMessage` transforms of `/tf` and `/tf_static`,
//!   composed from the root of the tree down to the depth image's `header.frame_id` (for
//!   example `map -> odom -> base_link` on `/tf`, then `base_link -> camera_link ->
//!   camera_color_frame -> camera_color_optical_frame` on `/tf_static`), each moving link
//!   interpolated as tf2 does; without either, every pose is the identity. A frame that no
//!   transform places, or a static chain that stops short of the frames `/tf` moves, is an
//!   error naming the frames.
//!
//! Topics come from [`McapTopics`] or, by default: the depth topic is the one `Image` topic whose
//! name contains `depth`, the colour topic the one other `Image` topic, the camera info the
//! `camera_info` beside the depth topic (else the one `CameraInfo` topic), the pose topic the one
//! `PoseStamped` topic. A choice that is ambiguous is an error listing the candidates.
//!
//! Frames are stamped with the depth image's `header.stamp` and associated as TUM's are: each
//! depth image with the colour image of nearest stamp within the tolerance, each pose
//! interpolated at the depth stamp.
//!
//! The file (at most [`MAX_MCAP_BYTES`]) is streamed twice (channels, then messages), each
//! record at most [`MAX_MCAP_RECORD_BYTES`]; the image payloads stay in memory, at most
//! [`MAX_MCAP_IMAGE_BYTES`], and are converted when a frame is asked for. Errors name the
//! file, the record (topic, type, index on the topic) and the field.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use byteorder::LittleEndian;
use glam::DAffine3;
use serde::{Deserialize, Serialize};

use super::Intrinsics;
use super::poses::{PoseSample, interpolate_pose, nearest};
use super::reader::{
    AssociationStats, Layout, Parts, RecordingError, RecordingOptions, check_depth_scale, check_intrinsics,
    check_tolerance, io_error, value_error, warn_skipped,
};

/// ROS's depth scale for `16UC1` depth (REP 118: millimetres): units per metre.
pub const ROS_DEPTH_SCALE: f32 = 1000.0;
/// Largest MCAP file read, bytes.
pub const MAX_MCAP_BYTES: u64 = 1 << 30;
/// Largest record (after decompression) of an MCAP file, bytes: bounds what a corrupt length
/// field can make the reader allocate (a 4K RGB image is 25 MB).
pub const MAX_MCAP_RECORD_BYTES: usize = 256 << 20;
/// Most image bytes kept in memory for the frames of one MCAP recording.
pub const MAX_MCAP_IMAGE_BYTES: usize = 2 << 30;

pub const IMAGE: &str = "sensor_msgs/msg/Image";
pub const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
pub const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";
/// The topic of transforms valid at every time.
pub const TF_STATIC_TOPIC: &str = "/tf_static";
/// What an error about the transform tree names as its record.
const TF_RECORD: &str = "/tf and /tf_static";

pub use super::reader::McapTopics;

/// ROS 2 message types as CDR lays them out (field order and types of the `.msg` files).
pub mod msg {
    use super::*;

    /// `builtin_interfaces/msg/Time`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Time {
        pub sec: i32,
        pub nanosec: u32,
    }

    impl Time {
        /// Seconds.
        pub fn seconds(self) -> f64 {
            f64::from(self.sec) + f64::from(self.nanosec) / 1e9
        }

        /// The time of `seconds` to the nearest nanosecond.
        pub fn from_seconds(seconds: f64) -> Time {
            let sec = seconds.floor();
            let nanosec = ((seconds - sec) * 1e9).round();
            if nanosec >= 1e9 {
                Time { sec: sec as i32 + 1, nanosec: 0 }
            } else {
                Time { sec: sec as i32, nanosec: nanosec as u32 }
            }
        }
    }

    /// `std_msgs/msg/Header`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Header {
        pub stamp: Time,
        pub frame_id: String,
    }

    /// `sensor_msgs/msg/Image`.
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    pub struct Image<'a> {
        pub header: Header,
        pub height: u32,
        pub width: u32,
        pub encoding: String,
        pub is_bigendian: u8,
        /// Bytes per row.
        pub step: u32,
        #[serde(borrow)]
        pub data: Cow<'a, [u8]>,
    }

    /// `sensor_msgs/msg/RegionOfInterest`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct RegionOfInterest {
        pub x_offset: u32,
        pub y_offset: u32,
        pub height: u32,
        pub width: u32,
        pub do_rectify: bool,
    }

    /// `sensor_msgs/msg/CameraInfo`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct CameraInfo {
        pub header: Header,
        pub height: u32,
        pub width: u32,
        pub distortion_model: String,
        pub d: Vec<f64>,
        /// Row-major 3x3 `[fx 0 cx; 0 fy cy; 0 0 1]`.
        pub k: [f64; 9],
        pub r: [f64; 9],
        pub p: [f64; 12],
        pub binning_x: u32,
        pub binning_y: u32,
        pub roi: RegionOfInterest,
    }

    /// `geometry_msgs/msg/Vector3` and `Point`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Vector3 {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    /// `geometry_msgs/msg/Quaternion`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Quaternion {
        pub x: f64,
        pub y: f64,
        pub z: f64,
        pub w: f64,
    }

    /// `geometry_msgs/msg/Transform`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Transform {
        pub translation: Vector3,
        pub rotation: Quaternion,
    }

    /// `geometry_msgs/msg/TransformStamped`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TransformStamped {
        pub header: Header,
        pub child_frame_id: String,
        pub transform: Transform,
    }

    /// `tf2_msgs/msg/TFMessage`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TfMessage {
        pub transforms: Vec<TransformStamped>,
    }

    /// `geometry_msgs/msg/Pose` (`position` is a `Point`, laid out as `Vector3`).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Pose {
        pub position: Vector3,
        pub orientation: Quaternion,
    }

    /// `geometry_msgs/msg/PoseStamped`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct PoseStamped {
        pub header: Header,
        pub pose: Pose,
    }

    /// A message as ROS 2 stores it: the 4-byte CDR little-endian encapsulation header, then
    /// the CDR body.
    pub fn encode<T: Serialize>(message: &T) -> Result<Vec<u8>, cdr_encoding::Error> {
        let mut bytes = vec![0, 1, 0, 0];
        bytes.extend(cdr_encoding::to_vec::<T, LittleEndian>(message)?);
        Ok(bytes)
    }

    /// Decodes a message stored as [`encode`] writes it (little- or big-endian CDR).
    pub fn decode<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, String> {
        let (header, body) = bytes.split_at_checked(4).ok_or("shorter than the 4-byte CDR header")?;
        let decoded = match header[..2] {
            [0, 1] => cdr_encoding::from_bytes::<T, LittleEndian>(body),
            [0, 0] => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body),
            _ => {
                return Err(format!(
                    "encapsulation {:02x} {:02x} is not plain CDR (00 00 or 00 01)",
                    header[0], header[1]
                ));
            }
        };
        decoded.map(|(value, _)| value).map_err(|e| format!("cannot decode CDR: {e}"))
    }
}

/// The image payloads of one frame, as recorded (a colour image may serve two frames).
#[derive(Clone, Debug)]
pub struct FrameImages {
    colour: Arc<ImagePayload>,
    depth: Arc<ImagePayload>,
}

/// One `sensor_msgs/msg/Image` with the name of its record, its layout checked at open.
#[derive(Clone, Debug)]
struct ImagePayload {
    record: String,
    frame_id: String,
    width: u32,
    height: u32,
    encoding: String,
    is_bigendian: bool,
    step: usize,
    data: Vec<u8>,
    /// Depth units per metre (integer depth only).
    depth_scale: f32,
}

/// Pixel layouts read: bytes per pixel.
fn bytes_per_pixel(encoding: &str) -> Option<usize> {
    Some(match encoding {
        "mono8" => 1,
        "rgb8" | "bgr8" => 3,
        "rgba8" | "bgra8" | "32FC1" => 4,
        "16UC1" | "mono16" => 2,
        _ => return None,
    })
}

const COLOUR_ENCODINGS: [&str; 5] = ["rgb8", "bgr8", "rgba8", "bgra8", "mono8"];
const DEPTH_ENCODINGS: [&str; 3] = ["16UC1", "mono16", "32FC1"];

/// A channel of the file.
#[derive(Clone, Debug)]
struct ChannelInfo {
    topic: String,
    schema: String,
}

/// Reads the MCAP file `file`.
pub(super) fn open(file: &Path, options: &RecordingOptions) -> Result<Parts<Vec<FrameImages>>, RecordingError> {
    let tolerance = check_tolerance(options)?;
    let name = PathBuf::from(file.file_name().unwrap_or(file.as_os_str()));
    let record_error = |record: &str, message: String| RecordingError::Record {
        file: name.clone(),
        record: record.to_owned(),
        message,
    };
    let size = std::fs::metadata(file).map_err(|e| io_error(&name, e))?.len();
    if size > MAX_MCAP_BYTES {
        return Err(record_error(
            "file",
            format!("is {size} bytes, more than the {MAX_MCAP_BYTES} read (split it, e.g. `mcap filter`)"),
        ));
    }
    let stream_error = |e: mcap::McapError| record_error("file", format!("not a valid MCAP file: {e}"));
    let messages = || -> Result<_, RecordingError> {
        let reader = std::io::BufReader::new(std::fs::File::open(file).map_err(|e| io_error(&name, e))?);
        let options = mcap::sans_io::LinearReaderOptions::default().with_record_length_limit(MAX_MCAP_RECORD_BYTES);
        Ok(mcap::io::MessageReader::new_with_options(reader, options))
    };

    // Pass 1: the channels.
    let mut channels: BTreeMap<u16, ChannelInfo> = BTreeMap::new();
    for message in messages()? {
        let message = message.map_err(stream_error)?;
        channels.entry(message.channel.id).or_insert_with(|| ChannelInfo {
            topic: message.channel.topic.clone(),
            schema: message.channel.schema.as_ref().map_or_else(String::new, |s| s.name.clone()),
        });
    }
    let topics = choose_topics(&channels, &options.mcap).map_err(|message| record_error("topics", message))?;

    // Pass 2: the messages of the chosen topics.
    let depth_scale = match options.depth_scale {
        Some(scale) => {
            check_depth_scale(scale).map_err(|message| value_error("recording options", "depth_scale", message))?;
            scale
        }
        None => ROS_DEPTH_SCALE,
    };
    let mut colour = Vec::new();
    let mut depth = Vec::new();
    let mut camera_info: Option<(String, msg::CameraInfo)> = None;
    let mut poses = Vec::new();
    let mut transforms = Transforms::default();
    let mut counts: HashMap<u16, usize> = HashMap::new();
    let mut image_bytes = 0usize;
    for message in messages()? {
        let message = message.map_err(stream_error)?;
        let channel = &message.channel;
        let index = counts.entry(channel.id).or_default();
        let schema = channel.schema.as_ref().map_or("", |s| s.name.as_str());
        let record = format!("{} message {} ({schema})", channel.topic, *index);
        *index += 1;
        let wanted = channel.topic == topics.colour
            || channel.topic == topics.depth
            || topics.camera_info.as_deref() == Some(channel.topic.as_str())
            || topics.pose.as_deref() == Some(channel.topic.as_str())
            || (topics.pose.is_none() && schema == TF_MESSAGE);
        if !wanted {
            continue;
        }
        if channel.message_encoding != "cdr" {
            return Err(record_error(
                &record,
                format!("message encoding is `{}`, relume reads `cdr`", channel.message_encoding),
            ));
        }
        let data = &message.data[..];
        let fail = |message: String| record_error(&record, message);
        match schema {
            IMAGE => {
                let image: msg::Image = msg::decode(data).map_err(fail)?;
                let is_depth = channel.topic == topics.depth;
                let payload = image_payload(&record, image, is_depth, depth_scale).map_err(fail)?;
                image_bytes = image_bytes.saturating_add(payload.1.data.len());
                if image_bytes > MAX_MCAP_IMAGE_BYTES {
                    return Err(fail(format!(
                        "the images so far hold more than the {MAX_MCAP_IMAGE_BYTES} bytes kept in memory (split the file, e.g. `mcap filter`)"
                    )));
                }
                if is_depth { depth.push(payload) } else { colour.push(payload) }
            }
            CAMERA_INFO if camera_info.is_none() => {
                let info: msg::CameraInfo = msg::decode(data).map_err(fail)?;
                camera_info = Some((record.clone(), info));
            }
            CAMERA_INFO => {}
            POSE_STAMPED => {
                let pose: msg::PoseStamped = msg::decode(data).map_err(fail)?;
                let (p, q) = (pose.pose.position, pose.pose.orientation);
                let sample = PoseSample::new(pose.header.stamp.seconds(), [p.x, p.y, p.z], [q.x, q.y, q.z, q.w])
                    .map_err(|m| fail(format!("field `pose.orientation`: {m}")))?;
                poses.push(sample);
            }
            TF_MESSAGE => {
                let tf: msg::TfMessage = msg::decode(data).map_err(fail)?;
                let is_static = channel.topic == TF_STATIC_TOPIC;
                transforms.add(&tf, is_static).map_err(fail)?;
            }
            _ => return Err(fail(format!("topic has schema `{schema}`, not one relume reads here"))),
        }
    }

    let intrinsics = match &camera_info {
        Some((record, info)) => intrinsics_of(info)
            .map_err(|(field, message)| record_error(record, format!("field `{field}`: {message}")))?,
        None => {
            let Some(k) = options.intrinsics else {
                return Err(record_error(
                    "topics",
                    format!(
                        "no {CAMERA_INFO} topic, so the camera's intrinsics are unknown: record the camera's \
                         camera_info topic too, or give them with --intrinsics fx,fy,cx,cy"
                    ),
                ));
            };
            check_intrinsics(&k).map_err(|(field, message)| value_error("recording options", field, message))?;
            tracing::warn!("{}: no camera info; using the given intrinsics {k:?}", file.display());
            k
        }
    };
    for (_, image) in colour.iter().chain(&depth) {
        check_size(&name, image, &intrinsics)?;
    }
    let stamps = |images: &[(f64, ImagePayload)], what: &str| -> Result<Vec<f64>, RecordingError> {
        let times: Vec<f64> = images.iter().map(|(t, _)| *t).collect();
        if let Some(i) = (1..times.len()).find(|&i| times[i] <= times[i - 1]) {
            return Err(record_error(
                &images[i].1.record,
                format!(
                    "field `header.stamp`: {what} stamp {} is not after the previous image's {}",
                    times[i],
                    times[i - 1]
                ),
            ));
        }
        Ok(times)
    };
    let colour_times = stamps(&colour, "colour")?;
    stamps(&depth, "depth")?;

    let camera_frame = depth.first().map(|(_, image)| image.frame_id.clone()).unwrap_or_default();
    let pose_source = if topics.pose.is_some() {
        poses.sort_by(|a, b| a.timestamp.total_cmp(&b.timestamp));
        PoseSource::Samples(poses)
    } else if transforms.is_empty() {
        tracing::warn!("{}: no poses (no pose topic, no /tf); every frame gets the identity pose", file.display());
        PoseSource::None
    } else {
        let moves = transforms.check_frame(&camera_frame).map_err(|message| record_error(TF_RECORD, message))?;
        if !moves {
            tracing::warn!(
                "{}: no /tf transform moves the depth image's frame `{camera_frame}` (only /tf_static places it): \
                 every frame gets the same pose",
                file.display()
            );
        }
        PoseSource::Tf(transforms)
    };

    let mut stats = AssociationStats { depth_frames: depth.len(), colour_frames: colour.len(), ..Default::default() };
    let colour: Vec<Arc<ImagePayload>> = colour.into_iter().map(|(_, image)| Arc::new(image)).collect();
    let (mut timestamps, mut kept_poses, mut frames) = (Vec::new(), Vec::new(), Vec::new());
    let mut used_colour = HashSet::new();
    for (t, image) in depth {
        let Some(c) = nearest(&colour_times, t).filter(|&c| (colour_times[c] - t).abs() <= tolerance) else {
            stats.without_colour += 1;
            continue;
        };
        let Some(pose) = pose_source.at(&camera_frame, t, tolerance) else {
            stats.without_pose += 1;
            continue;
        };
        if !used_colour.insert(c) {
            stats.shared_colour += 1;
        }
        timestamps.push(t);
        kept_poses.push(pose);
        frames.push(FrameImages { colour: colour[c].clone(), depth: Arc::new(image) });
    }
    if timestamps.is_empty() {
        return Err(RecordingError::NoFrames { stats });
    }
    warn_skipped(file, &stats, tolerance);
    Ok(Parts {
        dir: file.to_path_buf(),
        intrinsics,
        depth_scale,
        has_groundtruth: !matches!(pose_source, PoseSource::None),
        timestamps,
        poses: kept_poses,
        frames,
        stats,
        layout: Layout::Mcap,
    })
}

/// The topics read: the options' or the defaults (module docs).
#[derive(Debug, PartialEq)]
struct Chosen {
    colour: String,
    depth: String,
    camera_info: Option<String>,
    pose: Option<String>,
}

fn choose_topics(channels: &BTreeMap<u16, ChannelInfo>, options: &McapTopics) -> Result<Chosen, String> {
    let of_schema = |schema: &str| -> Vec<&str> {
        let mut topics: Vec<&str> =
            channels.values().filter(|c| c.schema == schema).map(|c| c.topic.as_str()).collect();
        topics.dedup();
        topics
    };
    let images = of_schema(IMAGE);
    let given = |flag: &str, topic: &Option<String>, schema: &str| -> Result<Option<String>, String> {
        let Some(topic) = topic else { return Ok(None) };
        match channels.values().find(|c| &c.topic == topic) {
            Some(c) if c.schema == schema => Ok(Some(topic.clone())),
            Some(c) => Err(format!("{flag} `{topic}` has schema `{}`, not {schema}", c.schema)),
            None => Err(format!("{flag} `{topic}` is not in the file; its {schema} topics: {:?}", of_schema(schema))),
        }
    };
    let one = |what: &str, candidates: Vec<&str>, flag: &str| -> Result<String, String> {
        match candidates[..] {
            [topic] => Ok(topic.to_owned()),
            [] => Err(format!("no {what} topic (sensor_msgs/msg/Image topics: {images:?}); name it with {flag}")),
            _ => Err(format!("several {what} topics {candidates:?}; choose one with {flag}")),
        }
    };
    let depth = match given("--depth-topic", &options.depth, IMAGE)? {
        Some(topic) => topic,
        None => one("depth", images.iter().copied().filter(|t| t.contains("depth")).collect(), "--depth-topic")?,
    };
    let colour = match given("--colour-topic", &options.colour, IMAGE)? {
        Some(topic) => topic,
        None => one("colour", images.iter().copied().filter(|&t| t != depth).collect(), "--colour-topic")?,
    };
    let camera_info = match given("--camera-info-topic", &options.camera_info, CAMERA_INFO)? {
        Some(topic) => Some(topic),
        None => {
            let infos = of_schema(CAMERA_INFO);
            let beside = depth.rsplit_once('/').map(|(namespace, _)| format!("{namespace}/camera_info"));
            match (beside.filter(|b| infos.contains(&b.as_str())), &infos[..]) {
                (Some(topic), _) => Some(topic),
                (None, []) => None,
                (None, [topic]) => Some((*topic).to_owned()),
                (None, _) => {
                    return Err(format!("several camera info topics {infos:?}; choose one with --camera-info-topic"));
                }
            }
        }
    };
    let pose = match given("--pose-topic", &options.pose, POSE_STAMPED)? {
        Some(topic) => Some(topic),
        None => match of_schema(POSE_STAMPED)[..] {
            [] => None,
            [topic] => Some(topic.to_owned()),
            ref several => return Err(format!("several pose topics {several:?}; choose one with --pose-topic")),
        },
    };
    Ok(Chosen { colour, depth, camera_info, pose })
}

/// A decoded image's layout checked (`encoding` one relume reads, `step` and `data` long enough),
/// its pixels copied; with its stamp (s).
fn image_payload(
    record: &str,
    image: msg::Image,
    is_depth: bool,
    depth_scale: f32,
) -> Result<(f64, ImagePayload), String> {
    let encodings: &[&str] = if is_depth { &DEPTH_ENCODINGS } else { &COLOUR_ENCODINGS };
    if !encodings.contains(&image.encoding.as_str()) {
        let what = if is_depth { "depth" } else { "colour" };
        return Err(format!(
            "field `encoding`: `{}` is not a {what} encoding relume reads ({encodings:?})",
            image.encoding
        ));
    }
    let bpp =
        bytes_per_pixel(&image.encoding).ok_or_else(|| format!("field `encoding`: `{}` unknown", image.encoding))?;
    if image.width == 0 || image.height == 0 {
        return Err(format!("fields `width`, `height`: image is {}x{}", image.width, image.height));
    }
    let row = image.width as usize * bpp;
    let step = image.step as usize;
    if step < row {
        return Err(format!("field `step`: {step} bytes per row, fewer than width {} x {bpp} bytes", image.width));
    }
    let needed = step * (image.height as usize - 1) + row;
    if image.data.len() < needed {
        return Err(format!(
            "field `data`: {} bytes, fewer than the {needed} of {} rows of {step} bytes",
            image.data.len(),
            image.height
        ));
    }
    if image.is_bigendian > 1 {
        return Err(format!("field `is_bigendian`: must be 0 or 1, got {}", image.is_bigendian));
    }
    let stamp = image.header.stamp;
    if stamp.nanosec >= 1_000_000_000 {
        return Err(format!("field `header.stamp.nanosec`: {} is not below 1e9", stamp.nanosec));
    }
    Ok((
        stamp.seconds(),
        ImagePayload {
            record: record.to_owned(),
            frame_id: image.header.frame_id,
            width: image.width,
            height: image.height,
            encoding: image.encoding,
            is_bigendian: image.is_bigendian == 1,
            step,
            data: image.data.into_owned(),
            depth_scale,
        },
    ))
}

/// The pinhole intrinsics of a camera info: `k` row-major `[fx 0 cx; 0 fy cy; 0 0 1]`.
fn intrinsics_of(info: &msg::CameraInfo) -> Result<Intrinsics, (&'static str, String)> {
    let k = info.k;
    if [k[1], k[3], k[6], k[7]] != [0.0; 4] || k[8] != 1.0 {
        return Err(("k", format!("must be a pinhole matrix without skew [fx 0 cx 0 fy cy 0 0 1], got {k:?}")));
    }
    let intrinsics = Intrinsics {
        width: info.width,
        height: info.height,
        fx: k[0] as f32,
        fy: k[4] as f32,
        cx: k[2] as f32,
        cy: k[5] as f32,
    };
    check_intrinsics(&intrinsics)?;
    Ok(intrinsics)
}

/// The transforms of `/tf` and `/tf_static`: for each child frame, its parent and its samples
/// (parent-to-child placement, i.e. child-to-parent coordinates), or one static transform.
#[derive(Debug, Default)]
struct Transforms {
    edges: HashMap<String, Edge>,
}

#[derive(Debug)]
struct Edge {
    parent: String,
    samples: Vec<PoseSample>,
    is_static: bool,
}

impl Transforms {
    fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    fn add(&mut self, tf: &msg::TfMessage, is_static: bool) -> Result<(), String> {
        for (i, t) in tf.transforms.iter().enumerate() {
            let field = format!("transforms[{i}]");
            let (v, q) = (t.transform.translation, t.transform.rotation);
            let sample = PoseSample::new(t.header.stamp.seconds(), [v.x, v.y, v.z], [q.x, q.y, q.z, q.w])
                .map_err(|m| format!("field `{field}.transform.rotation`: {m}"))?;
            if !sample.translation.is_finite() {
                return Err(format!("field `{field}.transform.translation`: not finite"));
            }
            let edge = self.edges.entry(t.child_frame_id.clone()).or_insert_with(|| Edge {
                parent: t.header.frame_id.clone(),
                samples: Vec::new(),
                is_static,
            });
            if edge.parent != t.header.frame_id {
                return Err(format!(
                    "field `{field}.header.frame_id`: frame `{}` has parent `{}` here and `{}` before",
                    t.child_frame_id, t.header.frame_id, edge.parent
                ));
            }
            if is_static {
                edge.samples = vec![sample];
            } else if edge.samples.last().is_some_and(|last| last.timestamp >= sample.timestamp) {
                // Out of order or repeated: keep the samples sorted, later duplicates win.
                edge.samples.retain(|s| s.timestamp != sample.timestamp);
                let at = edge.samples.partition_point(|s| s.timestamp < sample.timestamp);
                edge.samples.insert(at, sample);
            } else {
                edge.samples.push(sample);
            }
        }
        Ok(())
    }

    /// The frames from `frame` up to the root of its tree (`frame` first), with whether a
    /// dynamic link lies on the way; `None` on a cycle.
    fn chain<'a>(&'a self, frame: &'a str) -> Option<(Vec<&'a str>, bool)> {
        let (mut chain, mut moves) = (vec![frame], false);
        for _ in 0..=self.edges.len() {
            let Some(edge) = self.edges.get(*chain.last()?) else { return Some((chain, moves)) };
            moves |= !edge.is_static;
            chain.push(&edge.parent);
        }
        None
    }

    /// Checks that `frame` is in the tree, that its chain to the root has no cycle, and, when
    /// `/tf` moves some frames, that the chain reaches one of them (a chain of static links
    /// that stops short of the moving ones means a link is missing from the recording).
    /// Returns whether a dynamic link lies on the chain.
    fn check_frame(&self, frame: &str) -> Result<bool, String> {
        if !self.edges.contains_key(frame) {
            let mut frames: Vec<&str> = self.edges.keys().map(String::as_str).collect();
            frames.sort_unstable();
            let hint = if self.edges.values().any(|e| e.is_static) {
                ""
            } else {
                " (the file has no /tf_static, where the camera's optical frames usually are: record it too)"
            };
            return Err(format!(
                "no transform places the depth image's frame `{frame}` (its header.frame_id){hint}; the transforms place {frames:?}"
            ));
        }
        let (chain, moves) =
            self.chain(frame).ok_or_else(|| format!("the transforms above frame `{frame}` form a cycle"))?;
        if !moves && self.edges.values().any(|e| !e.is_static) {
            let top = chain.last().copied().unwrap_or(frame);
            let mut moving_roots: Vec<&str> = self
                .edges
                .iter()
                .filter(|(_, edge)| !edge.is_static)
                .filter_map(|(child, _)| self.chain(child).and_then(|(up, _)| up.last().copied()))
                .collect();
            moving_roots.sort_unstable();
            moving_roots.dedup();
            let path: Vec<&str> = chain.iter().rev().copied().collect();
            return Err(format!(
                "the depth image's frame `{frame}` hangs from `{top}` by static links only ({}), and no transform \
                 places `{top}` in the tree that /tf moves (rooted at {moving_roots:?}): a link above `{top}` is \
                 missing",
                path.join(" -> ")
            ));
        }
        Ok(moves)
    }

    /// Root-to-`frame` placement at `t`: the chain of parent transforms composed, static ones
    /// as they are, dynamic ones as tf2 looks them up: interpolated between the link's two
    /// samples around `t` however far apart (a localiser may publish `map -> odom` at 1 Hz),
    /// the end sample just outside them; `None` when `t` lies further than `tolerance` outside
    /// a link's samples.
    fn at(&self, frame: &str, t: f64, tolerance: f64) -> Option<DAffine3> {
        let mut pose = DAffine3::IDENTITY;
        let mut current = frame;
        for _ in 0..=self.edges.len() {
            let Some(edge) = self.edges.get(current) else { return Some(pose) };
            let local = if edge.is_static {
                let s = edge.samples.first()?;
                DAffine3::from_rotation_translation(s.rotation, s.translation)
            } else {
                let inside = edge.samples.first().is_some_and(|s| s.timestamp <= t)
                    && edge.samples.last().is_some_and(|s| t <= s.timestamp);
                interpolate_pose(&edge.samples, t, if inside { f64::INFINITY } else { tolerance })?
            };
            pose = local * pose;
            current = &edge.parent;
        }
        None
    }
}

/// Where poses come from.
enum PoseSource {
    None,
    Samples(Vec<PoseSample>),
    Tf(Transforms),
}

impl PoseSource {
    fn at(&self, camera_frame: &str, t: f64, tolerance: f64) -> Option<DAffine3> {
        match self {
            PoseSource::None => Some(DAffine3::IDENTITY),
            PoseSource::Samples(samples) => interpolate_pose(samples, t, tolerance),
            PoseSource::Tf(transforms) => transforms.at(camera_frame, t, tolerance),
        }
    }
}

/// Colour (sRGB, row-major) and depth (m) of a frame's images, checked against `intrinsics`.
pub(super) fn decode_frame(
    file: &Path,
    images: &FrameImages,
    intrinsics: &Intrinsics,
) -> Result<(Vec<[u8; 3]>, Vec<f32>), RecordingError> {
    for image in [&images.colour, &images.depth] {
        check_size(file, image, intrinsics)?;
    }
    Ok((colour_pixels(&images.colour), depth_metres(&images.depth)))
}

/// The image's size against the intrinsics; the error names the file and the record.
fn check_size(file: &Path, image: &ImagePayload, intrinsics: &Intrinsics) -> Result<(), RecordingError> {
    if (image.width, image.height) == (intrinsics.width, intrinsics.height) {
        return Ok(());
    }
    Err(RecordingError::ImageSize {
        file: PathBuf::from(format!("{}: {}", file.display(), image.record)),
        width: image.width,
        height: image.height,
        expected_width: intrinsics.width,
        expected_height: intrinsics.height,
    })
}

/// The rows of an image, `step` apart, each `width * bpp` bytes (the layout was checked).
fn rows(image: &ImagePayload, bpp: usize) -> impl Iterator<Item = &[u8]> {
    let row = image.width as usize * bpp;
    (0..image.height as usize).map(move |y| &image.data[y * image.step..y * image.step + row])
}

fn colour_pixels(image: &ImagePayload) -> Vec<[u8; 3]> {
    let bpp = bytes_per_pixel(&image.encoding).unwrap_or(3);
    let mut pixels = Vec::with_capacity((image.width * image.height) as usize);
    for row in rows(image, bpp) {
        pixels.extend(row.chunks_exact(bpp).map(|p| match image.encoding.as_str() {
            "mono8" => [p[0]; 3],
            "bgr8" | "bgra8" => [p[2], p[1], p[0]],
            _ => [p[0], p[1], p[2]],
        }));
    }
    pixels
}

fn depth_metres(image: &ImagePayload) -> Vec<f32> {
    let float = image.encoding == "32FC1";
    let bpp = if float { 4 } else { 2 };
    let mut depth = Vec::with_capacity((image.width * image.height) as usize);
    for row in rows(image, bpp) {
        depth.extend(row.chunks_exact(bpp).map(|p| {
            if float {
                let bytes = [p[0], p[1], p[2], p[3]];
                let d = if image.is_bigendian { f32::from_be_bytes(bytes) } else { f32::from_le_bytes(bytes) };
                if d.is_finite() && d > 0.0 { d } else { 0.0 }
            } else {
                let raw = if image.is_bigendian {
                    u16::from_be_bytes([p[0], p[1]])
                } else {
                    u16::from_le_bytes([p[0], p[1]])
                };
                f32::from(raw) / image.depth_scale
            }
        }));
    }
    depth
}
