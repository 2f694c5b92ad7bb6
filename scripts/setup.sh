#!/usr/bin/env bash
# One-shot set-up of a fresh machine: the Debian FreeCAD package (for STEP import tests, when root),
# a virtual environment in .venv and the pinned Python stack (torch 2.13.0 CPU; cadquery 2.8.0 + build123d 0.12.0
# on OCP 7.9.3; no torchvision; the ray extra for --executor ray). Safe to run again and from several shells at
# once: it takes a lock, and only does what is missing (the stamp .venv/.v2c-installed records a hash of
# pyproject.toml and of this install recipe).
#
# Environment: PYTHON (interpreter for the venv, default python3.11), V2C_WHEELS (folder with a local torch CPU
# wheel, default /opt/wheels), V2C_SKIP_FREECAD=1 (do not apt-get FreeCAD).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
RECIPE=6  # bump when the install steps below change, so existing venvs are brought up to date

log() { echo "[setup] $*"; }
die() { echo "[setup] ERROR: $*" >&2; exit 1; }

# Serialise concurrent runs (several `make test` at once would otherwise run pip into the same venv together).
LOCK="${TMPDIR:-/tmp}/v2c-setup-$(printf '%s' "$ROOT" | md5sum | cut -c1-12).lock"
exec 9>"$LOCK"
flock 9

# --- FreeCAD (Debian package; used only by tests that re-import our STEP files) ---------------------------------
if ! command -v freecadcmd >/dev/null 2>&1 && [ "${V2C_SKIP_FREECAD:-0}" != "1" ]; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    log "installing Debian freecad (FreeCAD 0.20, used by the STEP import tests; about 1.4 GB)"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq && apt-get install -y -qq --no-install-recommends freecad >/dev/null \
      || log "WARNING: apt-get install freecad failed; FreeCAD import tests will be skipped"
  else
    log "freecadcmd not found and not root: FreeCAD import tests will be skipped" >&2
  fi
fi

# --- virtual environment ------------------------------------------------------------------------------------------
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c 'import sys; assert sys.version_info[:2] == (3, 11)' 2>/dev/null; then
  "$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11)' 2>/dev/null \
    || die "need Python 3.11 (set PYTHON=/path/to/python3.11); $PY is $("$PY" --version 2>&1)"
  log "creating .venv with $("$PY" --version)"
  rm -rf .venv
  "$PY" -m venv .venv
fi
VPY=.venv/bin/python

STAMP=.venv/.v2c-installed
TORCH_VERSION=2.13.0  # keep equal to the torch pin of pyproject.toml
install_torch() {
  # The CPU build, installed alone, so nothing pulls the multi-GB CUDA wheels. A local wheel is used when the
  # machine has one; otherwise the PyTorch CPU index (its X+cpu sorts above PyPI's X).
  if ! "$VPY" -c "import torch, sys; sys.exit(0 if torch.__version__.split('+')[0] == '$TORCH_VERSION' else 1)" 2>/dev/null; then
    WHL=$(ls "${V2C_WHEELS:-/opt/wheels}"/torch-"$TORCH_VERSION"+cpu-cp311-*.whl 2>/dev/null | head -n1 || true)
    if [ -n "$WHL" ]; then
      log "torch $TORCH_VERSION CPU from $WHL"
      "$VPY" -m pip install -q "$WHL"
    else
      log "torch $TORCH_VERSION CPU from the PyTorch CPU index"
      "$VPY" -m pip install -q "torch==$TORCH_VERSION" --extra-index-url https://download.pytorch.org/whl/cpu
    fi
  fi
}
# build123d's cadquery-ocp-novtk requirement is met by a files-less stand-in (scripts/shims/cadquery-ocp-novtk),
# so the no-VTK OCP wheel is never installed over cadquery-ocp's OCP/ (scripts/ocp_single.py checks it).
SHIM=scripts/shims/cadquery-ocp-novtk
install_shim() {
  if ! "$VPY" -c 'import importlib.metadata as m, sys; d = m.distribution("cadquery-ocp-novtk"); sys.exit(0 if not any(str(f).startswith("OCP/") for f in d.files or []) else 1)' 2>/dev/null; then
    log "cadquery-ocp-novtk stand-in ($SHIM): build123d's OCP requirement met by cadquery-ocp"
    "$VPY" -m pip install -q --no-build-isolation --no-deps "./$SHIM"
  fi
}
WANT="recipe=$RECIPE pyproject=$(sha256sum pyproject.toml $SHIM/pyproject.toml | sha256sum | cut -c1-16)"
if [ "$(cat "$STAMP" 2>/dev/null || true)" != "$WANT" ]; then
  if [ -f "$STAMP" ]; then
    # An installed venv whose pyproject changed: add only what is missing, so pip does not re-resolve the CAD
    # stack (that would bring cadquery-ocp-novtk back over the OCP binary while others use the venv).
    log "updating .venv: installing only the requirements it lacks"
    rm -f "$STAMP"
    install_torch
    "$VPY" scripts/ocp_single.py --fix  # a venv of an older recipe: its no-VTK copy goes through pip, not by hand
    install_shim
    mapfile -t MISSING < <("$VPY" scripts/missing_reqs.py | grep -v -E '^torch([^a-z0-9_-]|$)' || true)
    if [ "${#MISSING[@]}" -gt 0 ]; then
      log "installing: ${MISSING[*]}"
      "$VPY" -m pip install -q "${MISSING[@]}"
    fi
    "$VPY" -m pip install -q --no-deps -e .
  else
    log "installing Python packages into .venv (a few minutes on a fresh machine)"
    "$VPY" -m pip install -q --upgrade pip setuptools wheel
    install_torch
    install_shim
    # Everything else in ONE resolve (pyproject pins cadquery==2.8.0 and build123d==0.12.0 side by side).
    "$VPY" -m pip install -q -e ".[dev,ray]"
  fi
  # exactly one distribution owns site-packages/OCP/ and its files match that distribution's RECORD
  "$VPY" scripts/ocp_single.py --fix --hashes
  if "$VPY" -m pip list 2>/dev/null | grep -qi '^torchvision '; then
    die "torchvision is installed: its wheels here are CUDA builds that break imports (NOTES.md); remove it"
  fi
  V2C_TORCH=$TORCH_VERSION "$VPY" -c 'import os, OCP, OCP.IVtkOCC, build123d, cadquery, torch, cv2
assert torch.__version__.split("+")[0] == os.environ["V2C_TORCH"] and not torch.version.cuda, torch.__version__
assert build123d.__version__ == "0.12.0" and cadquery.__version__ == "2.8.0", (build123d.__version__, cadquery.__version__)
v = build123d.Box(1, 2, 3).volume
assert abs(v - 6) < 1e-9, v
assert abs(cadquery.Workplane().box(1, 2, 3).val().Volume() - 6) < 1e-9
' || die "the installed stack does not import or work (see above)"
  # pip check is clean: every requirement (build123d's OCP one through the stand-in) is met
  PC=$("$VPY" -m pip check 2>&1 || true)
  PC=$(printf '%s\n' "$PC" | grep -v -e '^No broken requirements found' || true)
  if [ -n "$PC" ]; then log "WARNING: pip check: $PC"; fi
  echo "$WANT" > "$STAMP"
else
  # fast path (every `make test`): metadata-only check that nothing brought a second OCP distribution back
  "$VPY" scripts/ocp_single.py >/dev/null || { "$VPY" scripts/ocp_single.py --fix --hashes && install_shim; }
fi
log "ready: $("$VPY" -c 'import importlib.metadata as m; print(", ".join(f"{p} {m.version(p)}" for p in ("torch", "cadquery", "build123d", "cadquery-ocp")))')"
