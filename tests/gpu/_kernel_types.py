"""Run with ``NUMBA_ENABLE_CUDASIM=1``: ``python _kernel_types.py OUT.json SCRIPT[:CASE] ...`` runs
the named simulator scripts (this folder's ``_simulated_*.py``, with their arguments after ``:``)
and writes the argument types of every launch of every GPU kernel
(:mod:`fbmflow.gpu._kernels`) to ``OUT.json``: ``{kernel: [[type, ...], ...]}``, the types as
Numba writes them, for :file:`_compile_kernels.py` to compile for a real GPU. Exits 1 where a
script fails or a kernel was never launched."""
import json
import runpy
import sys
from pathlib import Path

import numba

import fbmflow.gpu._kernels as kernels
from fbmflow.gpu.launches import KERNELS as NAMES

seen: dict[str, set] = {name: set() for name in NAMES}


def type_of(a) -> str:
    """Numba's type of a launch argument (a simulator's device array as the host array it holds)."""
    return repr(numba.typeof(a.copy_to_host() if hasattr(a, "copy_to_host") else a))


class Recorder:
    """A kernel whose launches record their argument types, then run."""

    def __init__(self, name, kernel):
        self.name, self.kernel = name, kernel

    def __getitem__(self, config):
        launch = self.kernel[config]

        def call(*args):
            seen[self.name].add(tuple(type_of(a) for a in args))
            return launch(*args)
        return call


out, specs = Path(sys.argv[1]), sys.argv[2:]
for name in NAMES:
    setattr(kernels, name, Recorder(name, getattr(kernels, name)))
failed = False
for spec in specs:
    script, *argv = spec.split(":")
    sys.argv = [script, *argv]
    try:
        runpy.run_path(str(Path(__file__).with_name(script)), run_name="__main__")
    except SystemExit as stop:
        failed |= bool(stop.code)
        print(f"{spec}: exit {stop.code}", flush=True)
out.write_text(json.dumps({name: sorted(map(list, types)) for name, types in seen.items()}, indent=1))
never = [name for name, types in seen.items() if not types]
print(f"launch types of {len(NAMES) - len(never)} kernels written to {out}; never launched: {never}")
sys.exit(1 if failed or never else 0)
