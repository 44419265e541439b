# accelnav: `make demo` runs the whole chain on the built-in default model,
# `make test` runs the test suite. Each does the setup it needs.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.accelnav-installed

# numpy's BLAS threads on 4x4 and block products only fight each other on a
# 2-core machine (measured: a fit took 8x the CPU); one thread is faster.
export OPENBLAS_NUM_THREADS ?= 1

.PHONY: setup demo test docs lint format bench bench-coverage bench-studies fuzz fuzz-merge fuzz-corpus clean

include firmware/firmware.mk

setup: $(STAMP)

# the editable install also compiles the C kernels of setup.py's cffi_modules: redo it when they change
KERNELS := setup.py $(wildcard host/estimate/csrc/* host/data/csrc/* codegen/csrc/* host/link/csrc/* host/native/*.py)

$(STAMP): pyproject.toml $(KERNELS)
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,docs]'
	touch $@

demo: setup
	$(VENV)/bin/accelnav demo --out build/demo

test: setup
	$(PY) -m pytest -q

# the documentation site into build/docs; -W: a warning (a broken reference, a docstring that is not
# valid markup, a model key or a command without its page) fails the build. -E: every page re-read, so
# a warning is not hidden by the last build's cache.
docs: setup
	$(PY) -m sphinx -W --keep-going -E -q -b html docs build/docs
	@echo "docs: build/docs/index.html"

lint: setup
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	@files=$$(git ls-files '*.c' '*.h'); \
	if [ -n "$$files" ]; then clang-format --dry-run -Werror $$files; fi

format: setup
	$(PY) -m ruff format .
	$(PY) -m ruff check --fix .
	@files=$$(git ls-files '*.c' '*.h'); \
	if [ -n "$$files" ]; then clang-format -i $$files; fi

# bench/speed/bench_*.py: their markdown in build/bench/results.md, ending with one targets table
# (goal, measured, met) gathered from the scripts that state targets; the real recordings' targets
# (study_real_rests, about 10 s once its data is cached) join them there
bench: setup
	$(PY) bench/run_all.py speed --also bench/studies/study_real_rests.py --out build/bench/results.md

# bench/coverage/coverage_*.py: interval coverage over many seeds (minutes each)
bench-coverage: setup
	$(PY) bench/run_all.py coverage --out build/bench/coverage.md

# bench/studies/study_*.py: design studies and the real recordings (these download from PyPI)
bench-studies: setup
	$(PY) bench/run_all.py studies --out build/bench/studies.md

# libFuzzer on the firmware's receive path (clang + libclang-rt-14-dev): FUZZ_SECONDS of fuzzing from
# the seeds and firmware/fuzz/grown; the corpus it grows stays in build/fuzz/, a failing input is
# also kept in firmware/fuzz/regressions (replayed by every test run). CI runs a bounded run of the
# same harness (tests/firmware/test_fuzz_rx.py).
FUZZ_SECONDS ?= 600
fuzz: setup
	$(PY) firmware/fuzz/fuzz.py run --seconds $(FUZZ_SECONDS) --out build/fuzz

# minimise build/fuzz/corpus (a long `make fuzz`) and firmware/fuzz/grown into firmware/fuzz/grown
# (libFuzzer -merge=1 over the seeds): commit what it adds, and the next CI run starts from there
fuzz-merge: setup
	$(PY) firmware/fuzz/fuzz.py merge build/fuzz/corpus --out build/fuzz

# rewrite firmware/fuzz/corpus from the frame layout (after a layout change)
fuzz-corpus: setup
	$(PY) firmware/fuzz/fuzz.py corpus

clean:
	rm -rf build .pytest_cache
