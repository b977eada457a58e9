# Quick start: `make demo` and `make test`. Both create .venv and install what they need, at
# the versions locked in constraints.txt (docs/dependencies.md: `make test-latest`, `make lock`).
PY ?= python3
export PY
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
BENCH_STAMP := $(VENV)/.installed-bench
LOCK := constraints.txt

.PHONY: demo test test-latest lock bench clean

$(STAMP): pyproject.toml $(LOCK)
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -c $(LOCK) -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/trackgen validate examples/thesis_figure8.txt
	$(BIN)/trackgen build examples/thesis_figure8.txt -o out/thesis_figure8 --force
	mkdir -p out/demo
	$(BIN)/simrunner drive examples/line_follower.py --track out/thesis_figure8 --laps 2 \
		--video out/demo/run.mp4 --csv out/demo/run.csv --plot out/demo/run.png \
		--summary out/demo/summary.json
	@echo "demo outputs: out/thesis_figure8/ (preview.png, world.sdf, track.json, models/) and out/demo/ (run.mp4, run.csv, run.png, summary.json)"

test: $(STAMP)
	$(BIN)/python -m pytest -n 2

$(BENCH_STAMP): $(STAMP)
	$(BIN)/pip install -q -c $(LOCK) -e '.[test,bench]'
	touch $(BENCH_STAMP)

# the newest releases in .venv-latest: the tests, and the reference drives' bytes against .venv
test-latest: $(STAMP)
	bash tools/test_latest.sh

# rewrite constraints.txt from the newest releases (after test-latest passes)
lock:
	bash tools/lock.sh

bench: $(BENCH_STAMP)
	$(BIN)/python -m bench
	$(BIN)/python tools/render_bench_tables.py

clean:
	rm -rf $(VENV) .venv-latest out build *.egg-info
