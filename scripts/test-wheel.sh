#!/usr/bin/env bash
# Installs a built wheel into a clean virtualenv, with no cargo and no rustc on
# PATH, and runs the main job from outside the source tree:
#
#   edccif reproduce --runs 2 --nodes 3 4 8 --no-figures --no-flights
#
# (the paper's tables at 2 Monte Carlo runs instead of 100, without the figures,
# the timing pass and the real flights: the extension, the CLI and every row of
# the tables, in about a minute), then checks that the package imported is the
# installed one and that the tables were written.
#
# Usage: bash scripts/test-wheel.sh dist/edccif-*.whl
# The wheel's dependencies (numpy, matplotlib, tqdm) come from the package
# index as binary wheels (--only-binary :all:): nothing is compiled.
set -euo pipefail
[ $# -eq 1 ] || { echo "usage: test-wheel.sh WHEEL" >&2; exit 2; }
wheel=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
[ -f "$wheel" ] || { echo "test-wheel.sh: no such wheel: $1" >&2; exit 2; }

printf '\n==> %s\n' "the wheel in a clean virtualenv, no Rust toolchain on PATH: $(basename "$wheel")"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 -m venv "$tmp/venv"
"$tmp/venv/bin/python" -m pip install --quiet --upgrade pip
"$tmp/venv/bin/python" -m pip install --quiet --only-binary :all: "$wheel"

# Only the venv's bin and the system's base directories; cargo and rustc must
# not be reachable from there (rustup installs them in ~/.cargo/bin).
clean_path="$tmp/venv/bin:/usr/bin:/bin"
for tool in cargo rustc maturin; do
    if PATH="$clean_path" command -v "$tool" >/dev/null 2>&1; then
        echo "test-wheel.sh: $tool is on the clean PATH ($(PATH="$clean_path" command -v "$tool")); cannot show an install without a Rust toolchain" >&2
        exit 1
    fi
done

mkdir -p "$tmp/work"
cd "$tmp/work"
start=$(date +%s)
env -i HOME="$tmp" PATH="$clean_path" LANG=C.UTF-8 \
    python -c 'import edccif, sys; print("edccif", edccif.__version__, "from", edccif.__file__); sys.exit(0 if edccif.__file__.startswith(sys.prefix) else "not the installed package")'
# The tables go to the log (shown if the job fails); the files are checked below.
if ! env -i HOME="$tmp" PATH="$clean_path" LANG=C.UTF-8 \
    edccif reproduce --runs 2 --nodes 3 4 8 --no-figures --no-flights --quiet --out "$tmp/work/results" \
    > "$tmp/reproduce.log" 2>&1; then
    cat "$tmp/reproduce.log" >&2
    echo "test-wheel.sh: edccif reproduce failed" >&2
    exit 1
fi
for f in results.md results.json; do
    [ -s "$tmp/work/results/$f" ] || { echo "test-wheel.sh: reproduce wrote no $f" >&2; exit 1; }
done
grep -q 'EDC-CIF' "$tmp/work/results/results.md" || { echo "test-wheel.sh: results.md has no EDC-CIF row" >&2; exit 1; }
echo "the installed wheel ran the main job in $(( $(date +%s) - start )) s (results.md: $(wc -l < "$tmp/work/results/results.md") lines)"
