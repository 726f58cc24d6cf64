# occgp: `make demo` and `make test` each do the whole set-up on a fresh Debian
# machine (system packages, .venv, the package with its extras), then run.
# Both are idempotent: the set-up is redone only when the build inputs change.
# `make test-fast` runs the tests not marked slow (pytest -m "not slow", about a
# minute on 2 cores) for a quick check while editing; `make test` runs every test.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.occgp-installed
EXTRAS ?= test,dask,ros,iln,stereo
# the CPU build of PyTorch, installed before the iln extra (an unpinned torch pulls the CUDA
# build, several GB); the package itself asks for torch>=2.1
TORCH  ?= torch==2.13.0
BUILD_INPUTS := setup.py pyproject.toml $(wildcard ext/*.pyx ext/*.pxd ext/*.pxi ext/*.h)

.PHONY: all demo test test-fast bench docs asan soak fuzz system venv install clean distclean dist

all: test

system:
	@PYTHON=$(PYTHON) bash tools/install-system-deps.sh

$(PY):
	@PYTHON=$(PYTHON) bash tools/install-system-deps.sh
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): $(PY) $(BUILD_INPUTS)
	@PYTHON=$(PYTHON) bash tools/install-system-deps.sh
	$(PY) -m pip install -q "setuptools>=77" wheel "Cython>=3.1" "numpy>=2.0"
	$(PY) -m pip install -q "$(TORCH)"
	$(PY) -m pip install -q --no-build-isolation -e ".[$(EXTRAS)]"
	@touch $@

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/occgp demo -o demo_out

# Results that pass through BLAS differ in their last bits between CPUs (OpenBLAS picks
# its kernels by CPU); the tests compare them with stated tolerances. The GP, grid and
# mixture tests run again under two other kernel sets, so that a bit-equality claim on
# BLAS output fails here and not only on someone else's machine.
BLAS_GUARD ?= tests/gp/test_gp_grid.py tests/gp/test_gp_mixture.py tests/gp/test_gpomik.py \
              tests/gp/test_gp_committee.py tests/grid/test_grid.py
# the layer contract (.importlinter, docs/architecture.rst) first: an upward import or an
# import circle fails here before the tests run; import-linter comes with the test extra,
# and is installed here too where an older .venv lacks it
test: $(STAMP)
	@$(PY) -m pip show -q import-linter >/dev/null 2>&1 || $(PY) -m pip install -q "import-linter>=2.1"
	$(VENV)/bin/lint-imports
	$(PY) -m pytest -q
	@for core in Prescott Haswell; do \
	  echo "OPENBLAS_CORETYPE=$$core: $(BLAS_GUARD)"; \
	  OPENBLAS_CORETYPE=$$core $(PY) -m pytest -q -p no:cacheprovider $(BLAS_GUARD) || exit 1; \
	done

# the quick subset while editing: every test module but the tests marked slow
# (pyproject.toml's `slow` marker); `make test` above runs them all
test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

bench: $(STAMP)
	$(PY) bench/bench_octree.py

# the extensions built with AddressSanitizer + UBSan (build/asan), the test suite under them
asan: $(STAMP)
	PY=$(PY) bash tools/asan.sh

# >= 1,000 scans into one map: resident memory and time per scan in blocks
soak: $(STAMP)
	$(PY) bench/bench_soak.py

docs: $(STAMP)
	$(PY) -m pip install -q -e ".[docs]" --no-build-isolation
	$(PY) -m sphinx -W --keep-going -b html docs docs/_build/html

# The release artefacts (issue 43, RELEASING.md): dist/occgp-<version>.tar.gz and a
# self-contained manylinux wheel (liboctomap, liboctomath and libgomp inside), built from a
# clean copy of the tree by PyPA's build, repaired by auditwheel, then installed and run by
# tests/test_wheel.py in fresh venvs (tools/dist.sh). The tools live in their own venv,
# .venv-dist; .venv's editable install is not touched. Not part of CI (`make test`).
DIST_VENV  ?= .venv-dist
DIST_STAMP := $(DIST_VENV)/.occgp-dist-tools
# empty: the working tree's files; a tag or commit (make dist DIST_REF=v0.1.0): its tree
DIST_REF   ?=
# 1: the wheel's libraries stripped of symbols and debug information (auditwheel --strip)
DIST_STRIP ?= 1
$(DIST_STAMP): tools/dist-requirements.txt
	@PYTHON=$(PYTHON) bash tools/install-system-deps.sh
	$(PYTHON) -m venv $(DIST_VENV)
	$(DIST_VENV)/bin/python -m pip install -q -r tools/dist-requirements.txt
	@touch $@

dist: $(DIST_STAMP)
	DIST_PY=$(DIST_VENV)/bin/python DIST_REF=$(DIST_REF) DIST_STRIP=$(DIST_STRIP) bash tools/dist.sh

clean:
	rm -rf build docs/_build docs/auto_examples docs/gen_modules ext/*.cpp occgp/*.so demo_out

distclean: clean
	rm -rf $(VENV) $(DIST_VENV) dist wheelhouse *.egg-info

# Long fuzz campaign of the readers and loaders (tools/fuzz.py): FUZZ_CASES seeded
# mutation cases per reader, then as many coverage-guided atheris runs where atheris
# installs (the seeded generator alone otherwise). Prints a table; fails on any
# crash, hang or unclear exception.
FUZZ_CASES ?= 10000
FUZZ_JOBS  ?= 2
fuzz: $(STAMP)
	-$(PY) -m pip install -q atheris || echo "atheris does not install here: the seeded generator runs alone"
	$(PY) tools/fuzz.py --cases $(FUZZ_CASES) --jobs $(FUZZ_JOBS) --atheris-runs $(FUZZ_CASES)
