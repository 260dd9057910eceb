#!/usr/bin/env bash
# Create .venv (or $AVRISK_VENV) and install avrisk with the given extras.
#   scripts/setup.sh            -> runtime only
#   scripts/setup.sh dev        -> with test tools
#   scripts/setup.sh dev,bench  -> with the benchmark comparators too
#   scripts/setup.sh dev,ray    -> with Ray (make test: the `ray` tests run)
# Uses uv when it can be installed (about ten times faster than pip), else pip.
# Honours a local wheel folder configured for pip (`pip config list`, find-links),
# which is where a CPU-only torch wheel may live.
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"
venv="${AVRISK_VENV:-.venv}"
python="${PYTHON:-python3}"

[ -x "$venv/bin/python" ] || "$python" -m venv "$venv"
spec="."
[ -n "$extras" ] && spec=".[$extras]"

find_links=()
for dir in $("$venv/bin/python" -m pip config list 2>/dev/null \
             | sed -n "s/^[^=]*find-links='\(.*\)'$/\1/p"); do
    [ -d "$dir" ] && find_links+=(--find-links "$dir")
done

# Bytecode is compiled at install (pip does so by default, uv when asked): where
# PYTHONDONTWRITEBYTECODE is set, a process would otherwise compile the ~3,500
# modules it imports (torch's among them) from source every time it starts,
# seconds per command (BENCHMARKS.md, "Start-up").
if "$venv/bin/python" -m pip install -q uv >/dev/null 2>&1; then
    "$venv/bin/python" -m uv pip install -q --compile-bytecode \
        --python "$venv/bin/python" "${find_links[@]}" -c constraints.txt -e "$spec"
else
    "$venv/bin/python" -m pip install -q "${find_links[@]}" -c constraints.txt -e "$spec"
fi
"$venv/bin/python" -m compileall -q avrisk >/dev/null
echo "avrisk installed in $venv ($("$venv/bin/python" -c 'import avrisk; print(avrisk.__version__)'))"
