#!/usr/bin/env bash
# Run THERE (the device machine, through the device tool's `run`, which starts in the repository
# root and sends back what is under $OUT), after training/gpu/prepare.sh here:
#   run(command="bash training/gpu/run.sh", carry=[".whl", ".gl"], timeout_s=590)
# 1. installs the carried wheels and GL loaders; 2. a CUDA smoke test (the tiny config, 20 steps);
# 3. times MEASURE_STEPS steps of CONFIG with data_workers 0 and WORKERS (samples/s of each);
# 4. trains CONFIG from INIT on a fresh cosine schedule at LR for as many steps as fit TRAIN_S
#    seconds at the rate measured with WORKERS, and copies model.pt, last.pt and train_log.csv
#    to $OUT (what comes back: at most 8 files of 16 MiB); 5. with PHASE2_CONFIG, then trains that
#    config from step 4's model for PHASE2_STEPS steps (e.g. the blind encoder alone on the new
#    network: PHASE2_CONFIG=realistic_rig_authored_blind) and copies its model.pt, last.pt and
#    train_log.csv to $OUT/phase2/.
# Everything is written to $OUT/log.txt as it goes, so a run stopped at its limit still says
# where it was. Settings (environment): CONFIG, INIT, LR, WORKERS, TRAIN_S, MEASURE_STEPS, SEED,
# PHASE2_CONFIG, PHASE2_STEPS, PHASE2_LR;
# SKIP_INSTALL=1 for a dry run here, e.g. (the tiny model of the smoke test as INIT):
#   PATH=.venv/bin:$PATH SKIP_INSTALL=1 CONFIG=tiny INIT=/tmp/smoke/model.pt WORKERS=1 TRAIN_S=10 MEASURE_STEPS=10 OUT=/tmp/gpu_out bash training/gpu/run.sh
set -uo pipefail
CONFIG=${CONFIG:-realistic_rig_authored_decoder_neutral}   # the bundled stages 22-23's run: its
# decoder alone trains, every source with its neutral, so frames without their neutral are read as
# before (RESULTS "Stage 22"); its export fits the gated code map, about a minute, so model.pt
# comes back with it. A config whose model differs from INIT's stops at the first measuring run
# (retarget train: "the checkpoint's model does not match").
INIT=${INIT:-retarget/checkpoints/default.pt}   # --init takes the network only, not its map
LR=${LR:-5e-5}   # stages 22 and 23's
# Judge what comes back on the ARKit rig without the neutral too: configs that also train the CNN
# (whose image code the blind encoder reads), e.g. realistic_rig_authored_frozen_blind, left it
# 1.2-1.3x worse there for 2-5 % with the neutral (RESULTS "The network trained on with its blind
# encoder frozen"); the decoder alone, or with the identity and skinning encoders
# (realistic_rig_authored_target_neutral), left it level (RESULTS "Stage 22").
WORKERS=${WORKERS:-14}
TRAIN_S=${TRAIN_S:-360}
MEASURE_STEPS=${MEASURE_STEPS:-60}
SEED=${SEED:-1}
PHASE2_CONFIG=${PHASE2_CONFIG:-}
PHASE2_STEPS=${PHASE2_STEPS:-1000}
PHASE2_LR=${PHASE2_LR:-$LR}
OUT=${OUT:-runs/gpu_out}
mkdir -p "$OUT"
LOG="$OUT/log.txt"
exec > >(tee -a "$LOG") 2>&1
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
t0=$(date +%s)
stamp() { echo "[$(( $(date +%s) - t0 )) s] $*"; }

stamp "install"
if [ -n "${SKIP_INSTALL:-}" ]; then :   # a dry run on a machine that has the dependencies
elif [ -d .gl ]; then for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig; fi
if [ -z "${SKIP_INSTALL:-}" ] && [ -d .whl ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
fi
[ -f /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json ] && \
  export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())" || exit 1
python3 -c "
import numpy as np
from retarget.render import render_frontal
img = render_frontal(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]], float), np.array([[0, 1, 2]]), 32)
assert img.shape[-2:] == (32, 32) and img.max() > 0, 'the EGL render is empty'
print('EGL render ok', img.shape)" || exit 1
train() { python3 -m retarget.cli train --no-progress --max-minutes 0 --seed "$SEED" "$@"; }

stamp "smoke: tiny config on CUDA, 20 steps"
rm -rf /tmp/smoke /tmp/measure_* /tmp/gpu_run /tmp/gpu_phase2   # this script's own outputs, from an earlier run
train --config tiny --steps 20 --out /tmp/smoke || { stamp "smoke test failed"; exit 1; }

rate() {  # samples/s over the run's logged steps: steps x sources / logged training time
  python3 - "$1" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
print(f"{float(rows[-1]['step']) / float(rows[-1]['elapsed_s']):.3f}")
PY
}
# the measuring runs export without the code map (fitting it takes about a minute a run)
CONFIG_FILE=$(python3 -c 'import sys; from retarget.config import find_config
print(find_config(sys.argv[1], "train").resolve())' "$CONFIG") || exit 1
printf 'base: %s\ncode_map: {identities: 0}\n' "$CONFIG_FILE" > /tmp/measure_config.yaml
for w in $(printf '%s\n' 0 "$WORKERS" | sort -un); do   # once when WORKERS is 0
  stamp "measure: $MEASURE_STEPS steps of $CONFIG with data_workers $w"
  train --config /tmp/measure_config.yaml --init "$INIT" --steps "$MEASURE_STEPS" --lr "$LR" --data-workers "$w" \
    --out "/tmp/measure_$w" > "/tmp/measure_$w.txt" 2>&1 || { tail -20 "/tmp/measure_$w.txt"; exit 1; }
  stamp "steps/s with $w workers: $(rate /tmp/measure_$w/train_log.csv)"
done
steps_per_s=$(rate "/tmp/measure_$WORKERS/train_log.csv")
STEPS=$(python3 -c "print(max(100, int($steps_per_s * $TRAIN_S) // 100 * 100))")
stamp "train: $STEPS steps of $CONFIG from $INIT at lr $LR with $WORKERS workers"
train --config "$CONFIG" --init "$INIT" --steps "$STEPS" --lr "$LR" --data-workers "$WORKERS" \
  --out /tmp/gpu_run
cp /tmp/gpu_run/model.pt /tmp/gpu_run/last.pt /tmp/gpu_run/train_log.csv "$OUT"/ 2>/dev/null
stamp "done: $(tail -1 /tmp/gpu_run/train_log.csv)"
[ -n "$PHASE2_CONFIG" ] || exit 0
stamp "phase 2: $PHASE2_STEPS steps of $PHASE2_CONFIG from the model above at lr $PHASE2_LR"
train --config "$PHASE2_CONFIG" --init /tmp/gpu_run/model.pt --steps "$PHASE2_STEPS" --lr "$PHASE2_LR" \
  --data-workers "$WORKERS" --out /tmp/gpu_phase2
mkdir -p "$OUT/phase2"
cp /tmp/gpu_phase2/model.pt /tmp/gpu_phase2/last.pt /tmp/gpu_phase2/train_log.csv "$OUT/phase2"/ 2>/dev/null
stamp "phase 2 done: $(tail -1 /tmp/gpu_phase2/train_log.csv)"
