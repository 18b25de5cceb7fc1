#!/usr/bin/env python3
"""Independent evaluation of the `paper` model (docs/model.md) on a tiny 5x5 two-layer
stack, in plain Python (no numpy), written from that page's formulas only.
Its output is embedded in crates/drbokeh/tests/render.rs (test `golden_5x5_two_layers`).
Run: python3 tools/golden_paper.py
"""
import math

W = H = 5
K, F, L, GAMMA = 4.0, 0.5, 5, 2.2
R = L // 2

def pix(l, x, y):
    """Layer l's (rgb, alpha, disparity) at (x, y): simple closed-form content."""
    if l == 0:  # front: partial alpha blob, near
        a = max(0.0, 1.0 - 0.35 * math.hypot(x - 1.5, y - 2.0))
        rgb = (0.9, 0.2 + 0.1 * x, 0.1)
        d = 0.8 + 0.02 * y
    else:       # background: opaque gradient, far
        a = 1.0
        rgb = (0.1 + 0.15 * x, 0.3, 0.2 + 0.1 * y)
        d = 0.2 + 0.03 * x
    return rgb, a, d

def reflect(i, n):
    period = 2 * (n - 1)
    m = i % period
    return m if m < n else period - m

def S(r, dist): return 1.0 / (1.0 + 10.0 * math.exp(-3.0 * (r - dist)))
def s_step(D): return 0.5 + 0.5 * math.tanh(10.0 * (D - 0.1))

def layer_render(l, x, y):
    rgb_x, a_x, disp_x = pix(l, x, y)
    d_x = disp_x - F
    e_x = math.exp(-3.0 * (K * d_x) ** 2)
    C = [0.0, 0.0, 0.0]; Wsum = 0.0
    for dy in range(-R, R + 1):
        for dx in range(-R, R + 1):
            dist = math.sqrt(dx * dx + dy * dy)
            if not dist < R:
                continue
            sx, sy = reflect(x + dx, W), reflect(y + dy, H)
            rgb_y, a_y, disp_y = pix(l, sx, sy)
            d_y = disp_y - F
            r_y = K * abs(d_y) + 1.0
            w = S(r_y, dist) / (r_y * r_y)
            O = 1.0 if (dx == 0 and dy == 0) else 1.0 + e_x * (s_step(d_y - d_x) - 1.0)
            c = a_y * w * O
            for ch in range(3):
                C[ch] += (rgb_y[ch] ** GAMMA) * c
            Wsum += c
    B = [c / (Wsum + 1e-8) for c in C]
    r_x = K * abs(d_x) + 1.0
    h = min(int(math.floor(r_x / 2.0)), R)
    tot = 0.0
    for dy in range(-h, h + 1):
        for dx in range(-h, h + 1):
            tot += pix(l, reflect(x + dx, W), reflect(y + dy, H))[1]
    o = tot / (2 * h + 1) ** 2
    return B, o

out = []
for y in range(H):
    for x in range(W):
        acc = [0.0, 0.0, 0.0]; T = 1.0
        for l in range(2):
            B, o = layer_render(l, x, y)
            for ch in range(3):
                acc[ch] += B[ch] * o * T
            T *= 1.0 - o
        out.append([v ** (1.0 / GAMMA) for v in acc])
print("// (x, y) row-major, RGB display-encoded")
for i, v in enumerate(out):
    print("    [%r, %r, %r], // x=%d y=%d" % (v[0], v[1], v[2], i % W, i // W))
