#!/usr/bin/env bash
# The one test command (README, `.ci/run`): the Rust tests of the workspace, then the Python
# package built from ./python by maturin, installed into a virtual environment with its test
# dependencies, and its pytest tests (python/tests), which compare it with the `iuq` binary.
#
#   bash scripts/test.sh
#
# Environment: IUQ_VENV (default target/python-venv), PYTHON (interpreter for the venv, default
# python3, CPython >= 3.9), PYTEST_ARGS (extra pytest arguments).
set -euo pipefail
cd "$(dirname "$0")/.."

cargo test --workspace --locked

venv="${IUQ_VENV:-target/python-venv}"
build_flags=(--no-build-isolation)
if [ -x "$venv/bin/python" ] || "${PYTHON:-python3}" -m venv "$venv"; then
    py="$venv/bin/python"
    export PATH="$PWD/$venv/bin:$PATH"
else
    # No venv module (e.g. Debian without python3-venv): the interpreter's own site, as .ci/run
    # installs umbridge; pip builds the package in an isolated environment with maturin.
    echo "scripts/test.sh: cannot create $venv; installing into ${PYTHON:-python3}'s site" >&2
    py="${PYTHON:-python3}"
    build_flags=()
fi
"$py" -m pip install --quiet "maturin>=1.5,<2" pytest numpy scikit-learn SALib scipy \
    arviz pandas nbclient nbformat ipykernel
# --no-build-isolation (in the venv): build with the maturin just installed. The extension is
# built in the dev profile (optimised, opt-level 2), reusing what `cargo test` just compiled
# instead of a second, release build of every crate; its results equal the release build's.
MATURIN_PEP517_ARGS="--profile dev" \
    "$py" -m pip install --quiet "${build_flags[@]}" --no-deps --force-reinstall ./python
# The command line the Python tests compare with: the binary `cargo test` built (the test
# profile is optimised, and its results equal the release build's bit for bit).
IUQ_BIN="$PWD/target/debug/iuq" IUQ_REQUIRE_CLI=1 "$py" -m pytest python/tests -q ${PYTEST_ARGS:-}
