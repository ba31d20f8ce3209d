# The README's two commands: `make demo` (the main job on the bundled default scene)
# and `make test`.  Each sets up what it needs: a virtual environment in .venv and,
# where apt works as root, libLLVM 19 for Mitsuba's fast LLVM backend.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-fast lint bench setup llvm clean error-model docs docs-build

# the error models shipped in mirrorsim/data, each fitted on the project's own dataset of
# the scene format's domain: the ideal bench (scenes/dataset_spec_domain.yaml) and
# hand-built benches (scenes/dataset_spec_domain_bench.yaml); tests/test_uncertainty.py
# renders again the rows each model's provenance records and checks them against it
ERROR_MODEL_SEED := 20261206
ERROR_MODEL_N := 360
BENCH_MODEL_SEED := 20261207
BENCH_MODEL_N := 300

setup: $(STAMP) llvm

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $@

# libLLVM 15/16 crash drjit's LLVM backend and 19 works; without it mirrorsim still
# runs, on the slower scalar backend.  Best effort: never fails the build.
llvm:
	@if [ -n "$$(ls /usr/lib/*/libLLVM-19.so* /usr/lib/libLLVM-19.so* 2>/dev/null)" ]; then :; \
	elif command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	  echo "installing libllvm19 (Mitsuba's fast CPU backend)"; \
	  apt-get install -y -q libllvm19 >/dev/null 2>&1 || \
	  { apt-get update -q >/dev/null 2>&1 && apt-get install -y -q libllvm19 >/dev/null 2>&1; } || \
	  echo "warning: could not install libllvm19; rendering will use scalar_rgb"; \
	else echo "note: install libLLVM 19 (apt-get install libllvm19) for the fast backend"; fi

demo: setup
	$(BIN)/mirrorsim evaluate scenes/default.yaml --keep plot annotated

# the loaders a learning pipeline uses (Hugging Face's datasets, mlcroissant, pycocotools):
# the extra `ml`, which tests/test_dataset_exports.py loads each dataset export with
ML_STAMP := $(VENV)/.ml-installed
$(ML_STAMP): pyproject.toml $(STAMP)
	$(BIN)/pip install -q -e '.[ml]'
	touch $@

test: setup docs-build $(ML_STAMP)
	$(BIN)/python -m pytest
	$(BIN)/ruff check .

# the documentation site, built strictly (a broken include or reference fails it)
DOCS_STAMP := $(VENV)/.docs-installed
$(DOCS_STAMP): pyproject.toml $(STAMP)
	$(BIN)/pip install -q -e '.[docs]'
	touch $@

docs-build: setup $(DOCS_STAMP)
	$(BIN)/python docs/gen_reference.py --check
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

# re-run every command that feeds a table or figure in the README and the docs (about
# an hour on 2 cores; throughput figures want a quiet machine), then build the site
docs: setup $(DOCS_STAMP)
	$(BIN)/python docs/regenerate.py
	$(BIN)/python docs/gen_reference.py
	$(BIN)/python docs/make_images.py
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

test-fast: setup
	$(BIN)/python -m pytest -m "not slow"

lint: setup
	$(BIN)/ruff check .

bench: setup
	$(BIN)/python benchmarks/render.py
	$(BIN)/python benchmarks/detect.py
	$(BIN)/python benchmarks/detect.py --offaxis --plot docs/detect_offaxis.png
	$(BIN)/python benchmarks/edges.py
	$(BIN)/python benchmarks/particle.py
	$(BIN)/python benchmarks/paper.py
	$(BIN)/python benchmarks/evaluate.py
	$(BIN)/python benchmarks/dataset.py
	$(BIN)/python benchmarks/pieces.py --rss 30
	$(BIN)/python benchmarks/edge_noise.py
	$(BIN)/python benchmarks/pencil_edges.py --spp 1024
	$(BIN)/python benchmarks/sensor_noise.py

error-model: setup
	rm -rf renders/em-ideal renders/em-bench
	$(BIN)/mirrorsim dataset --n $(ERROR_MODEL_N) --seed $(ERROR_MODEL_SEED) \
	  --spec scenes/dataset_spec_domain.yaml --out renders/em-ideal --workers 2 --quiet
	$(BIN)/mirrorsim dataset --n $(BENCH_MODEL_N) --seed $(BENCH_MODEL_SEED) \
	  --spec scenes/dataset_spec_domain_bench.yaml --out renders/em-bench --workers 2 --quiet
	$(BIN)/mirrorsim errormodel renders/em-ideal
	$(BIN)/mirrorsim errormodel renders/em-bench
	cp renders/em-ideal/error_model.json mirrorsim/data/error_model.json
	cp renders/em-bench/error_model.json mirrorsim/data/error_model_bench.json

clean:
	rm -rf $(VENV) renders/*/ .pytest_cache .ruff_cache .hypothesis
