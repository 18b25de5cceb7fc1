#!/usr/bin/env python3
"""Where a drbokeh process spends its time, by engine part.

Usage:
    perf record -F 499 -o run.data ./target/release/drbokeh render ...
    python3 tools/profile_engine.py run.data ./target/release/drbokeh [--lines]

Maps every sample inside the binary through its inlined frames (addr2line -i; the release
profile keeps line tables) to the innermost function that names an engine part: the span
engine's ring profile (S(r - g) evaluations), ring tap accumulation, interior span writes,
per-source/row control, focus rows, coverage, prefix sums and compositing, planes, I/O.
Samples outside the binary (kernel, libm, libc) are listed by library. `--lines` lists the
hottest source lines of the span engine instead.
"""
import collections
import re
import subprocess
import sys

CATEGORIES = [
    ("ring profile S(r-g) (exp, divide, gauge/mask loads)",
     ["ring_step", "sharp_step_fast", "soft_step_fast", "exp_fast", "exp_f32"]),
    ("ring taps accumulated (ring_add)", ["ring_add"]),
    ("interior span writes (difference arrays)", ["interior<"]),
    ("focus rows (in-focus occlusion)", ["interior_focus", "focus_sums", "coefficients", "classify"]),
    ("coverage (soft-disc gather / box SAT)", ["coverage::", "DiscGather", "AlphaSat", "box_coverage"]),
    ("prefix sums, layer colour, composite (finish)", ["scatter::finish"]),
    ("per-source/row control (source scan, circle rows, runs)",
     ["scatter_rows_circle", "scatter_sources", "circle_row", "floor_sqrt", "chunk_runs",
      "scatter_row", "sub_band", "new_acc"]),
    ("auto choice (predicted work)", ["predicted_work", "choice::"]),
    ("planes (linearise, radius, focus weight)", ["Planes", "planes::", "source_linear", "linearize"]),
    ("fast engine taps", ["engine::fast"]),
    ("decode/encode/io", ["io::", "png::", "image::", "zip", "npy", "flate", "miniz", "crc", "adler"]),
    ("scene/stack/layering", ["scene", "layering", "stack", "decompose"]),
]
SPAN_FILES = ("scatter.rs", "coverage.rs", "focus.rs", "geometry.rs", "choice.rs", "planes.rs")


def samples(data, binary):
    mm = subprocess.run(["perf", "script", "-i", data, "--show-mmap-events"],
                        capture_output=True, text=True).stdout
    m = re.search(r"\[(0x[0-9a-f]+)\(0x[0-9a-f]+\) @ (0x[0-9a-f]+) [^\]]*\]: r-xp (\S+)", mm)
    base, off, path = int(m.group(1), 16), int(m.group(2), 16), m.group(3)
    # Virtual address of the mapped file offset (the executable segment's alignment).
    seg = subprocess.run(["readelf", "-lW", binary], capture_output=True, text=True).stdout
    for line in seg.splitlines():
        f = line.split()
        if f and f[0] == "LOAD" and "E" in f[-2:-1][0]:
            vaddr, foff = int(f[2], 16), int(f[1], 16)
            break
    shift = vaddr - foff
    lines = subprocess.run(["perf", "script", "-i", data, "-F", "ip,dso", "--hide-call-graph"],
                           capture_output=True, text=True).stdout.splitlines()
    inside, outside = collections.Counter(), collections.Counter()
    for l in lines:
        p = l.split()
        if len(p) < 2:
            continue
        if path in l:
            inside[int(p[0], 16) - base + off + shift] += 1
        else:
            outside[p[1].strip("()").split("/")[-1]] += 1
    return inside, outside


def frames(binary, addrs):
    out = subprocess.run(["addr2line", "-a", "-i", "-f", "-C", "-e", binary],
                         input="\n".join(hex(a) for a in addrs),
                         capture_output=True, text=True).stdout.splitlines()
    fr, cur, i = collections.defaultdict(list), None, 0
    while i < len(out):
        if out[i].startswith("0x"):
            cur, i = int(out[i], 16), i + 1
            continue
        fr[cur].append((out[i], out[i + 1].split("/")[-1].split(" ")[0]))
        i += 2
    # The first name is the symbol; the others pair each location with its function.
    return {a: f[1:] + f[:1] for a, f in fr.items()}


def main():
    data, binary = sys.argv[1], sys.argv[2]
    inside, outside = samples(data, binary)
    fr = frames(binary, sorted(inside))
    total = sum(inside.values()) + sum(outside.values())
    agg = collections.Counter()
    for a, c in inside.items():
        if "--lines" in sys.argv:
            key = next((f"{fn[:45]} @ {loc}" for fn, loc in fr.get(a, [])
                        if loc.startswith(SPAN_FILES)), "other")
        else:
            key = next((name for fn, _ in fr.get(a, []) for name, keys in CATEGORIES
                        if any(k in fn for k in keys)), None)
            key = key or "other in binary"
        agg[key] += c
    for lib, c in outside.items():
        agg[f"outside the binary: {lib}"] += c
    for k, c in agg.most_common(30):
        print(f"{100 * c / total:5.1f}%  {k}")
    print(f"samples: {total}")


if __name__ == "__main__":
    main()
