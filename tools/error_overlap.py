#!/usr/bin/env python3
"""Whether two images get the same pixels wrong: how much of one image's squared error against
a reference lies in the 1 % of pixels where another image differs most from it.

For the clusters' maps against blockers near the receiver: REFERENCE the exact image, TEST
the brute force through the maps over the same VALs (`relume compare --reference exact
--images DIR`: `indirect_exact.exr`, `indirect_brute_force_clusters.exr`), PROBE the exact
image with near blockers left out (`examples/exact_split.rs --blockers-from M --images DIR`).
Prints TEST's rel RMSE against REFERENCE (over RGB, as `compare` reports it), its share of
squared error in PROBE's worst 1 % of pixels, how many of those pixels TEST makes too
bright, how many of them are in TEST's own worst 1 %, and TEST's rel RMSE with those pixels
taken from REFERENCE.

    python3 tools/error_overlap.py REFERENCE.exr TEST.exr PROBE.exr

Only the standard library (the EXR reader of `estimate_draws.py`).
"""
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from estimate_draws import read_exr  # noqa: E402


def errors(test, reference, n):
    """Per pixel: the squared error over RGB and the mean signed difference."""
    sq = [sum((test[c][i] - reference[c][i]) ** 2 for c in 'RGB') for i in range(n)]
    signed = [sum(test[c][i] - reference[c][i] for c in 'RGB') / 3 for i in range(n)]
    return sq, signed


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    w, h, reference = read_exr(sys.argv[1])
    n = w * h
    test, probe = read_exr(sys.argv[2])[2], read_exr(sys.argv[3])[2]
    sq, signed = errors(test, reference, n)
    probe_sq, _ = errors(probe, reference, n)
    worst = math.ceil(0.01 * n)
    probe_top = sorted(range(n), key=lambda i: -probe_sq[i])[:worst]
    test_top = set(sorted(range(n), key=lambda i: -sq[i])[:worst])
    norm = sum(reference[c][i] ** 2 for c in 'RGB' for i in range(n))
    total, inside = sum(sq), sum(sq[i] for i in probe_top)
    print('rel RMSE %.4f' % math.sqrt(total / norm))
    print("share of its squared error in the probe's worst 1 %%: %.3f" % (inside / total))
    print('of those pixels, too bright: %.3f, in its own worst 1 %%: %.3f' % (
        sum(signed[i] > 0 for i in probe_top) / worst, sum(i in test_top for i in probe_top) / worst))
    print('rel RMSE with those pixels from the reference: %.4f' % math.sqrt((total - inside) / norm))


if __name__ == '__main__':
    main()
