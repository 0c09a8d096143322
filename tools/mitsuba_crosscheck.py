#!/usr/bin/env python3
"""Independent cross-check of relume's exact reference with Mitsuba 3 (test-time tool).

Renders a relume scene file's one-bounce indirect light with Mitsuba 3's `path` integrator
(`max_depth` 3 minus `max_depth` 2: camera, one diffuse bounce, the light) and compares it with
relume's exact reference, the linear `indirect_exact.exr` that
`relume compare <scene> --reference exact --images DIR` writes. Prints one JSON object: the
relative RMSE with Mitsuba's own noise taken out, the same without the worst 1 % of pixels, the
mean ratio (summed luminance, relume over Mitsuba) and the noise.

Mitsuba's noise is measured, not assumed: the indirect image is rendered as two independent
halves (different seeds), and each pixel's variance of their mean is `(A - B)² / 4`.

Supported scenes: meshes without `transform` and with one diffuse `material`, one spot `light`
(relume's spot is Mitsuba's: linear falloff in angle from `inner_angle_deg` (beam_width) to
`outer_angle_deg` (cutoff_angle), `intensity` W/sr on the axis), camera `position`, `target`,
`up`, `fov_y_deg`. Anything else is an error naming it.

    pip install mitsuba   # llvm_ad_rgb needs libLLVM >= 16 (apt-get install libllvm16)
    python3 tools/mitsuba_crosscheck.py fixtures/scenes/sponza_gallery.json \
        --relume out/gallery/indirect_exact.exr --spp 1024 --out out/gallery
See docs/measurements/independent-renderer.md.
"""
import argparse
import json
import os
import sys

import numpy as np


def fail(message):
    print(f"mitsuba_crosscheck: {message}", file=sys.stderr)
    sys.exit(2)


def load_obj(mi, path, albedo, name):
    """The OBJ at `path` as a Mitsuba mesh, read here rather than by Mitsuba's loader (which
    refuses a zero normal): triangles (polygons fanned), one vertex per face corner with the
    file's vertex normal, normalised, a zero or non-finite one replaced by the face's normal, as
    relume loads it (`scene::normals`)."""
    positions, normals, corners = [], [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                positions.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("vn"):
                normals.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                refs = [c.split("/") for c in line.split()[1:]]
                ids = [(int(r[0]), int(r[2]) if len(r) > 2 and r[2] else 0) for r in refs]
                for k in range(1, len(ids) - 1):
                    corners.append((ids[0], ids[k], ids[k + 1]))
    positions = np.array(positions, dtype=np.float64)
    normals = np.array(normals if normals else [[0.0, 0.0, 0.0]], dtype=np.float64)
    c = np.array(corners, dtype=np.int64)  # (faces, 3 corners, (position, normal)), 1-based
    p = positions[c[:, :, 0] - 1]
    face = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    face /= np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-30)
    n = np.where(c[:, :, 1:2] > 0, normals[np.maximum(c[:, :, 1], 1) - 1], 0.0)
    length = np.linalg.norm(n, axis=2, keepdims=True)
    good = np.isfinite(length) & (length > 0)
    n = np.where(good, n / np.where(good, length, 1.0), face[:, None, :])
    faces = len(c)
    mesh = mi.Mesh(name, vertex_count=3 * faces, face_count=faces, has_vertex_normals=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(p.reshape(-1).astype(np.float32))
    params["vertex_normals"] = mi.Float(n.reshape(-1).astype(np.float32))
    params["faces"] = mi.UInt32(np.arange(3 * faces, dtype=np.uint32))
    params.update()
    mesh.set_bsdf(mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": albedo}}))
    return mesh


def scene_dict(mi, path, width, height):
    with open(path) as f:
        scene = json.load(f)
    base = os.path.dirname(os.path.abspath(path))
    out = {"type": "scene"}
    for i, mesh in enumerate(scene.get("meshes", [])):
        if "transform" in mesh:
            fail(f"meshes[{i}].transform is not supported")
        if "obj" not in mesh:
            fail(f"meshes[{i}]: only OBJ meshes are supported")
        material = mesh.get("material", {})
        if any(k in material for k in ("specular", "exponent")):
            fail(f"meshes[{i}].material: only diffuse materials are supported")
        albedo = material.get("diffuse", [0.8, 0.8, 0.8])
        out[f"mesh{i}"] = load_obj(mi, os.path.join(base, mesh["obj"]), albedo, f"mesh{i}")
    if scene.get("lights"):
        fail("lights[] are not supported (point lights' range window has no Mitsuba twin)")
    light = scene.get("light")
    if light is None:
        fail("light: a spot light is required")
    position = np.array(light["position"], dtype=float)
    direction = np.array(light["direction"], dtype=float)
    up = light.get("up", [0.0, 0.0, 1.0] if abs(direction[1]) > 0.99 * np.linalg.norm(direction) else [0.0, 1.0, 0.0])
    out["light"] = {
        "type": "spot",
        "to_world": mi.ScalarTransform4f().look_at(
            origin=position.tolist(), target=(position + direction).tolist(), up=list(up)
        ),
        "intensity": {"type": "rgb", "value": light["intensity"]},
        "cutoff_angle": float(light["outer_angle_deg"]),
        "beam_width": float(light["inner_angle_deg"]),
    }
    camera = scene["camera"]
    out["sensor"] = {
        "type": "perspective",
        "fov": float(camera["fov_y_deg"]),
        "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(
            origin=camera["position"], target=camera["target"], up=camera.get("up", [0.0, 1.0, 0.0])
        ),
        "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
                 "pixel_format": "rgb"},
    }
    return out


def render_indirect(mi, scene, spp, seed):
    """One indirect image: paths of up to 3 vertices minus those of up to 2."""
    images = []
    for depth in (3, 2):
        integrator = mi.load_dict({"type": "path", "max_depth": depth, "hide_emitters": True})
        images.append(np.array(mi.render(scene, integrator=integrator, spp=spp, seed=seed)))
    return images[0] - images[1]


def luminance(rgb):
    return rgb[..., 0] * 0.2126 + rgb[..., 1] * 0.7152 + rgb[..., 2] * 0.0722


def compare(test, reference, variance, covered):
    t, g, s2 = test[covered], reference[covered], variance[covered]
    err = ((t - g) ** 2).sum(axis=1)
    ref = (g**2).sum(axis=1)
    noise = s2.sum(axis=1)
    order = np.argsort(-err)
    keep = order[int(len(order) * 0.01):]
    return {
        "rel_rmse": float(np.sqrt(err.sum() / ref.sum())),
        "rel_rmse_corrected": float(np.sqrt(max(0.0, err.sum() - noise.sum()) / ref.sum())),
        "rel_rmse_without_worst_1pct": float(np.sqrt(max(0.0, err[keep].sum() - noise[keep].sum()) / ref[keep].sum())),
        "mean_ratio": float(luminance(t).sum() / luminance(g).sum()),
        "worst_1pct_error_share": float(err[order[: int(len(order) * 0.01)]].sum() / err.sum()),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene")
    parser.add_argument("--relume", help="relume's indirect_exact.exr (its size sets the image's)")
    parser.add_argument("--width", type=int, default=64)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--spp", type=int, default=256, help="samples per pixel of each of the two halves")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--out", help="directory for mitsuba_indirect.exr and mitsuba_variance.exr")
    parser.add_argument("--seed", type=int, default=1, help="seed of the first half (the second takes seed + 1)")
    parser.add_argument("--reuse", nargs="+", help="directories earlier runs wrote with --out (independent seeds): "
                        "compare with their mean, render nothing")
    args = parser.parse_args()
    args.width_given = any(a.startswith(("--width", "--height")) for a in sys.argv[1:])

    import mitsuba as mi

    mi.set_variant(args.variant)
    relume = None
    width, height = args.width, args.height
    if args.relume:
        relume = np.array(mi.Bitmap(args.relume), dtype=np.float64)
        if not (args.width_given or args.reuse):
            height, width = relume.shape[:2]
    if args.reuse:
        read = lambda d, name: np.array(mi.Bitmap(os.path.join(d, name)), dtype=np.float64)[..., :3]
        means = [read(d, "mitsuba_indirect.exr") for d in args.reuse]
        # Independent runs: the mean's variance is the runs' summed variances over n².
        variance = sum(read(d, "mitsuba_variance.exr") for d in args.reuse) / len(args.reuse) ** 2
        mean = sum(means) / len(means)
        height, width = mean.shape[:2]
    else:
        scene = mi.load_dict(scene_dict(mi, args.scene, width, height))
        a = render_indirect(mi, scene, args.spp, seed=args.seed).astype(np.float64)
        b = render_indirect(mi, scene, args.spp, seed=args.seed + 1).astype(np.float64)
        mean = 0.5 * (a + b)
        variance = 0.25 * (a - b) ** 2
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        mi.Bitmap(mean.astype(np.float32)).write(os.path.join(args.out, "mitsuba_indirect.exr"))
        mi.Bitmap(variance.astype(np.float32)).write(os.path.join(args.out, "mitsuba_variance.exr"))
    report = {
        "scene": args.scene,
        "width": width,
        "height": height,
        "spp": None if args.reuse else 2 * args.spp,
        "variant": args.variant,
        "mitsuba_rel_stderr": float(np.sqrt(variance.sum() / (mean**2).sum())),
    }
    if relume is not None:
        # A relume image k times the size is averaged over k x k blocks: the pixel's area, as
        # Mitsuba's box filter integrates it (relume's exact reference samples pixel centres).
        k = relume.shape[0] // height
        if relume.shape[:2] != (k * height, k * width) or k < 1:
            fail(f"--relume is {relume.shape[1]}x{relume.shape[0]}, not a multiple of {width}x{height}")
        relume = relume.reshape(height, k, width, k, relume.shape[-1]).mean(axis=(1, 3))
        report["relume_supersampling"] = k * k
        rgb = relume[..., :3]
        covered = relume[..., 3] > 0 if relume.shape[-1] > 3 else np.ones(rgb.shape[:2], bool)
        report["relume_vs_mitsuba"] = compare(rgb, mean, variance, covered)
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
