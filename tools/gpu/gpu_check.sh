#!/usr/bin/env bash
# tpnet-gpu: the check run on a lent GPU machine (tools/gpu/README.md). Run from the project root of the device's
# copy of the checkout, after the staging run, carrying .whl (both made by ../shared/gpu/make_payload.sh):
#   run: carry [".whl-stage"], command "bash .whl-stage/stage.sh", timeout_s 60
#   run (within 30 s): carry [".whl"], command "bash tools/gpu/gpu_check.sh", timeout_s 560
# Installs Warp (the staged part + the carried parts) and rawpy into $SITE with no network, links the package
# folders as `pip install -e .` would map them, then runs tools/gpu/gpu_check.py; its files land in $OUT.
# Extra arguments go to gpu_check.py (e.g. --steps env,tp --budget-s 300).
set -u
T0=$(date +%s)
OUT=${OUT:-/tmp/gpu-check-out}; mkdir -p "$OUT"
LOG=$OUT/install.log; : > "$LOG"
PY=${PY:-python3}
SITE=${GPU_CHECK_SITE:-/tmp/site}; STAGE=${GPU_CHECK_STAGE:-/tmp/gpu-stage}
BUDGET=${GPU_CHECK_BUDGET_S:-480}
export PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1
export WARP_CACHE_PATH=${WARP_CACHE_PATH:-/tmp/warp-cache} TPNET_CACHE_DIR=${TPNET_CACHE_DIR:-/tmp/tpnet-cache}
say() { echo "[gpu_check.sh $(( $(date +%s) - T0 ))s] $*" >&2; }  # stderr: the run's output tail
[ -f pyproject.toml ] && grep -q 'name = "tpnet-gpu"' pyproject.toml || { say "run from the tpnet-gpu project root"; exit 2; }
mkdir -p "$SITE"

install_warp() {  # the Warp tarball's parts: part-00 staged in $STAGE (or .whl-stage/), the rest in .whl/
  if "$PY" -c 'import warp' 2>/dev/null || [ -d "$SITE/warp" ]; then say "warp: already importable"; return 0; fi
  local whl; whl=$(ls .whl/warp_lang-*.whl 2>/dev/null | head -1)
  if [ -n "$whl" ]; then "$PY" -m pip install -q --no-index --no-deps --no-compile --target "$SITE" "$whl"; return; fi
  declare -A seen; local parts=() f b
  for f in "$STAGE"/warp-cuda.tar.xz.part-* .whl-stage/warp-cuda.tar.xz.part-* .whl/warp-cuda.tar.xz.part-*; do
    [ -f "$f" ] || continue; b=$(basename "$f"); [ -n "${seen[$b]:-}" ] && continue; seen[$b]=1; parts+=("$b:$f")
  done
  if [ ${#parts[@]} -eq 0 ]; then say "warp: no payload (did the staging run come within 30 s?)"; return 1; fi
  local files; files=$(printf '%s\n' "${parts[@]}" | sort | cut -d: -f2-)
  if [ -f .whl/warp-cuda.tar.xz.sha256 ]; then
    # shellcheck disable=SC2086
    [ "$(cat $files | sha256sum | cut -d' ' -f1)" = "$(cat .whl/warp-cuda.tar.xz.sha256)" ] \
      || { say "warp: sha256 mismatch (a part is missing)"; return 1; }
  fi
  # shellcheck disable=SC2086
  cat $files | tar -xJ -C "$SITE"
}
install_warp >> "$LOG" 2>&1 || say "warp install failed: $(tail -n 3 "$LOG" | tr '\n' ' ')"
for w in .whl/*.whl; do
  [ -f "$w" ] || continue
  case "$w" in *warp_lang*) continue;; esac
  "$PY" -m pip install -q --no-index --no-deps --no-compile --target "$SITE" "$w" >> "$LOG" 2>&1 || say "pip failed: $w"
done
# pyproject maps tpnet_gpu.kernels -> kernels/, .net -> net/, .bench -> bench/: links do it in this disposable copy
for pkg in kernels net bench; do [ -e "tpnet_gpu/$pkg" ] || ln -s "../$pkg" "tpnet_gpu/$pkg"; done
export PYTHONPATH=$SITE:$PWD${PYTHONPATH:+:$PYTHONPATH}
command -v nvidia-smi > /dev/null && nvidia-smi >> "$LOG" 2>&1
say "installed in $(( $(date +%s) - T0 ))s; running gpu_check.py (budget ${BUDGET}s)"
left=$(( BUDGET - ($(date +%s) - T0) ))
timeout -k 10 $(( left + 30 )) "$PY" tools/gpu/gpu_check.py --out "$OUT" --budget-s "$left" "$@" 2> "$OUT/gpu_check.log"
rc=$?
tail -n 30 "$OUT/gpu_check.log" >&2
say "gpu_check.py exit status $rc"
exit $rc
