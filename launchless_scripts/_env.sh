# The environment of balance_calib: creates or refreshes .venv from the pinned requirements, installs
# this package into it (editable), and sets a loopback-only ROS 2 environment.
# Needs only python3.11 on PATH (or PYTHON=/path/to/python3.11).
#
# Two ways to use it:
#   source launchless_scripts/_env.sh     in your shell: afterwards balance-calib, the node
#                                         executables and launchless_scripts/* are on PATH. Your
#                                         shell's options are left as they were (no `set -e` that
#                                         would close the terminal at the next typo).
#   launchless_scripts/NAME               every script sources it first; inside a script it also
#                                         turns on `set -euo pipefail`, so the script stops at the
#                                         first failing command.
# It installs requirements-run.txt; with BALANCE_CALIB_REQUIREMENTS=test (launchless_scripts/test
# and colcon_check set it) requirements-test.txt, which adds pytest, hypothesis and colcon.
# A failed setup returns non-zero (sourced) or exits (scripts) with one line saying what failed.

_balance_calib_setup_venv() (
  # A subshell: `set -e` here stops the setup at the first error without touching the caller.
  set -euo pipefail
  venv="$BALANCE_CALIB_ROOT/.venv"
  python_bin="${PYTHON:-$(command -v python3.11 || command -v python3 || true)}"
  if [ -z "$python_bin" ]; then
    echo "[balance_calib] no python3.11 on PATH (set PYTHON=/path/to/python3.11)" >&2
    exit 1
  fi
  stamp="$venv/.requirements.sha256"
  # Two pinned sets: requirements-run.txt (what the nodes, balance-calib and the demo import) and
  # requirements-test.txt (run + pytest, hypothesis, mcap-ros2-support, colcon). The test set
  # contains the run set, so a venv set up for the tests also serves the demo.
  wanted="${BALANCE_CALIB_REQUIREMENTS:-run}"
  case "$wanted" in
    run|test) ;;
    *) echo "[balance_calib] BALANCE_CALIB_REQUIREMENTS=$wanted: expected run or test" >&2; exit 1 ;;
  esac
  hash="$(cat "$BALANCE_CALIB_ROOT/requirements-run.txt" "$BALANCE_CALIB_ROOT/requirements-test.txt" \
               "$BALANCE_CALIB_ROOT/setup.py" "$BALANCE_CALIB_ROOT/pyproject.toml" \
               "$BALANCE_CALIB_ROOT/balance_calib/live/_sample_kernel.c" | sha256sum | cut -d' ' -f1)"
  have="$(cat "$stamp" 2>/dev/null || true)"
  if [ ! -x "$venv/bin/python" ] || { [ "$have" != "$wanted:$hash" ] && [ "$have" != "test:$hash" ]; }; then
    echo "[balance_calib] setting up $venv from requirements-$wanted.txt (first use or requirements changed)..." >&2
    "$python_bin" -c 'import sys; assert sys.version_info[:2] == (3, 11), "balance_calib needs Python 3.11 (ROS 2 Jazzy wheels)"'
    [ -x "$venv/bin/python" ] || "$python_bin" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$BALANCE_CALIB_ROOT/requirements-$wanted.txt"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e "$BALANCE_CALIB_ROOT"
    echo "$wanted:$hash" > "$stamp"
  fi
)

BALANCE_CALIB_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export BALANCE_CALIB_ROOT
# Called plainly, not in `if`, `!`, `&&` or `||`: there bash would ignore the `set -e` inside it.
# (If the caller already runs with `set -e`, a failure stops the caller here, as it should.)
_balance_calib_setup_venv
_balance_calib_status=$?
if [ "$_balance_calib_status" != 0 ]; then
  echo "[balance_calib] setting up $BALANCE_CALIB_ROOT/.venv failed (see above)" >&2
  unset -f _balance_calib_setup_venv; unset _balance_calib_status
  case "$-" in
    *i*) return 1 ;;      # sourced in your shell: give the prompt back
    *) exit 1 ;;          # inside a script: stop it
  esac
fi
unset -f _balance_calib_setup_venv; unset _balance_calib_status
# The executables: .venv/bin (pip installs the package editable, PEP 660, as pyproject.toml is
# there); .venv/lib/balance_calib is where setup.cfg puts them for `setup.py develop` and colcon.
case ":$PATH:" in
  *":$BALANCE_CALIB_ROOT/.venv/bin:"*) ;;
  *) export PATH="$BALANCE_CALIB_ROOT/.venv/bin:$BALANCE_CALIB_ROOT/.venv/lib/balance_calib:$BALANCE_CALIB_ROOT/launchless_scripts:$PATH" ;;
esac
export VIRTUAL_ENV="$BALANCE_CALIB_ROOT/.venv"
# Real DDS, but never off this machine.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
export MPLBACKEND="${MPLBACKEND:-Agg}"
export PYTHONUNBUFFERED=1
# Small least-squares problems: threaded BLAS on 2 busy cores is ~10x slower than one thread.
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
# Inside a script (a non-interactive shell): fail fast. In an interactive shell: leave it alone.
case "$-" in
  *i*) ;;
  *) set -euo pipefail ;;
esac
