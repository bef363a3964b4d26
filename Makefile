# `make demo` and `make test` work on a fresh machine: they create .venv on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test figures figures-vulkan lint typecheck clean export conformance notebooks docs

# The extras of `make notebooks` and `make docs`, installed into the same .venv on first use.
NB_STAMP   := $(VENV)/.installed-notebooks
DOCS_STAMP := $(VENV)/.installed-docs

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt -e ".[dev]"
	touch $(STAMP)

$(NB_STAMP): $(STAMP)
	$(PY) -m pip install -q -c constraints.txt -e ".[dev,notebooks]"
	touch $(NB_STAMP)

$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install -q -c constraints.txt -e ".[dev,docs]"
	touch $(DOCS_STAMP)

demo: $(STAMP)
	$(VENV)/bin/caustics-jax demo --cpu-devices all --figure figures/solver_comparison.png --json figures/solver_comparison.json

test: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile --hypothesis-profile=ci

# Every experiment's figure and JSON on the CPU (an hour or more: the start-point sweep
# builds a 1M-triangle scene, the throughput benchmark alone takes ~10 minutes). The GLSL
# walk and Newton against the JAX ones need a Vulkan device: `make figures-vulkan`.
figures: $(STAMP)
	$(PY) -m experiments.conic_curve
	$(PY) -m experiments.float32_audit
	$(PY) -m experiments.kernel_approximations
	$(PY) -m experiments.start_point_throughput
	$(PY) -m experiments.start_point_device
	$(PY) -m experiments.irradiance_agreement
	$(PY) -m experiments.estimators
	$(PY) -m experiments.visibility
	$(PY) -m experiments.features_benchmark
	$(PY) -m experiments.stability
	$(PY) -m experiments.scaling
	$(PY) -m experiments.precision_agreement
	$(PY) -m experiments.exhaustive_cost
	$(PY) -m experiments.throughput
	$(PY) -m experiments.compile_options
	$(PY) -m experiments.ellipse
	$(PY) -m experiments.differential
	$(PY) -m experiments.denoiser
	$(PY) -m experiments.temporal
	$(PY) -m experiments.reuse
	$(PY) -m experiments.cull
	$(PY) -m experiments.budget
	$(VENV)/bin/caustics-jax demo --cpu-devices all --figure figures/solver_comparison.png --json figures/solver_comparison.json

# The GLSL walk and one-step Newton on lavapipe (or another Vulkan device) against the JAX
# ones (docs/export.md); `python tools/gpu_recipe.py` does it on a Vulkan GPU.
figures-vulkan: $(STAMP)
	$(PY) -m experiments.glsl_throughput

# Execute every notebook headless (nbclient); fails on any cell error. A full run rewrites the
# executed copies notebooks/*.ipynb; CAUSTICS_JAX_QUICK=1 (what CI runs) uses small lane and
# photon counts and writes its copies to build/notebooks/ instead (docs/notebooks.md).
notebooks: $(NB_STAMP)
	$(PY) notebooks/execute.py

# The documentation site, offline, strict (broken links and docstring warnings fail): site/.
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

# Shader reference data (docs/export.md): every kernel and every scene, and the GLSL ports
# (kernels; start point, walk, D, irradiance on the scenes) run against it on a Vulkan
# device (lavapipe: apt-get install glslang-tools libvulkan1 libvulkan-dev mesa-vulkan-drivers).
REFDATA := out/refdata
export: $(STAMP)
	$(VENV)/bin/caustics-jax export --out $(REFDATA) --count 1024 --lanes 4096 --seed 0

conformance: export
	$(VENV)/bin/caustics-jax conformance $(REFDATA) --json $(REFDATA)/conformance.json

lint: $(STAMP)
	$(VENV)/bin/ruff check caustics_jax experiments tests notebooks/*.py docs/_hooks.py

# mypy on the package, configured in pyproject.toml [tool.mypy] (CI runs lint and typecheck first).
typecheck: $(STAMP)
	$(VENV)/bin/mypy

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis site build
