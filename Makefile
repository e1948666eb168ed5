# Two entry points do all the set-up: `make demo` and `make test` (see README).
VENV ?= .venv
PY := $(VENV)/bin/python
OUT ?= out

.PHONY: setup demo test lint bench clean

setup:
	@bash scripts/bootstrap.sh

# The main job on the built-in default: a simulated boat guided home along the Zshape field
# (trains out/zshape.pt first if it is not there).
demo: setup
	$(VENV)/bin/koopguide demo --out $(OUT)

# The whole suite: the closed-loop flights (marker `flight`, most of the time) on two workers, the rest after
# them in one process (its timing tests measure an unloaded machine). A plain `pytest` runs it all in one.
test: setup
	$(VENV)/bin/ruff check koopguide sitl tests examples
	$(VENV)/bin/lint-imports
	$(VENV)/bin/python -m pytest -q -m flight -n 2
	$(VENV)/bin/python -m pytest -q -m "not flight"

bench: setup
	$(VENV)/bin/koopguide bench speed
	$(VENV)/bin/koopguide bench guidance

clean:
	rm -rf $(OUT) .pytest_cache
