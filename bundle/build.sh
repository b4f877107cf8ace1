#!/usr/bin/env bash
# Builds the OpenFX bundle and prints its path:
#
#   bash bundle/build.sh                 # → target/release/nerfx.ofx.bundle
#   bash bundle/build.sh --profile test  # what the integration tests load (target/debug/…)
#
# Layout (OpenFX, Linux): nerfx.ofx.bundle/Contents/{Info.plist, Resources/<id>.png,
# Linux-x86-64/nerfx.ofx}, where nerfx.ofx is the plugin crate's cdylib renamed.
set -euo pipefail
cd "$(dirname "$0")/.."

profile=release
while (($#)); do
    case "$1" in
        --profile) profile="$2"; shift 2 ;;
        *) echo "usage: bash bundle/build.sh [--profile release|test|dev]" >&2; exit 2 ;;
    esac
done
case "$profile" in
    dev | test) dir=debug ;;
    *) dir="$profile" ;;
esac

cargo build --quiet -p nerfx-ofx --profile "$profile" >&2
target="${CARGO_TARGET_DIR:-target}/$dir"
bundle="$target/nerfx.ofx.bundle"
# Several test binaries may assemble at once: one at a time, and only when the binary changed.
# A changed binary goes in as a fresh copy (new inode), so a process that still maps the old
# one is not disturbed.
exec 9>"$target/.nerfx-bundle.lock"
flock 9
if ! cmp -s "$target/libnerfx_ofx.so" "$bundle/Contents/Linux-x86-64/nerfx.ofx"; then
    rm -rf "$bundle"
    mkdir -p "$bundle/Contents/Linux-x86-64" "$bundle/Contents/Resources"
    cp "$target/libnerfx_ofx.so" "$bundle/Contents/Linux-x86-64/nerfx.ofx"
fi
cp bundle/Info.plist "$bundle/Contents/"
cp bundle/Resources/*.png "$bundle/Contents/Resources/"
realpath "$bundle"
