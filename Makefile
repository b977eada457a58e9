# Quick start: `make demo` and `make test`. Both create .venv and install what they need.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
BENCH_STAMP := $(VENV)/.installed-bench

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
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
	$(BIN)/pip install -q -e '.[test,bench]'
	touch $(BENCH_STAMP)

bench: $(BENCH_STAMP)
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) out build *.egg-info
