# The course's commands. Every target creates the environment first (a .venv beside this file),
# so each works on a fresh machine that has only Python 3.11.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup demo test test-fast assignments student-release datasets-check gradescope formgrader mutants bench numbers site figures clean

$(STAMP): pyproject.toml lectures/requirements.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e . -r lectures/requirements.txt
	$(PY) -m rlcourse.video
	@# Chromium for tests/test_browser.py (the notebooks in JupyterLab): installed as root, else the test says it skips.
	@if [ "$$(id -u)" = 0 ] && ! command -v chromium >/dev/null && command -v apt-get >/dev/null; then \
		echo "installing chromium for the browser tests"; \
		DEBIAN_FRONTEND=noninteractive apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium \
			|| echo "could not install chromium: tests/test_browser.py will skip"; fi
	@# Slurm and munge for tests/outputs/test_slurm.py (a single-node Slurm of its own grades a class as a job array):
	@# installed as root, else the test says it skips.
	@if [ "$$(id -u)" = 0 ] && ! PATH="$$PATH:/usr/sbin:/sbin" command -v slurmctld >/dev/null && command -v apt-get >/dev/null; then \
		echo "installing slurm-wlm and munge for the Slurm test"; \
		DEBIAN_FRONTEND=noninteractive apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge \
			|| echo "could not install slurm-wlm and munge: tests/outputs/test_slurm.py will skip"; fi
	touch $(STAMP)

setup: $(STAMP)

## The grading demo: batch-grade every assignment's sample submissions, print the gradebooks.
demo: setup
	$(PY) -m autograder demo

## The whole test suite: over both cores (pytest-xdist, a test file per worker so that its fixtures are built
## once), then the tests marked serial alone (they time themselves, or starve the CPU on purpose).
test: setup
	$(PY) -m pytest -q -n 2 --dist loadfile -m "not serial"
	$(PY) -m pytest -q -m serial

## The edit-test loop: everything but the end-to-end tests marked slow (notebook runs, batches, the
## security corpus, the site), over both cores (pytest-xdist). CI runs the whole suite (make test).
test-fast: setup
	$(PY) -m pytest -q -m "not slow" -n 2

## Regenerate every student notebook from solutions/ with nbgrader, and the samples made from them.
assignments: setup
	$(PY) -m autograder assignments

## The student-only tree: make student-release OUT=DIR
student-release: setup
	@test -n "$(OUT)" || { echo "usage: make student-release OUT=DIR"; exit 2; }
	$(PY) -m autograder student-release $(OUT)

## Verify every shipped data file against datasets/MANIFEST.json.
datasets-check: setup
	$(PY) -m rlcourse.data check

## The Gradescope bundle: make gradescope ID=hw0_setup
gradescope: setup
	@test -n "$(ID)" || { echo "usage: make gradescope ID=<assignment>"; exit 2; }
	$(PY) -m autograder gradescope $(ID)

## nbgrader's formgrader on this course, to grade written answers: http://127.0.0.1:PORT/formgrader, PORT 8888
## if free, else a free one (make formgrader PORT=9000 to choose); after python -m autograder nbgrader-sync
## (docs/instructors.md: Generate and Autograde are refused there by nbgrader_config.py).
formgrader: setup
	@port="$(PORT)"; [ -n "$$port" ] || port=$$($(PY) -c 'import socket; s = socket.socket(); \
		free = s.connect_ex(("127.0.0.1", 8888)) != 0; s.close(); s = socket.socket(); s.bind(("127.0.0.1", 0)); \
		print(8888 if free else s.getsockname()[1])'); \
	echo "formgrader: http://127.0.0.1:$$port/formgrader"; \
	PATH="$(abspath $(VENV))/bin:$$PATH" $(VENV)/bin/jupyter server --no-browser --ip=127.0.0.1 --port=$$port \
		$$([ "$$(id -u)" = 0 ] && echo --allow-root)

## Mutation testing of one assignment's hidden suite: make mutants ID=hw0_setup [ARGS="--max-per-stub 12"]
mutants: setup
	@test -n "$(ID)" || { echo "usage: make mutants ID=<assignment> [ARGS=...]"; exit 2; }
	nice -n 10 $(PY) -m autograder mutants $(ID) $(ARGS)

## Every benchmark; each prints the table the README shows.
bench: setup
	set -e; for script in bench/bench_*.py; do $(PY) $$script; done

## The numbers pages (docs/numbers/), rewritten from bench/results/*.json; tests/test_numbers_pages.py checks them.
numbers: setup
	$(PY) bench/numbers_pages.py

## The lecture site, built from scratch, offline, failing on any warning or unparsable formula.
site: setup
	rm -rf lectures/_build
	$(VENV)/bin/jupyter-book build lectures --warningiserror --nitpick --keep-going
	$(PY) lectures/check_site.py
	@echo "open lectures/_build/html/index.html"

## The lecture figures (matplotlib scripts in lectures/figures/).
figures: setup
	$(PY) lectures/figures/make_figures.py

clean:
	rm -rf build .pytest_cache
