# The two commands a newcomer runs on a fresh machine:  `make demo`  and  `make test`.
# Both create .venv, install the package (and the Debian libraries headless MuJoCo rendering needs), then run.

PYTHON   ?= python3
VENV     := .venv
BIN      := $(VENV)/bin
EXTRAS   ?= test
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl

.PHONY: demo test test-all lint bench reproduce system-deps clean

demo: $(VENV)/.installed system-deps
	$(BIN)/bodyschema demo

test: $(VENV)/.installed system-deps
	$(BIN)/python -m pytest -q

test-all: $(VENV)/.installed system-deps   ## including tests marked slow
	$(BIN)/python -m pytest -q -m ""

lint: $(VENV)/.installed   ## ruff (pinned in the test extra; config in pyproject.toml)
	$(BIN)/ruff check .

# scripts that need a store, trained models, a subcommand or another environment first (each docstring says how)
BENCH_SETUP := decoder_rule decoder_size lerobot_check levels_speed same_csvs tracking

bench: $(VENV)/.installed system-deps   ## every script that runs on its own defaults (hours); the rest are named
	@for script in bench/*.py; do name=$$(basename $$script .py); \
	  case " $(BENCH_SETUP) " in *" $$name "*) echo "== $$script: skipped, needs setup first (see its docstring)"; \
	  continue;; esac; echo "== $$script"; $(BIN)/python $$script || exit 1; done

reproduce: $(VENV)/.installed system-deps   ## the README's tables from its own commands (hours); ONLY=levels: one
	$(BIN)/bodyschema reproduce $(if $(ONLY),--only $(ONLY)) $(ARGS)

system-deps:
	@bash .ci/system_deps.sh

$(VENV)/.installed: pyproject.toml
	test -d $(VENV) || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch first and pinned: the local CPU wheel; an unpinned torch pulls a multi-GB CUDA build.
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[$(EXTRAS)]"
	touch $@

clean:
	rm -rf $(VENV) build *.egg-info outputs mlruns mlflow.db
