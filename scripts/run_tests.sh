#!/usr/bin/env bash
# Every test of `make test`, at CI scale, in three independent steps that run side by side:
#
#   pytest      the library's tests (tests/)
#   nbval       every chapter through the rfmap kernel, from notebooks/ (its figures go to a temporary folder,
#               so that it never writes a file the book build is reading)
#   book        the Jupyter Book build with warnings as errors (every chapter executed again, figures to book/figures),
#               then scripts/book_text_check.py (no unresolved placeholder, no raw repr on any page)
#
# Each step is single-threaded (OMP_NUM_THREADS=1), so that three steps on a 2-core machine share the cores instead
# of fighting over them; each writes its output to _build/test-logs/STEP.log, which is printed when all have ended.
# Exit status: 0 when every step passed, else 1 (the failed steps are named on the last line).
#
#   scripts/run_tests.sh BIN NBVAL_FLAGS BOOK_FLAGS         (as the Makefile calls it)
set -uo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
BIN=$1 NBVAL_FLAGS=$2 BOOK_FLAGS=$3
ROOT=$PWD
LOGS=$ROOT/_build/test-logs
mkdir -p "$LOGS"
NBFIG=$(mktemp -d)
trap 'rm -rf "$NBFIG"' EXIT
export RFMAP_SCALE=ci OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
NB_ENV=(env VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow "PATH=$ROOT/$BIN:$PATH")

declare -A PIDS
start=$(date +%s)
"$BIN/pytest" tests/ >"$LOGS/pytest.log" 2>&1 & PIDS[pytest]=$!
(cd notebooks && RFMAP_FIGURES=$NBFIG "${NB_ENV[@]}" "$ROOT/$BIN/pytest" $NBVAL_FLAGS .) >"$LOGS/nbval.log" 2>&1 &
PIDS[nbval]=$!
("${NB_ENV[@]}" "$BIN/jupyter-book" build . $BOOK_FLAGS && "$BIN/python" scripts/book_text_check.py --html _build/html) \
    >"$LOGS/book.log" 2>&1 & PIDS[book]=$!

failed=()
for step in pytest nbval book; do
    if wait "${PIDS[$step]}"; then status=passed; else status=FAILED; failed+=("$step"); fi
    echo "===== $step: $status ($(( $(date +%s) - start )) s since the start; log: _build/test-logs/$step.log)"
    if [ "$status" = FAILED ] || [ "$step" != book ]; then tail -n 40 "$LOGS/$step.log"; else tail -n 5 "$LOGS/$step.log"; fi
done
if [ ${#failed[@]} -gt 0 ]; then
    echo "make test: failed: ${failed[*]}" >&2
    exit 1
fi
echo "make test: pytest, nbval and the book build passed in $(( $(date +%s) - start )) s"
