# stratawalk: make demo | make test | make lint | make docs
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.docs-installed

.PHONY: demo test test-long lint bench fuzz clean docs

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/stratawalk demo

# the suite on every core (pytest-xdist), a test file per worker at a time so that its
# module fixtures (plans) are made once, in collection order (tests/conftest.py puts the
# files that plan long walks first; xdist's default order, most tests first, started the
# 10 cm climb last); TEST_WORKERS=0 runs it in one process
# (the tests marked long, whole courses crossed where shorter tests check the same rules,
# run in make test-long and make bench: ~4 min on 2 cores)
TEST_WORKERS ?= auto
test: $(STAMP)
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder -m "not long"

test-long: $(STAMP)
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder -m long

# Theta1-4: IPOPT (exact derivatives) vs SLSQP (finite differences); ~4 min on 2 cores
# courses: LittleDog x 17 courses (9 named, 8 of issue 15) x soft/recursive, 240 s budget;
#   ~60 min on 2 cores
# physics: 9 courses + 20 generated, plan then MuJoCo open/feedback/correct at time scale 1;
#   ~90 min on 2 cores (a 2 m plan takes 30-60 s since the rolling feet; docs/guide/performance.md);
#   ladder: one feature per course at growing sizes, the limits table (~20 min);
#   generated set: 60 generated courses (seeds 0-19 at difficulty 0.6, 1 and 1.3, all seven
#   kinds), up to 120 s of planning each, then open loop and feedback on the planned ones,
#   a summary line per difficulty: long, ~2-3 hours on 2 cores (up to 1 h of planning alone;
#   a planned 3 m course takes ~1.5 min open loop and ~3 min feedback);
#   speed: planning time per course (median of 5), where it goes, flat 1-8 m (~10 min);
#   robots: every robot of the list on flat, rough and step courses scaled to it (~15 min)
bench: $(STAMP)
	$(MAKE) test-long
	$(VENV)/bin/stratawalk bench theta --jit
	$(VENV)/bin/stratawalk bench courses
	$(VENV)/bin/stratawalk bench physics
	$(VENV)/bin/stratawalk bench physics --courses ladder --generated 0 --modes open,feedback \
		--planned-only --time-budget 120 --out bench/results/ladder
	$(VENV)/bin/stratawalk bench physics --courses generated-set --generated 0 \
		--modes open,feedback --planned-only --time-budget 120 --out bench/results/generated-set
	$(VENV)/bin/stratawalk bench speed
	$(VENV)/bin/stratawalk bench robots

# every command fed generated bad input (hypothesis), 20x the cases of make test (~7,400,
# a fresh seed each run): never a traceback, never a hang; ~6 min on 2 cores
fuzz: $(STAMP)
	STRATAWALK_FUZZ_SCALE=20 $(PY) -m pytest -q tests/test_fuzz.py --hypothesis-show-statistics

# the documentation site into site/ (open site/index.html; .venv/bin/mkdocs serve previews it):
# mkdocs build --strict, so any warning (a broken cross-reference, a missing page) fails it;
# the API reference, the command pages and the settings reference are generated from the code
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 DISABLE_MKDOCS_2_WARNING=true $(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(VENV)/bin/ruff check planner tests
	$(VENV)/bin/ruff format --check planner tests

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
