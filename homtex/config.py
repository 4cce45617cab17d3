"""Package-wide defaults: ``homtex.set_options`` and ``homtex.get_options``.

Every entry point that takes a ``solver`` or ``tol`` reads its default here when the argument
is left at None, so a default lives in one place::

    homtex.set_options(static_solver="direct")            # from now on
    with homtex.set_options(static_solver="direct", tol=1e-8):
        homtex.solve_static(frame, fixed, loads)           # only inside the block

Options (validated when set; an unknown name or a bad value is an InputError):

============================ ============ ==========================================================
name                         default      meaning
============================ ============ ==========================================================
``static_solver``            ``"amg"``    ``solve_static`` (also with contact): "amg", "direct", "cg"
``homogenize_solver``        ``"amg"``    ``homogenize``, ``solve_macro``, ``compression_modulus``
``compress_solver``          ``"direct"`` ``compress(geometry="linear")``, linear seam cells; small, often
                                          ill-conditioned contact systems
``nonlinear_solver``         ``"auto"``   ``solve_nonlinear``: "auto" (LU where moments act on free rotations,
                                          else LDL^T), "ldl", "lu" ("direct" = "ldl")
``amg_setup``                ``"fast"``   AMG hierarchy setup: "fast" (Lanczos spectral bounds on the numba
                                          products) or "pyamg" (pyamg's own, restarted Arnoldi bounds)
``amg_cycle``                ``"numba"``  AMG-CG phase: "numba" (V-cycle applied directly, fused parallel
                                          kernels), "pyamg" (pyamg's preconditioner, scipy products) or
                                          "gpu" (hierarchy and CG on a CUDA device; the ``gpu`` extra)
``amg_precision``            ``"float64"`` values of the AMG level matrices in the V-cycle: "float64" or
                                          "float32" (half the bytes; CG stays in float64)
``tangent_solver``           ``"auto"``   tangent solves of ``solve_nonlinear`` and the large-motion engine:
                                          "ldl" (qdldl LDL^T, inertia counted), "cholmod" (supernodal
                                          Cholesky, scikit-sparse), "pardiso" (MKL PARDISO's supernodal
                                          LDL^T with pivoting and inertia, the ``pardiso`` extra), "amg"
                                          (AMG-PCG on the PD PTC-shifted tangent, reused hierarchy),
                                          "auto" (rule: ``tangent_auto_dof``)
``tangent_auto_dof``         ``30000``    "auto": "cholmod" from this many free DOFs on where scikit-sparse
                                          imports, else "ldl" (measured: homtex.linalg.tangent_backends)
``contact_aggregation``      ``"elements"`` AMG of contact systems: aggregate along the beam elements only
                                          ("elements") or by the strength of the whole operator ("strength")
``amg_threads``              ``None``     numba threads of the AMG-CG phase (None: numba's setting, 1 when the
                                          load average says the other cores are busy)
``amg_reuse``                ``False``    keep AMG hierarchies per matrix pattern across solves (load steps,
                                          study points on one cell) and rebuild them by a measured rule
                                          (homtex.linalg.reuse)
``tol``                      ``1e-10``    relative residual of iterative linear solves, in (0, 1)
``contact_penalty``          ``None``     contact stiffness k, N/mm; None: the mean translational
                                          diagonal of the frame stiffness (about EA / L)
``modulus_penalty``          ``5000.0``   penalty (N/mm) of the small-strain compression that
                                          measures a fabric's modulus for the foundation seam model
``threads``                  ``None``     numba and BLAS threads. None: all cores for problems of at least
                                          ``SERIAL_BELOW_DOF`` (50 000) DOFs, one thread below in
                                          ``solve_static`` and ``compress`` (:func:`threads_for`): on the shared
                                          2-core machine, a 20-step spacer compression took 3.0 s on 2
                                          threads next to a busy process and 1.7 s on one (the same 1.8 s
                                          on an idle machine), while a 1.2e5-DOF homogenisation took 5.2 s
                                          on 2 threads and 9.1 s on one (also next to a busy process).
                                          An integer: that many, for every size
``progress``                 ``False``    progress bars in long computations (the command line
                                          turns them on)
``max_elements``             ``2000000``  largest frame a generator builds (elements); a cell file
                                          asking for more is refused before anything is allocated
============================ ============ ==========================================================
"""

from __future__ import annotations

import contextlib
import math
import numbers
from typing import Any, Callable

from .errors import InputError

__all__ = ["OPTIONS", "SERIAL_BELOW_DOF", "get_options", "option", "set_options", "threads_for"]

#: with ``threads=None`` (the default), problems below this many DOFs run numba's loops on one
#: thread (:func:`threads_for`): their parallel regions are too short to pay for the launch, and on
#: a shared machine every region waits for the thread a busy process has descheduled
SERIAL_BELOW_DOF = 50_000

SOLVERS = ("amg", "direct", "cg")
NONLINEAR_SOLVERS = ("auto", "ldl", "lu", "direct")
AMG_SETUPS = ("fast", "pyamg")
TANGENT_SOLVERS = ("ldl", "cholmod", "pardiso", "amg", "auto")
AMG_CYCLES = ("numba", "pyamg", "gpu")
AMG_PRECISIONS = ("float64", "float32")


def _choice(choices) -> Callable[[Any], bool]:
    """A validator accepting a string among ``choices`` (a numpy array, list or other object is
    refused by type before it is compared, so ``v in choices`` never meets an array)."""
    return lambda v: isinstance(v, str) and v in choices


_solver = _choice(SOLVERS)


def _real(v) -> bool:
    """A real number (Python or numpy; not a boolean)."""
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and type(v).__name__ != "bool_"


def _integer(v) -> bool:
    """An integer (Python or numpy; not a boolean)."""
    return isinstance(v, numbers.Integral) and not isinstance(v, bool) and type(v).__name__ != "bool_"


def _tol(v) -> bool:
    return _real(v) and math.isfinite(v) and 0.0 < v < 1.0


def _penalty(v) -> bool:
    return v is None or (_real(v) and math.isfinite(v) and v > 0)


def _threads(v) -> bool:
    return v is None or (_integer(v) and v >= 1)


def _bool(v) -> bool:
    return isinstance(v, bool)


_DEFAULTS: dict[str, Any] = {
    "static_solver": "amg",
    "homogenize_solver": "amg",
    "compress_solver": "direct",
    "nonlinear_solver": "auto",
    "amg_setup": "fast",
    "amg_cycle": "numba",
    "amg_precision": "float64",
    "amg_threads": None,
    "amg_reuse": False,
    "tangent_solver": "auto",
    "tangent_auto_dof": 30_000,
    "contact_aggregation": "elements",
    "tol": 1e-10,
    "contact_penalty": None,
    "modulus_penalty": 5000.0,
    "threads": None,
    "progress": False,
    "max_elements": 2_000_000,
}

_VALIDATORS: dict[str, tuple[Callable[[Any], bool], str]] = {
    "static_solver": (_solver, f"one of {SOLVERS}"),
    "homogenize_solver": (_solver, f"one of {SOLVERS}"),
    "compress_solver": (_solver, f"one of {SOLVERS}"),
    "nonlinear_solver": (_choice(NONLINEAR_SOLVERS), f"one of {NONLINEAR_SOLVERS}"),
    "amg_setup": (_choice(AMG_SETUPS), f"one of {AMG_SETUPS}"),
    "amg_cycle": (_choice(AMG_CYCLES), f"one of {AMG_CYCLES}"),
    "amg_precision": (_choice(AMG_PRECISIONS), f"one of {AMG_PRECISIONS}"),
    "tangent_solver": (_choice(TANGENT_SOLVERS), f"one of {TANGENT_SOLVERS}"),
    "tangent_auto_dof": (lambda v: _integer(v) and v >= 1, "an integer >= 1"),
    "contact_aggregation": (_choice(("elements", "strength")), "'elements' or 'strength'"),
    "amg_threads": (_threads, "None or an integer >= 1"),
    "amg_reuse": (_bool, "True or False"),
    "tol": (_tol, "a finite number in (0, 1)"),
    "contact_penalty": (_penalty, "None or a positive stiffness in N/mm"),
    "modulus_penalty": (_penalty, "a positive stiffness in N/mm"),
    "threads": (_threads, "None or an integer >= 1"),
    "progress": (_bool, "True or False"),
    "max_elements": (lambda v: _integer(v) and v >= 1, "an integer >= 1"),
}

#: the current options (read with :func:`option`; change with :func:`set_options`)
OPTIONS: dict[str, Any] = dict(_DEFAULTS)


def _apply_threads(n) -> None:
    """Set numba's and the BLAS pools' thread counts (None: all cores)."""
    import numba

    n = numba.config.NUMBA_NUM_THREADS if n is None else min(int(n), numba.config.NUMBA_NUM_THREADS)
    numba.set_num_threads(n)
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(n)
    except ImportError:  # pragma: no cover - threadpoolctl is a core dependency
        pass


@contextlib.contextmanager
def threads_for(ndof: int):
    """A block that runs numba's loops on one thread when the problem is small (``ndof`` below
    :data:`SERIAL_BELOW_DOF`) and the option ``threads`` is None (the default); an explicit
    ``threads`` setting, or a large problem, keeps the threads as they are. BLAS is limited to one
    thread in the block as well (the small dense products of a contact solve; the linear solves
    limit it themselves)."""
    if OPTIONS["threads"] is not None or int(ndof) >= SERIAL_BELOW_DOF:
        yield
        return
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        with _blas_controller().limit(limits=1, user_api="blas"):
            yield
    finally:
        numba.set_num_threads(old)


_CONTROLLER: list = []


def _blas_controller():
    """threadpoolctl's controller, made once (making one costs about 0.4 ms)."""
    if not _CONTROLLER:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER.append(ThreadpoolController())
    return _CONTROLLER[0]


class set_options:
    """Change options for the session, or for a ``with`` block (restored on exit).

    >>> homtex.set_options(tol=1e-8)
    >>> with homtex.set_options(static_solver="direct"):
    ...     ...
    """

    def __init__(self, **kwargs):
        self.old: dict[str, Any] = {}
        for name, value in kwargs.items():
            if name not in _VALIDATORS:
                raise InputError(f"set_options: unknown option {name!r}; options are {sorted(_VALIDATORS)}")
            ok, what = _VALIDATORS[name]
            if not ok(value):
                raise InputError(f"set_options: option {name!r} must be {what}, got {_short(value)}")
        for name, value in kwargs.items():
            self.old[name] = OPTIONS[name]
            OPTIONS[name] = _plain(value)
            if name == "threads":
                _apply_threads(value)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for name, value in self.old.items():
            OPTIONS[name] = value
            if name == "threads":
                _apply_threads(value)
        return False


def get_options() -> dict[str, Any]:
    """A copy of the current options."""
    return dict(OPTIONS)


def option(name: str, value=None):
    """``value`` if it is given (not None), checked like the option ``name`` (InputError naming the
    argument: ``solver`` for the ``*_solver`` options), else the current option ``name``."""
    if value is None:
        return OPTIONS[name]
    ok, what = _VALIDATORS[name]
    if not ok(value):
        arg = "solver" if name.endswith("_solver") else name
        raise InputError(f"{arg} must be {what}, got {_short(value)}")
    return _plain(value)


def _plain(v):
    """A validated value as a plain Python object (``np.str_("amg")`` -> ``"amg"``, numpy numbers
    -> int / float)."""
    if isinstance(v, str):
        return str(v)
    if isinstance(v, numbers.Integral):
        return int(v)
    if isinstance(v, numbers.Real):
        return float(v)
    return v


def _short(v, n: int = 80) -> str:
    """repr(v) cut to about n characters (a large array in a message)."""
    r = repr(v)
    return r if len(r) <= n else f"{r[:n - 20]}...({len(r)} characters)"
