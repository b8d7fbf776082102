# GPU path (README "GPU"): MuJoCo Warp + torch on one NVIDIA GPU. Included by the Makefile.
# `make gpu-check` is the first command a person with a GPU runs: it installs the CUDA build of torch
# (unless the installed torch already sees a GPU) and MuJoCo Warp (extra `gpu`), runs the Warp parity
# tests on the GPU, scripts/bench_gpu.py at 1,024 / 4,096 / 8,192 envs and a GPU_CHECK_MINUTES-long
# `scale=paper` cgail run with env.backend=warp, and writes outputs/gpu-check/report.md.
GPU_CHECK_OUT ?= outputs/gpu-check
GPU_CHECK_MINUTES ?= 10
TORCH_CUDA ?= torch
TORCH_CUDA_INDEX ?= https://download.pytorch.org/whl/cu128

.PHONY: gpu-install gpu-check bench-gpu

gpu-install: ## GPU: CUDA build of torch (TORCH_CUDA from TORCH_CUDA_INDEX) + charctl with MuJoCo Warp (extra gpu)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@if $(PY) -c "import torch, sys; sys.exit(0 if torch.cuda.is_available() else 1)" 2>/dev/null; then \
	  echo "torch already sees a GPU: keeping it"; \
	else \
	  $(PIP) uninstall -y -q torch 2>/dev/null || true; \
	  $(PIP) install -q "$(TORCH_CUDA)" --index-url $(TORCH_CUDA_INDEX); \
	fi
	$(MAKE) --no-print-directory install TORCH=skip
	$(PIP) install -q -e '.[test,gpu]'
	$(PY) -c "import torch, mujoco_warp; assert torch.cuda.is_available(), 'torch sees no CUDA device'; print('GPU:', torch.cuda.get_device_name(0), '| torch', torch.__version__, '| mujoco_warp', mujoco_warp.__version__)"

gpu-check: gpu-install ## GPU: parity tests on the GPU, bench at 1k/4k/8k envs, a 10-min scale=paper run -> outputs/gpu-check/report.md
	$(PY) scripts/gpu_check.py --out $(GPU_CHECK_OUT) --minutes $(GPU_CHECK_MINUTES)

bench-gpu: ## GPU path throughput: raw Warp physics, rollout, whole cgail loop at 1k/4k/8k envs (BENCH_GPU_ARGS to change)
	$(PY) scripts/bench_gpu.py $(BENCH_GPU_ARGS)
