#!/usr/bin/env bash
# Make ./.venv with torchsplice installed, once; later runs reuse it.
#
# torch comes first so that pip installs nothing more for it: by default torch==2.13.0 from
# pip's configured index (PyPI's Linux build includes CUDA). Choose another with TORCHSPLICE_TORCH
# (a pip requirement) and TORCHSPLICE_TORCH_INDEX (an index URL, e.g.
# https://download.pytorch.org/whl/cpu for the CPU-only build).
# Source it (". scripts/setup_env.sh") to get the environment activated.
set -euo pipefail
# pip's notes about unused local package folders on some machines are noise here
_pip() { python -m pip "$@" --quiet --disable-pip-version-check 2> >(grep -v "is ignored: it is neither" >&2); }
_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_py="${PYTHON:-python3}"
if [ ! -x "$_root/.venv/bin/python" ]; then
  echo "setup: creating $_root/.venv" >&2
  "$_py" -m venv "$_root/.venv"
fi
# shellcheck disable=SC1091
. "$_root/.venv/bin/activate"
if ! python -c "import torch" >/dev/null 2>&1; then
  echo "setup: installing ${TORCHSPLICE_TORCH:-torch==2.13.0}" >&2
  _pip install "${TORCHSPLICE_TORCH:-torch==2.13.0}" \
    ${TORCHSPLICE_TORCH_INDEX:+--index-url "$TORCHSPLICE_TORCH_INDEX"}
fi
# extras: the tests also install Ray and the documentation's tools (TORCHSPLICE_EXTRAS=test,ray,docs, set by
# scripts/test.sh)
_extras="${TORCHSPLICE_EXTRAS:-test}"
# The stamp holds the pyproject.toml checksum and the extras installed: a later run with fewer
# extras (the demo after the tests) reuses the environment instead of reinstalling.
_stamp="$_root/.venv/.torchsplice-installed"
# (with a mark of how it installs: "repository-pth", the .pth below)
_sum="$(cksum < "$_root/pyproject.toml") repository-pth"
_have="$(cat "$_stamp" 2>/dev/null || true)"
_install=0
if [ "${_have% *}" != "$_sum" ]; then
  _install=1
else
  _had="${_have##* }"
  _add=""
  for _e in ${_extras//,/ }; do
    case ",$_had," in *",$_e,"*) ;; *) _add="$_add,$_e" ;; esac
  done
  if [ -n "$_add" ]; then _install=1; _extras="$_had$_add"; fi
fi
if [ "$_install" = 1 ]; then
  echo "setup: installing torchsplice and its dependencies" >&2
  _pip install -e "$_root[$_extras]"
  # the repository's folder on sys.path too (after everything else), so that a script or `python -m`
  # run from the clone's parent folder (itself named torchsplice) imports the package, not the clone
  # as an empty namespace package ("cannot import name '__version__' from 'torchsplice'"): a regular
  # package anywhere on sys.path wins over a namespace one
  echo "$_root" > "$(python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/torchsplice-repository.pth"
  echo "$_sum $_extras" > "$_stamp"
fi
# compile the CPU splicer's kernels once per version of their sources (numba caches them)
_kernels="$(cat "$_root"/torchsplice/cpu/*.py "$_root"/torchsplice/core/quat_formulas.py | cksum)"
if [ ! -f "$_root/.venv/.torchsplice-kernels" ] || [ "$(cat "$_root/.venv/.torchsplice-kernels")" != "$_kernels" ]; then
  python -m torchsplice.warmup
  echo "$_kernels" > "$_root/.venv/.torchsplice-kernels"
fi
