#!/usr/bin/env python3
"""Compare two outputs of scripts/compare-fixtures.sh (two builds of relume): every JSON value
but times, rates and what a timing chose, and every image byte for byte. Prints what differs
and exits 1 when anything does.

    tools/compare-runs.py BEFORE AFTER
"""
import hashlib
import json
import os
import re
import sys

# Times and rates, and the CPU reference's shadow-ray traversal, which a timed pilot chooses
# (both traversals give the same image).
TIMING = re.compile(r'(_ms|^ms|_ms_after_\d+|rays_per_s|seconds|_per_s|^speedup|^exact_traversal|^adapter)$')


def values(x, path=''):
    """(path, value) of every leaf of a JSON document but the timings."""
    if isinstance(x, dict):
        for k, v in x.items():
            if not TIMING.search(k):
                yield from values(v, f'{path}.{k}')
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from values(v, f'{path}[{i}]')
    else:
        yield path, x


def digest(path):
    with open(path, 'rb') as f:
        return hashlib.sha256(f.read()).hexdigest()


def main(before, after):
    differences = images = documents = 0
    for root, _, files in os.walk(before):
        for name in sorted(files):
            a = os.path.join(root, name)
            rel = os.path.relpath(a, before)
            b = os.path.join(after, rel)
            if not name.endswith(('.json', '.png', '.exr')):
                continue
            if not os.path.exists(b):
                print(f'{rel}: missing after')
                differences += 1
            elif name.endswith('.json'):
                documents += 1
                try:
                    with open(a) as fa, open(b) as fb:
                        va, vb = dict(values(json.load(fa))), dict(values(json.load(fb)))
                except ValueError as error:
                    print(f'{rel}: not JSON on one side ({error})')
                    differences += 1
                    continue
                changed = [(k, va.get(k), vb.get(k)) for k in sorted(set(va) | set(vb)) if va.get(k) != vb.get(k)]
                for k, x, y in changed[:12]:
                    print(f'{rel}: {k} {x!r} -> {y!r}')
                differences += len(changed)
            else:
                images += 1
                if digest(a) != digest(b):
                    print(f'{rel}: image differs')
                    differences += 1
    print(f'{documents} JSON documents and {images} images compared; {differences} differences')
    return 1 if differences else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1], sys.argv[2]))
