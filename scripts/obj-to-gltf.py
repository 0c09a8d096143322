#!/usr/bin/env python3
"""Converts an OBJ + MTL mesh to glTF 2.0 (.gltf with a .bin beside it, or one .glb), with only
the Python standard library, for relume's glTF fixtures.

    scripts/obj-to-gltf.py fixtures/meshes/cornell_box/CornellBox-Original.obj \
        fixtures/meshes/cornell_box_gltf/CornellBox-Original.gltf
    scripts/obj-to-gltf.py fixtures/meshes/cornell_box/CornellBox-Original.obj \
        fixtures/meshes/cornell_box_gltf/CornellBox-Original.glb \
        --light-and-camera fixtures/scenes/cornell_bunny_small.json

What it keeps, so that relume loads the same triangles from both files:
- One node and one mesh per OBJ model as tobj splits them (a new model at `g`/`o` and at a
  `usemtl` that changes the material, once the current one has faces), named by the group, in
  file order. Polygons are fans from their first corner; each primitive's vertices are in
  order of first use, as tobj's single-index export has them. Positions are float32, indices
  uint32. No normals are written when the OBJ has none (relume computes them, as for the OBJ).
- Materials (relume's mapping inverted, docs/scene-format.md "glTF"): Kd and Ks become baseColorFactor =
  Kd / (1 - Ks), metallic 0, KHR_materials_specular (specularFactor 0 when Ks = 0, else
  specularColorFactor = Ks / 0.04), roughnessFactor from Ns; so relume's rho_d, rho_s and
  exponent come back as Kd, Ks and Ns (up to float rounding). Emission (Ke) is dropped: relume
  ignores it in both formats.
- With --light-and-camera SCENE.json: that scene's spot light as a KHR_lights_punctual spot
  light (intensity in candela = W/sr x 683) and its camera as a perspective camera node.
"""

import argparse
import json
import math
import os
import struct
import sys


def parse_mtl(path):
    materials, current = {}, None
    with open(path, encoding="utf-8") as f:
        for raw in f:
            words = raw.split("#", 1)[0].split()
            if not words:
                continue
            if words[0] == "newmtl":
                current = " ".join(words[1:])
                materials[current] = {"Kd": [0.5, 0.5, 0.5], "Ks": [0.0, 0.0, 0.0], "Ns": 1.0}
            elif current is not None and words[0] in ("Kd", "Ks"):
                materials[current][words[0]] = [float(x) for x in words[1:4]]
            elif current is not None and words[0] == "Ns":
                materials[current]["Ns"] = float(words[1])
    return materials


def parse_obj(path):
    """Models as tobj splits them: [(name, material or None, [polygon of (v, vt, vn) triples])]."""
    positions, models, mtllibs = [], [], []
    name, material, faces = "unnamed_object", None, []

    def flush():
        nonlocal faces
        if faces:
            models.append((name, material, faces))
            faces = []

    with open(path, encoding="utf-8") as f:
        for raw in f:
            line = raw.rstrip("\r\n")
            words = line.split()
            if not words:
                continue
            key = words[0]
            if key == "v":
                positions.append([float(x) for x in words[1:4]])
            elif key in ("vt", "vn"):
                sys.exit(f"{path}: `{key}` is not supported by this converter (the fixtures have none)")
            elif key == "f":
                polygon = []
                for corner in words[1:]:
                    index = int(corner.split("/")[0])
                    polygon.append(index - 1 if index > 0 else len(positions) + index)
                faces.append(polygon)
            elif key in ("g", "o"):
                flush()
                name = line[1:].strip() or "unnamed_object"
            elif key == "usemtl":
                new = line.split(None, 1)[1].strip()
                if new != material:
                    flush()
                material = new
            elif key == "mtllib":
                mtllibs.append(line.split(None, 1)[1].strip())
    flush()
    return positions, models, mtllibs


def gltf_material(name, mtl):
    kd, ks, ns = mtl["Kd"], mtl["Ks"], mtl["Ns"]
    base = [min(d / (1.0 - s), 1.0) if s < 1.0 else 0.0 for d, s in zip(kd, ks)]
    # relume: k = (2 / alpha^2 - 2) / 4 with alpha = roughness^2, so alpha^2 = 2 / (4k + 2).
    roughness = (2.0 / (4.0 * ns + 2.0)) ** 0.25
    specular = {"specularFactor": 0.0} if max(ks) == 0 else {"specularColorFactor": [s / 0.04 for s in ks]}
    return {
        "name": name,
        "pbrMetallicRoughness": {"baseColorFactor": base + [1.0], "metallicFactor": 0.0, "roughnessFactor": roughness},
        "extensions": {"KHR_materials_specular": specular},
    }


def normalize(v):
    length = math.sqrt(sum(x * x for x in v))
    return [x / length for x in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def look_rotation(forward, up):
    """Unit quaternion [x, y, z, w] turning -Z to `forward` with +Y towards `up`."""
    z = normalize([-c for c in forward])
    x = normalize(cross(up, z))
    y = cross(z, x)
    m00, m11, m22 = x[0], y[1], z[2]
    trace = m00 + m11 + m22
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [(y[2] - z[1]) / s, (z[0] - x[2]) / s, (x[1] - y[0]) / s, 0.25 * s]
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = [0.25 * s, (y[0] + x[1]) / s, (z[0] + x[2]) / s, (y[2] - z[1]) / s]
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = [(y[0] + x[1]) / s, 0.25 * s, (z[1] + y[2]) / s, (z[0] - x[2]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = [(z[0] + x[2]) / s, (z[1] + y[2]) / s, 0.25 * s, (x[1] - y[0]) / s]
    return normalize(q)


def convert(obj_path, out_path, scene_path):
    positions, models, mtllibs = parse_obj(obj_path)
    mtl = {}
    for lib in mtllibs:
        mtl.update(parse_mtl(os.path.join(os.path.dirname(obj_path), lib)))
    binary = bytearray()
    doc = {
        "asset": {"version": "2.0", "generator": "relume scripts/obj-to-gltf.py from " + os.path.basename(obj_path)},
        "scene": 0,
        "scenes": [{"nodes": []}],
        "nodes": [],
        "meshes": [],
        "materials": [],
        "accessors": [],
        "bufferViews": [],
        "extensionsUsed": ["KHR_materials_specular"],
    }
    material_index = {}

    def view(data, target):
        offset = len(binary)
        binary.extend(data)
        while len(binary) % 4:
            binary.append(0)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": offset, "byteLength": len(data), "target": target})
        return len(doc["bufferViews"]) - 1

    for name, material, polygons in models:
        remap, vertices, indices = {}, [], []
        for polygon in polygons:
            for i in range(1, len(polygon) - 1):
                for corner in (polygon[0], polygon[i], polygon[i + 1]):
                    if corner not in remap:
                        remap[corner] = len(vertices)
                        vertices.append(positions[corner])
                    indices.append(remap[corner])
        packed = struct.pack("<%df" % (3 * len(vertices)), *[c for v in vertices for c in v])
        # Bounds of the float32 values, as the spec requires for POSITION.
        stored = [struct.unpack("<3f", packed[12 * i : 12 * i + 12]) for i in range(len(vertices))]
        doc["accessors"].append({
            "bufferView": view(packed, 34962),
            "componentType": 5126,
            "count": len(vertices),
            "type": "VEC3",
            "min": [min(v[k] for v in stored) for k in range(3)],
            "max": [max(v[k] for v in stored) for k in range(3)],
        })
        primitive = {"attributes": {"POSITION": len(doc["accessors"]) - 1}, "mode": 4}
        doc["accessors"].append({
            "bufferView": view(struct.pack("<%dI" % len(indices), *indices), 34963),
            "componentType": 5125,
            "count": len(indices),
            "type": "SCALAR",
        })
        primitive["indices"] = len(doc["accessors"]) - 1
        if material is not None and material in mtl:
            if material not in material_index:
                material_index[material] = len(doc["materials"])
                doc["materials"].append(gltf_material(material, mtl[material]))
            primitive["material"] = material_index[material]
        doc["meshes"].append({"name": name, "primitives": [primitive]})
        doc["nodes"].append({"name": name, "mesh": len(doc["meshes"]) - 1})
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)

    if scene_path:
        with open(scene_path, encoding="utf-8") as f:
            scene = json.load(f)
        light, camera = scene["light"], scene["camera"]
        peak = max(light["intensity"])
        doc["extensionsUsed"].append("KHR_lights_punctual")
        doc["extensions"] = {"KHR_lights_punctual": {"lights": [{
            "name": "spot",
            "type": "spot",
            "color": [c / peak for c in light["intensity"]],
            "intensity": peak * 683.0,
            "spot": {
                "innerConeAngle": math.radians(light["inner_angle_deg"]),
                "outerConeAngle": math.radians(light["outer_angle_deg"]),
            },
        }]}}
        doc["nodes"].append({
            "name": "spot_light",
            "translation": light["position"],
            "rotation": look_rotation(light["direction"], [0.0, 1.0, 0.0]),
            "extensions": {"KHR_lights_punctual": {"light": 0}},
        })
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)
        forward = [t - p for t, p in zip(camera["target"], camera["position"])]
        doc["cameras"] = [{"name": "camera", "type": "perspective", "perspective": {
            "yfov": math.radians(camera["fov_y_deg"]),
            "aspectRatio": camera["width"] / camera["height"],
            "znear": 0.01,
        }}]
        doc["nodes"].append({
            "name": "camera",
            "translation": camera["position"],
            "rotation": look_rotation(forward, camera.get("up", [0.0, 1.0, 0.0])),
            "camera": 0,
        })
        doc["scenes"][0]["nodes"].append(len(doc["nodes"]) - 1)

    os.makedirs(os.path.dirname(out_path) or ".", exist_ok=True)
    if out_path.endswith(".glb"):
        doc["buffers"] = [{"byteLength": len(binary)}]
        text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
        text += b" " * (-len(text) % 4)
        total = 12 + 8 + len(text) + 8 + len(binary)
        with open(out_path, "wb") as f:
            f.write(struct.pack("<4sII", b"glTF", 2, total))
            f.write(struct.pack("<I4s", len(text), b"JSON") + text)
            f.write(struct.pack("<I4s", len(binary), b"BIN\0") + bytes(binary))
    else:
        bin_name = os.path.splitext(os.path.basename(out_path))[0] + ".bin"
        doc["buffers"] = [{"byteLength": len(binary), "uri": bin_name}]
        with open(os.path.join(os.path.dirname(out_path), bin_name), "wb") as f:
            f.write(binary)
        with open(out_path, "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=1)
            f.write("\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("obj")
    parser.add_argument("out", help="a .gltf (with a .bin beside it) or a .glb")
    parser.add_argument("--light-and-camera", metavar="SCENE_JSON", help="add this relume scene's spot light and camera")
    args = parser.parse_args()
    convert(args.obj, args.out, args.light_and_camera)


if __name__ == "__main__":
    main()
