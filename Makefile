# Two commands: `make run` (the main job on the default experiment) and `make test`.
# Both set everything up first and are safe to repeat.
EXPERIMENT ?= experiments/default.toml
OUT ?= out/default

.PHONY: setup run test lint docs bench tradeoff
setup:
	@bash scripts/setup.sh

run: setup
	.venv/bin/study calibrate $(EXPERIMENT) --out $(OUT)

tradeoff: setup
	.venv/bin/study tradeoff experiments/default.toml experiments/deep_steps.toml --out out/tradeoff

# the suite on TEST_WORKERS processes (pytest-xdist), whole test files per process: a file's
# module fixtures (a shared reference, a CLI run) are built once; PYTEST_ARGS adds options
TEST_WORKERS ?= 2
test: setup lint
	.venv/bin/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile $(PYTEST_ARGS)

lint: setup
	.venv/bin/ruff check .
	.venv/bin/ruff format --check .

# the documentation site, served at http://127.0.0.1:8000 (tests build it with --strict)
docs: setup
	.venv/bin/python scripts/build_docs.py
	.venv/bin/mkdocs serve

# the four headline benchmarks; the others in benchmarks/ are run alone (each says how)
bench: setup
	.venv/bin/python benchmarks/bench_reference.py
	.venv/bin/python benchmarks/bench_port.py
	.venv/bin/python benchmarks/bench_fit.py
	.venv/bin/python benchmarks/bench_sweep.py
