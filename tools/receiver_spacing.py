#!/usr/bin/env python3
"""What the differential pass's receiver spacing does to the composite (docs/measurements/
differential.md, "Receiver spacing"): replays the first frames of the TUM recording with
`settings.mr.receiver_step` at 1, 2, 4 (the default), 8 and 16 (the frame budget's thinned
rungs take 2x and 4x the scene's step), the exact pass at 4, and the pass off; then, per frame,
compares each composite's change (the composite's luminance minus the composite without the
pass, 8-bit sRGB levels, over the pixels the pass changes by a level or more at step 1) with
step 1's: relative RMSE of the change, and the darkest change over step 1's darkest. Prints a
markdown table of the medians over the frames and each run's median frame time. With
`--exact-step-1` the exact pass at step 1 is measured against the fast one there too: the
reference's own error (the exact pass at step 1 costs about 25 s a frame on 2 cores), and a
second table splits each run's difference by the size of step 1's change there. `--reuse`
takes the replays already in --out.

    tools/receiver_spacing.py --bin BIN [--frames N] [--out DIR] [--exact-step-1] [--reuse]

Needs numpy and Pillow (tools/requirements.txt).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys

import numpy as np
from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, 'fixtures/scenes/mr_bunny_differential.json')
RECORDING = os.path.join(ROOT, 'fixtures/recordings/tum_fr1_xyz')
# (name, settings.mr); the first with the pass is the reference.
RUNS = [
    ('off', {'differential': False}),
    ('step 1', {'receiver_step': 1}),
    ('step 2', {'receiver_step': 2}),
    ('step 4 (default)', {'receiver_step': 4}),
    ('step 4, exact pass', {'receiver_step': 4, 'differential_method': 'exact'}),
    ('step 8', {'receiver_step': 8}),
    ('step 16', {'receiver_step': 16}),
]


def luminance(path):
    a = np.asarray(Image.open(path).convert('RGB'), dtype=np.float64)
    return 0.2126 * a[..., 0] + 0.7152 * a[..., 1] + 0.0722 * a[..., 2]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--bin', required=True)
    p.add_argument('--frames', type=int, default=6)
    p.add_argument('--out', default='out/receiver-spacing')
    p.add_argument('--exact-step-1', action='store_true')
    p.add_argument('--reuse', action='store_true')
    args = p.parse_args()
    runs = RUNS + ([('step 1, exact pass', {'receiver_step': 1, 'differential_method': 'exact'})]
                   if args.exact_step_1 else [])
    os.makedirs(args.out, exist_ok=True)
    scene = json.load(open(SCENE))
    for mesh in scene['meshes']:
        mesh['obj'] = os.path.normpath(os.path.join(os.path.dirname(SCENE), mesh['obj']))
    ms = {}
    for i, (name, mr) in enumerate(runs):
        scene['settings']['mr'] = mr
        path = os.path.join(args.out, f'scene{i}.json')
        json.dump(scene, open(path, 'w'))
        out = os.path.join(args.out, f'run{i}')
        if not (args.reuse and os.path.exists(os.path.join(out, 'summary.json'))):
            cmd = [args.bin, 'replay', RECORDING, '--scene', path, '--frames', str(args.frames), '--out', out]
            r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            if r.returncode != 0:
                sys.exit(f'receiver_spacing: {name}: {r.stderr}')
        summary = json.load(open(os.path.join(out, 'summary.json')))
        ms[name] = statistics.median(summary['frame_ms'][1:] or summary['frame_ms'])
    frames = sorted(os.listdir(os.path.join(args.out, 'run0', 'composited')))
    figures = {name: ([], []) for name, _ in runs[2:]}
    # Per run and bin of step 1's |change| (levels): squared difference, squared change.
    bins = [(1, 3), (3, 10), (10, 1000)]
    split = {name: [[0.0, 0.0] for _ in bins] for name, _ in runs[2:]}
    for f in frames:
        off = luminance(os.path.join(args.out, 'run0', 'composited', f))
        reference = luminance(os.path.join(args.out, 'run1', 'composited', f)) - off
        mask = np.abs(reference) >= 1.0
        norm = np.sqrt(np.mean(reference[mask] ** 2))
        for i, (name, _) in enumerate(runs[2:], start=2):
            change = luminance(os.path.join(args.out, f'run{i}', 'composited', f)) - off
            figures[name][0].append(np.sqrt(np.mean((change - reference)[mask] ** 2)) / norm)
            figures[name][1].append(change.min() / reference.min())
            for b, (lo, hi) in enumerate(bins):
                m = mask & (np.abs(reference) >= lo) & (np.abs(reference) < hi)
                split[name][b][0] += np.sum((change - reference)[m] ** 2)
                split[name][b][1] += np.sum(reference[m] ** 2)
    print(f'{len(frames)} frames of the TUM replay at 640x480, the scene\'s level (balanced); '
          f'against step 1 (median {ms["step 1"]:.0f} ms a frame).\n')
    print('| receivers | rel RMSE of the change against step 1 (median) | darkest change / step 1\'s (median) '
          '| median frame ms |')
    print('|---|---|---|---|')
    for name, _ in runs[2:]:
        rel, dark = figures[name]
        print(f'| {name} | {statistics.median(rel):.3f} | {statistics.median(dark):.3f} | {ms[name]:.0f} |')
    print(f'| off | 1 | 0 | {ms["off"]:.0f} |')
    print('\nThe difference by the size of step 1\'s change (levels), over all frames: rel RMSE within '
          'the pixels of each size, and that size\'s share of the run\'s squared difference.\n')
    print('| receivers | ' + ' | '.join(f'{lo}-{hi} levels' if hi < 1000 else f'{lo}+ levels' for lo, hi in bins) + ' |')
    print('|---|' + '---|' * len(bins))
    for name, _ in runs[2:]:
        total = sum(e for e, _ in split[name]) or 1.0
        cells = [f'{np.sqrt(e / r) if r else 0:.3f} ({e / total:.0%})' for e, r in split[name]]
        print(f'| {name} | ' + ' | '.join(cells) + ' |')


if __name__ == '__main__':
    main()
