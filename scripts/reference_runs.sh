#!/usr/bin/env bash
# Reference runs of issue 3: gt and identity on every task, val split, built-in and
# real PartNet-Mobility assets, both observation modes. Resumable (--resume).
set -uo pipefail  # a failed run is reported in the log; the others still run
cd "$(dirname "$0")/.."
EPISODES="${EPISODES:-50}"
PARTNET="${PARTNET:-../shared/partnet-mobility}"
for obs in ${OBS:-camera mesh}; do
  for task in open-door place-in open-then-place; do
    for policy in gt identity; do
      .venv/bin/wpbench run --policy "$policy" --task "$task" --split val --episodes "$EPISODES" \
        --obs "$obs" --resume --no-progress
      if [ -d "$PARTNET" ]; then
        .venv/bin/wpbench run --policy "$policy" --task "$task" --episodes "$EPISODES" \
          --obs "$obs" --assets "$PARTNET" --resume --no-progress
      fi
    done
  done
done
.venv/bin/wpbench leaderboard
