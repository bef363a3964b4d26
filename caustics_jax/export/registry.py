"""The kernel registry of the shader reference data (DESIGN.md "Reference data for shader tests").

A kernel is registered once, next to its case generator, by decorating the function that
evaluates the package kernel on a dict of inputs:

    @register("refract", equations="GLSL refract (math.md §1; seed 002 eq. 3.1-3.2)",
              reference=geometry.refract, inputs={"I": "vec3", "N": "vec3", "eta": "float"},
              outputs={"T": "vec3"}, generate=_generate, keep=_keep,
              audit={"T": ("refract (abs, unit vector)", "abs")})
    def _evaluate(x):
        return {"T": geometry.refract(x["I"], x["N"], x["eta"])}

That one call gives the record layout (inputs, outputs, then `case_tag`), the equations
and reference function written into the manifest, the case generator, the optional
conditioning filter and the float32 audit entries its tolerances may not undercut.
`KERNELS` holds the kernels in registration order, which is the order of the manifests,
the C header and the CLI's default.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from .records import CASE_FIELD, Field


@dataclasses.dataclass(frozen=True)
class Kernel:
    """A kernel's record layout, equations, case generator and float64/float32 evaluation.

    Attributes:
        name: kernel name, also the file stem of its `.json`/`.bin` and of its GLSL port.
        equations: the equations it implements, as cited in the manifest and the C header.
        fields: inputs, outputs, then `case_tag` (`records.Field`), in record order.
        generate: `generate(rng, n)` returns float64 inputs (dict of arrays, leading axis
            = records) and case codes for `n` random/planted candidates plus the fixed
            adversarial set.
        evaluate: `evaluate(inputs)` runs the package kernel in the inputs' dtype and
            returns a dict of outputs.
        keep: `keep(inputs, ref)` marks random candidates whose discrete outcome and
            conditioning are unambiguous in float32 (a shader test must not depend on a
            coin flip of rounding); None keeps every candidate.
        audit: output field -> (key in the float32 audit, "abs" or "rel").
        reference: dotted name of the package function that computes the reference outputs.
        filter_planted: apply `keep` to planted candidates too.
    """

    name: str
    equations: str
    fields: tuple[Field, ...]
    generate: Callable
    evaluate: Callable
    keep: Callable | None = None
    audit: dict = dataclasses.field(default_factory=dict)
    reference: str = ""
    filter_planted: bool = False

    def inputs(self) -> list[Field]:
        return [f for f in self.fields if f.role == "input"]

    def outputs(self) -> list[Field]:
        return [f for f in self.fields if f.role == "output"]


#: Every registered kernel by name, in registration order.
KERNELS: dict[str, Kernel] = {}


def _dotted_name(fn) -> str:
    return f"{fn.__module__}.{fn.__qualname__}"


def register(name: str, *, equations: str, reference: Callable, inputs: dict[str, str], outputs: dict[str, str],
             generate: Callable, keep: Callable | None = None, filter_planted: bool = False,
             audit: dict[str, tuple[str, str]] | None = None, scale: dict[str, str] | None = None):
    """Decorator registering the decorated `evaluate(inputs) -> outputs` as kernel `name`.

    `inputs` and `outputs` map field names to GLSL member types (`"vec3"`, `"vec3[3]"`,
    `"float[6]"`) in record order; `reference` is the package function the outputs come
    from (its dotted name goes into the manifest); `scale` maps an output to the input
    whose magnitude scales its tolerance (default: its own). See `Kernel` for the rest.
    """
    audit, scale = dict(audit or {}), dict(scale or {})
    if name in KERNELS:
        raise ValueError(f"kernel {name!r} is registered twice")
    if not set(audit) <= set(outputs) or not set(scale) <= set(outputs) or not set(scale.values()) <= set(inputs):
        raise ValueError(f"{name}: audit {audit} and scale {scale} must name outputs (and scale inputs)")
    for kind in (kind for _, kind in audit.values()):
        if kind not in ("abs", "rel"):
            raise ValueError(f"{name}: audit kind must be 'abs' or 'rel', got {kind!r}")
    fields = ([Field.parse(n, t, "input") for n, t in inputs.items()]
              + [Field.parse(n, t, "output", scale.get(n)) for n, t in outputs.items()] + [CASE_FIELD])

    def decorator(evaluate: Callable) -> Callable:
        KERNELS[name] = Kernel(name, equations, tuple(fields), generate, evaluate, keep, audit,
                               _dotted_name(reference), filter_planted)
        return evaluate

    return decorator
