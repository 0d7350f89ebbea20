#!/usr/bin/env bash
# GPU time of the shipped default (unet-gtao), the fast model (unet-fast), this project's GTAO and its SSAO,
# measured by the C host (runtime/host/neuralao_host.c) with GL timer queries (GL_TIME_ELAPSED) and by the
# Vulkan runner (runtime/host/neuralao_vk.c) with vkCmdWriteTimestamp, at 1920x1080 and 3840x2160, for both
# generator presets (gpu, cpu) and both precisions (fp32, fp16). Prints a markdown table of ms and ratios to
# GTAO, a row per API (gl, vulkan), and writes JSON.
#
#   bench/gpu.sh prepare   here, with the venv: build the host (and the Vulkan runner where vulkan/vulkan.h
#                          exists), generate the exports (network + frame passes, GLSL and, for the runner,
#                          Vulkan SPIR-V) and the SSAO baseline's shaders into build/bench-gpu
#   bench/gpu.sh run       anywhere with EGL and OpenGL 4.3 (no Python packages needed): time, table, JSON;
#                          each case through Vulkan too where the runner was built and finds a Vulkan device
#   bench/gpu.sh           both
#
# Environment (prepare): MODELS ("unet-gtao unet-fast"), PRESETS ("gpu cpu"), PRECISIONS ("fp32 fp16"),
# ARCHS (architectures to time before training them, seeded untrained networks made by
# bench/gpu_candidates.py, the first preset and precision only; default: the frame-local default at
# 4/8/16/32 and pure fast models at 4/8/16/32, 6/12/24/48 and 8/16/32/64); (run) SIZES ("1920x1080
# 3840x2160"), REPEATS (timed runs per case, 20), OUT (build/bench-gpu/gpu.json). BENCH_GPU_SMALL=1: one
# 128x96 frame, 1 run (what the test runs on llvmpipe). `run` times every export `prepare` made; each
# model's steps are also timed one by one (GL, the first preset and precision) into
# build/bench-gpu/profile.txt.
#
# On an NVIDIA GPU (the device machine, which fetches nothing): `bench/gpu.sh prepare` here, then one call
# carrying .gl (the GL/EGL and Vulkan loader debs, libvulkan1 among them, /work/.library/device/README.md) and
# build/bench-gpu:
#   for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig; \
#   export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json \
#     VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json; \
#   bench/gpu.sh run
# Frames are the host's synthetic G-buffer (a wavy surface, every pixel foreground, as in a game frame).
# A model's time is its whole frame as an engine runs it, every step of the manifest's frame.steps
# (position from depth, a hybrid's GTAO and blur, point sampling, the input assembly, the network,
# upsampling with the correction and combine); the JSON also has its network steps alone. GTAO is the
# hybrid's own GTAO steps (f_gtao + f_gtao_blur) in the same runs; SSAO is the project's SSAO and its blur
# (neuralao.runtime.baselines' fragment shaders) on the same G-buffer in every run. Where GL reports no
# GPU time (Mesa's llvmpipe: 0 for compute), the wall clock between glFinish calls is used and the table
# says so; Vulkan rows likewise where the queue has no timestamps (the wall clock from submission to fence).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=build/bench-gpu
HOST=$BUILD/neuralao_host
VK=$BUILD/neuralao_vk
PY=${PY:-.venv/bin/python}
SIZES=${SIZES:-1920x1080 3840x2160}
REPEATS=${REPEATS:-20}
MODELS=${MODELS:-unet-gtao unet-fast}
PRESETS=${PRESETS:-gpu cpu}
PRECISIONS=${PRECISIONS:-fp32 fp16}
ARCHS=${ARCHS-v3-default=4,8,16,32+gtao v3-fast-w4=4,8,16,32 v3-fast-w6=6,12,24,48 v3-fast-w8=8,16,32,64}
OUT=${OUT:-$BUILD/gpu.json}
if [[ ${BENCH_GPU_SMALL:-0} == 1 ]]; then SIZES=128x96 REPEATS=1; fi

prepare() {
  mkdir -p "$BUILD"
  ${CC:-cc} -O2 -std=c11 -Wall -Wextra -Werror -o "$HOST" runtime/host/neuralao_host.c -lEGL -lOpenGL -lm
  local vulkan=0
  rm -f "$VK"
  if [[ -f /usr/include/vulkan/vulkan.h ]]; then
    ${CC:-cc} -O2 -std=c11 -Wall -Wextra -Werror -o "$VK" runtime/host/neuralao_vk.c -lvulkan -lm
    vulkan=1
  else
    echo "bench/gpu.sh: no vulkan/vulkan.h (Debian: libvulkan-dev): GL only" >&2
  fi
  rm -rf "$BUILD/exports" "$BUILD/candidates"
  echo "-${PRESETS%% *}-${PRECISIONS%% *}" >"$BUILD/profiled"  # the exports run times step by step
  # each job: name, source folder, presets, precisions
  local jobs=() name
  for name in $MODELS; do jobs+=("$name|runtime/models/$name|$PRESETS|$PRECISIONS"); done
  if [[ -n $ARCHS ]]; then
    "$PY" bench/gpu_candidates.py "$BUILD/candidates" $ARCHS >/dev/null
    for name in $ARCHS; do
      jobs+=("${name%%=*}|$BUILD/candidates/${name%%=*}|${PRESETS%% *}|${PRECISIONS%% *}")
    done
  fi
  "$PY" - "$BUILD" "$vulkan" "${jobs[@]}" <<'PYEOF'
import dataclasses, json, shutil, sys
from pathlib import Path

import onnx

from neuralao.export.glsl import write_compute_export
from neuralao.runtime.baselines import SSAOSettings, blur_source, fragment_source, noise_tile, ssao_kernel
from neuralao.runtime.frame_runner import frame_program
from neuralao.runtime.internal_resolution import vertex_source


def ssao_entry(out: Path) -> dict:
    """The SSAO baseline's fragment passes under out/ssao/ and how the host runs them (the layout of an
    export's "gtao" entry): what neuralao.runtime.baselines.ScreenSpaceAO binds and sets."""
    s = SSAOSettings()
    sources = {"vertex": "fullscreen.vert", "ssao": "ssao.frag", "ssao_blur": "ssao_blur.frag"}
    texts = {"vertex": vertex_source(), "ssao": fragment_source("ssao", s), "ssao_blur": blur_source(s.noise_size)}
    (out / "ssao").mkdir()
    for key, name in sources.items():
        (out / "ssao" / name).write_text(texts[key])
    tile = noise_tile(s.noise_size, s.seed, "ssao")[::-1]  # GL rows, bottom up
    return {
        "folder": "ssao",
        "sources": sources,
        "settings": dataclasses.asdict(s),
        "textures": {"u_position": 0, "u_normal": 1, "u_noise": 2},
        "noise": {"width": s.noise_size, "height": s.noise_size, "texels": [float(v) for v in tile.reshape(-1)]},
        "uniforms": {
            "u_proj": {"type": "vec2", "formula": "(P00, P11) = (f * H / W, f), f = 1 / tan(yfov / 2)"},
            "u_radius": {"type": "float", "formula": "R, the AO radius in scene units"},
            "u_bias": {"type": "float", "times_radius": s.bias_rel},
            "u_kernel": {
                "type": f"vec3[{s.samples}]",
                "value": [float(v) for v in ssao_kernel(s.samples, s.seed).reshape(-1)],
            },
        },
        "blur": {"textures": {"u_position": 0, "u_raw": 3}} if s.blur else None,
    }


build, vulkan = Path(sys.argv[1]), sys.argv[2] == "1"
for job in sys.argv[3:]:
    model, folder, presets, precisions = job.split("|")
    src = Path(folder)
    for preset in presets.split():
        for precision in precisions.split():
            out = build / "exports" / f"{model}-{preset}-{precision}"
            shutil.rmtree(out, ignore_errors=True)
            out.mkdir(parents=True)  # exports/<model>-<preset>-<precision>: `run` reads the three back
            manifest = json.loads((src / "manifest.json").read_text())
            manifest.pop("internal_resolution", None)  # its fragment passes: the frame section replaces them
            manifest["ssao"] = ssao_entry(out)
            (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
            proto = onnx.load(src / "model.onnx")
            program = frame_program(proto, precision=precision, preset=preset)
            write_compute_export(program, out / "glsl", validate=False)
            if vulkan:  # the same passes as Vulkan GLSL, compiled to SPIR-V, for the Vulkan runner
                program = frame_program(proto, dialect="vulkan", precision=precision, preset=preset)
                write_compute_export(program, out / "vulkan", validate=False)
PYEOF
}

# Whether the Vulkan runner was built and runs here (a Vulkan device): one small frame of the first export.
vulkan_runs() {
  [[ -x $VK ]] || return 1
  local first err
  first=$(exports | head -n 1)
  if ! err=$("$VK" "$first" synthetic 64 48 0.5 60 "$BUILD/ao-vulkan.f32" 2>&1 >/dev/null); then
    echo "bench/gpu.sh: the Vulkan runner does not run here (${err##*neuralao_vk: }): GL only" >&2
    return 1
  fi
}

# time_case API RUNNER EXPORT SIZE CASE: one case's timed frames, its JSON line (CASE's fields and the api)
# appended to $lines; a case that fails is reported and left out, the others still run (errors: $errors).
time_case() {
  local api=$1 runner=$2 export=$3 size=$4 case=$5 json
  if json=$(NEURALAO_HOST_REPEATS=$REPEATS "$runner" "$export" synthetic "${size%x*}" "${size#*x}" 0.5 60 \
    "$BUILD/ao-$api.f32" 2>>"$errors"); then
    json=${json#\{}
    [[ $json == *'"api"'* ]] || json="\"api\": \"$api\", $json"  # the Vulkan runner names its own
    echo "{$case, $json" >>"$lines"
  else
    echo "bench/gpu.sh: $api failed: $export $size (see $errors)" >&2
  fi
}

# The exports `prepare` made, one folder a line.
exports() {
  local e
  for e in "$BUILD"/exports/*/; do [[ -d $e ]] && echo "${e%/}"; done
}

run() {
  [[ -x $HOST ]] || { echo "bench/gpu.sh: no $HOST: run 'bench/gpu.sh prepare' first" >&2; exit 1; }
  local lines=$BUILD/runs.jsonl errors=$BUILD/errors.log vulkan=0
  : >"$lines"
  : >"$errors"
  [[ -n $(exports) ]] || { echo "bench/gpu.sh: no exports in $BUILD: run 'bench/gpu.sh prepare'" >&2; exit 1; }
  if vulkan_runs; then vulkan=1; fi
  local size export tag
  for size in $SIZES; do
    for export in $(exports); do
      tag=${export##*/}  # <model>-<preset>-<precision>; the model's name may hold dashes
      local precision=${tag##*-} rest=${tag%-*}
      local case="\"model\": \"${rest%-*}\", \"preset\": \"${rest##*-}\", \"precision\": \"$precision\""
      time_case gl "$HOST" "$export" "$size" "$case"
      if ((vulkan)); then time_case vulkan "$VK" "$export" "$size" "$case"; fi
    done
  done
  # where each model's frame goes: every step timed alone (GL, the first preset and precision)
  local profile=$BUILD/profile.txt profiled
  profiled=$(cat "$BUILD/profiled")  # -<preset>-<precision>, written by prepare
  : >"$profile"
  for size in $SIZES; do
    for export in $(exports); do
      [[ $export == *"$profiled" ]] || continue
      echo "== ${export##*/} $size (GL)" >>"$profile"
      NEURALAO_HOST_PROFILE=1 NEURALAO_HOST_REPEATS=$REPEATS "$HOST" "$export" synthetic \
        "${size%x*}" "${size#*x}" 0.5 60 "$BUILD/ao-gl.f32" 2>&1 >/dev/null | grep "step" >>"$profile" || true
    done
  done
  echo "bench/gpu.sh: per-step times in $profile" >&2
  python3 bench/gpu_table.py "$lines" "$OUT"
}

case ${1:-all} in
  prepare) prepare ;;
  run) run ;;
  all) prepare && run ;;
  *) echo "usage: bench/gpu.sh [prepare|run]" >&2; exit 2 ;;
esac
