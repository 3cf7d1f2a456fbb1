#!/usr/bin/env bash
# The release artefacts of this platform, in one folder with their SHA256SUMS:
#   campro-VERSION-cp39-abi3-manylinux_*.whl   the wheel: the `campro` command and `import campro`
#   campro-VERSION.tar.gz                      the sdist (builds the wheel anywhere with Rust)
#   campro-VERSION-x86_64-unknown-linux-gnu.tar.gz   the stripped `campro` binary, LICENSE, README
# Usage: bash docs/scripts/release.sh [OUT]   (default target/release-artefacts; refuses a
# folder that already holds files). The wheel and the binary are built with the workspace's
# release profile on its target folder, so a tree that ran the tests compiles little.
# A release runs it on each platform of the matrix in docs/python.md.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-target/release-artefacts}
if [ -d "$out" ] && [ -n "$(ls -A "$out")" ]; then
  echo "error: $out already holds files; give an empty or new folder" >&2
  exit 1
fi
mkdir -p "$out"
python3 -m maturin --version >/dev/null 2>&1 || python3 -m pip install -q 'maturin>=1.9,<2'
version=$(sed -n 's/^version = "\(.*\)"/\1/p' crates/campro-py/Cargo.toml | head -n 1)
triple=$(rustc -vV | sed -n 's/^host: //p')
start=$(date +%s)
python3 -m maturin build --locked --release --out "$out"
python3 -m maturin sdist --out "$out"
cargo build --locked --release -p campro-cli
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
dir="$stage/campro-$version-$triple"
mkdir -p "$dir"
strip -o "$dir/campro" target/release/campro
cp LICENSE README.md "$dir/"
tar -C "$stage" -czf "$out/campro-$version-$triple.tar.gz" "campro-$version-$triple"
(cd "$out" && sha256sum -- *.whl *.tar.gz > SHA256SUMS)
echo "built in $(( $(date +%s) - start )) s:"
(cd "$out" && ls -l -- *.whl *.tar.gz SHA256SUMS)
