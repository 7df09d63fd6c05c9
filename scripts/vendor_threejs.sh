#!/usr/bin/env bash
# Re-fetch the three.js files the browser viewer inlines (torchsplice/viz/vendor/) from npm.
#
# Usage: bash scripts/vendor_threejs.sh [VERSION]   (default: the pinned version below)
# Needs npm (the registry only; nothing is installed). 0.185.0 is the newest release whose npm
# package still ships the minified builds (build/three.core.min.js, build/three.module.min.js).
set -euo pipefail
version="${1:-0.185.0}"
root="$(cd "$(dirname "$0")/.." && pwd)"
dest="$root/torchsplice/viz/vendor"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
(cd "$work" && npm pack --silent "three@$version" >/dev/null && tar xzf "three-$version.tgz")
pkg="$work/package"
mkdir -p "$dest"
for f in build/three.core.min.js build/three.module.min.js examples/jsm/controls/OrbitControls.js LICENSE; do
  [ -f "$pkg/$f" ] || { echo "vendor_threejs: three@$version has no $f" >&2; exit 1; }
done
cp "$pkg/build/three.core.min.js" "$pkg/build/three.module.min.js" "$dest/"
cp "$pkg/examples/jsm/controls/OrbitControls.js" "$dest/OrbitControls.js"
cp "$pkg/LICENSE" "$dest/LICENSE"
echo "$version" > "$dest/VERSION"
echo "vendored three@$version into $dest"
