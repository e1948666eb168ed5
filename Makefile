# Two entry points do all the set-up: `make demo` and `make test` (see README).
VENV ?= .venv
PY := $(VENV)/bin/python
OUT ?= out

.PHONY: setup demo test lint bench clean

setup:
	@bash scripts/bootstrap.sh

# The main job on the built-in default: train Zshape, evaluate it, plot it.
demo: setup
	@mkdir -p $(OUT)
	$(VENV)/bin/koopguide train --lasa Zshape -o $(OUT)/zshape.pt --seed 0
	$(VENV)/bin/koopguide eval $(OUT)/zshape.pt
	$(VENV)/bin/koopguide plot $(OUT)/zshape.pt -o $(OUT)/zshape.png

test: setup
	$(VENV)/bin/ruff check koopguide sitl tests
	$(VENV)/bin/python -m pytest -q

bench: setup
	$(VENV)/bin/koopguide bench speed
	$(VENV)/bin/koopguide bench guidance

clean:
	rm -rf $(OUT) .pytest_cache
