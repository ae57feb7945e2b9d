# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEMO := runs/demo

.PHONY: demo test setup clean

$(STAMP): pyproject.toml Makefile
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
		{ echo "gymnast needs Python >= 3.11 (found $$($(PYTHON) --version)); set PYTHON=python3.11"; exit 1; }
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@# A CUDA build of torch (or its nvidia-* wheels) would mean gigabytes nobody asked for.
	@! $(BIN)/python -m pip list 2>/dev/null | grep -qi '^nvidia' || \
		{ echo "set-up pulled CUDA packages; the CPU build is expected"; exit 1; }
	$(BIN)/gymnast doctor
	@touch $(STAMP)

setup: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest

DEMO_TASKS := drawer-open-v3,reach-v3,push-v3

demo: $(STAMP)
	$(BIN)/gymnast collect --tasks $(DEMO_TASKS) --episodes-per-task 6 --out $(DEMO)/data
	$(BIN)/gymnast inspect --data $(DEMO)/data --sheet $(DEMO)/episodes.png --episodes 6
	$(BIN)/gymnast contact-sheet --tasks mt10 --out $(DEMO)/mt10.png
	$(BIN)/gymnast sft --data $(DEMO)/data --out $(DEMO)/sft --preset demo --demos-per-task 4
	$(BIN)/gymnast eval --policy $(DEMO)/sft --tasks $(DEMO_TASKS) --episodes 10 --out $(DEMO)/sft_eval.json
	$(BIN)/gymnast train-wm --data $(DEMO)/data --out $(DEMO)/wm --preset demo
	$(BIN)/gymnast eval-wm --wm $(DEMO)/wm --data $(DEMO)/data --out $(DEMO)/wm_eval.json --control-scenes 2 --gifs 1

clean:
	rm -rf $(VENV) runs .pytest_cache
