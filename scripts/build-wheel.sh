#!/usr/bin/env bash
# Builds the release artifacts of the Python package and checks them:
#
#   - a manylinux abi3 wheel (one wheel for CPython >= 3.9) by maturin with
#     --zig (the linker of the `ziglang` wheel targets glibc 2.17, so the wheel
#     is tagged manylinux_2_17 / manylinux2014 and runs on any x86-64 Linux
#     with glibc >= 2.17), compiled for the baseline x86-64 (the release
#     build of `pip install .`, without a target-cpu);
#   - an sdist (the workspace's sources, for `pip install edccif-*.tar.gz`);
#   - `twine check` of both, the wheel's tags (its WHEEL file), the glibc symbol
#     versions its extension needs (`auditwheel show`, and the highest GLIBC_x.y
#     of `objdump -T`, which must be <= 2.17);
#   - unless --no-test: scripts/test-wheel.sh, which installs the wheel into a
#     clean virtualenv with no cargo or rustc on PATH and runs the main job.
#
# Usage: bash scripts/build-wheel.sh [--out DIR] [--no-test] [--no-sdist]
#   --out DIR   where the wheel and the sdist go (default: dist; emptied of
#               earlier edccif artifacts first)
#
# The build tools (maturin, ziglang, twine, auditwheel) are installed into
# their own virtualenv, target/wheel-tools (reused by later runs), not into
# the caller's environment. The Rust build itself is the release build that
# `pip install .` makes (pyproject.toml's [tool.maturin]).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

out=dist
run_test=1
sdist=1
while [ $# -gt 0 ]; do
    case "$1" in
        --out) out="$2"; shift 2 ;;
        --no-test) run_test=0; shift ;;
        --no-sdist) sdist=0; shift ;;
        -h|--help) sed -n '2,23p' "$0"; exit 0 ;;
        *) echo "build-wheel.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done

step() { printf '\n==> %s\n' "$*"; }

export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"

step "build tools (maturin, ziglang, twine, auditwheel) in target/wheel-tools"
tools="$root/target/wheel-tools"
if [ ! -x "$tools/bin/python" ]; then
    mkdir -p "$root/target"
    python3 -m venv "$tools"
fi
"$tools/bin/python" -m pip install --quiet --upgrade pip
# maturin's `zig` extra pins the ziglang versions its --zig supports.
"$tools/bin/python" -m pip install --quiet 'maturin[zig]>=1.5,<2' 'twine>=5' 'auditwheel>=6'
maturin="$tools/bin/maturin"

mkdir -p "$out"
rm -f "$out"/edccif-*.whl "$out"/edccif-*.tar.gz

step "wheel: maturin build --release --zig (manylinux2014 = glibc 2.17, abi3)"
# maturin looks for the zig of the `ziglang` wheel through the interpreter
# that has it installed: put the tools' venv first on PATH.
PATH="$tools/bin:$PATH" "$maturin" build --release --zig --compatibility manylinux2014 --out "$out"
wheel=$(ls "$out"/edccif-*.whl)

if [ "$sdist" -eq 1 ]; then
    step "sdist: maturin sdist"
    "$maturin" sdist --out "$out"
fi

step "check: twine check"
"$tools/bin/python" -m twine check --strict "$out"/edccif-*

step "check: the wheel's tags"
"$tools/bin/python" - "$wheel" <<'EOF'
import sys
import zipfile

path = sys.argv[1]
with zipfile.ZipFile(path) as z:
    meta = next(n for n in z.namelist() if n.endswith(".dist-info/WHEEL"))
    tags = [line.split(":", 1)[1].strip() for line in z.read(meta).decode().splitlines()
            if line.startswith("Tag:")]
print(f"{path}:")
for t in tags:
    print(f"  Tag: {t}")
want = "cp39-abi3-manylinux_2_17_x86_64"
if not any(t == want or t == "cp39-abi3-manylinux2014_x86_64" for t in tags):
    sys.exit(f"the wheel is not tagged {want}: {tags}")
EOF

step "check: glibc symbol versions (auditwheel show; objdump -T)"
"$tools/bin/auditwheel" show "$wheel"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$tools/bin/python" -m zipfile -e "$wheel" "$tmp/unpacked"
for so in $(find "$tmp/unpacked" -name '*.so'); do
    versions=$(objdump -T "$so" | grep -o 'GLIBC_[0-9][0-9.]*' | sort -u -V)
    highest=$(printf '%s\n' $versions | tail -1)
    echo "$(basename "$so"): needs ${highest:-no glibc symbol} (all: $(echo $versions))"
    if [ -n "$highest" ] && [ "$(printf '%s\n%s\n' GLIBC_2.17 "$highest" | sort -V | tail -1)" != GLIBC_2.17 ]; then
        echo "$(basename "$so") needs $highest, above manylinux2014's GLIBC_2.17" >&2
        exit 1
    fi
done

if [ "$run_test" -eq 1 ]; then
    bash scripts/test-wheel.sh "$wheel"
fi

step "built"
ls -l "$out"/edccif-*
