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
        "replay": work / "replay" / "summary.json",
        "mr_640": work / "mr_640" / "summary.json",
        "mr_1280": work / "mr_1280" / "summary.json",
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


def median(values):
    ordered = sorted(values)
    return ordered[len(ordered) // 2] if ordered else None


def fps(ms):
    return 1000.0 / ms if ms and ms > 0 else None


def main() -> int:
    work, steps_tsv, out, smoke = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4] == "1"
    steps = []
    for line in steps_tsv.read_text().splitlines():
        name, status, ms, limit = line.split("\t")
        steps.append(
            {
                "name": name,
                "exit": int(status),
                "timed_out": int(status) in (124, 137),
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
    md += [f"| {s['name']} | {s['exit']}{' (timed out)' if s['timed_out'] else ''} | {s['wall_s']:.1f} |" for s in steps]

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
            "| lobes | tile size | points per invocation | gather ms | pairs/s | pairs/s / FMA/s |",
            "|---|---|---|---|---|---|",
        ]
        for v in fma.get("gather_variants", []):
            lobes = {
                "diffuse": "diffuse",
                "glossy_lights": "diffuse + glossy (mean position)",
                "glossy_radiance": "diffuse + glossy (sum only)",
            }[v["lobes"]]
            md.append(
                f"| {lobes} | {v['tile_size']} | {v.get('receivers', 1)} | {fmt(v['gather_ms'])} "
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

    replay = by_name.get("replay")
    if isinstance(replay, dict) and replay.get("frame_ms"):
        frames = replay["frame_ms"]
        steady = frames[1:] or frames
        shown.add("replay")
        md += ["", "## Replay of the fixture recording", ""]
        md += [
            f"{replay['frames']} frames at {replay['width']}x{replay['height']}: mean frame {fmt(sum(steady) / len(steady))} ms "
            f"after the first (load to read-back, wall clock); stage means: "
            + ", ".join(f"{k} {fmt(sum(v) / len(v))} ms" for k, v in sorted(replay.get("stage_ms", {}).items()) if v)
            + "."
        ]
    mr = [(n, by_name.get(n)) for n in ("mr_640", "mr_1280")]
    mr = [(n, r) for n, r in mr if isinstance(r, dict) and r.get("frame_ms")]
    if mr:
        md += ["", "## Mixed reality at stream rate (the default job's scene: differential pass and environment)", ""]
        md += ["| step | size | frames | median frame ms | fps | holds 30 fps | holds 90 fps | median ms per stage |"]
        md += ["|---|---|---|---|---|---|---|---|"]
        for name, r in mr:
            shown.add(name)
            steady = r["frame_ms"][1:] or r["frame_ms"]
            ms = median(steady)
            stages = ", ".join(f"{k} {fmt(median(v[1:] or v))}" for k, v in sorted(r.get("stage_ms", {}).items()) if v)
            md.append(
                f"| {name} | {r['width']}x{r['height']} | {r['frames']} | {fmt(ms)} | {fmt(fps(ms))} | "
                f"{'yes' if ms <= 1000 / 30 else 'no'} | {'yes' if ms <= 1000 / 90 else 'no'} | {stages} |"
            )
        md += ["", "(Medians after the first frame, which builds the pipelines; frame: load to read-back, wall clock.)"]
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
