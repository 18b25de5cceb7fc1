#!/usr/bin/env bash
# Renders a `drbokeh gallery` page (and optionally an `drbokeh eval` report) in headless
# Chromium and checks that the screenshot is non-trivial. Not a cargo test: CI has no
# Chromium. Installs Debian's `chromium` if it is missing (needs root and network).
#
# Usage:
#   tools/check_gallery.sh [DRBOKEH_BINARY] [EVAL_REPORT_DIR]
# Environment:
#   WORK    working directory (default: a new temporary directory); the screenshots are
#           written there as gallery.png (and eval.png).
#   PLANES  focal planes of the sweep (default 10).
#
# Steps: make a tiny benchmark (2 scenes, 128 px, 16 spp) to get image + disparity pairs,
# copy them as NAME.png + NAME.disp.png, run `drbokeh gallery`, screenshot index.html,
# check the PNG (size, dimensions, and with Python + Pillow when available: enough
# distinct colours and non-background pixels).
set -euo pipefail

BIN=${1:-${DRBOKEH:-target/release/drbokeh}}
REPORT=${2:-}
PLANES=${PLANES:-10}
WORK=${WORK:-$(mktemp -d /tmp/drbokeh-gallery-check.XXXXXX)}
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)

if [ ! -x "$BIN" ]; then
    echo "check_gallery: drbokeh binary '$BIN' not found (build with cargo build --release)" >&2
    exit 2
fi
if ! command -v chromium >/dev/null 2>&1; then
    echo "check_gallery: installing chromium" >&2
    apt-get update && apt-get install -y chromium
fi

rm -rf "$WORK/bench" "$WORK/images" "$WORK/gallery"
"$BIN" benchmark make --scenes 2 --size 128 --spp 16 --quiet --output "$WORK/bench"
mkdir -p "$WORK/images"
for i in 0 1; do
    cp "$WORK/bench/scene_00$i/aif.png" "$WORK/images/scene$i.png"
    cp "$WORK/bench/scene_00$i/disparity.png" "$WORK/images/scene$i.disp.png"
done
"$BIN" gallery --images "$WORK/images" --focal-planes "$PLANES" --blur 12 \
    --output "$WORK/gallery" --quiet

shoot() { # page.html screenshot.png
    chromium --headless --no-sandbox --disable-gpu --disable-background-networking \
        --disable-component-update --disable-sync --no-first-run --hide-scrollbars \
        --virtual-time-budget=10000 --screenshot="$2" --window-size=1280,2000 \
        "file://$1" >/dev/null 2>&1 || true
}

check_png() { # screenshot.png
    local png=$1
    if [ ! -s "$png" ]; then
        echo "check_gallery: FAIL: no screenshot $png" >&2
        return 1
    fi
    if [ "$(head -c 8 "$png" | od -An -tx1 | tr -d ' \n')" != "89504e470d0a1a0a" ]; then
        echo "check_gallery: FAIL: $png is not a PNG" >&2
        return 1
    fi
    local size width height
    size=$(stat -c %s "$png")
    width=$((16#$(od -An -tx1 -j16 -N4 "$png" | tr -d ' \n')))
    height=$((16#$(od -An -tx1 -j20 -N4 "$png" | tr -d ' \n')))
    echo "check_gallery: $png: ${width}x${height}, $size bytes"
    if [ "$width" -lt 1000 ] || [ "$height" -lt 1000 ] || [ "$size" -lt 50000 ]; then
        echo "check_gallery: FAIL: screenshot too small or too simple" >&2
        return 1
    fi
    if command -v python3 >/dev/null 2>&1 && python3 -c "import PIL" >/dev/null 2>&1; then
        python3 - "$png" <<'EOF'
import sys
from PIL import Image
im = Image.open(sys.argv[1]).convert("RGB")
px = list(im.getdata())
colours = len(set(px))
bg = max(set(px[::97]), key=px[::97].count)
busy = sum(1 for p in px if sum(abs(a - b) for a, b in zip(p, bg)) > 30) / len(px)
print(f"check_gallery: {colours} distinct colours, {busy:.1%} non-background pixels")
if colours < 2000 or busy < 0.2:
    print("check_gallery: FAIL: the page looks empty (images not rendered?)", file=sys.stderr)
    sys.exit(1)
EOF
    fi
}

shoot "$WORK/gallery/index.html" "$WORK/gallery.png"
check_png "$WORK/gallery.png"
if [ -n "$REPORT" ]; then
    REPORT=$(cd "$REPORT" && pwd)
    shoot "$REPORT/index.html" "$WORK/eval.png"
    check_png "$WORK/eval.png"
fi
echo "check_gallery: OK (screenshots in $WORK)"
