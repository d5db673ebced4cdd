#!/usr/bin/env bash
# The one prepared script a session lent a GPU runs, in the repository's root on the device
# machine (benchmarks/bench_gpu.py's GPU side; docs/where-it-runs.md, "At a game's resolution"):
#
#   1. parity at 256x256: the calibration on cuda_ad_rgb, its fitted constants against the CPU's
#      in their combined standard errors, both fitted at 128x128 by the squared error
#      (PARITY_SETS: equal fit resolution, so the comparison is of backends alone; the CPU's from
#      docs/results/gpu/bench.json, measured with the same overrides; on the device too when it
#      has a libLLVM >= 16);
#   2. 1920x1080 on cuda_ad_rgb: a cold pass (empty render and kernel caches), then a warm one in
#      the same process, the fit's normal equations formed on the device (fit.normal_equations);
#   3. the tradeoff study on the GPU, GPU_TRADEOFF_WORKERS worker processes sharing the device and
#      the fits' normal equations formed there, only if 5 minutes of the call's budget remain
#      (--tradeoff: this step alone). Its rows count each point's kernels (compiled, cached,
#      replayed) and copies.
#
# Everything lands in $OUT: bench.json (one invocation per step, the file scripts/build_docs.py
# turns into docs/results/gpu/report.md once merged into docs/results/gpu/bench.json), the
# session's log, and the tradeoff's report.md and summary.json.
#
# Usage:
#   bash benchmarks/gpu_session.sh --build-bundle  # here, once: .gpu_bundle/ (what must travel)
#   bash benchmarks/gpu_session.sh --dry-run       # print the steps, run nothing
#   bash benchmarks/gpu_session.sh                 # on the device machine
#   bash benchmarks/gpu_session.sh --tradeoff      # step 3 alone, with the whole budget
#   bash benchmarks/gpu_session.sh --prune DIR     # prune an unpacked site folder as the bundle
#
# The device machine reaches no registry, so what it lacks travels with the call, in the folder
# .gpu_bundle/ (ignored by git; name it in the run's carry): site.tar.xz, the Python packages its
# image lacks as wheels downloaded for its Python (3.12, manylinux x86-64) with `pip download`,
# unpacked and pruned (Mitsuba's variants other than llvm_ad_rgb, cuda_ad_rgb and scalar_rgb, the plugins
# the study's scenes do not load, type stubs and C++ headers), and debs/: the OpenGL loaders
# (EGL through the NVIDIA driver) and glslang, SPIRV-Tools and SPIRV-Cross for the export.
# Everything that travels (the tracked tree and .gpu_bundle/) must stay under 64 MiB a call;
# --build-bundle prints the sizes and refuses a bundle that does not fit. Pyoidn (87 MB) does
# not fit: every step runs with the lighting and walls raw (BENCH_SETS), on both backends.
#
# Environment: OUT (default /tmp/gpu_session_out), GPU_SESSION_BUDGET (seconds the whole script
# may take; default 560, for a 600-s call), GPU_TRADEOFF_WORKERS (the tradeoff's worker processes,
# all on the one GPU; default 4), DEVICE_PYTHON_VERSION (default 3.12), WHEELS (the download
# cache of --build-bundle; default /tmp/study_gpu_wheels).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUNDLE="$REPO/.gpu_bundle"
OUT="${OUT:-/tmp/gpu_session_out}"
BUDGET="${GPU_SESSION_BUDGET:-560}"
TRADEOFF_NEEDS=300  # seconds that must remain for step 3
TRADEOFF_WORKERS="${GPU_TRADEOFF_WORKERS:-4}"  # worker processes sharing the one device
LIMIT_MIB=64
PYVER="${DEVICE_PYTHON_VERSION:-3.12}"
WHEELS="${WHEELS:-/tmp/study_gpu_wheels}"
SITE=/tmp/study_site
TOOLS=/tmp/study_tools
BENCH_SETS=(--set 'reference.lighting_denoise="none"' --set 'reference.wall_denoise="none"')
PARITY_SETS=("${BENCH_SETS[@]}" --set 'fit.resolution=[128, 128]' --set 'fit.loss="linear"')
# the fit's normal equations formed on the GPU, which needs the squared error (FLIP's residual is
# formed on the host): steps 2 and 3
DEVICE_FIT_SETS=(--set 'fit.normal_equations="device"' --set 'fit.loss="linear"')
# pinned as in pyproject.toml; the device's image has numpy, scipy, jax, matplotlib, pandas,
# pyarrow, pillow and the rest (docs/where-it-runs.md)
PACKAGES=(mitsuba==3.9.1 drjit==1.5.0 OpenEXR==3.5.3 moderngl==5.13.0 glcontext==3.1.0
  flip-evaluator==1.7 optimistix==0.1.0 equinox==0.13.8 lineax==0.1.1 dask==2026.8.0
  distributed==2026.8.0 tornado==6.6.1 partd==1.4.2 locket==1.0.0 tblib==3.2.2 zict==3.0.0)
VARIANTS_KEPT=(llvm_ad_rgb cuda_ad_rgb scalar_rgb)
PLUGINS_KEPT="aov area bitmap box constant constvolume cube d65 dielectric diffuse directional
  envmap gaussian hdrfilm homogeneous independent irregular isotropic merge multijitter null obj
  orthographic path perspective ply rectangle regular roughdielectric serialized srgb stratified
  twosided uniform volpath"
GL_DEBS=(libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
TOOL_DEBS=(glslang-tools spirv-tools spirv-cross)

DRY=0
MODE=session
PRUNE_DIR=
for arg in "$@"; do
  if [ "$MODE" = prune ] && [ -z "$PRUNE_DIR" ]; then PRUNE_DIR="$arg"; continue; fi
  case "$arg" in
    --dry-run) DRY=1 ;;
    --build-bundle) MODE=bundle ;;
    --tradeoff) MODE=tradeoff ;;  # step 3 alone
    --prune) MODE=prune ;;  # --prune DIR: prune an unpacked site folder as the bundle does
    -h|--help) sed -n '2,37p' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) echo "gpu_session.sh: unknown argument $arg (use --dry-run, --build-bundle, --tradeoff or --help)" >&2
       exit 2 ;;
  esac
done

say() { echo "gpu_session: $*" >&2; }
run() {  # a step's command: printed, and run unless --dry-run
  echo "+ $*" >&2
  if [ "$DRY" = 0 ]; then "$@"; fi
}

# ---- here: the bundle --------------------------------------------------------------------------
prune_site() {  # $1: the unpacked site folder
  local m="$1/mitsuba" keep f b
  for f in "$m"/*.cpython-*.so; do
    b="$(basename "$f")"; b="${b%%.cpython-*}"
    case "$b" in mitsuba_ext|mitsuba_alias) continue ;; esac
    keep=0; for v in "${VARIANTS_KEPT[@]}"; do [ "$b" = "$v" ] && keep=1; done
    [ "$keep" = 1 ] || rm -f "$f"
  done
  for f in "$m"/plugins/*.so; do
    b="$(basename "$f" .so)"
    echo " $(echo $PLUGINS_KEPT) " | grep -q " $b " || rm -f "$f"
  done
  rm -rf "$m/include" "$m/cmake" "$m/pkgconfig" "$m/mitsuba_stubs" "$m/data/srgb.coeff" \
    "$1/drjit/include"
  find "$1" -name '*.pyi' -delete
}

build_bundle() {
  local py="${PYTHON:-$REPO/.venv/bin/python}" stage lists mib
  run mkdir -p "$WHEELS" "$BUNDLE/debs"
  run "$py" -m pip download --no-deps --only-binary=:all: --python-version "$PYVER" \
    --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
    --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
    --platform manylinux1_x86_64 -d "$WHEELS" "${PACKAGES[@]}"
  stage="$(mktemp -d)"
  if [ "$DRY" = 0 ]; then
    local p n w
    for p in "${PACKAGES[@]}"; do  # the pinned wheels only, whatever else the cache holds
      n="$(echo "${p%%==*}" | tr 'A-Z-' 'a-z_')"
      w="$(ls "$WHEELS"/*.whl | grep -i "/${n}-${p##*==}-" | head -1)"
      [ -n "$w" ] || { say "no wheel of $p in $WHEELS"; exit 1; }
      unzip -q -o "$w" -d "$stage"
    done
    prune_site "$stage"
    tar -C "$stage" -cf - . | xz -9 -T0 > "$BUNDLE/site.tar.xz"
    rm -rf "$stage"
  else
    say "would unpack $WHEELS/*.whl, prune Mitsuba to ${VARIANTS_KEPT[*]} and write site.tar.xz"
  fi
  lists=/tmp/study_apt_amd64
  run mkdir -p "$lists/partial"
  local o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists")
  run apt-get "${o[@]}" -qq update
  run sh -c "cd '$BUNDLE/debs' && apt-get ${o[*]} -qq download ${GL_DEBS[*]} ${TOOL_DEBS[*]}"
  if [ "$DRY" = 0 ]; then
    local tree bundle
    tree=$(cd "$REPO" && git ls-files -z | xargs -0 du -cb 2>/dev/null | tail -1 | cut -f1)
    bundle=$(du -sb "$BUNDLE" | cut -f1)
    mib=$(( (tree + bundle) / 1048576 ))
    say "tracked tree $((tree / 1048576)) MiB + .gpu_bundle $((bundle / 1048576)) MiB =" \
      "$mib MiB of the $LIMIT_MIB MiB a call carries"
    [ "$mib" -lt "$LIMIT_MIB" ] || { say "too large: prune more (PLUGINS_KEPT)"; exit 1; }
  fi
}

# ---- on the device machine -----------------------------------------------------------------------
install_bundle() {
  if [ ! -f "$BUNDLE/site.tar.xz" ]; then
    if [ "$DRY" = 1 ]; then say "(no .gpu_bundle/site.tar.xz here: build it first)"; else
      say "no .gpu_bundle/site.tar.xz: run 'bash benchmarks/gpu_session.sh --build-bundle'" \
        "here and name .gpu_bundle in the run's carry"; exit 2; fi
  fi
  run mkdir -p "$SITE" "$TOOLS" "$OUT"
  run tar -C "$SITE" -xJf "$BUNDLE/site.tar.xz"
  for d in "${GL_DEBS[@]}"; do  # the loaders go to / (the device README's way), the tools aside
    for f in "$BUNDLE"/debs/"${d}"_*.deb; do [ -e "$f" ] && run dpkg -x "$f" /; done
  done
  for d in "${TOOL_DEBS[@]}"; do
    for f in "$BUNDLE"/debs/"${d}"_*.deb; do [ -e "$f" ] && run dpkg -x "$f" "$TOOLS"; done
  done
  run ldconfig
  export PATH="$TOOLS/usr/bin:$PATH"
  export LD_LIBRARY_PATH="$TOOLS/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  export PYTHONPATH="$SITE:$REPO${PYTHONPATH:+:$PYTHONPATH}"
  # the fit's JAX stays on the CPU (and takes none of the GPU's memory); Dr.Jit has the GPU
  export JAX_PLATFORMS=cpu XLA_PYTHON_CLIENT_PREALLOCATE=false PYTHONUNBUFFERED=1
  export STUDY_CACHE=/tmp/study_cache
  if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ] \
    && [ -f /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json ]; then
    export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  fi
}

left() { echo $(( BUDGET - ($(date +%s) - START) )); }

tradeoff_step() {  # step 3: the default tradeoff, its workers sharing the one GPU
  local py=$1
  say "step 3: the tradeoff on the GPU, $TRADEOFF_WORKERS workers on one device (runs only if \
${TRADEOFF_NEEDS} s of ${BUDGET} remain in a whole session)"
  run timeout "$(( $(left) - 20 ))" "$py" -m study.cli tradeoff \
    "$REPO/experiments/default.toml" --out /tmp/study_tradeoff --backend cuda_ad_rgb \
    --workers "$TRADEOFF_WORKERS" "${BENCH_SETS[@]}" "${DEVICE_FIT_SETS[@]}" \
    || say "the tradeoff stopped early (budget)"
  run sh -c "cp /tmp/study_tradeoff/report.md /tmp/study_tradeoff/summary.json \
    /tmp/study_tradeoff/tradeoff.parquet /tmp/study_tradeoff/screen.parquet '$OUT/' \
    2>/dev/null || true"
}

session() {
  START=$(date +%s)
  local py=python3 backends=(cuda_ad_rgb)
  install_bundle
  if [ "$DRY" = 0 ]; then
    exec > >(tee -a "$OUT/session.log") 2>&1
    nvidia-smi -L || true
    "$py" -c "import sys, drjit as dr, mitsuba as mi, jax, optimistix, numpy as np
print('python', sys.version.split()[0], 'drjit', dr.__version__, 'mitsuba', mi.__version__,
      'jax', jax.__version__, 'numpy', np.__version__)
sys.exit(0 if dr.has_backend(dr.JitBackend.CUDA) else 3)" \
      || { say "Dr.Jit finds no CUDA device here; nothing to measure"; exit 3; }
    if "$py" -c "from study._backend import ensure_llvm; ensure_llvm()" 2>/dev/null; then
      backends=(llvm_ad_rgb cuda_ad_rgb)  # the CPU column on the device too
    else
      say "no libLLVM >= 16 here: the CPU side of the parity is this repository's measurement"
    fi
  fi
  if [ "$MODE" = tradeoff ]; then
    tradeoff_step "$py"
  else
    local bench=("$py" "$REPO/benchmarks/bench_gpu.py" --json "$OUT/bench.json" --append)
    say "step 1: parity at 256x256 (${backends[*]})"
    run "${bench[@]}" --sizes 256x256 --backends "${backends[@]}" "${PARITY_SETS[@]}" --parity \
      --parity-with "$REPO/docs/results/gpu/bench.json" --title "256x256: parity, CPU and GPU" \
      --timeout "$(left)"
    say "step 2: 1920x1080 on cuda_ad_rgb, cold then warm ($(left) s left)"
    # the fit reads its normal equations from the device: nothing of the 1080p image crosses the
    # bus during the fit (docs/results/normal-equations)
    run "${bench[@]}" --sizes 1920x1080 --backends cuda_ad_rgb --passes cold warm \
      "${BENCH_SETS[@]}" "${DEVICE_FIT_SETS[@]}" \
      --title "1920x1080 on the GPU, cold and warm, normal equations on the device" \
      --timeout "$(left)"
    if [ "$DRY" = 1 ] || [ "$(left)" -ge "$TRADEOFF_NEEDS" ]; then
      tradeoff_step "$py"
    else
      say "step 3 skipped: $(left) s left, the tradeoff needs $TRADEOFF_NEEDS"
    fi
  fi
  say "done in $(( $(date +%s) - START )) s; results in $OUT"
}

case "$MODE" in
  bundle) build_bundle ;;
  prune) [ -d "$PRUNE_DIR" ] || { echo "gpu_session.sh: --prune DIR" >&2; exit 2; }
         prune_site "$PRUNE_DIR" ;;
  *) session ;;  # the whole session, or with --tradeoff step 3 alone
esac
