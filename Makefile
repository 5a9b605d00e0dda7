# flagsim entry points. `make demo` and `make test` bootstrap a fresh Debian/Ubuntu machine:
# missing Debian packages are installed with apt-get when run as root (otherwise the command to
# run is printed), Python packages go into .venv, and the build is incremental in build/.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
BUILD := build
CTEST := $(VENV)/bin/ctest
# libegl1 ... libgl1-mesa-dri: off-screen OpenGL for the viewer's tests and screenshots (polyscope
# through EGL on Mesa's software rasteriser; each one found needed in a bare Debian 12 chroot).
APT_PACKAGES := g++ make python3-venv python3-dev libeigen3-dev libfftw3-dev libgtest-dev povray \
    libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri
JOBS ?= 2

.PHONY: all demo test test-cpp test-python build bench bench-deps study clean system-deps lint format

all: build

system-deps:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; \
	  else \
	    echo "flagsim needs these Debian packages:$$missing"; \
	    echo "run:  sudo apt-get install -y$$missing   and then make again"; exit 1; \
	  fi; \
	fi

# The requirement lists live in pyproject.toml; tools/requirements.py prints them (it reads the
# file with tomllib, or tomli on Python 3.10, installed first).
$(VENV)/.deps: pyproject.toml tools/requirements.py | system-deps
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "tomli>=2.0; python_version < '3.11'" cmake ninja
	$(PY) -m pip install -q -r <($(PY) tools/requirements.py build project test lint viewer usd distributed)
	@touch $@

# Incremental: scikit-build-core reuses build/ and ninja rebuilds only what changed.
build: $(VENV)/.deps
	@PATH="$(abspath $(VENV))/bin:$$PATH" $(PY) -m pip install -q --no-build-isolation --no-deps -e . \
	    -Cbuild-dir=$(BUILD) -Ccmake.define.FLAGSIM_BUILD_TESTS=ON \
	    -Ccmake.build-type=Release -Cbuild.tool-args=-j$(JOBS)

# Layout and lint: ruff (Python: pycodestyle, pyflakes, bugbear, imports; pyproject.toml) and
# clang-format (C++, .clang-format), both at 100 columns. `make format` applies both.
CXX_SOURCES = $(shell find csrc tests/cpp examples/cpp -name '*.cpp' -o -name '*.h')
lint: $(VENV)/.deps
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/clang-format --dry-run --Werror $(CXX_SOURCES)

format: $(VENV)/.deps
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .
	$(VENV)/bin/clang-format -i $(CXX_SOURCES)

test: lint build
	$(CTEST) --test-dir $(BUILD) --output-on-failure -j$(JOBS)
	$(PY) -m pytest -q

test-cpp: build
	$(CTEST) --test-dir $(BUILD) --output-on-failure -j$(JOBS)

test-python: build
	$(PY) -m pytest -q

# The paper's flag rendered by POV-Ray into out/demo/flag.gif (resumes; --overwrite replaces an
# export made with other settings).
demo: build
	$(PY) examples/paper_demo.py
	$(VENV)/bin/flagsim run paper --seconds 4 --fps 25 --out out/demo --render --gif \
	    --width 480 --height 360 --overwrite

# The engines the benchmark compares with: pyproject's [bench] extra (pip install .[bench]),
# installed here from its list so the editable build is left as it is. One that fails is skipped.
bench-deps: $(VENV)/.deps
	$(PY) -m pip install -q -r <($(PY) tools/requirements.py bench) || echo "some peers did not install: the benchmark skips them"

# Regenerates docs/reports/performance.md (run it on a quiet machine: other processes skew the figures).
bench: build bench-deps
	$(PY) -m benchmarks --peers --out out/bench --docs docs/reports/performance.md

# Regenerates docs/reports/accuracy.md (with docs/reports/images/accuracy_*.png),
# docs/reports/flutter.md (images/flutter.png) and docs/reports/stability.md. Accuracy runs on
# one worker so its timings are undisturbed; on 2 cores each study takes tens of minutes.
study: build
	$(VENV)/bin/flagsim study accuracy --out out/accuracy --docs docs/reports --jobs 1
	$(VENV)/bin/flagsim study flutter --out out/flutter --docs docs/reports --jobs $(JOBS)
	$(VENV)/bin/flagsim study stability --out out/stability --docs docs/reports --jobs $(JOBS)

clean:
	rm -rf $(BUILD) out
