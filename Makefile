# The README's two commands: `make demo` and `make test`. Each sets itself up on first use.
# `make test-unit`: the tests that start no ROS graph or node process and run no long experiment, in under 2 minutes.
VENV ?= .venv
PYTEST_ARGS ?=

.PHONY: setup demo lint test test-unit bench clean

setup:
	@scripts/setup.sh $(VENV)

demo: setup
	$(VENV)/bin/woody run --fillets 12 --out bags/demo --force

lint: setup
	$(VENV)/bin/ruff check .

test: setup lint
	$(VENV)/bin/python -m pytest tests $(PYTEST_ARGS)

test-unit: setup lint
	$(VENV)/bin/python -m pytest tests -m "not ros and not slow" $(PYTEST_ARGS)

bench: setup
	$(VENV)/bin/woody bench sim
	$(VENV)/bin/woody bench sim --lanes 6 --speed-fpm 130
	$(VENV)/bin/woody bench vision
	$(VENV)/bin/woody bench graph
	$(VENV)/bin/woody bench graph --lanes 6 --speed-fpm 130
	$(VENV)/bin/woody bench sweep

clean:
	rm -rf ros_ws/build ros_ws/log
