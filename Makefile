# neuralao: meshes -> ray-traced AO -> neural AO models -> ONNX -> GLSL.
# Stages are real file targets under build/, so only stale stages rerun.
SHELL := bash
.SHELLFLAGS := -eu -o pipefail -c
.DELETE_ON_ERROR:
.DEFAULT_GOAL := help
MAKEFLAGS += --warn-undefined-variables --no-builtin-rules

PYTHON_SYSTEM ?= python3
comma := ,
space := $(subst ,, )
VENV := .venv
PY := $(VENV)/bin/python
NEURALAO := $(VENV)/bin/neuralao
STAMP := $(VENV)/.installed
# OSMesa by default; EGL (surfaceless llvmpipe) works too: `make demo PYOPENGL_PLATFORM=egl`.
export PYOPENGL_PLATFORM ?= osmesa
# Two cores: keep BLAS/torch from oversubscribing when we fan out ourselves.
export OMP_NUM_THREADS ?= 2
# Idle OpenMP threads sleep instead of spinning: with a spinning pool, torch ran 20-50x slower
# whenever another process held one of the two cores (measured in bench/bench_unet.py).
export OMP_WAIT_POLICY ?= PASSIVE

DEMO_CONFIG := configs/demo.json
BUILD := build/demo
DATASET := $(BUILD)/dataset/manifest.json
# The demo keeps every stage and one model of each kind small enough to run in minutes on 2 cores:
# the smallest baked MLP, the paper's U-Net for a fixed number of epochs, and a field for three scenes
# (an object, a room, a validation mesh). Larger sizes: `neuralao train ... --size 64x32`.
MLP_SIZES := 16x8
# The baked MLP is one network per mesh (as in the paper): the demo trains it for this scene.
MLP_SCENE := bunny
MLP_CKPTS := $(foreach s,$(MLP_SIZES),$(BUILD)/models/mlp-$(s).pt)
UNET_CKPT := $(BUILD)/models/unet.pt
UNET_EPOCHS := 15
# The AO field is one network per mesh too (the report shows one field-<size> row over all of them,
# and selection picks per scene).
FIELD_SCENES := bunny cornell_box fandisk
FIELD_SIZES := 16x8
FIELD_STEPS := 2000
FIELD_CKPTS := $(foreach sc,$(FIELD_SCENES),$(foreach s,$(FIELD_SIZES),$(BUILD)/models/field-$(sc)-$(s).pt))
EXPORTS := $(foreach s,$(MLP_SIZES),$(BUILD)/export/mlp-$(s)/manifest.json) $(BUILD)/export/unet/manifest.json \
	$(patsubst $(BUILD)/models/%.pt,$(BUILD)/export/%/manifest.json,$(FIELD_CKPTS))
# The demo's models train for minutes on 2 cores, and none reaches the production target of masked
# SSIM 0.95 (docs/results.md), so the demo selects at 0.75 to show the smallest-first choice at work.
DEMO_TARGET := 0.75
PARITY := $(BUILD)/parity.json
REPORT := $(BUILD)/report/report.md
# The demo report: 512-ray ground truth on 2 frames a scene (the held-back views), GL times at 256x256, the demo's models
# beside the shipped default and fast U-Nets and the baselines (`--shipped all` adds every shipped one).
DEMO_REPORT_FLAGS := --gt-rays 512 --frames-per-scene 2 --time-size 256 256 --repeats 5 \
	--set 'expected_exports=[$(subst $(space),$(comma),$(foreach s,$(MLP_SIZES),"mlp-$(s)") "unet")]'
VIEWER_PNG := $(BUILD)/viewer.png

.PHONY: bench-gpu help setup system-deps dataset corpus corpus-large corpus-full curve experiments evaluate models model-shaders train export parity report select demo host host-vk test fuzz bench lint clean

help: ## Show this help
	@grep -hE '^[a-zA-Z0-9_-]+:.*?## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*?## "}; {printf "  \033[36m%-10s\033[0m %s\n", $$1, $$2}'

# chromium + chromium-driver: the headless browser of the viewer test (tests/test_viewer.py, selenium).
SYSTEM_PACKAGES := libosmesa6 libegl1 libgles2 libgl1-mesa-dri glslang-tools chromium chromium-driver \
  mesa-vulkan-drivers spirv-cross gcc libegl-dev libgl-dev libvulkan-dev

system-deps: ## Install Debian packages: OSMesa, EGL/GLES (Mesa llvmpipe), glslangValidator, headless Chromium, lavapipe (Vulkan, for WGSL and the Vulkan runner), SPIRV-Cross, EGL/GL headers (C host), Vulkan headers (Vulkan runner)
	@if ! dpkg -s $(SYSTEM_PACKAGES) >/dev/null 2>&1; then \
	  echo "installing system packages (apt-get)"; \
	  apt-get update -qq; \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(SYSTEM_PACKAGES) >/dev/null; \
	fi

$(STAMP): pyproject.toml
	$(MAKE) system-deps
	test -x $(PY) || $(PYTHON_SYSTEM) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# opencv-python-headless (older pins) and opencv-contrib-python-headless both install cv2/: keep one.
	$(PY) -m pip uninstall -q -y opencv-python-headless 2>/dev/null || true
	$(PY) -m pip install -q -e '.[dev]'
	# pyrender pins PyOpenGL 3.1.0, which lacks OSMesaCreateContextAttribs: replace it (pip warns).
	$(PY) -m pip install -q --no-deps 'PyOpenGL==3.1.10'
	touch $@

setup: $(STAMP) ## Create .venv with pinned packages (and apt packages when missing)

$(DATASET): $(DEMO_CONFIG) | $(STAMP)
	$(NEURALAO) dataset $(DEMO_CONFIG) --out $(BUILD)/dataset

dataset: $(DATASET) ## Render and label the default scenes (G-buffers + Embree AO)

# The composed-scene corpus (configs/full.json: 2,420 train frames from 180 composed scenes
# plus the Sponza interiors, val/test split by mesh, 256x256, AO at 4 radii). Resumable; ~1.6 h at the
# rate measured on 2 cores shared with a training job.
# The training corpus (configs/corpus.json): every object mesh alone on an orbit (train meshes in
# train, val/test meshes in val/test), the interiors and composed rooms, frames of 128x128, 256x256,
# 384x384 and 320x180 (one size per shard) at 30-90 degree fields of view; AO at 4 radii, split by
# mesh. 2,768 frames, 209 Mpx; resumable.
CORPUS_CONFIG := configs/corpus.json
CORPUS := build/corpus/dataset/manifest.json
$(CORPUS): $(CORPUS_CONFIG) | $(STAMP)
	$(NEURALAO) dataset $(CORPUS_CONFIG) --out build/corpus/dataset

corpus: $(CORPUS) ## Render and label the training corpus: isolated objects, rooms, sizes, fields of view (resumable)

# The larger corpus (configs/corpus-large.json), 8,608 frames: every train mesh on a 48-view orbit and in
# 24 close-ups at 30-90 degree fields of view, the interiors, 480 composed rooms (objects on floors, against
# walls and in corners, the thin-part props), val/test split by mesh; four meshes (beetle, Spaceship,
# Corset, ClearcoatWicker) appear in none of its frames, for a held-aside evaluation; the G-buffer's back
# layer beside every shard. Sharded and resumable: rerun to continue an interrupted build.
CORPUS_LARGE_CONFIG := configs/corpus-large.json
CORPUS_LARGE := build/corpus-large/dataset/manifest.json
$(CORPUS_LARGE): $(CORPUS_LARGE_CONFIG) | $(STAMP)
	$(NEURALAO) dataset $(CORPUS_LARGE_CONFIG) --out build/corpus-large/dataset

corpus-large: $(CORPUS_LARGE) ## Render and label the larger corpus (8,608 frames; resumable across sessions)

# The composed-room corpus the earlier budget and corpus-size experiments trained on (configs/full.json).
FULL_CONFIG := configs/full.json
CORPUS_FULL := build/full/dataset/manifest.json
$(CORPUS_FULL): $(FULL_CONFIG) | $(STAMP)
	$(NEURALAO) dataset $(FULL_CONFIG) --out build/full/dataset

corpus-full: $(CORPUS_FULL) ## Render and label the composed-room corpus of the experiments (configs/full.json)

# The release U-Nets: configs/models.json trains each model on the larger corpus with its wall-clock budget
# (resumable: checkpoints under build/ship), exports, checks parity, evaluates the test split against
# SSAO/GTAO at every radius and installs runtime/models/<name>/ + index.json; `make models MODELS=...`
# ships only those. The default continues the learning curve's main run (its 4-CPU-hour snapshot, constant
# rate) with a cosine decay of 4 CPU-hours, so `make curve` comes first. `make evaluate` then scores them
# where users run them (configs/eval.json). The whole chain, resumable across sessions:
# `make corpus-large curve models evaluate`.
MODELS_CONFIG := configs/models.json
MODELS ?=
# The Unity, Unreal and Godot wrappers of docs/engines written again from the installed models' manifests.
ENGINE_DOCS = for f in runtime/models/*/model.onnx; do m=$$(basename $$(dirname $$f)); \
	$(PY) -m neuralao.export.glsl.engines $$f $$m docs/engines || exit 1; done
models: $(CORPUS_LARGE) $(MODELS_CONFIG) | $(STAMP) ## Train, export, check and install the release U-Nets (configs/models.json)
	$(NEURALAO) ship $(MODELS_CONFIG) $(if $(MODELS),--only $(MODELS))
	$(ENGINE_DOCS)

# The installed models' shaders regenerated from their committed ONNX files (no corpus, no training): after
# a change of the shader generator. Checked against onnxruntime before each folder is replaced.
model-shaders: $(MODELS_CONFIG) | $(STAMP) ## Regenerate the shipped models' shaders from their ONNX files (no training)
	$(NEURALAO) ship $(MODELS_CONFIG) --shaders-only $(if $(MODELS),--only $(MODELS))
	$(ENGINE_DOCS)

# Learning curves of the screen-space U-Net on the larger corpus (configs/curve.json): one run per line of
# the config, snapshots at 0.25-4 hours scored on the validation split and the test categories against
# GTAO; the table and plot replace the learning-curve section of docs/results.md, and every point's figures
# are kept in docs/learning_curve.json. Hours of training: resumable, rerun to continue. `make curve
# CURVE_RUNS="wide crop-128"` trains and scores only those runs; the others keep their recorded points.
CURVE_CONFIG := configs/curve.json
curve: $(CORPUS_LARGE) $(CURVE_CONFIG) | $(STAMP) ## Learning curves of the U-Net (hours, resumable) into docs/results.md
	$(PY) bench/learning_curve.py --config $(CURVE_CONFIG) --out build/curve --results docs/results.md \
		$(if $(CURVE_RUNS),--only $(CURVE_RUNS))

# The budget and corpus-size experiments (configs/experiments.json) on the composed-room corpus;
# exports go to build/experiments/models (not shipped); their figures are in docs/results.md.
EXPERIMENTS_CONFIG := configs/experiments.json
experiments: $(CORPUS_FULL) $(EXPERIMENTS_CONFIG) | $(STAMP) ## Train and export the budget and corpus-size experiment U-Nets
	$(NEURALAO) ship $(EXPERIMENTS_CONFIG) $(if $(MODELS),--only $(MODELS))

# Every shipped U-Net, SSAO and GTAO on test meshes by category (scans, glTF assets, low-poly interiors,
# composed rooms) x resolution (128, 256, 512, 1920x1080) at every radius: SSIM, RMSE, FLIP; the
# labels are built once (resumable, build/eval/frames) and each model's manifest gets its table.
EVAL_CONFIG := configs/eval.json
SHIPPED_DIRS = $(patsubst %/manifest.json,%,$(wildcard runtime/models/*/manifest.json))
evaluate: $(EVAL_CONFIG) | $(STAMP) ## Score the shipped U-Nets against SSAO/GTAO by category x resolution (configs/eval.json)
	$(NEURALAO) evaluate $(EVAL_CONFIG) --models $(SHIPPED_DIRS) --out build/eval --write-manifest

$(BUILD)/models/mlp-%.pt: $(DATASET)
	$(NEURALAO) train mlp --data $(BUILD)/dataset --scene $(MLP_SCENE) --size $* --out $@

# field-<scene>-<size>.pt: the scene is everything before the last '-' (scene names may contain '-').
$(BUILD)/models/field-%.pt: $(DATASET)
	stem='$*'; $(NEURALAO) train field --data $(BUILD)/dataset --scene "$${stem%-*}" --size "$${stem##*-}" \
	  --set steps=$(FIELD_STEPS) --no-progress --out $@

# The demo's frames are 128 rows: its U-Nets run at that height (a 256-row internal height would
# point-sample every frame up, 4x the pixels, for no gain on frames of one size).
DEMO_INTERNAL_HEIGHT := 128
$(UNET_CKPT): $(DATASET)
	$(NEURALAO) train unet --data $(BUILD)/dataset --set internal_height=$(DEMO_INTERNAL_HEIGHT) \
	  --set epochs=$(UNET_EPOCHS) --out $@

train: $(MLP_CKPTS) $(UNET_CKPT) $(FIELD_CKPTS) ## Train the baked MLP, the U-Net and the per-scene AO fields

$(BUILD)/export/%/manifest.json: $(BUILD)/models/%.pt
	$(NEURALAO) export $< --out $(@D)

export: $(EXPORTS) ## Export ONNX + GLSL for every trained model

$(PARITY): $(EXPORTS)
	$(NEURALAO) parity $(BUILD)/export --data $(BUILD)/dataset --out $@

parity: $(PARITY) ## Run generated GLSL against onnxruntime on real frames; fail above tolerance

# --shipped: the release U-Nets of runtime/models too (rows shipped:<name>, their learning curves and
# corpus-size plot); with none shipped the report says so in one line.
SHIPPED_INDEX := $(wildcard runtime/models/index.json)
$(REPORT): $(PARITY) $(SHIPPED_INDEX)
	$(NEURALAO) report --data $(BUILD)/dataset --exports $(BUILD)/export --shipped --target $(DEMO_TARGET) \
	  $(DEMO_REPORT_FLAGS) --out $(@D)

# A picture of the report's viewer page for the MLP's scene: the bake, the MLP and the field side by side
# (headless Chromium; docs/viewer.png is a copy of it).
$(VIEWER_PNG): $(REPORT)
	$(PY) bench/viewer_screenshot.py $(BUILD)/report/viewer/$(MLP_SCENE) --out $@

report: $(REPORT) ## Speed-vs-error report of every method (and the shipped U-Nets) at every label radius

select: $(EXPORTS) ## Pick the smallest model meeting the error target per scene
	$(NEURALAO) select --data $(BUILD)/dataset --exports $(BUILD)/export --target $(DEMO_TARGET) --out $(BUILD)/select.json

demo: $(REPORT) $(VIEWER_PNG) ## Set up if needed, then dataset -> train -> export -> parity -> report on the default scenes
	@echo "demo done: $(REPORT) (and report.html, contact sheets, viewer pages in $(BUILD)/report/), $(VIEWER_PNG)"

# The C reference hosts (runtime/host/), no Python: EGL (surfaceless Mesa) + OpenGL 4.3 compute, and the
# Vulkan runner (the export's SPIR-V through libvulkan: lavapipe here).
HOST := build/host/neuralao_host
VK_HOST := build/host/neuralao_vk
HOST_CFLAGS := -O2 -std=c11 -Wall -Wextra -Werror

bench-gpu: $(STAMP) ## GPU time of the shipped U-Nets' whole frames, GTAO and SSAO (C host: GL timer queries; Vulkan runner: timestamps): bench/gpu.sh
	bench/gpu.sh

host: $(HOST) ## Build the standalone C host that runs a shipped export on a raw float32 G-buffer

$(HOST): runtime/host/neuralao_host.c runtime/host/host_common.h
	mkdir -p $(@D)
	$${CC:-cc} $(HOST_CFLAGS) -o $@ $< -lEGL -lOpenGL -lm

host-vk: $(VK_HOST) ## Build the standalone C Vulkan runner of a shipped export's SPIR-V (same command line as the host)

$(VK_HOST): runtime/host/neuralao_vk.c runtime/host/host_common.h
	mkdir -p $(@D)
	$${CC:-cc} $(HOST_CFLAGS) -o $@ $< -lvulkan -lm

test: $(STAMP) ## Set up if needed, check the import layers, then run the test suite
	$(VENV)/bin/lint-imports --no-cache
	$(PY) -m pytest -n 2 --dist loadfile

# tests/test_cli_fuzz.py runs 500 seeded cases in `make test`; this runs more, from a fresh seed each time
# (printed; NEURALAO_FUZZ_SEED=N replays a run).
FUZZ_EXAMPLES ?= 5000
fuzz: $(STAMP) ## CLI fuzz harness with FUZZ_EXAMPLES (5000) cases from a fresh seed (NEURALAO_FUZZ_SEED replays)
	seed=$${NEURALAO_FUZZ_SEED:-$$RANDOM$$RANDOM}; echo "fuzz seed $$seed"; \
	NEURALAO_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) NEURALAO_FUZZ_SEED=$$seed $(PY) -m pytest tests/test_cli_fuzz.py -q

bench: $(STAMP) ## Run benchmarks under bench/ (JSON + markdown tables in build/bench)
	mkdir -p build/bench
	for b in bench/bench_*.py; do $(PY) $$b --out build/bench; done

lint: $(STAMP) ## ruff check + format check + import layers
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports --no-cache

clean: ## Remove build outputs (keeps .venv)
	rm -rf build
