#!/usr/bin/env bash
# Checks that no modules import each other in a circle, installs edccif with its
# test tools and runs every check: Rust format, lints,
# the API docs, the no_std build, the Rust test suites, the Python suite, ruff
# and the stub check.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s (%d s so far)\n' "$*" "$SECONDS"; }
disk() { df -h . | awk 'NR==2 {print "disk: " $4 " free on " $6}'; du -sh target 2>/dev/null | sed 's/^/target: /' || true; }

# Keep the build small on disk: a full workspace test build with debug info and
# incremental caches needs several GB, and every doctest links its own binary.
# Line tables keep backtraces readable. Either can be overridden from outside.
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
export CARGO_PROFILE_DEV_DEBUG="${CARGO_PROFILE_DEV_DEBUG:-line-tables-only}"
disk

# Pure Python, a second: a cycle fails CI before anything is built.
step "no import cycles between the modules of any crate or of the Python package"
python3 scripts/check_imports.py --self-test
python3 scripts/check_imports.py

step "install (maturin builds the extension; numpy, matplotlib, pytest, mypy, ruff, mcap, evo, dask, zenoh)"
python3 -m pip install --quiet --upgrade pip
# The tests time nothing, so the extension is built without the release
# profile's link-time optimisation, single code-generation unit and debug
# info, which cost minutes on a two-core runner and change no result (Rust
# does not reorder floating-point operations at any optimisation setting).
CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16 CARGO_PROFILE_RELEASE_DEBUG=0 \
    python3 -m pip install --quiet --only-binary=dask,distributed,eclipse-zenoh '.[test,evo,sweep,agents]'

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (all targets, warnings are errors)"
cargo clippy --workspace --all-targets -- -D warnings

step "cargo doc (warnings are errors: broken, ambiguous or private intra-doc links)"
# --no-deps documents the workspace crates only (about 20 MB, well under a
# minute); the dependencies are only checked for their metadata.
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps

step "edccif-core builds without std (no_std, no alloc)"
cargo build -p edccif-core --no-default-features

step "cargo test"
# The bindings crate is a cdylib without Rust tests (its doctests cannot run:
# no rlib); pytest tests it through the installed extension.
cargo test --workspace --exclude edccif-py

disk

step "pytest"
# Run from outside the source tree so the installed package is the one tested.
# pytest exits 5 when it collected no test: that must fail too.
set +e
(cd /tmp && python3 -m pytest -q "$OLDPWD/python/tests" -p no:cacheprovider)
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "pytest collected no tests" >&2
    exit 1
fi
[ "$rc" -eq 0 ] || exit "$rc"

step "ruff"
python3 -m ruff check python $( [ -d benchmarks ] && echo benchmarks )

step "stubs match the extension (mypy.stubtest)"
(cd /tmp && python3 -m mypy.stubtest edccif._edccif --ignore-missing-stub)

disk
printf '\nall checks passed\n'
