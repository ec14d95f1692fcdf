# Sourced by the launch scripts: make .venv on a fresh clone, install multigpu into it, and
# install MPI from the `mpich` wheel when no system `mpiexec` exists. Idempotent and quick
# when nothing changed (a stamp keyed on pyproject.toml).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${MULTIGPU_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -m venv "$VENV"
fi
STAMP="$VENV/.multigpu-installed"
WANT="$(cat "$ROOT/pyproject.toml" | sha1sum | cut -d' ' -f1)"
if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$WANT" ]; then
    EXTRAS="test,plots,video,bench"
    if ! command -v mpiexec >/dev/null 2>&1 && [ ! -x "$VENV/bin/mpiexec" ]; then
        EXTRAS="$EXTRAS,mpich"
    fi
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e "$ROOT[$EXTRAS]"
    echo "$WANT" > "$STAMP"
fi
export PATH="$VENV/bin:$PATH"
# llvmpipe's rasterizer threads: each rank chooses (gpu/render.py raster_threads) unless
# LP_NUM_THREADS is set here.
