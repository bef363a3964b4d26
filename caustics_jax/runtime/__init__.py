"""The runtime layer, below every other: what any computation of the package runs on.

- `precision`: float32/float64 policy (`precision`, `enable_x64`, the dtype rules);
- `arguments`: host-side checks of API arguments (the input contract of entry points);
- `kernel_contract`: the `float_inputs` decorator, the input contract of the kernels;
- `lanes`: lane size classes, padding, compaction, packing;
- `pools`: the slot-pool scheduler and compacted `map_where`;
- `blocks`: blocks of lanes over devices;
- `compilation`: JAX's persistent cache and the project's XLA options;
- `progress`: progress reporting of long runs.

It imports nothing else of the package, so every layer may use it.
"""
