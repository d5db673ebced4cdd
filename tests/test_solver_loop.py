"""The one loop every solver runs under (``study.fit.solver_loop``): the order of its stopping
rules, the trace, a residual that aborts a run, and the registry and settings of ``fit``; on a
NumPy residual (no Dr.Jit)."""

from dataclasses import FrozenInstanceError, dataclass

import numpy as np
import pytest

from study.fit.jax_residual import NonFiniteResidualError, make_jax_residual
from study.fit.params import Param
from study.fit.problem import FitProblem, SolverSettings
from study.fit.solver_loop import Objective, Solution, Solver, Stop, Trace, run_solver
from study.fit.solvers import SOLVER_CLASSES, SOLVERS, fit

TARGET = np.array([0.3, -0.2])


def _objective(wall: float | None = None) -> Objective:
    """``r(u) = u - TARGET``; with ``wall``, non-finite where ``u[0] > wall``."""

    def value(u):
        r = np.asarray(u, np.float64) - TARGET
        return np.full_like(r, np.nan) if wall is not None and u[0] > wall else r

    def value_and_jac(u):
        return value(u), np.eye(2)

    problem = FitProblem(
        [Param("a", 0.0), Param("b", 0.0)],
        lambda v: value([v["a"], v["b"]]),
        lambda v, names: (value([v["a"], v["b"]]), np.eye(2)[:, : len(names)]),
    )
    residual = make_jax_residual(value, value_and_jac, 2, 2)
    return Objective(residual, problem, {"a": 0.0, "b": 0.0}, ["a", "b"])


@dataclass(frozen=True)
class _Walk:
    u: np.ndarray


class _Walker(Solver[_Walk]):
    """Moves ``u`` a fixed step towards +x and evaluates the loss there; stops on its own at
    ``u[0] >= stop_at``."""

    name = "walker"
    stop_at = 10.0

    def init(self, objective, u0):
        return _Walk(np.asarray(u0, np.float64))

    def step(self, objective, state):
        u = state.u + np.array([0.1, 0.0])
        objective.loss(u)
        return _Walk(u)

    def terminate(self, objective, state):
        return Stop(True, "reached") if state.u[0] >= self.stop_at - 1e-12 else None

    def postprocess(self, objective, state):
        return Solution(state.u)


def test_the_loop_stops_at_the_solver_criterion_then_the_stall_then_the_cap():
    obj = _objective()
    walker = _Walker(SolverSettings())
    walker.stop_at = 0.3
    run = run_solver(walker, obj, np.zeros(2), 50, Trace(0.0, obj.loss(np.zeros(2))), None)
    assert run.converged and run.steps == 3 and run.message == "reached after 3 steps"
    # past the target the loss rises: the lowest loss stops falling and the stall rule ends it
    walker.stop_at = 10.0
    trace = Trace(0.0, obj.loss(np.zeros(2)))
    run = run_solver(walker, _objective(), np.zeros(2), 50, trace, 1e-6)
    assert run.converged and "fell by less than" in run.message and run.steps == 6
    assert len(trace.losses) == run.steps and trace.losses[-1] == trace.losses[2]
    run = run_solver(walker, _objective(), np.zeros(2), 4, Trace(0.0, 1.0), None)
    assert not run.converged and run.steps == 4 and "maximum number of steps" in run.message


def test_a_non_finite_residual_aborts_with_the_best_point_and_other_errors_propagate():
    obj = _objective(wall=0.25)
    run = run_solver(_Walker(SolverSettings()), obj, np.zeros(2), 50, Trace(0.0, 1.0), None)
    assert not run.converged and run.steps == 2
    assert run.message.startswith("solver aborted (NonFiniteResidualError)")
    assert np.allclose(run.u, [0.2, 0.0])
    assert isinstance(obj.residual.last_error, NonFiniteResidualError)

    class Broken(_Walker):
        def step(self, objective, state):
            raise KeyError("a bug")

    with pytest.raises(KeyError):
        run_solver(Broken(SolverSettings()), _objective(), np.zeros(2), 5, Trace(0.0, 1.0), None)


def test_every_solver_is_registered_under_its_name_and_fits_a_line():
    assert SOLVERS == tuple(SOLVER_CLASSES)
    assert SOLVERS == (
        "levenberg_marquardt",
        "gauss_newton",
        "dogleg",
        "bfgs",
        "nelder_mead",
        "adam",
    )
    problem = _objective().problem
    for name, cls in SOLVER_CLASSES.items():
        assert cls.name == name and issubclass(cls, Solver)
        if name == "adam":
            continue  # needs a Dr.Jit backend (tests/test_fit.py)
        res = fit(problem, solver=name, settings=SolverSettings(max_steps=500, rtol=1e-10))
        assert res.converged and np.allclose(res.x, TARGET, atol=1e-4), (name, res.message)
        assert len(res.step_losses) == res.iterations == len(res.step_seconds)


def test_settings_are_one_frozen_record_and_keywords_override_single_fields():
    s = SolverSettings(ftol=1e-6, ftol_se=1.0)
    with pytest.raises(FrozenInstanceError):
        s.max_steps = 3
    assert s.stall_tolerance(m=1001, k=1) == pytest.approx(1e-3)
    assert s.stall_tolerance(m=10**9, k=1) == 1e-6
    with pytest.raises(ValueError, match="max_steps"):
        SolverSettings(max_steps=0)
    problem = _objective().problem
    with pytest.raises(TypeError):
        fit(problem, solver="levenberg_marquardt", no_such_setting=1)
    a = fit(problem, solver="nelder_mead", settings=SolverSettings(max_steps=7))
    b = fit(problem, solver="nelder_mead", max_steps=7)
    assert a.iterations == b.iterations == 7 and np.array_equal(a.u, b.u)


@pytest.mark.parametrize("name", ["levenberg_marquardt", "bfgs"])
def test_fits_of_one_size_share_one_compilation_and_each_reaches_its_own_residual(name, caplog):
    """Two residuals of the same sizes, alive together: the second fit compiles nothing (JAX
    logs no compilation), and every call of each fit reaches its own residual (the handle the
    compiled step passes), each solving its own target."""
    import logging

    import jax

    def fit_to(target):
        t = np.asarray(target, np.float64)
        res = make_jax_residual(lambda u: u - t, lambda u: (u - t, np.eye(3)), 3, 3)
        solver = SOLVER_CLASSES[name](SolverSettings())
        obj = Objective(res, None, {}, ["a", "b", "c"])
        state = solver.init(obj, np.zeros(3))
        for _ in range(40):
            state = solver.step(obj, state)
            if solver.terminate(obj, state) is not None:
                break
        np.testing.assert_allclose(np.asarray(state.y), t, atol=1e-6)
        return res

    first = fit_to([0.5, -1.0, 2.0])
    calls = first.stats.n_value_calls + first.stats.n_jac_calls
    with jax.log_compiles(True), caplog.at_level(logging.WARNING):
        second = fit_to([-0.25, 0.75, 0.1])
    compiled = [r.getMessage() for r in caplog.records if "ompil" in r.getMessage()]
    assert not compiled, compiled[:3]
    # no call of the second fit reached the first residual
    assert first.stats.n_value_calls + first.stats.n_jac_calls == calls
    assert second.stats.n_value_calls + second.stats.n_jac_calls > 0
