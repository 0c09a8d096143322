#!/usr/bin/env python3
"""Repack the first frames of the bundled TUM recording as a ROS 2 bag (MCAP) written by an
independent writer: the reference implementation's own Python packages (`mcap`,
`mcap-ros2-support`; versions in tools/requirements.txt), not relume's code.

The layout is that of `ros2 bag record` on a robot carrying a RealSense camera:

- `/camera/color/image_raw`: sensor_msgs/msg/Image `rgb8`, the centre 320x240 of the TUM
  colour PNGs (pixels 160..480 x 120..360, copied as they are: the crop keeps the file small);
- `/camera/aligned_depth_to_color/image_raw`: sensor_msgs/msg/Image `16UC1` in millimetres,
  the same crop of the TUM depth PNGs (5000 units per metre) converted as
  mm = round(raw / 5) = (raw + 2) // 5 (raw / 5 is never halfway: no ties), 0 still no depth;
- `/camera/color/camera_info`: sensor_msgs/msg/CameraInfo with each colour image, TUM's
  registered intrinsics moved by the crop (fx = fy = 525, cx = 159.5, cy = 119.5), no
  distortion;
- `/tf_static`: tf2_msgs/msg/TFMessage, base_link -> camera_link -> camera_color_frame ->
  camera_color_optical_frame, and camera_link -> camera_depth_frame ->
  camera_depth_optical_frame (a branch the reader must not take);
- `/tf`: map -> odom at 10 Hz (a localiser's constant correction) and odom -> base_link at
  each ground-truth sample (100 Hz), chosen so that map -> camera_color_optical_frame is TUM's
  ground truth (the colour camera's optical frame in TUM's world).

Both images carry `header.frame_id: camera_color_optical_frame` and their TUM timestamps as
`header.stamp` (sec, nanosec taken from the decimal text, exact). Messages are written in
order of a receive time (log time) a little after their stamps, in zstd-compressed chunks, with
`ros2msg` schemas: the top-level definition, then each dependency after a line of 80 `=` and
`MSG: package/msg/Type`, as rosbag2 stores them.

Usage (from the repository root):

    python3 -m pip install -r tools/requirements.txt
    python3 tools/make_ros2_mcap.py --frames 6 \
        --out fixtures/recordings/tum_fr1_xyz_ros2/tum_fr1_xyz_ros2.mcap
"""

import argparse
import math
import os
import sys
from array import array

from mcap_ros2.writer import Writer
from PIL import Image

SOURCE = "fixtures/recordings/tum_fr1_xyz"
COLOUR_TOPIC = "/camera/color/image_raw"
DEPTH_TOPIC = "/camera/aligned_depth_to_color/image_raw"
INFO_TOPIC = "/camera/color/camera_info"
OPTICAL_FRAME = "camera_color_optical_frame"

# The window of the 640x480 TUM frames kept: left, top, width, height.
CROP = (160, 120, 320, 240)
# TUM's registered depth intrinsics (fixtures/recordings/tum_fr1_xyz/SOURCE.md), moved by the
# crop.
FX, FY, CX, CY = 525.0, 525.0, 319.5 - CROP[0], 239.5 - CROP[1]
CROP_BOX = (CROP[0], CROP[1], CROP[0] + CROP[2], CROP[1] + CROP[3])
# TUM depth units per metre.
TUM_DEPTH_SCALE = 5000

# ros2msg definitions (ROS 2 Humble's fields, comments left out).
DEFINITIONS = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "sensor_msgs/msg/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data\n"
    ),
    "sensor_msgs/msg/RegionOfInterest": (
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
    ),
    "sensor_msgs/msg/CameraInfo": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
        "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
        "uint32 binning_y\nRegionOfInterest roi\n"
    ),
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/msg/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"
    ),
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
}


def full_name(package, field_type):
    """`pkg/msg/Type` of a field type written `pkg/Type` or `Type` (same package)."""
    base = field_type.split("[")[0]
    parts = base.split("/")
    name = f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else f"{package}/msg/{base}"
    return name if name in DEFINITIONS else None


def complete_definition(name):
    """The definition of `name` followed by those of its dependencies, depth first."""
    order = []

    def visit(type_name):
        package = type_name.split("/")[0]
        for line in DEFINITIONS[type_name].splitlines():
            dependency = full_name(package, line.split()[0])
            if dependency and dependency not in order:
                order.append(dependency)
                visit(dependency)

    visit(name)
    text = DEFINITIONS[name]
    for dependency in order:
        text += "=" * 80 + f"\nMSG: {dependency}\n" + DEFINITIONS[dependency]
    return text


# Rigid transforms as (translation, quaternion (x, y, z, w)), parent-to-child placement.
def q_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def q_normalised(q):
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


def q_rotate(q, v):
    x, y, z, _ = q_mul(q_mul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


def compose(a, b):
    """a * b: b's placement expressed in a's parent frame."""
    (ta, qa), (tb, qb) = a, b
    r = q_rotate(qa, tb)
    return ((ta[0] + r[0], ta[1] + r[1], ta[2] + r[2]), q_normalised(q_mul(qa, qb)))


def inverse(a):
    t, q = a
    qi = (-q[0], -q[1], -q[2], q[3])
    r = q_rotate(qi, t)
    return ((-r[0], -r[1], -r[2]), qi)


def about(axis, angle):
    s = math.sin(angle / 2)
    return q_normalised((axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2)))


# The static chain, as a RealSense driver and a robot description publish it: the camera on a
# mast, pitched down 10 degrees; the colour sensor 15 mm beside the depth sensor, slightly
# rotated (factory extrinsics); optical axes (x right, y down, z forward) from the body's.
OPTICAL = (-0.5, 0.5, -0.5, 0.5)
STATIC = [
    ("base_link", "camera_link", ((0.20, 0.0, 0.45), about((0.0, 1.0, 0.0), math.radians(10.0)))),
    ("camera_link", "camera_color_frame", ((-0.0003, 0.0148, 0.0001), q_normalised((0.0012, -0.0009, 0.0031, 1.0)))),
    ("camera_color_frame", OPTICAL_FRAME, ((0.0, 0.0, 0.0), OPTICAL)),
    ("camera_link", "camera_depth_frame", ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))),
    ("camera_depth_frame", "camera_depth_optical_frame", ((0.0, 0.0, 0.0), OPTICAL)),
]
# map -> odom: the localiser's correction, constant here.
MAP_TO_ODOM = ((2.0, -1.0, 0.0), about((0.0, 0.0, 1.0), 0.5))


def base_to_optical():
    links = {child: (parent, placement) for parent, child, placement in STATIC}
    chain, frame = [], OPTICAL_FRAME
    while frame != "base_link":
        parent, placement = links[frame]
        chain.append(placement)
        frame = parent
    result = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    for placement in reversed(chain):
        result = compose(result, placement)
    return result


def stamp(text):
    """(sec, nanosec) of a decimal timestamp string, exact."""
    whole, _, fraction = text.partition(".")
    return int(whole), int((fraction + "000000000")[:9])


def nanoseconds(text):
    sec, nanosec = stamp(text)
    return sec * 1_000_000_000 + nanosec


def time_msg(ns):
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def tum_lines(name):
    with open(os.path.join(SOURCE, name)) as f:
        for line in f:
            if line.strip() and not line.startswith("#"):
                yield line.split()


def transform_msg(ns, parent, child, placement):
    (x, y, z), (qx, qy, qz, qw) = placement
    return {
        "header": {"stamp": time_msg(ns), "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {"x": x, "y": y, "z": z},
            "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
        },
    }


def image_msg(ns, width, height, encoding, bytes_per_pixel, data):
    return {
        "header": {"stamp": time_msg(ns), "frame_id": OPTICAL_FRAME},
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": width * bytes_per_pixel,
        "data": data,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=6, help="depth frames to repack (from the first)")
    parser.add_argument("--out", required=True, help="the .mcap file to write")
    args = parser.parse_args()

    depth_frames = list(tum_lines("depth.txt"))[: args.frames]
    first, last = nanoseconds(depth_frames[0][0]), nanoseconds(depth_frames[-1][0])
    margin = 100_000_000  # 0.1 s of transforms and colour around the depth frames
    colour_frames = [f for f in tum_lines("rgb.txt") if first - 20_000_000 <= nanoseconds(f[0]) <= last + 20_000_000]

    messages = []  # (log time ns, topic, type, message)
    latency = {"image": 8_000_000, "tf": 1_000_000}

    start = first - margin
    static = [transform_msg(start, parent, child, placement) for parent, child, placement in STATIC]
    messages.append((start, "/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": static}))

    odom_to_map = inverse(MAP_TO_ODOM)
    optical_to_base = inverse(base_to_optical())
    for t, tx, ty, tz, qx, qy, qz, qw in tum_lines("groundtruth.txt"):
        ns = nanoseconds(t)
        if not first - margin <= ns <= last + margin:
            continue
        world_to_optical = (
            (float(tx), float(ty), float(tz)),
            q_normalised((float(qx), float(qy), float(qz), float(qw))),
        )
        odom_to_base = compose(compose(odom_to_map, world_to_optical), optical_to_base)
        tf = {"transforms": [transform_msg(ns, "odom", "base_link", odom_to_base)]}
        messages.append((ns + latency["tf"], "/tf", "tf2_msgs/msg/TFMessage", tf))
    period = 100_000_000  # 10 Hz
    for ns in range(start // period * period, last + margin + period, period):
        tf = {"transforms": [transform_msg(ns, "map", "odom", MAP_TO_ODOM)]}
        messages.append((ns + latency["tf"], "/tf", "tf2_msgs/msg/TFMessage", tf))

    for t, path in colour_frames:
        ns = nanoseconds(t)
        rgb = Image.open(os.path.join(SOURCE, path)).convert("RGB").crop(CROP_BOX)
        width, height = rgb.size
        messages.append(
            (ns + latency["image"], COLOUR_TOPIC, "sensor_msgs/msg/Image", image_msg(ns, width, height, "rgb8", 3, rgb.tobytes()))
        )
        info = {
            "header": {"stamp": time_msg(ns), "frame_id": OPTICAL_FRAME},
            "height": height,
            "width": width,
            "distortion_model": "plumb_bob",
            "d": [0.0] * 5,
            "k": [FX, 0.0, CX, 0.0, FY, CY, 0.0, 0.0, 1.0],
            "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "p": [FX, 0.0, CX, 0.0, 0.0, FY, CY, 0.0, 0.0, 0.0, 1.0, 0.0],
            "binning_x": 0,
            "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
        }
        messages.append((ns + latency["image"], INFO_TOPIC, "sensor_msgs/msg/CameraInfo", info))

    for t, path in depth_frames:
        ns = nanoseconds(t)
        png = Image.open(os.path.join(SOURCE, path))
        if png.mode != "I;16":
            raise SystemExit(f"{path}: mode {png.mode}, expected 16-bit greyscale (I;16)")
        png = png.crop(CROP_BOX)
        width, height = png.size
        raw = array("H")
        raw.frombytes(png.tobytes())  # I;16 is little-endian
        if sys.byteorder != "little":
            raw.byteswap()
        scale = TUM_DEPTH_SCALE // 1000
        millimetres = array("H", ((value + scale // 2) // scale for value in raw))
        if sys.byteorder != "little":
            millimetres.byteswap()
        messages.append(
            (ns + latency["image"], DEPTH_TOPIC, "sensor_msgs/msg/Image", image_msg(ns, width, height, "16UC1", 2, millimetres.tobytes()))
        )

    # /tf_static is latched (transient local): the recorder gets it as it subscribes, first.
    earliest = min(m[0] for m in messages)
    messages = [(earliest - 1_000_000, *m[1:]) if m[1] == "/tf_static" else m for m in messages]
    messages.sort(key=lambda m: m[0])
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "wb") as f:
        writer = Writer(f)
        schemas = {name: writer.register_msgdef(name, complete_definition(name)) for name in sorted({m[2] for m in messages})}
        sequence = {}
        for log_time, topic, type_name, message in messages:
            sequence[topic] = sequence.get(topic, 0) + 1
            writer.write_message(topic, schemas[type_name], message, log_time=log_time, publish_time=log_time, sequence=sequence[topic])
        writer.finish()
    counts = {}
    for _, topic, _, _ in messages:
        counts[topic] = counts.get(topic, 0) + 1
    print(f"{args.out}: {os.path.getsize(args.out)} bytes; messages per topic: {counts}")


if __name__ == "__main__":
    main()
