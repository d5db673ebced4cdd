# Two commands: `make run` (the main job on the default experiment) and `make test`.
# Both set everything up first and are safe to repeat.
EXPERIMENT ?= experiments/default.toml
OUT ?= out/default

.PHONY: setup run test bench tradeoff
setup:
	@bash scripts/setup.sh

run: setup
	.venv/bin/study calibrate $(EXPERIMENT) --out $(OUT)

tradeoff: setup
	.venv/bin/study tradeoff experiments/default.toml experiments/deep_steps.toml --out out/tradeoff

test: setup
	.venv/bin/python -m pytest -q

bench: setup
	.venv/bin/python benchmarks/bench_reference.py
	.venv/bin/python benchmarks/bench_port.py
	.venv/bin/python benchmarks/bench_fit.py
	.venv/bin/python benchmarks/bench_sweep.py
