//! ROS 2 message types as CDR lays them out (field order and types of the `.msg` files).

use std::borrow::Cow;

use byteorder::LittleEndian;
use serde::{Deserialize, Serialize};
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
            return Err(format!("encapsulation {:02x} {:02x} is not plain CDR (00 00 or 00 01)", header[0], header[1]));
        }
    };
    decoded.map(|(value, _)| value).map_err(|e| format!("cannot decode CDR: {e}"))
}
