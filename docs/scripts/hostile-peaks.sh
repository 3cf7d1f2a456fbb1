#!/usr/bin/env bash
# Peak memory (GNU time's maximum resident set) of `campro simulate` on the worst hostile
# inputs of issue 44, crafted here: a small grey PNG of 14000 x 14000, a PNG with a 256 MiB
# inflated iCCP profile, a 12000 x 12000 video, a FIFO and a link to /dev/urandom named like
# images. Usage: docs/scripts/hostile-peaks.sh [path/to/campro]   (needs python3, ffmpeg)
set -euo pipefail
campro="${1:-target/release/campro}"
params="$(dirname "$0")/../../params/identity.json"
d="$(mktemp -d)"; trap 'rm -rf "$d"' EXIT
python3 - "$d" <<'PY'
import struct, sys, zlib
d = sys.argv[1]
def chunk(k, data):
    return struct.pack(">I", len(data)) + k + data + struct.pack(">I", zlib.crc32(k + data) & 0xffffffff)
def png(w, h, ct, extra=b"", rows=1):
    ch = {0: 1, 2: 3}[ct]
    raw = b"\0" * ((1 + w * ch) * rows)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, ct, 0, 0, 0)) + extra
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
open(d + "/grey-14000.png", "wb").write(png(14000, 14000, 0))
icc = zlib.compressobj(1)
prof = b"".join(icc.compress(b"\0" * (1 << 20)) for _ in range(256)) + icc.flush()
open(d + "/iccp-256MiB.png", "wb").write(png(4, 4, 2, chunk(b"iCCP", b"bomb\0\0" + prof), rows=4))
PY
ffmpeg -hide_banner -v error -nostdin -y -f lavfi -i color=c=black:size=12000x12000:rate=1:duration=1 \
  -frames:v 1 -c:v ffv1 "$d/video-12000.mkv"
mkfifo "$d/fifo.png"
ln -s /dev/urandom "$d/urandom.png"
printf '| input | file bytes | exit | peak RSS (MiB) | message |\n|---|---|---|---|---|\n'
for f in grey-14000.png iccp-256MiB.png video-12000.mkv fifo.png urandom.png; do
  out="$d/out-$f"
  set +e
  /usr/bin/time -v -o "$d/time" "$campro" simulate "$params" "$d/$f" -o "$out" 2>"$d/err" >/dev/null
  rc=$?
  set -e
  peak=$(awk -F: '/Maximum resident/ {print int($2 / 1024)}' "$d/time")
  size=$(stat -Lc %s "$d/$f" 2>/dev/null || echo -)
  if [ -p "$d/$f" ]; then size=fifo; fi
  msg=$( (grep -m1 -E '^(error|warning)' "$d/err" || echo ok) | sed "s|$d/||g" | cut -c1-120)
  printf '| %s | %s | %s | %s | %s |\n' "$f" "$size" "$rc" "$peak" "$msg"
done
