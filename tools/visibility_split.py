#!/usr/bin/env python3
"""Where a visibility mode's error lies: at the pixels or in the sparse sampling.

Reads what `relume compare --reference exact --images DIR` writes (linear EXR): the exact
reference, the brute force without visibility, the brute force through the clusters' maps at
every pixel, and the sparse frames without visibility and with the clusters. Prints each one's
relative RMSE against exact over the RGB channels (as `compare` reports it), and that of the
sparse frame without visibility times the per-pixel maps' visibility ratio (the brute force
through the maps over the plain brute force, pixel by pixel): the best a scalar visibility
factor per pixel could do on top of the sparse method's unoccluded light.

    python3 tools/visibility_split.py DIR [DIR ...]

Only the standard library (the EXR reader of `estimate_draws.py`).
"""
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from estimate_draws import read_exr  # noqa: E402

IMAGES = ['brute_force', 'brute_force_clusters', 'sparse_occlusion_off', 'sparse_occlusion_clusters']


def rel_rmse(test, exact, n):
    num = den = 0.0
    for c in 'RGB':
        for t, e in zip(test[c][:n], exact[c][:n]):
            num += (t - e) ** 2
            den += e * e
    return math.sqrt(num / den)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for d in sys.argv[1:]:
        w, h, exact = read_exr(os.path.join(d, 'indirect_exact.exr'))
        images = {k: read_exr(os.path.join(d, 'indirect_%s.exr' % k))[2] for k in IMAGES}
        n = w * h
        bf, bfc, off = images['brute_force'], images['brute_force_clusters'], images['sparse_occlusion_off']
        ratio = {c: [o * (v / b if b > 0 else 1.0) for o, v, b in zip(off[c], bfc[c], bf[c])] for c in 'RGB'}
        figures = [(k, rel_rmse(images[k], exact, n)) for k in IMAGES]
        figures.append(('sparse_off_times_pixel_ratio', rel_rmse(ratio, exact, n)))
        print(os.path.basename(os.path.normpath(d)), ' '.join('%s %.4f' % f for f in figures))


if __name__ == '__main__':
    main()
