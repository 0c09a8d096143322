#!/usr/bin/env python3
"""How the per-frame error estimate's choice of pixels behaves on one image pair.

Reads the exact reference and a frame's indirect light as linear EXR (as `relume compare
--reference exact --images DIR` writes them: `indirect_exact.exr`, and a mode's
`indirect_sparse_occlusion_<mode>.exr`) and draws the estimate's pixels many times, without the
reference's own sampling noise, uniformly (one pick in each equal run of the covered pixels)
by brightness (q = 1/2 + 1/2 L^2 / mean(L^2), weights 1/q), and by brightness and contrast, as
`src/renderer/estimate.rs` draws them (q = (1 + L^2 / mean(L^2) + C / mean(C)) / 3, C the larger
central difference of the frame's luminance), printing the estimate over the true relative RMSE
(mean, 10th percentile, median, 90th, and how often it falls outside 1.5x of it).

    python3 tools/estimate_draws.py DIR/indirect_exact.exr DIR/indirect_sparse_occlusion_product.exr

Only the standard library: the EXR reader handles what relume writes (scanline or tiled,
uncompressed or RLE, 32-bit float channels).
"""
import bisect
import math
import random
import struct
import sys


def _unrle(data):
    out = bytearray()
    i = 0
    while i < len(data):
        n = struct.unpack('b', data[i:i + 1])[0]
        i += 1
        if n < 0:
            out += data[i:i - n]
            i += -n
        else:
            out += bytes([data[i]]) * (n + 1)
            i += 1
    for k in range(1, len(out)):
        out[k] = (out[k - 1] + out[k] - 128) & 255
    half = (len(out) + 1) // 2
    merged = bytearray(len(out))
    merged[0::2] = out[:half]
    merged[1::2] = out[half:]
    return bytes(merged)


def read_exr(path):
    """(width, height, {channel: [floats]}) of a float EXR."""
    d = open(path, 'rb').read()
    p = 8
    attrs = {}
    while d[p] != 0:
        e = d.index(b'\0', p)
        name = d[p:e].decode()
        p = e + 1
        e = d.index(b'\0', p)
        p = e + 1
        size = struct.unpack('<i', d[p:p + 4])[0]
        p += 4
        attrs[name] = d[p:p + size]
        p += size
    p += 1
    xmin, ymin, xmax, ymax = struct.unpack('<4i', attrs['dataWindow'])
    w, h = xmax - xmin + 1, ymax - ymin + 1
    channels = []
    b = attrs['channels']
    q = 0
    while b[q] != 0:
        e = b.index(b'\0', q)
        channels.append(b[q:e].decode())
        q = e + 1 + 16
    img = {c: [0.0] * (w * h) for c in channels}
    if 'tiles' in attrs:
        tw, th = struct.unpack('<2I', attrs['tiles'][:8])
        chunks = struct.unpack('<i', attrs['chunkCount'])[0]
    else:
        tw, th, chunks = w, 1, h
    offsets = struct.unpack('<%dQ' % chunks, d[p:p + 8 * chunks])
    for off in offsets:
        if 'tiles' in attrs:
            tx, ty, _, _, size = struct.unpack('<5i', d[off:off + 20])
            data = d[off + 20:off + 20 + size]
            x0, y0 = tx * tw, ty * th
        else:
            y, size = struct.unpack('<2i', d[off:off + 8])
            data = d[off + 8:off + 8 + size]
            x0, y0 = 0, y - ymin
        cw, ch = min(tw, w - x0), min(th, h - y0)
        raw = cw * ch * len(channels) * 4
        if size < raw:
            data = _unrle(data)
        values = struct.unpack('<%df' % (raw // 4), data)
        k = 0
        for yy in range(ch):
            for c in channels:
                row = (y0 + yy) * w + x0
                img[c][row:row + cw] = values[k:k + cw]
                k += cw
    return w, h, img


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    w, h, ex = read_exr(sys.argv[1])
    w2, h2, fr = read_exr(sys.argv[2])
    assert (w, h) == (w2, h2), 'the images differ in size'
    n = w * h
    ref = [(ex['R'][i], ex['G'][i], ex['B'][i]) for i in range(n)]
    frame = [(fr['R'][i], fr['G'][i], fr['B'][i]) for i in range(n)]
    covered = [i for i in range(n) if any(ref[i]) or any(frame[i])]
    err = [sum((frame[i][c] - ref[i][c]) ** 2 for c in range(3)) for i in covered]
    sq = [sum(ref[i][c] ** 2 for c in range(3)) for i in covered]
    truth = math.sqrt(sum(err) / sum(sq))
    every = [0.2126 * r + 0.7152 * g + 0.0722 * b for (r, g, b) in frame]
    lum = [every[i] for i in covered]
    mean_sq = sum(x * x for x in lum) / len(lum)

    def contrast(i):
        x, y = i % w, i // w
        dx = abs(every[i + 1] - every[i - 1]) if 0 < x < w - 1 else 0.0
        dy = abs(every[i + w] - every[i - w]) if 0 < y < h - 1 else 0.0
        return max(dx, dy)
    con = [contrast(i) for i in covered]
    mean_con = sum(con) / len(con)
    print('rel RMSE %.4f over %d covered pixels' % (truth, len(covered)))
    rules = [('uniform', [1.0] * len(covered)),
             ('by brightness', [0.5 + 0.5 * x * x / mean_sq for x in lum]),
             ('+ contrast', [(1 + x * x / mean_sq + c / mean_con) / 3 for x, c in zip(lum, con)])]
    for name, q in rules:
        total = sum(q)
        running = []
        acc = 0.0
        for x in q:
            acc += x
            running.append(acc)
        for pixels, draws in ((1024, 300), (64, 1000)):
            ratios = []
            for seed in range(draws):
                rng = random.Random(seed)
                se = sr = 0.0
                for k in range(pixels):
                    j = min(bisect.bisect_left(running, (k + rng.random()) / pixels * total), len(covered) - 1)
                    se += err[j] / q[j]
                    sr += sq[j] / q[j]
                ratios.append(math.sqrt(se / sr) / truth)
            ratios.sort()
            outside = sum(1 for r in ratios if r > 1.5 or r < 1 / 1.5) / draws
            print('%-14s %5d pixels: estimate / error mean %.3f, p10 %.3f, median %.3f, p90 %.3f, '
                  'outside 1.5x %.0f %%' % (name, pixels, sum(ratios) / draws, ratios[draws // 10],
                                            ratios[draws // 2], ratios[9 * draws // 10], 100 * outside))


if __name__ == '__main__':
    main()
