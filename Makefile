# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# This exact version from PyPI is the CPU build of torch: it installs without CUDA packages. The
# library itself accepts any torch in pyproject.toml's range, such as a GPU user's CUDA build.
TORCH_CPU := torch==2.13.0
# LeRobot's policies (the [lerobot] extra brings what they import); lerobot itself pins torch < 2.11,
# so it goes in without its dependencies, which would replace this torch (docs/lerobot.md).
LEROBOT := lerobot==0.4.4
DEMO := runs/demo
TEST_PROCESSES ?= 2

.PHONY: demo test setup clean

# The example of a world model and a policy of one's own (docs/world_model.md): its tests plug it in.
EXAMPLE := examples/tiny_video_wm

$(STAMP): pyproject.toml Makefile $(EXAMPLE)/pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
		{ echo "gymnast needs Python >= 3.11 (found $$($(PYTHON) --version)); set PYTHON=python3.11"; exit 1; }
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@# pip fetches only the installer, uv, and torch's own wheel, so that pip's configuration (an index,
	@# a directory of wheels) still decides which build of torch comes; uv then resolves and installs
	@# the rest in parallel, minutes faster than pip, the same versions, and keeps that torch.
	$(BIN)/python -m pip install --quiet --no-deps uv '$(TORCH_CPU)'
	$(BIN)/uv pip install --quiet --python $(BIN)/python -e '.[dev]' '$(TORCH_CPU)'
	$(BIN)/uv pip install --quiet --python $(BIN)/python --no-deps '$(LEROBOT)'
	@# Without its dependencies (torch and safetensors, already here): an installed package's entry
	@# points are what `--wm plugin:NAME` finds.
	$(BIN)/uv pip install --quiet --python $(BIN)/python --no-deps -e $(EXAMPLE)
	@# A CUDA build of torch (or its nvidia-* wheels) would mean gigabytes nobody asked for.
	@! $(BIN)/python -m pip list 2>/dev/null | grep -qi '^nvidia' || \
		{ echo "set-up pulled CUDA packages; the CPU build is expected"; exit 1; }
	$(BIN)/gymnast doctor
	@touch $(STAMP)

setup: $(STAMP)

test: $(STAMP)
	@# The import floors and "no cycles" (pyproject.toml, [tool.importlinter]) come before the tests.
	$(BIN)/lint-imports --no-cache --no-logo
	@# Two processes, a test file each at a time (session fixtures are built once per process): many
	@# tests wait on subprocesses, simulators and timeouts. Each process computes with its share of
	@# the cores (tests/conftest.py): with torch's default of a thread per core in both, the suite
	@# took 17.5 minutes on 2 cores; with one each, 11.6. The slowest are listed at the end.
	@# W&B (--tracker wandb) offline: nothing reaches the network (tests/conftest.py also sets it).
	WANDB_MODE=offline $(BIN)/python -m pytest -n $(TEST_PROCESSES) --dist loadfile --durations=25

# The headline experiment on a few tasks: every stage from data to report, then the table.
demo: $(STAMP)
	$(BIN)/gymnast experiment --preset demo --out $(DEMO)

clean:
	rm -rf $(VENV) runs .pytest_cache
