#!/usr/bin/env bash
# The wheel as a user gets it: built from this tree, installed into a fresh virtual environment
# (not editable; it sees nothing of .venv or of this checkout), then the installed command runs:
# --version, one `evaluate`, the resources from the installed package, and the GUI smoke test.
#
#   packaging/check_wheel.sh [WHEEL]      # default: build one from this tree with pip
#
# Slow (about 1-2 min: a new venv and PySide6, numba, numpy, vqf from pip's cache or the
# index), so CI runs it after the test suite (.ci/run) instead of inside pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
WORK=$(mktemp -d "${TMPDIR:-/tmp}/inclinometer-wheel.XXXXXX")
trap 'rm -rf "$WORK"' EXIT
start=$SECONDS

if [ $# -ge 1 ]; then
    WHEEL=$(realpath "$1")
else
    "$PYTHON" -m pip wheel --quiet --no-deps --wheel-dir "$WORK/wheel" . >"$WORK/build.log" 2>&1 \
        || { cat "$WORK/build.log"; exit 1; }
    WHEEL=$(ls "$WORK"/wheel/inclinometer-*.whl)
fi
echo "check_wheel: $(basename "$WHEEL") built in $((SECONDS - start)) s"

"$PYTHON" -m venv "$WORK/venv"
"$WORK/venv/bin/python" -m pip install --quiet "$WHEEL" >"$WORK/install.log" 2>&1 \
    || { cat "$WORK/install.log"; exit 1; }
echo "check_wheel: installed into a fresh venv with its dependencies in $((SECONDS - start)) s"

# Run from an empty folder with the user's directories redirected: nothing comes from this
# checkout and nothing is written to the real home.
cd "$WORK"
export XDG_CACHE_HOME="$WORK/cache" XDG_CONFIG_HOME="$WORK/config" XDG_DATA_HOME="$WORK/data"
export XDG_STATE_HOME="$WORK/state" QT_QPA_PLATFORM=offscreen
BIN="$WORK/venv/bin"
"$BIN/python" - <<'PY'
import importlib.metadata as metadata
import app, drivers, resources
from app.core.recording import sample_recordings

for module in (app, drivers, resources):
    assert "site-packages" in module.__file__, f"{module.__name__} from {module.__file__}"
direct = metadata.distribution("inclinometer").read_text("direct_url.json") or ""
assert '"editable": true' not in direct, "an editable install"
assert len(sample_recordings()) >= 3, sample_recordings()
print(f"check_wheel: app, drivers and resources from {app.__file__.rsplit('/app/', 1)[0]}, "
      f"{len(sample_recordings())} sample recordings")
PY
"$BIN/inclinometer" --version
"$BIN/inclinometer" evaluate "sim://static?odr=52" --seconds 5 --filter ekf vqf
"$BIN/inclinometer" --smoke-test 2> >(grep -v propagateSizeHints >&2)
echo "check_wheel: passed in $((SECONDS - start)) s"
