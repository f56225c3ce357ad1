# Sourced by the launchless scripts: creates or refreshes .venv from the pinned requirements,
# installs this package into it (editable), and sets a loopback-only ROS 2 environment.
# Needs only python3.11 on PATH (or PYTHON=/path/to/python3.11).
set -euo pipefail
BALANCE_CALIB_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export BALANCE_CALIB_ROOT
venv="$BALANCE_CALIB_ROOT/.venv"
python_bin="${PYTHON:-$(command -v python3.11 || command -v python3)}"
stamp="$venv/.requirements.sha256"
want="$(cat "$BALANCE_CALIB_ROOT/requirements.txt" "$BALANCE_CALIB_ROOT/setup.py" | sha256sum | cut -d' ' -f1)"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "[balance_calib] setting up $venv from requirements.txt (first use or requirements changed)..." >&2
  "$python_bin" -c 'import sys; assert sys.version_info[:2] == (3, 11), "balance_calib needs Python 3.11 (ROS 2 Jazzy wheels)"'
  [ -x "$venv/bin/python" ] || "$python_bin" -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$BALANCE_CALIB_ROOT/requirements.txt"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e "$BALANCE_CALIB_ROOT"
  echo "$want" > "$stamp"
fi
# setup.cfg puts the executables where ros2 run looks for them: lib/balance_calib
export PATH="$venv/bin:$venv/lib/balance_calib:$PATH"
export VIRTUAL_ENV="$venv"
# Real DDS, but never off this machine.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
export MPLBACKEND="${MPLBACKEND:-Agg}"
export PYTHONUNBUFFERED=1
# Small least-squares problems: threaded BLAS on 2 busy cores is ~10x slower than one thread.
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
