#!/usr/bin/env bash
# Train surrogates on a lent accelerator in one call, then score and ship them back on a CPU.
#
#   scripts/device_train.sh [MINUTES] [CONFIG ...]        (default: 8 minutes, dem3d-cube dem3d-free)
#
# Made for the first command of a session with a 16-core GPU machine that starts bare: nothing is installed (the
# image has PyTorch; the package runs from src/ through PYTHONPATH), the configs train one after the other within
# MINUTES in all (at most 8, so that one 10-minute call finishes), with no validation during or after the runs, and
# every run's last snapshots and its log are copied to $OUT (at most 8 files of at most 16 MiB come back: 3
# snapshots and the log per config, two configs).  Back on the CPU:
#
#   rfmap validate /work/.device/.../dem3d-cube --ship runs/device      # score on the validation stream, ship best
#
# Environment (all optional): OUT (default ./device-out), DEVICE (cuda), PRESET (full), PRECISION (bf16: the network
# under bfloat16 autocast; fp32), THREADS (2), WORKERS (12),
# SNAPSHOT_EVERY (steps between snapshots, 250), KEEP (snapshots kept per config, 3), TRAIN_ARGS (options of
# rfmap train for every config; by default each config continues its shipped network, widened twofold by the
# function-preserving growth, on the size curriculum: 3D "--init CONFIG --grow 16 --n-range 24 64 --n-sampling log
# --batch-points 442368 --batch 16", 2D "--init CONFIG --grow 32 --n-range 32 256 --n-sampling log --batch-points
# 82944 --batch 32", both with "--lr 0.0002 --ema 0.999"; "--teacher flow" adds the classical teacher).
# Bad input (an unknown config, a non-numeric or out-of-range MINUTES) prints one line, exits 2 and writes nothing.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

MINUTES=${1:-8}
shift || true
CONFIGS=("$@")
[ ${#CONFIGS[@]} -gt 0 ] || CONFIGS=(dem3d-cube dem3d-free)
OUT=${OUT:-device-out}
DEVICE=${DEVICE:-cuda}
PRESET=${PRESET:-full}
PRECISION=${PRECISION:-bf16}
THREADS=${THREADS:-2}
WORKERS=${WORKERS:-12}
SNAPSHOT_EVERY=${SNAPSHOT_EVERY:-250}
KEEP=${KEEP:-3}
TRAIN_ARGS=${TRAIN_ARGS:-}
PY=${PYTHON:-python3}
export PYTHONPATH="$PWD/src${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1

fail() { echo "device_train: error: $*" >&2; exit 2; }
# every check before anything is written
"$PY" - "$MINUTES" "$PRESET" "$DEVICE" "$PRECISION" "${CONFIGS[@]}" <<'EOF' || exit 2
import sys
from rfmap.core.device import check_precision, resolve_device
from rfmap.training.config import get_config
minutes, preset, device, precision, *names = sys.argv[1:]
try:
    check_precision(precision, resolve_device(device))
except ValueError as e:
    sys.exit(print(f"device_train: error: {e}", file=sys.stderr) or 2)
try:
    m = float(minutes)
except ValueError:
    sys.exit(print(f"device_train: error: MINUTES must be a number, got {minutes!r}", file=sys.stderr) or 2)
if not 0 < m <= 8:
    sys.exit(print(f"device_train: error: MINUTES must lie in (0, 8], got {m:g}", file=sys.stderr) or 2)
for name in names:
    try:
        get_config(name, preset)
    except ValueError as e:
        sys.exit(print(f"device_train: error: {e}", file=sys.stderr) or 2)
EOF
[ "$KEEP" -ge 1 ] 2>/dev/null || fail "KEEP must be a positive integer, got '$KEEP'"
[ $(( KEEP * ${#CONFIGS[@]} + ${#CONFIGS[@]} )) -le 8 ] || fail "$(( KEEP + 1 )) files for each of ${#CONFIGS[@]} configs exceed the 8 files that come back"

# the seconds of each config: MINUTES in all, less a start-up allowance per run
PER=$("$PY" -c "print(max(5, int(($MINUTES * 60 - 20 * ${#CONFIGS[@]}) / ${#CONFIGS[@]})))")
WORK=$(mktemp -d)
mkdir -p "$OUT"
# the default options of a config: its shipped network grown twofold, on the size curriculum of its dimension
default_args() {
    case "$1" in
        *3d*) echo "--init $1 --grow 16 --n-range 24 64 --n-sampling log --batch-points 442368 --batch 16 --lr 0.0002 --ema 0.999" ;;
        *) echo "--init $1 --grow 32 --n-range 32 256 --n-sampling log --batch-points 82944 --batch 32 --lr 0.0002 --ema 0.999" ;;
    esac
}
for cfg in "${CONFIGS[@]}"; do
    ARGS=${TRAIN_ARGS:-$(default_args "$cfg")}
    echo "== $cfg: $PER s on $DEVICE, $ARGS"
    # shellcheck disable=SC2086  # TRAIN_ARGS is a list of options
    "$PY" -m rfmap.training --config "$cfg" --preset "$PRESET" --device "$DEVICE" --precision "$PRECISION" --threads "$THREADS" \
        --workers "$WORKERS" --time-limit "$PER" --steps 1000000 --no-validate --snapshot-every "$SNAPSHOT_EVERY" \
        --out "$WORK/$cfg" --no-progress $ARGS || echo "== $cfg: training failed (exit $?)"
    mkdir -p "$OUT/$cfg"
    cp "$WORK/$cfg/log.jsonl" "$OUT/$cfg/" 2>/dev/null || true
    if [ -d "$WORK/$cfg/snapshots" ]; then
        ls "$WORK/$cfg/snapshots"/*.safetensors | sort | tail -n "$KEEP" | xargs -I{} cp {} "$OUT/$cfg/"
    fi
    echo "== $cfg: $(ls "$OUT/$cfg" | tr '\n' ' ')"
done
rm -rf "$WORK"
