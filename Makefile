# Two commands set everything up on a fresh machine:
#   make demo   creates .venv, installs, runs a short seeded batch of pick episodes on the default
#               scene and prints its summary
#   make test   creates/updates .venv, installs Debian's chromium for the browser test when
#               missing, runs ruff and mypy, the CI regression gate (a seeded batch of pick
#               episodes checked against tests/baselines/paper_ci.json) and the tests
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
DEMO_OUT ?= out/demo
# The CI regression gate: this batch, checked against the baseline that the same command
# made (make ci-baseline regenerates it after an intended change of the success rate).
CI_GATE_OUT  ?= out/ci_gate
CI_BASELINE  := tests/baselines/paper_ci.json
CI_GATE_ARGS := --scene paper --seeds 0:40 --workers 2 --quiet

# Headless offscreen rendering through Mesa's EGL (no GPU, no display needed).
export MUJOCO_GL ?= egl

.PHONY: demo test ci-gate ci-baseline lint bench gl-check browser system-deps clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "error: Python >= 3.11 is required; $(PYTHON) is $$($(PYTHON) --version 2>&1)"; exit 1; }
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	$(BIN)/python -c 'from stackpick_sim.vision.kernels import warm_up; warm_up()'
	@touch $(STAMP)

# One line naming the missing Debian packages if EGL rendering does not work.
gl-check: $(STAMP)
	@$(BIN)/python -m stackpick_sim.glcheck

# The HTML report's browser test drives Debian's chromium (through the playwright package,
# which downloads nothing). Installed here when missing (as root with apt-get); otherwise one
# line says why not, and that test is skipped with the reason.
CHROMIUM ?= /usr/bin/chromium
browser:
	@test -x $(CHROMIUM) || { \
	  if [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then \
	    echo "note: no $(CHROMIUM) and no root apt-get: the browser test will be skipped" \
	      "(as root on Debian/Ubuntu: apt-get install chromium)"; \
	  else \
	    echo "installing Debian's chromium for the browser test (apt-get)"; \
	    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	      apt-get install -y -qq --no-install-recommends chromium >/dev/null; } || \
	    echo "note: apt-get could not install chromium: the browser test will be skipped"; \
	  fi; }

demo: $(STAMP) gl-check
	rm -rf $(DEMO_OUT)
	$(BIN)/stackpick run --scene paper --seeds 0:10 --out $(DEMO_OUT) --quiet

# Lint and the gate run first so that pytest's summary stays the last line of the output.
test: $(STAMP) gl-check browser lint ci-gate
	STACKPICK_CHROMIUM=$(CHROMIUM) $(BIN)/python -m pytest -q

ci-gate: $(STAMP) gl-check
	rm -rf $(CI_GATE_OUT)
	$(BIN)/stackpick run $(CI_GATE_ARGS) --out $(CI_GATE_OUT)
	$(BIN)/stackpick check $(CI_GATE_OUT) --baseline $(CI_BASELINE)

ci-baseline: $(STAMP) gl-check
	rm -rf $(CI_GATE_OUT)
	$(BIN)/stackpick run $(CI_GATE_ARGS) --out $(CI_GATE_OUT)
	cp $(CI_GATE_OUT)/summary.json $(CI_BASELINE)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

bench: $(STAMP) gl-check
	$(BIN)/python benchmarks/bench_scene.py

# The system libraries EGL rendering needs (Debian/Ubuntu, as root); gl-check says if missing.
system-deps:
	apt-get update && apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache
