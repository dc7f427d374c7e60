#!/usr/bin/env bash
# Evaluation runs behind results/: every policy in POLICIES on every task, val split,
# built-in furniture and (when present) the real PartNet-Mobility objects, in each
# observation mode of OBS, as `wpbench sweep` calls (all episodes of a sweep scheduled at
# once over WORKERS processes, default: every core). Resumable: rerun it after an interruption.
#   scripts/reference_runs.sh                                   # gt and identity (issue 3's bounds)
#   POLICIES="gf tp oracle" OBS=camera EPISODES=50 PARTNET_EPISODES=20 scripts/reference_runs.sh
# RAY=ADDRESS runs them on a Ray cluster instead (RAY=local starts one here).
# WEIGHTS_ROOT=DIR evaluates an experiment's weights instead (learned policies only), run by
# run; its runs go to DIR/runs/ and the leaderboard of results/ is left alone.
set -uo pipefail  # a failed sweep is reported; the others still run
cd "$(dirname "$0")/.."
POLICIES="${POLICIES:-gt identity}"
EPISODES="${EPISODES:-50}"
PARTNET="${PARTNET:-../shared/partnet-mobility}"
PARTNET_EPISODES="${PARTNET_EPISODES:-$EPISODES}"
TASKS="${TASKS:-$(.venv/bin/python -c 'from wpbench.names import BUILTIN_TASKS; print(*BUILTIN_TASKS)')}"
POOL=()
if [ -n "${RAY:-}" ]; then POOL=(--ray "$RAY"); elif [ -n "${WORKERS:-}" ]; then POOL=(--workers "$WORKERS"); fi
if [ -n "${WEIGHTS_ROOT:-}" ]; then  # sweep takes no --weights-root: one run after another
  for obs in ${OBS:-camera mesh}; do for task in $TASKS; do for policy in $POLICIES; do
    .venv/bin/wpbench run --policy "$policy" --task "$task" --split val --episodes "$EPISODES" \
      --obs "$obs" --resume --no-progress --weights-root "$WEIGHTS_ROOT"
  done; done; done
  exit 0
fi
for obs in ${OBS:-camera mesh}; do
  .venv/bin/wpbench sweep --policies "$POLICIES" --tasks "$TASKS" --splits val --episodes "$EPISODES" \
    --obs "$obs" --no-progress "${POOL[@]}"
  if [ -d "$PARTNET" ] && [ "$PARTNET_EPISODES" -gt 0 ]; then
    .venv/bin/wpbench sweep --policies "$POLICIES" --tasks "$TASKS" --assets "$PARTNET" \
      --episodes "$PARTNET_EPISODES" --obs "$obs" --no-progress "${POOL[@]}"
  fi
done
