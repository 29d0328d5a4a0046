"""A CasADi fatrop solver as generated C code, compiled once and called without CasADi.

CasADi writes the whole solver (the fatrop interface and the problem's functions with their
derivatives) as C; gcc compiles it into a shared library that links CasADi's own ``libfatrop``.
The library is cached on disk under a hash of its source, so a problem is compiled once per
machine (a few seconds) and every later controller, worker process or unpickled copy loads it.
A call copies the inputs into fixed buffers and runs the solver through ``ctypes``: the same
arithmetic as CasADi's interpreted solver, without its per-call bookkeeping.

The cache lives in ``$HAZARDHUNT_CACHE`` or else ``$XDG_CACHE_HOME/hazardhunt`` (default
``~/.cache/hazardhunt``).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import weakref
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from hazardhunt.errors import HazardhuntError

FloatArray = NDArray[np.float64]

COMPILER_FLAGS = ("-O1", "-fPIC", "-shared")
"""gcc flags: -O1 compiles in about half the time of -O2 and solves as fast (the solver's time
goes into fatrop's linear algebra, which is already compiled)."""
_SLOTS = 256
"""Solver memories per library: controllers alive at once in one process."""

_ENTRY = """
/* hazardhunt: one solve with plain pointers, and fatrop's status and iteration count. */
CASADI_SYMBOL_EXPORT int hazardhunt_solve(const casadi_real* x0, const casadi_real* p,
    const casadi_real* lbx, const casadi_real* ubx, const casadi_real* lbg,
    const casadi_real* ubg, casadi_real* x, casadi_real* f, casadi_int* iw, casadi_real* w,
    int mem, int* out) {
  const casadi_real* arg[%(sz_arg)d];
  casadi_real* res[%(sz_res)d];
  int i;
  for (i = 0; i < %(sz_arg)d; ++i) arg[i] = 0;
  for (i = 0; i < %(sz_res)d; ++i) res[i] = 0;
  arg[0] = x0; arg[1] = p; arg[2] = lbx; arg[3] = ubx; arg[4] = lbg; arg[5] = ubg;
  res[0] = x; res[1] = f;  /* constraints and multipliers are not needed */
  out[0] = casadi_f0(arg, res, iw, w, mem);
  out[1] = casadi_f0_mem[mem].success;
  out[2] = casadi_f0_mem[mem].return_status;
  out[3] = casadi_f0_mem[mem].stats.iterations_count;
  return out[0];
}
"""


class CompileError(HazardhuntError, RuntimeError):
    """The solver could not be generated, compiled or loaded."""


@dataclass
class SolveResult:
    """The outputs of one compiled solve."""

    x: FloatArray
    cost: float
    success: bool
    status: int
    """fatrop's return flag (0 on success)."""
    iterations: int


def cache_directory() -> Path:
    """Where compiled solvers are kept."""
    configured = os.environ.get("HAZARDHUNT_CACHE")
    if configured:
        return Path(configured) / "solvers"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hazardhunt" / "solvers"


def compiler() -> str | None:
    """The C compiler to use (``$CC`` or gcc), or None when there is none."""
    return shutil.which(os.environ.get("CC", "gcc"))


_libraries: dict[Path, ctypes.CDLL] = {}
_lock = threading.Lock()


class CompiledSolver:
    """A fatrop ``nlpsol`` in its compiled library (see :func:`compile_solvers`), with its own
    solver memory.

    Example:
        >>> solver = ca.nlpsol("nmpc", "fatrop", nlp, options)  # doctest: +SKIP
        >>> (compiled,) = compile_solvers([solver])  # doctest: +SKIP
        >>> compiled.set_fixed(lbx, ubx, lbg, ubg)  # doctest: +SKIP
        >>> result = compiled.solve(x0, p)  # doctest: +SKIP
    """

    def __init__(self, solver: ca.Function, library: ctypes.CDLL) -> None:
        name = solver.name()
        self._solve = library.hazardhunt_solve
        self._solve.restype = ctypes.c_int
        self._solve.argtypes = [ctypes.c_void_p] * 10 + [ctypes.c_int, ctypes.c_void_p]
        checkout = getattr(library, f"{name}_checkout")
        checkout.restype = ctypes.c_int
        self._memory = checkout()
        if self._memory < 0:
            raise CompileError(f"more than {_SLOTS} compiled solvers alive in one process")
        release = getattr(library, f"{name}_release")
        release.argtypes = [ctypes.c_int]
        weakref.finalize(self, release, self._memory)
        sizes = [ctypes.c_longlong() for _ in range(4)]
        getattr(library, f"{name}_work")(*(ctypes.byref(s) for s in sizes))
        variables, constraints = solver.size1_in(0), solver.size1_in(4)
        parameters = solver.size1_in(1)
        self._inputs = [
            np.zeros(n) for n in (variables, parameters, variables, variables, constraints)
        ] + [np.zeros(constraints)]
        self._x, self._cost = np.zeros(variables), np.zeros(1)
        self._iw = np.zeros(max(sizes[2].value, 1), dtype=np.int64)
        self._w = np.zeros(max(sizes[3].value, 1))
        self._out = np.zeros(4, dtype=np.intc)
        buffers = [*self._inputs, self._x, self._cost, self._iw, self._w]
        self._pointers = [b.ctypes.data for b in buffers]
        self._out_pointer = self._out.ctypes.data

    def set_fixed(self, lbx: FloatArray, ubx: FloatArray, lbg: FloatArray, ubg: FloatArray) -> None:
        """Store the bounds, which stay the same from call to call."""
        for buffer, values in zip(self._inputs[2:], (lbx, ubx, lbg, ubg), strict=True):
            buffer[:] = values

    def solve(self, x0: FloatArray, p: FloatArray) -> SolveResult:
        """Solve from the initial guess ``x0`` with parameters ``p`` and the stored bounds."""
        self._inputs[0][:] = x0
        self._inputs[1][:] = p
        flag = self._solve(*self._pointers, self._memory, self._out_pointer)
        return SolveResult(
            x=self._x.copy(),
            cost=float(self._cost[0]),
            success=flag == 0 and bool(self._out[1]),
            status=int(self._out[2]),
            iterations=int(self._out[3]),
        )


@dataclass
class _Source:
    name: str
    code: str
    target: Path


def _source(solver: ca.Function) -> _Source:
    """The solver's C code with the entry point, and where its library is cached."""
    generator = ca.CodeGenerator(f"{solver.name()}.c", {"with_header": False})
    generator.add(solver)
    code = generator.dump()
    if "static struct casadi_fatrop_data casadi_f0_mem[" not in code:
        raise CompileError("CasADi generated an unexpected layout for the fatrop solver")
    code += _ENTRY % {"sz_arg": solver.sz_arg(), "sz_res": solver.sz_res()}
    key = hashlib.sha256(
        "\n".join([str(getattr(ca, "__version__", "")), *_flags(), code]).encode()
    ).hexdigest()
    return _Source(solver.name(), code, cache_directory() / f"{solver.name()}-{key[:24]}.so")


def _flags() -> list[str]:
    return [*COMPILER_FLAGS, f"-DCASADI_MAX_NUM_THREADS={_SLOTS}"]


def compile_solvers(solvers: list[ca.Function]) -> list[CompiledSolver]:
    """Compiled versions of fatrop ``nlpsol`` functions; missing libraries compile in parallel.

    Raises:
        CompileError: When there is no compiler, gcc fails or a library does not load.
    """
    sources = [_source(s) for s in solvers]
    with _lock:
        _compile([s for s in sources if s.target not in _libraries and not s.target.exists()])
        for source in sources:
            if source.target not in _libraries:
                try:
                    _libraries[source.target] = ctypes.CDLL(str(source.target))
                except OSError as error:
                    raise CompileError(f"cannot load {source.target}: {error}") from error
    return [
        CompiledSolver(solver, _libraries[source.target])
        for solver, source in zip(solvers, sources, strict=True)
    ]


def _compile(sources: list[_Source]) -> None:
    """Compile each source into its target, atomically (workers may compile the same one)."""
    if not sources:
        return
    cc = compiler()
    if cc is None:
        raise CompileError("no C compiler found (set CC or install gcc)")
    casadi_dir = Path(ca.__file__).parent
    folder = cache_directory()
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder) as scratch:
        running = []
        for source in sources:
            c_file = Path(scratch) / f"{source.name}.c"
            c_file.write_text(source.code)
            built = Path(scratch) / source.target.name
            command = [
                cc,
                *_flags(),
                str(c_file),
                f"-I{casadi_dir / 'include'}",
                f"-L{casadi_dir}",
                "-lfatrop",
                f"-Wl,-rpath,{casadi_dir}",
                "-o",
                str(built),
            ]
            process = subprocess.Popen(
                command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
            )
            running.append((process, built, source.target))
        errors = []
        for process, built, target in running:
            _, stderr = process.communicate()
            if process.returncode != 0:
                errors.append(stderr[-2000:])
            else:
                os.replace(built, target)
        if errors:
            raise CompileError(f"{cc} failed to compile the NMPC solver:\n{errors[0]}")
