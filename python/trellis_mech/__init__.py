"""trellis_mech — Python interface to trellis (C++): exact linearizations of constrained
mechanical systems, TV-LQR and trajectory optimization, with NumPy arrays.

Import name: ``trellis_mech`` (PyPI's ``trellis`` and ``pytrellis`` are unrelated projects).

Conventions (the C++ ones, in snake_case):

* a ``Model`` is immutable (``load_scene``, ``parse_scene``, ``ModelBuilder.finalize``); a ``Data``
  is its preallocated workspace, reused across calls, one per thread;
* state ``x = [q; dq]`` (``nx = 2 nq``), input ``u`` (``nu``);
* one rule for array axes, everywhere: **time first** — an array of samples is shaped ``(N, ...)``,
  row ``k`` at time ``t_k``: ``Trajectory.states`` ``(N, nx)``, ``inputs`` ``(N, nu)``,
  ``state_derivatives`` ``(N, nx)``, ``Trajectory.sample(times)`` ``((K, nx), (K, nu))``,
  ``GainSchedule.gains`` ``(N, nu, nx)``, ``TvlqrSolution.S`` ``(N, nx, nx)``,
  ``solve_discrete_riccati_recursion`` ``(N+1, nx, nx), (N, nu, nx)``, the midpoints of an
  optimization ``(N-1, nx)``; a batch of starts ``simulate_closed_loop_many(x0s)`` is ``(K, nx)``
  (one row per run). A single matrix keeps its mathematical shape (``A`` ``(nx, nx)``, ``K``
  ``(nu, nx)``, a tangent basis ``T`` ``(nx, d)``);
* array arguments accept anything convertible to float64: a contiguous float64 array is read in
  place, anything else (other dtype, Fortran/C order mismatch, a non-contiguous slice, a list) is
  copied first; a complex array where a real one is expected raises ``TypeError`` instead of being
  cut to its real part, naming the argument or field (``"A: got a complex array ..."``,
  ``"q: ..."``, ``"times: ..."``, ``"input_lower: ..."``).
  Results are fresh C-order float64 arrays that own their memory. The ``out``-style keywords
  (``compute_linearization(..., A=, B=)``, ``compute_dynamics(..., qdd=, lambda_=)``) write into the
  caller's float64 array of the exact shape, in any memory order (strided writes), and raise
  ValueError for a wrong dtype, shape or a read-only array;
* one status vocabulary: every result of numerical work has ``status`` — the C++ ``Status``:
  ``code`` (the enum's name as a str, e.g. ``"ok"``, ``"blow_up"``), ``message``, ``t`` (NaN: no
  time), ``index`` (-1: none), ``ok``, ``describe()`` — and ``ok``, ``describe()`` (one line) and
  ``json()`` (one JSON object, as the command line prints it) on the result itself
  (``DynamicsStatus``, ``LqrResult``, ``MatrixEquationSolution``, ``ControllabilityReport``,
  ``GramianReport``, ``TvlqrSolution``, ``SimulationResult``);
* bad input raises ``ValueError`` (``ModelError``, ``TrajectoryError`` and ``ProblemError`` are
  ValueError subclasses) with the C++ message naming the element, field and value; a numerical
  failure is a status, never an exception (``NumericalError``, a RuntimeError, remains for the few
  functions that return bare arrays, e.g. a zero-order hold whose exponential overflows); a file
  that cannot be read or written raises ``OSError`` of the matching kind (``FileNotFoundError`` for
  a missing file or directory, ``PermissionError``, ``IsADirectoryError``), with the path in the
  message; Ctrl-C inside a Python callback (a simulation policy, ``on_iteration``) stops the
  computation and raises ``KeyboardInterrupt``;
* TV-LQR has one entry, ``solve_tvlqr`` (continuous or sampled, on the constraint manifold when
  the model has constraints), the same solve as ``trellis gains``;
* long computations (linearization, Riccati, simulation, optimization) release the GIL.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ._trellis_mech import *  # noqa: F401,F403
from ._trellis_mech import (Data, DynamicsStatus, compute_constraint_tangent_basis,
                            compute_dynamics, compute_linearization)

from ._version import __version__  # written by CMake from project(trellis VERSION ...)


@dataclass
class Dynamics:
    """Forward dynamics at a state: qdd (nq,), lambda_ (nc,), the mass matrix M (nq, nq)."""
    qdd: np.ndarray
    lambda_: np.ndarray
    M: np.ndarray
    status: DynamicsStatus


@dataclass
class Linearization:
    """xdot ~ A dx + B du at a state: A (nx, nx), B (nx, nu), with qdd, lambda_, M; with
    ``tangent=True`` also the tangent basis T (nx, d) of the constraint manifold and
    reduced_A = T^T A T (d, d), reduced_B = T^T B (d, nu)."""
    A: np.ndarray
    B: np.ndarray
    qdd: np.ndarray
    lambda_: np.ndarray
    M: np.ndarray
    status: DynamicsStatus
    tangent_basis: Optional[np.ndarray] = None
    reduced_A: Optional[np.ndarray] = None
    reduced_B: Optional[np.ndarray] = None


def _require_finite(model, q, dq, u):
    """ValueError naming the argument, entry, name and value of the first non-finite entry of the
    state: at a NaN or infinite state the result would be a failed status beside arrays that
    look like a linearization, and a convenience function must not hand those back."""
    for label, values, names in (("q", q, model.config_names), ("dq", dq, model.config_names),
                                 ("u", u, model.input_names)):
        try:
            array = np.asarray(values, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            continue  # not numbers: the bound function reports it with its own message
        bad = np.flatnonzero(~np.isfinite(array))
        if bad.size:
            i = int(bad[0])
            name = names[i] if i < len(names) else "?"
            raise ValueError("%s[%d] (%s) = %r is not finite: the state must be finite"
                             % (label, i, name, float(array[i])))


def dynamics(model, q, dq, u=None, *, data=None):
    """q̈ and λ at (q, dq, u) (u defaults to zeros); ``data`` is reused when given. Raises
    ValueError when q, dq or u has a NaN or infinite entry (naming it)."""
    data = Data(model) if data is None else data
    u = np.zeros(model.nu) if u is None else u
    _require_finite(model, q, dq, u)
    status = compute_dynamics(model, data, q, dq, u)
    return Dynamics(data.qdd, data.lambda_, data.M, status)


def linearize(model, q, dq, u=None, *, data=None, tangent=False):
    """The exact linearization A, B at (q, dq, u) as a ``Linearization`` (copies of the arrays);
    ``data`` is reused when given. For hot loops call ``compute_linearization(model, data, q, dq,
    u, A=A, B=B)`` with preallocated arrays instead (no allocation). Raises ValueError when q, dq
    or u has a NaN or infinite entry (naming it); other failures are the returned status."""
    data = Data(model) if data is None else data
    u = np.zeros(model.nu) if u is None else u
    _require_finite(model, q, dq, u)
    status = compute_linearization(model, data, q, dq, u)
    result = Linearization(data.A, data.B, data.qdd, data.lambda_, data.M, status)
    if tangent and status.ok:
        compute_constraint_tangent_basis(model, data)
        result.tangent_basis = data.tangent_basis
        result.reduced_A = data.reduced_A
        result.reduced_B = data.reduced_B
    return result

