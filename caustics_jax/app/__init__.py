"""The application layer: user-facing jobs.

- `cli`: the `caustics-jax` command;
- `compare`: the solver comparison (`make demo`);
- `reporting`: tables and JSON of the comparison.
"""
