# Sourced by the launch scripts: make .venv on a fresh clone, install multigpu into it with MPI from
# the `mpich` wheel (the machine's own mpiexec, where it had one when the venv was made, stays the
# default). Idempotent and quick when nothing changed (a stamp keyed on pyproject.toml).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${MULTIGPU_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -m venv "$VENV"
fi
STAMP="$VENV/.multigpu-installed"
WANT="$(cat "$ROOT/pyproject.toml" | sha1sum | cut -d' ' -f1)"
# The machine's own MPI, where it has one when the venv is made, stays the default: its mpiexec is
# pinned (MULTIGPU_MPIEXEC, below) before the mpich wheel, always installed so that the MPICH tests
# run anywhere, puts its own mpiexec first on PATH.
PIN="$VENV/.multigpu-system-mpiexec"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$WANT" ]; then
    if [ ! -x "$VENV/bin/mpiexec" ] && [ ! -f "$PIN" ]; then
        SYSTEM_MPIEXEC="$(PATH="$(echo "$PATH" | tr ':' '\n' | grep -vxF "$VENV/bin" | paste -sd:)" command -v mpiexec || true)"
        [ -n "$SYSTEM_MPIEXEC" ] && echo "$SYSTEM_MPIEXEC" > "$PIN"
    fi
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e "$ROOT[test,plots,video,bench,mpich]"
    echo "$WANT" > "$STAMP"
fi
if [ -z "${MULTIGPU_MPIEXEC:-}" ] && [ -s "$PIN" ]; then
    export MULTIGPU_MPIEXEC="$(cat "$PIN")"
fi
export PATH="$VENV/bin:$PATH"
# llvmpipe's rasterizer threads: each rank chooses (gpu/render.py raster_threads) unless
# LP_NUM_THREADS is set here.
