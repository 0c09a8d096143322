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

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use self::images::{ImagePayload, check_size, image_payload};
use self::topics::{ChannelInfo, choose_topics};
use self::transforms::{PoseSource, Transforms};
use super::Intrinsics;
use super::poses::PoseSample;
use super::reader::{
    Associated, Layout, Parts, RecordingError, RecordingOptions, associate, check_depth_scale, check_intrinsics,
    check_tolerance, io_error, value_error,
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

mod images;
pub mod msg;
mod topics;
mod transforms;

pub use images::FrameImages;
pub(super) use images::decode_frame;

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

    let colour: Vec<Arc<ImagePayload>> = colour.into_iter().map(|(_, image)| Arc::new(image)).collect();
    let pose_at = |t| pose_source.at(&camera_frame, t, tolerance);
    let images = |depth, c: usize| FrameImages { colour: colour[c].clone(), depth: Arc::new(depth) };
    let Associated { timestamps, poses, frames, stats } =
        associate(file, depth.into_iter(), &colour_times, tolerance, pose_at, images)?;
    Ok(Parts {
        dir: file.to_path_buf(),
        intrinsics,
        depth_scale,
        has_groundtruth: !matches!(pose_source, PoseSource::None),
        timestamps,
        poses,
        frames,
        stats,
        layout: Layout::Mcap,
    })
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
