#!/usr/bin/env bash
# Checks that each vendored crate is its published release plus the patch kept beside it
# (vendor/NAME.patch), byte for byte: the release is fetched by cargo (a throwaway package
# that depends on exactly that version; the registry is the only network it needs), its
# kept files (Cargo.toml, LICENSE, README.md, src/) copied, the patch applied, and the
# result compared with vendor/NAME.
# Usage: bash vendor/check.sh            (exit 1 and the difference when one is not)
#        bash vendor/check.sh --write    (rewrite the patches from the vendored copies)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
status=0
for crate in candle-core@0.9.2 float8@0.6.1; do
  name="${crate%@*}"
  version="${crate#*@}"
  pkg="$work/fetch-$name"
  mkdir -p "$pkg/src"
  printf '[package]\nname = "fetch"\nversion = "0.0.0"\nedition = "2021"\n[dependencies]\n%s = "=%s"\n' \
    "$name" "$version" > "$pkg/Cargo.toml"
  echo 'fn main() {}' > "$pkg/src/main.rs"
  (cd "$pkg" && cargo fetch -q)
  # Where cargo unpacked it, whatever the registry's source is called here.
  manifest="$(cargo metadata -q --format-version 1 --manifest-path "$pkg/Cargo.toml" \
    | grep -o "\"manifest_path\":\"[^\"]*/$name-$version/Cargo.toml\"" | head -n 1)"
  release="$(dirname "$(printf '%s' "$manifest" | sed 's/^"manifest_path":"//; s/"$//')")"
  if [ ! -f "$release/Cargo.toml" ]; then
    echo "vendor/check.sh: cargo did not unpack $name $version" >&2
    exit 1
  fi
  mkdir -p "$work/a/$name"
  cp -r "$release/Cargo.toml" "$release/LICENSE" "$release/README.md" "$release/src" "$work/a/$name/"
  if [ "${1:-}" = "--write" ]; then
    # Paths relative to vendor/, no timestamps: the patch changes only when the copy does.
    (cd "$work/a" && diff -ruN "$name" "$root/vendor/$name" | sed "s|$root/vendor/||" \
      | awk '/^(---|[+][+][+]) / { sub(/\t.*/, "") } { print }') \
      > "$root/vendor/$name.patch" || true
    echo "wrote vendor/$name.patch ($(wc -l < "$root/vendor/$name.patch") lines)"
    continue
  fi
  (cd "$work/a" && patch -s -p0 < "$root/vendor/$name.patch")
  if diff -r "$work/a/$name" "$root/vendor/$name"; then
    echo "vendor/$name: $name $version plus vendor/$name.patch"
  else
    echo "vendor/$name differs from $name $version plus vendor/$name.patch" >&2
    status=1
  fi
done
exit $status
