#!/usr/bin/env python3
"""Pins the bytes of drbokeh's outputs, so that a refactor can be checked to change none.

Runs a fixed set of commands (render, vjp, layers, dfd, eval, gallery) with one binary on
deterministic inputs and records the SHA-256 of every output (for NPZ files, of every
member, so that zip metadata does not count; for eval, of every picture and of
results.json without its timings). Run it with the old and the new binary and compare:

    tools/pin_outputs.py run --bin OLD/drbokeh --work /tmp/pin --name old
    tools/pin_outputs.py run --bin target/release/drbokeh --work /tmp/pin --name new
    tools/pin_outputs.py compare /tmp/pin/old.txt /tmp/pin/new.txt

The inputs (random layer stacks with partial alpha, images, maps, a small ray-traced
benchmark made by the first binary run) are written once under WORK/inputs and reused.
Python standard library only.
"""

import argparse
import hashlib
import json
import os
import struct
import subprocess
import sys
import zipfile
import zlib


class Rng:
    """SplitMix64: deterministic across platforms."""

    def __init__(self, seed):
        self.s = seed & 0xFFFFFFFFFFFFFFFF

    def next(self):
        self.s = (self.s + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF
        z = self.s
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
        return z ^ (z >> 31)

    def uniform(self):
        return (self.next() >> 11) / float(1 << 53)


def npy_bytes(values, shape, dtype="<f4"):
    fmt = {"<f4": "f", "<f8": "d"}[dtype]
    header = "{'descr': '%s', 'fortran_order': False, 'shape': (%s), }" % (
        dtype,
        "".join("%d, " % s for s in shape) if len(shape) > 1 else "%d," % shape[0],
    )
    total = 10 + len(header) + 1
    header += " " * ((64 - total % 64) % 64) + "\n"
    out = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1")
    return out + struct.pack("<%d%s" % (len(values), fmt), *values)


def write_npz(path, arrays):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        for name, (values, shape) in arrays.items():
            z.writestr(name + ".npy", npy_bytes(values, shape))


def write_png(path, width, height, channels, values, bits=8):
    """values: row-major floats in [0, 1]."""
    colour = {1: 0, 3: 2}[channels]
    maxv = (1 << bits) - 1
    raw = bytearray()
    for y in range(height):
        raw.append(0)
        for x in range(width):
            for c in range(channels):
                v = int(round(min(max(values[(y * width + x) * channels + c], 0.0), 1.0) * maxv))
                raw += struct.pack(">H", v) if bits == 16 else bytes([v])

    def chunk(kind, data):
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    png = b"\x89PNG\r\n\x1a\n"
    png += chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, bits, colour, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(bytes(raw), 9))
    png += chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def random_stack(path, seed, n, w, h):
    """n layers, front first: smooth colour, soft and noisy partial alpha (exact 0 and 1
    included), disparity near a per-layer level with a ramp; the back layer opaque."""
    rng = Rng(seed)
    rgb, alpha, disp = [], [], []
    for layer in range(n):
        level = 0.9 - 0.8 * layer / max(n - 1, 1)
        cx, cy = rng.uniform() * w, rng.uniform() * h
        rad = (0.2 + 0.3 * rng.uniform()) * min(w, h)
        tint = [rng.uniform() for _ in range(3)]
        for y in range(h):
            for x in range(w):
                for c in range(3):
                    rgb.append(min(1.0, 0.6 * tint[c] + 0.4 * rng.uniform() * ((x + y + c) % 3) / 2))
                if layer == n - 1:
                    a = 1.0
                else:
                    r = ((x - cx) ** 2 + (y - cy) ** 2) ** 0.5
                    a = min(max(0.5 - (r - rad) / 3.0, 0.0), 1.0)
                    if 0.0 < a < 1.0 or rng.uniform() < 0.05:
                        a = min(1.0, a * (0.7 + 0.6 * rng.uniform()))
                alpha.append(a)
                disp.append(min(1.0, max(0.0, level + 0.1 * (y / h - 0.5) + 0.02 * rng.uniform())))
    write_npz(
        path,
        {"rgb": (rgb, (n, h, w, 3)), "alpha": (alpha, (n, h, w)), "disparity": (disp, (n, h, w))},
    )


def make_inputs(d, binary):
    os.makedirs(d, exist_ok=True)
    random_stack(os.path.join(d, "stack3.npz"), 11, 3, 56, 44)
    random_stack(os.path.join(d, "stack5.npz"), 23, 5, 64, 48)
    w, h = 64, 48
    rng = Rng(5)
    img, disp, matte, depth = [], [], [], []
    for y in range(h):
        for x in range(w):
            near = (x - 22) ** 2 + (y - 24) ** 2 < 14 ** 2
            mid = 34 <= x < 58 and 8 <= y < 30
            for c in range(3):
                base = 0.9 if (near and c == 0) else 0.2 + 0.6 * ((x // 6 + y // 6 + c) % 3) / 2
                img.append(min(1.0, base + 0.05 * rng.uniform()))
            dv = 0.85 if near else (0.5 if mid else 0.1 + 0.1 * y / h)
            disp.append(dv)
            matte.append(1.0 if near else 0.0)
            depth.append(1.0 / (0.2 + dv))
    write_png(os.path.join(d, "img.png"), w, h, 3, img)
    write_png(os.path.join(d, "disp.png"), w, h, 1, disp, bits=16)
    write_png(os.path.join(d, "matte.png"), w, h, 1, matte)
    with open(os.path.join(d, "depth.npy"), "wb") as f:
        f.write(npy_bytes(depth, (h, w)))
    kernel = [1.0 if abs(x - 7.5) + abs(y - 7.5) < 7 else 0.0 for y in range(16) for x in range(16)]
    write_png(os.path.join(d, "kernel.png"), 16, 16, 1, kernel)
    for name, (gw, gh), dtype in [
        ("g_demo.npy", (96, 64), "<f4"),
        ("g3_f32.npy", (56, 44), "<f4"),
        ("g3_f64.npy", (56, 44), "<f8"),
        ("g5_f64.npy", (64, 48), "<f8"),
        ("gimg_f64.npy", (64, 48), "<f8"),
    ]:
        r = Rng(len(name) * 7919 + gw)
        vals = [r.uniform() - 0.5 for _ in range(gw * gh * 3)]
        with open(os.path.join(d, name), "wb") as f:
            f.write(npy_bytes(vals, (gh, gw, 3), dtype))
    gal = os.path.join(d, "gallery")
    os.makedirs(gal, exist_ok=True)
    write_png(os.path.join(gal, "a.png"), w, h, 3, img)
    write_png(os.path.join(gal, "a.disp.png"), w, h, 1, disp, bits=16)
    subprocess.run(
        [binary, "benchmark", "make", "--scenes", "2", "--size", "48", "--spp", "16", "--seed", "3",
         "--output", os.path.join(d, "bench"), "-q"],
        check=True,
    )
    # A defocused target for dfd: the demo-free image rendered by the paper preset.
    subprocess.run(
        [binary, "render", "--image", os.path.join(d, "img.png"), "--disparity",
         os.path.join(d, "disp.png"), "--single-layer", "--preset", "paper", "--focus", "0.5",
         "--blur", "6", "-o", os.path.join(d, "defocused.png"), "-q"],
        check=True,
    )


def cases(i):
    """(name, argv after the binary, outputs relative to the case directory)."""
    stacks = {
        "demo": ["--demo", "--demo-size", "96x64"],
        "s3": ["--layers", f"{i}/stack3.npz", "--focus", "0.45", "--blur", "12"],
        "s5": ["--layers", f"{i}/stack5.npz", "--focus", "0.6", "--blur", "9"],
    }
    out = []
    for sname, sargs in stacks.items():
        for preset in ["paper", "physical"]:
            for prec in ["f32", "f64"]:
                for engine in ["fast", "threaded", "reference"]:
                    extra = ["--f64"] if prec == "f64" else []
                    out.append((f"render-{sname}-{preset}-{prec}-{engine}",
                                ["render", *sargs, "--preset", preset, "--engine", engine, *extra,
                                 "-o", "out.npy", "-q"], ["out.npy"]))
    variants = {
        "hexagon": ["--aperture", "hexagon"],
        "poly5": ["--aperture", "polygon:5:10"],
        "kernel": ["--aperture", f"kernel:{i}/kernel.png"],
        "highlight": ["--highlight"],
        "gamma": ["--gamma", "2.0", "--offset", "0.05"],
        "window9": ["--window", "9"],
        "focusat": ["--focus-at", "10,30"],
        "blur60": ["--blur", "60"],
    }
    for vname, vargs in variants.items():
        base = ["--layers", f"{i}/stack3.npz"]
        if vname != "focusat":
            base += ["--focus", "0.45"]
        if vname != "blur60":
            base += ["--blur", "12"]
        for preset in ["paper", "physical"]:
            for prec, engine in [("f32", "fast"), ("f64", "threaded")]:
                extra = ["--f64"] if prec == "f64" else []
                out.append((f"render-s3-{vname}-{preset}-{prec}-{engine}",
                            ["render", *base, *vargs, "--preset", preset, "--engine", engine,
                             *extra, "-o", "out.npy", "-q"], ["out.npy"]))
    image = ["--image", f"{i}/img.png"]
    photo = {
        "decompose": [*image, "--disparity", f"{i}/disp.png"],
        "matte": [*image, "--disparity", f"{i}/disp.png", "--alpha", f"{i}/matte.png"],
        "single": [*image, "--disparity", f"{i}/disp.png", "--single-layer"],
        "max2": [*image, "--disparity", f"{i}/disp.png", "--max-layers", "2"],
        "depth": [*image, "--depth", f"{i}/depth.npy"],
        "nonorm": [*image, "--depth", f"{i}/depth.npy", "--depth-kind", "disparity",
                   "--no-normalize"],
        "centre": [*image, "--disparity", f"{i}/disp.png"],
    }
    for pname, pargs in photo.items():
        focus = [] if pname == "centre" else ["--focus-at", "22,24"]
        if pname == "nonorm":
            focus = ["--focus", "0.3"]
        for preset in ["paper", "physical"]:
            out.append((f"render-photo-{pname}-{preset}",
                        ["render", *pargs, *focus, "--blur", "10", "--preset", preset,
                         "-o", "out.npy", "-q"], ["out.npy"]))
    out.append(("render-demo-png16", ["render", "--demo", "--demo-size", "80x60", "--preset",
                                      "paper", "--bit-depth", "16", "-o", "out.png", "-q"],
                ["out.png"]))
    vjps = [
        ("s3-paper-f64", ["--layers", f"{i}/stack3.npz", "--focus", "0.45", "--blur", "12",
                          "--preset", "paper", "--f64", "--grad-output", f"{i}/g3_f64.npy"]),
        ("s3-physical-f32-fast", ["--layers", f"{i}/stack3.npz", "--focus", "0.45", "--blur",
                                  "12", "--preset", "physical", "--grad-output",
                                  f"{i}/g3_f32.npy"]),
        ("s3-paper-f32-fast", ["--layers", f"{i}/stack3.npz", "--focus", "0.45", "--blur", "12",
                               "--preset", "paper", "--engine", "fast", "--grad-output",
                               f"{i}/g3_f32.npy"]),
        ("s3-physical-f64-threaded", ["--layers", f"{i}/stack3.npz", "--focus", "0.45",
                                      "--blur", "12", "--preset", "physical", "--f64",
                                      "--grad-output", f"{i}/g3_f64.npy"]),
        ("s3-physical-f32-kernel", ["--layers", f"{i}/stack3.npz", "--focus", "0.45", "--blur",
                                    "12", "--preset", "physical", "--aperture",
                                    f"kernel:{i}/kernel.png", "--grad-output",
                                    f"{i}/g3_f32.npy"]),
        ("s5-physical-f64-hexagon", ["--layers", f"{i}/stack5.npz", "--focus", "0.6", "--blur",
                                     "9", "--preset", "physical", "--aperture", "hexagon",
                                     "--f64", "--engine", "reference", "--grad-output",
                                     f"{i}/g5_f64.npy"]),
        ("s5-paper-f64-fast-rescale", ["--layers", f"{i}/stack5.npz", "--focus", "0.6", "--blur",
                                       "9", "--preset", "paper", "--f64", "--engine", "fast",
                                       "--rescale-small-gradients", "--grad-output",
                                       f"{i}/g5_f64.npy"]),
        ("demo-paper-f32", ["--demo", "--demo-size", "96x64", "--preset", "paper",
                            "--grad-output", f"{i}/g_demo.npy"]),
        ("photo-physical-f64", ["--image", f"{i}/img.png", "--disparity", f"{i}/disp.png",
                                "--focus-at", "22,24", "--blur", "10", "--preset", "physical",
                                "--f64", "--grad-output", f"{i}/gimg_f64.npy"]),
    ]
    for vname, vargs in vjps:
        out.append((f"vjp-{vname}", ["vjp", *vargs, "-o", "g.npz", "-q"], ["g.npz"]))
    out.append(("layers-decompose", ["layers", "--image", f"{i}/img.png", "--disparity",
                                     f"{i}/disp.png", "--focus", "0.85", "--blur", "10",
                                     "-o", "st.npz", "-q"],
                ["st.npz", "st.layer0.png", "st.layer0.disparity.png"]))
    for engine in ["fast", "threaded"]:
        out.append((f"dfd-{engine}", ["dfd", "--all-in-focus", f"{i}/img.png", "--defocused",
                                      f"{i}/defocused.png", "--focus", "0.5", "--blur", "6",
                                      "--iterations", "4", "--scales", "1", "--engine", engine,
                                      "-o", "d.npy", "--log", "d.log.json", "-q"],
                    ["d.npy"]))
    out.append(("eval", ["eval", "--benchmark", f"{i}/bench", "--output", "rep", "-q"], ["rep"]))
    out.append(("gallery", ["gallery", "--images", f"{i}/gallery", "--focal-planes", "3",
                            "--output", "gal", "-q"], ["gal"]))
    return out


def digest_path(path):
    """Yields (path, sha256) for a file or every file below a directory."""
    if os.path.isdir(path):
        for root, dirs, files in os.walk(path):
            dirs.sort()
            for f in sorted(files):
                yield from digest_path(os.path.join(root, f))
        return
    if path.endswith(".npz"):
        with zipfile.ZipFile(path) as z:
            for m in sorted(z.namelist()):
                yield path + ":" + m, hashlib.sha256(z.read(m)).hexdigest()
        return
    with open(path, "rb") as f:
        data = f.read()
    if os.path.basename(path) == "results.json":
        rep = json.loads(data)
        for s in rep.get("scenes", []):
            for r in s.get("results", []):
                r.pop("time_s", None)
        rep.get("summary", {}).pop("overall", None)
        rep.get("summary", {}).pop("by_bucket", None)
        data = json.dumps(rep, sort_keys=True).encode()
    elif path.endswith((".csv", ".md", ".svg", ".html", ".json")):
        return  # hold timings
    yield path, hashlib.sha256(data).hexdigest()


def run(args):
    binary = os.path.abspath(args.bin)
    work = os.path.abspath(args.work)
    inputs = os.path.join(work, "inputs")
    if not os.path.isdir(inputs):
        make_inputs(inputs, binary)
    lines = []
    selected = [c for c in cases(inputs) if not args.only or args.only in c[0]]
    for name, argv, outputs in selected:
        d = os.path.join(work, args.name, name)
        os.makedirs(d, exist_ok=True)
        p = subprocess.run([binary, *argv], cwd=d, capture_output=True, text=True)
        if p.returncode != 0:
            lines.append(f"{name} FAILED rc={p.returncode}: {p.stderr.strip()}")
            print(lines[-1], file=sys.stderr)
            continue
        for o in outputs:
            for rel, h in digest_path(os.path.join(d, o)):
                lines.append(f"{name} {os.path.relpath(rel, d)} {h}")
    path = os.path.join(work, args.name + ".txt")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"{len(selected)} cases, {len(lines)} outputs -> {path}")


def compare(args):
    def load(p):
        with open(p) as f:
            return [l.rstrip("\n") for l in f if l.strip()]

    a, b = load(args.a), load(args.b)
    if a == b:
        print(f"identical: {len(a)} outputs")
        return 0
    sa, sb = set(a), set(b)
    for l in a:
        if l not in sb:
            print(f"- {l}")
    for l in b:
        if l not in sa:
            print(f"+ {l}")
    return 1


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the cases with one binary")
    r.add_argument("--bin", required=True)
    r.add_argument("--work", required=True)
    r.add_argument("--name", required=True, help="manifest name (WORK/NAME.txt)")
    r.add_argument("--only", help="run only cases whose name contains this")
    c = sub.add_parser("compare", help="compare two manifests")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args()
    if args.cmd == "run":
        run(args)
    else:
        sys.exit(compare(args))


if __name__ == "__main__":
    main()
