# Two entry points for a fresh machine: `make run` and `make test`.
# Both create a local virtual environment in .venv on first use.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)
# The suite runs on this many processes (pytest-xdist): one more than the cores, since about a
# sixth of the tests' time is spent waiting on real time (serial boards, streams at their
# rate), not computing (2 cores: 314 s with 2 workers, 282 s with 3). Each test is ended after
# 10 minutes, so a hang is a failure that names the test, not a stalled run.
TEST_WORKERS ?= $(shell echo $$(( $$(nproc 2>/dev/null || echo 2) + 1 )))

.PHONY: venv run test lint bench clean bundle dist install-desktop uninstall-desktop

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

# The virtual environment alone (what `run` and `test` create on first use).
venv: $(STAMP)

run: $(STAMP)
	$(BIN)/inclinometer

# mypy (single-threaded, ~30 s from a cold cache) runs beside the suite at the lowest priority:
# it takes the time the cores would idle while tests wait on real time, not the time of the
# numba kernels compiled before the workers start, which keep both cores busy. Either failing
# fails.
# The suite writes Python's bytecode caches even where PYTHONDONTWRITEBYTECODE is set (an
# empty value is unset): each test process, and each command a test starts, would otherwise
# compile every module it imports from source again, and pytest rewrite every test file's
# asserts again in each worker (about 9 s of a core per worker).
test: $(STAMP)
	$(BIN)/ruff check app drivers tests benchmarks firmware/host
	$(BIN)/lint-imports --no-cache
	@nice -n 19 $(BIN)/mypy > .mypy-output 2>&1 & mypy=$$!; \
	QT_QPA_PLATFORM=offscreen PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest -n $(TEST_WORKERS) --dist worksteal \
		--timeout=600; tests=$$?; \
	wait $$mypy; typed=$$?; cat .mypy-output; rm -f .mypy-output; \
	test $$tests -eq 0 && test $$typed -eq 0

bench: $(STAMP)
	$(BIN)/python benchmarks/pipeline_throughput.py

# Distribution (packaging/README.md). The extras' tools go into the same venv on first use.
$(VENV)/.extra-%: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,$*]"
	touch $@

# The standalone one-folder app: dist/inclinometer/inclinometer (about 1 min; then check it
# with `dist/inclinometer/inclinometer --smoke-test`).
bundle: $(VENV)/.extra-bundle
	rm -rf dist/inclinometer
	$(BIN)/pyinstaller packaging/inclinometer.spec --noconfirm --log-level WARN \
		--distpath dist --workpath build/pyinstaller
	@du -sh dist/inclinometer

# The wheel and sdist in dist/, checked with `twine check --strict`.
dist: $(VENV)/.extra-dist
	rm -f dist/inclinometer-*.whl dist/inclinometer-*.tar.gz
	$(BIN)/python -m build --quiet --outdir dist .
	$(BIN)/twine check --strict dist/inclinometer-*.whl dist/inclinometer-*.tar.gz

# Menu entry, icons and AppStream data for the current user (~/.local/share); the command it
# starts: the bundle if built, else this venv's. The udev rule needs root: the script says how.
install-desktop:
	packaging/linux/install-desktop.sh "$(or $(INCLINOMETER),$(if $(wildcard dist/inclinometer/inclinometer),$(abspath dist/inclinometer/inclinometer),$(abspath $(BIN)/inclinometer)))"

uninstall-desktop:
	packaging/linux/install-desktop.sh --uninstall

clean:
	rm -rf $(VENV) test-artifacts .pytest_cache build dist
