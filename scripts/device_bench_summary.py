#!/usr/bin/env python3
"""Summary of scripts/device-bench.sh: results.json (every step's status, wall time and JSON
output) and results.md (the headline figures beside the GPU targets). Standard library only:
the device machine installs nothing.

usage: device_bench_summary.py WORK STEPS_TSV OUT SMOKE
"""

import json
import sys
from pathlib import Path


def load_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def step_output(work: Path, name: str):
    """A step's own JSON: the file its command wrote, else what it printed."""
    written = {
        "table1": work / "table1" / "results.json",
        "sweep": work / "sweep" / "results.json",
        "mr_640": work / "mr_640" / "summary.json",
        "mr_1280": work / "mr_1280" / "summary.json",
        "mr_640_cpu": work / "mr_640_cpu" / "summary.json",
        "mr_640_fast": work / "mr_640_fast" / "summary.json",
        "levels_1080": work / "levels_1080" / "levels.json",
        "levels_sponza": work / "levels_sponza" / "levels.json",
    }.get(name)
    if written is not None:
        return load_json(written)
    return load_json(work / f"{name}.out")


def fmt(value, digits=3):
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def fps(ms):
    return 1000.0 / ms if ms and ms > 0 else None


def main() -> int:
    work, steps_tsv, out, smoke = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4] == "1"
    steps = []
    for line in steps_tsv.read_text().splitlines():
        name, status, ms, limit = line.split("\t")
        skipped = status == "skipped"
        steps.append(
            {
                "name": name,
                "exit": None if skipped else int(status),
                "skipped": skipped,
                "timed_out": not skipped and int(status) in (124, 137),
                "wall_s": float(ms) / 1000.0,
                "limit_s": int(limit),
                "output": step_output(work, name),
            }
        )
    by_name = {s["name"]: s["output"] for s in steps}
    adapter = next((o.get("adapter") for o in by_name.values() if isinstance(o, dict) and o.get("adapter")), None)
    timing = next((o.get("timing") for o in by_name.values() if isinstance(o, dict) and o.get("timing")), None)
    (out / "results.json").write_text(
        json.dumps({"smoke": smoke, "adapter": adapter, "timing": timing, "steps": steps}, indent=1)
    )

    shown = set()
    md = [f"# relume device benchmark{' (smoke: tiny sizes, not figures)' if smoke else ''}", ""]
    md += [f"Adapter: {adapter or 'unknown'}; timing source: {timing or 'unknown'}.", ""]
    md += ["| step | exit | wall s |", "|---|---|---|"]
    md += [
        f"| {s['name']} | {'skipped (deadline)' if s['skipped'] else s['exit']}{' (timed out)' if s['timed_out'] else ''} "
        f"| {s['wall_s']:.1f} |"
        for s in steps
    ]

    table1 = by_name.get("table1")
    if isinstance(table1, dict) and table1.get("configs"):
        shown.add("table1")
        md += ["", "## Paper's Table 1 (target on an H100/H200: >= 1000 fps; 512k VALs >= 200 fps)", ""]
        md += ["| scene | triangles | sparse points | VALs | glossy | occlusion | size | frame ms | fps | paper fps |"]
        md += ["|---|---|---|---|---|---|---|---|---|---|"]
        for c in table1["configs"]:
            cfg = c.get("config", c)  # the configuration is flattened into each result
            md.append(
                f"| {c['variant']} | {c['triangles']} | {c['sparse_points']} | {c['vals']} | {cfg['glossy']} | "
                f"{cfg['occlusion']} | {cfg['width']}x{cfg['height']} | {fmt(c['frame_ms'])} | "
                f"{fmt(fps(c['frame_ms']))} | {fmt(c.get('paper_fps'))} |"
            )

    sweep = by_name.get("sweep")
    fma = sweep.get("fma") if isinstance(sweep, dict) else None
    if isinstance(fma, dict):
        shown.add("sweep")
        md += ["", "## Gather vs the FMA kernel (target: >= 50 % of the FMA kernel)", ""]
        md += [f"FMA kernel: {fmt(fma['fma_per_s'])} FMA/s; {fma['vals']} VALs, {fma['sparse_points']} sparse points.", ""]
        md += [
            "| lobes | tile size | points per invocation | invocations per point | gather ms | pairs/s | pairs/s / FMA/s |",
            "|---|---|---|---|---|---|---|",
        ]
        for v in fma.get("gather_variants", []):
            lobes = {
                "diffuse": "diffuse",
                "glossy_lights": "diffuse + glossy (mean position)",
                "glossy_radiance": "diffuse + glossy (sum only)",
            }[v["lobes"]]
            md.append(
                f"| {lobes} | {v['tile_size']} | {v.get('receivers', 1)} | {v.get('lanes', 1)} | {fmt(v['gather_ms'])} "
                f"| {fmt(v['interactions_per_s'])} | {fmt(v['ratio_to_fma'])} |"
            )

    brute = by_name.get("sparse_vs_brute")
    if isinstance(brute, dict):
        shown.add("sparse_vs_brute")
        md += ["", "## Sparse vs brute force (target at 1080p: >= 300x)", ""]
        md += [
            f"{brute['width']}x{brute['height']}, {brute['vals']} VALs, {brute['sparse_points']} sparse points: "
            f"sparse {fmt(brute['sparse_ms'])} ms, brute force {fmt(brute['brute_force_ms'])} ms, "
            f"speed-up {fmt(brute['speedup'])}x; rel RMSE {fmt(brute['indirect_rel_rmse'])}."
        ]

    exact = by_name.get("exact")
    # The exact comparison's fields are flattened into compare's report.
    if isinstance(exact, dict) and "exact_ms" in exact:
        e = exact
        shown.add("exact")
        md += ["", "## Exact reference", ""]
        md += [
            f"{exact['width']}x{exact['height']}, {e['exact_vals_used']} VALs on the {e['exact_device']}: "
            f"{fmt(e['exact_ms'])} ms in {e['exact_rounds']} rounds"
            + (f", {fmt(e['exact_rays_per_s'])} shadow rays/s" if e.get("exact_rays_per_s") else "")
            + "; sparse vs exact rel RMSE: "
            + ", ".join(f"{m['mode']} {fmt(m['rel_rmse'])}" for m in e.get("modes_vs_exact", []))
            + "."
        ]

    replays = (
        ("mr_640", ""),
        ("mr_1280", ""),
        ("mr_640_cpu", ", the differential pass on the CPU"),
        ("mr_640_fast", ", the fast differential pass"),
    )
    for name, where in replays:
        replay = by_name.get(name)
        if isinstance(replay, dict) and replay.get("frame_ms"):
            frames = replay["frame_ms"]
            steady = sorted(frames[1:] or frames)
            median = steady[len(steady) // 2]
            shown.add(name)
            md += ["", f"## Mixed-reality replay at {replay['width']}x{replay['height']}{where} (targets: 30 and 90 fps)", ""]
            md += [
                f"{replay['frames']} frames: median frame {fmt(median)} ms ({fmt(fps(median))} fps) after the first "
                f"(load to read-back, wall clock); stage means: "
                + ", ".join(f"{k} {fmt(sum(v) / len(v))} ms" for k, v in sorted(replay.get("stage_ms", {}).items()) if v)
                + "."
            ]

    levels = by_name.get("levels_1080")
    if isinstance(levels, dict) and levels.get("levels"):
        shown.add("levels_1080")
        md += ["", f"## Quality levels at {levels['width']}x{levels['height']}", ""]
        md += ["| level | technique | rel RMSE vs exact | estimate | indirect ms | fps |", "|---|---|---|---|---|---|"]
        for row in levels["levels"]:
            estimate = row.get("error_estimate") or {}
            method = row.get("resolved", {}).get("method", "")
            md.append(
                f"| {row['level']} | {method} | {fmt(row['rel_rmse_vs_exact'])} | {fmt(estimate.get('rel_rmse'))} "
                f"| {fmt(row['ms'])} | {fmt(fps(row['ms']))} |"
            )

    est = by_name.get("levels_sponza")
    if isinstance(est, dict) and est.get("levels"):
        shown.add("levels_sponza")
        md += ["", f"## Levels and their candidates: {est.get('scene', '')} at {est['width']}x{est['height']}", ""]
        md += ["| configuration | rel RMSE vs exact | indirect ms | dominated by |", "|---|---|---|---|"]
        for row in est["levels"]:
            by = ", ".join(row.get("dominated_by") or []) or "-"
            md.append(f"| {row['level']} | {fmt(row['rel_rmse_vs_exact'])} | {fmt(row['ms'])} | {by} |")
        for row in est.get("candidates") or []:
            md.append(f"| {row['name']} | {fmt(row['rel_rmse_vs_exact'])} | {fmt(row['ms'])} | |")
        suggested = est.get("suggested_levels") or {}
        if suggested:
            md += ["", "The scene file's `settings.levels` these figures suggest:", "", "```json"]
            md += [json.dumps(suggested, indent=2), "```"]

    sponza = by_name.get("sponza_512")
    if isinstance(sponza, dict) and "speedup" in sponza:
        shown.add("sponza_512")
        md += ["", "## Sponza: sparse vs brute force (target at 512 wide: >= 5x)", ""]
        md += [
            f"{sponza['width']}x{sponza['height']}, {sponza['vals']} VALs: sparse {fmt(sponza['sparse_ms'])} ms, "
            f"brute force {fmt(sponza['brute_force_ms'])} ms, speed-up {fmt(sponza['speedup'])}x."
        ]
        before = by_name.get("sponza_512_lanes1")
        if isinstance(before, dict) and "speedup" in before:
            shown.add("sponza_512_lanes1")
            md += [
                "",
                f"With one invocation per sparse point in the gather (`RELUME_GATHER_LANES=1`, the kernel before "
                f"GPUs shared each point among invocations), the same run: sparse {fmt(before['sparse_ms'])} ms, "
                f"brute force {fmt(before['brute_force_ms'])} ms, speed-up {fmt(before['speedup'])}x.",
            ]

        for name, what in [("sponza_512_near1", "not interleaved"), ("sponza_512_near4", "interleaved over 4 x 4")]:
            near = by_name.get(name)
            if isinstance(near, dict) and "sparse_stages_ms" in near:
                shown.add(name)
                stages = dict(near["sparse_stages_ms"])
                near_ms = stages.get("near_field", 0.0) + stages.get("near_field_grid", 0.0)
                rest = sum(v for k, v in stages.items() if k not in ("near_field", "near_field_grid", "direct", "error_estimate"))
                ratio = (rest + near_ms) / rest if rest > 0 else float("nan")
                md += [
                    "",
                    f"With the near field at 4 spacings, {what} (`{name}`): near field {fmt(near_ms)} ms against "
                    f"{fmt(rest)} ms for the rest of the sparse frame, {fmt(ratio)}x the frame without it (target "
                    f"<= 1.5x); rel RMSE against the brute force {fmt(near['indirect_rel_rmse'])} "
                    f"(without the near field {fmt(sponza['indirect_rel_rmse'])}).",
                ]

    load = by_name.get("load")
    if isinstance(load, dict) and "frames_per_second" in load:
        shown.add("load")
        md += ["", "## The service under load (one process, one GPU)", ""]
        md += [
            f"{load['streams']} streams at {fmt(load['fps_per_stream'])} fps and {load['http_clients']} HTTP clients for "
            f"{fmt(load['seconds'])} s: {fmt(load['frames_per_second'])} frames/s (p50 {fmt(load['frame_latency_p50_ms'])} ms, "
            f"p99 {fmt(load['frame_latency_p99_ms'])} ms, {load['frames_dropped']} dropped), "
            f"{fmt(load['renders_per_second'])} renders/s (p50 {fmt(load['render_latency_p50_ms'])} ms, "
            f"p99 {fmt(load['render_latency_p99_ms'])} ms, {load['renders_refused']} refused)."
        ]
    (out / "results.md").write_text("\n".join(md) + "\n")
    # A step that succeeded but whose figures could not be read means this script and relume's
    # output drifted apart: fail, so that CI's smoke run notices.
    unread = [s["name"] for s in steps if s["exit"] == 0 and s["name"] not in shown]
    if unread:
        print(f"device_bench_summary: no figures read from the output of {', '.join(unread)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
