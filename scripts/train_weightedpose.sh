#!/usr/bin/env bash
# The three WeightedPose variants, trained at once (three processes on the two cores) from a
# trained Goal Flow and TAX-Pose, then `--select-best`.
#   scripts/train_weightedpose.sh ROOT [GF_DIR] [TP_DIR]
# ROOT receives gf/ and tp/ (copies of GF_DIR and TP_DIR, default policies/weights/{gf,tp}, without
# their resume checkpoints), wp-og/, wp-postsvd/, wp-postsvd-t/ and best.json. Logs (with peak
# memory from /usr/bin/time -v) go to runs/logs/<basename ROOT>-<variant>.log.
# Environment: DATA (default data3), MINUTES (default 20), STEPS (a budget in optimiser steps, which
# makes the weights independent of the three sharing the cores; MINUTES is then only a cap),
# THREADS (torch threads each, default 1), EXTRA (more `wpbench train` options).
# Rerun it after an interruption: each training resumes from its checkpoint.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 1 ]; then echo "usage: $0 ROOT [GF_DIR] [TP_DIR]" >&2; exit 2; fi
ROOT="$1"; GF_DIR="${2:-policies/weights/gf}"; TP_DIR="${3:-policies/weights/tp}"
DATA="${DATA:-data3}"; MINUTES="${MINUTES:-20}"; THREADS="${THREADS:-1}"
BUDGET=(--minutes "$MINUTES")
if [ -n "${STEPS:-}" ]; then BUDGET+=(--steps "$STEPS"); fi
for dir in "$GF_DIR" "$TP_DIR"; do
  if [ ! -f "$dir/model.pt" ]; then echo "error: $dir/model.pt is missing; train it first (wpbench train --policy gf|tp)" >&2; exit 2; fi
done
mkdir -p "$ROOT/gf" "$ROOT/tp" runs/logs
for pair in "gf:$GF_DIR" "tp:$TP_DIR"; do
  name="${pair%%:*}"; src="${pair#*:}"
  if [ "$(cd "$src" && pwd)" != "$(cd "$ROOT/$name" && pwd)" ]; then
    find "$src" -maxdepth 1 -type f ! -name checkpoint.pt -exec cp {} "$ROOT/$name/" \;
  fi
done
pids=()
for variant in wp-og wp-postsvd wp-postsvd-t; do
  # shellcheck disable=SC2086  # EXTRA is a list of options
  OMP_NUM_THREADS=$THREADS /usr/bin/time -v .venv/bin/wpbench train --policy "$variant" --data "$DATA" "${BUDGET[@]}" \
    --threads "$THREADS" --weights-root "$ROOT" --out "$ROOT/$variant" ${EXTRA:-} > "runs/logs/$(basename "$ROOT")-$variant.log" 2>&1 &
  pids+=($!)
done
status=0
for pid in "${pids[@]}"; do wait "$pid" || status=1; done
.venv/bin/wpbench train --select-best --weights-root "$ROOT"
exit $status
