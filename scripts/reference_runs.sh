#!/usr/bin/env bash
# Evaluation runs behind results/: every policy in POLICIES on every task, val split,
# built-in furniture and (when present) the real PartNet-Mobility objects, in each
# observation mode of OBS. Resumable (--resume): rerun it after an interruption.
#   scripts/reference_runs.sh                                   # gt and identity (issue 3's bounds)
#   POLICIES="gf tp oracle" OBS=camera EPISODES=50 PARTNET_EPISODES=20 scripts/reference_runs.sh
# WEIGHTS_ROOT=DIR evaluates an experiment's weights instead (learned policies only); its runs
# go to DIR/runs/ and the leaderboard of results/ is left alone.
set -uo pipefail  # a failed run is reported in the log; the others still run
cd "$(dirname "$0")/.."
POLICIES="${POLICIES:-gt identity}"
EPISODES="${EPISODES:-50}"
PARTNET="${PARTNET:-../shared/partnet-mobility}"
PARTNET_EPISODES="${PARTNET_EPISODES:-$EPISODES}"
TASKS="${TASKS:-$(.venv/bin/python -c 'from wpbench.names import BUILTIN_TASKS; print(*BUILTIN_TASKS)')}"
WEIGHTS=()
if [ -n "${WEIGHTS_ROOT:-}" ]; then WEIGHTS=(--weights-root "$WEIGHTS_ROOT"); fi
for obs in ${OBS:-camera mesh}; do
  for task in $TASKS; do
    for policy in $POLICIES; do
      .venv/bin/wpbench run --policy "$policy" --task "$task" --split val --episodes "$EPISODES" \
        --obs "$obs" --resume --no-progress "${WEIGHTS[@]}"
      if [ -d "$PARTNET" ] && [ "$PARTNET_EPISODES" -gt 0 ]; then
        .venv/bin/wpbench run --policy "$policy" --task "$task" --episodes "$PARTNET_EPISODES" \
          --obs "$obs" --assets "$PARTNET" --resume --no-progress "${WEIGHTS[@]}"
      fi
    done
  done
done
if [ -z "${WEIGHTS_ROOT:-}" ]; then .venv/bin/wpbench leaderboard --quiet; fi
