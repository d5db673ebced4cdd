"""The JAX <-> Dr.Jit bridge on a small Dr.Jit image model: JVP and VJP against central
finite differences (eagerly and under jax.jit), call counting, shape and non-finite errors."""

import numpy as np
import pytest

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from helpers.drjit_toy import TRUTH, ToyModel  # noqa: E402
from study.fit.jax_residual import (  # noqa: E402
    NonFiniteParameterError,
    NonFiniteResidualError,
    make_jax_residual,
)

NAMES = ["amp", "rate", "shift"]
X = np.array([0.9, 1.1, 0.12])


@pytest.fixture(scope="module")
def toy():
    return ToyModel(height=32, width=48)


def _bridge(toy, nan_rate=None):
    model = ToyModel(height=32, width=48, nan_rate=nan_rate) if nan_rate is not None else toy
    base = dict(TRUTH)

    def vals(x):
        return {**base, **dict(zip(NAMES, map(float, x)))}

    return make_jax_residual(
        lambda x: model.residual(vals(x)),
        lambda x: model.residual_and_jacobian(vals(x), NAMES),
        3,
        model.m,
    )


def _fd_jac(f, x, h=1e-6):
    cols = [(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))]
    return np.stack(cols, axis=1)


def test_value_matches_drjit(toy):
    res = _bridge(toy)
    r = np.asarray(jax.jit(res)(jnp.asarray(X)))
    expect = toy.residual({**TRUTH, **dict(zip(NAMES, X))})
    assert r.dtype == np.float64
    np.testing.assert_array_equal(r, expect)
    assert res.stats.n_value_calls == 1 and res.stats.n_jac_calls == 0


@pytest.mark.parametrize("jit", [False, True])
def test_jvp_and_vjp_match_central_differences(toy, jit):
    res = _bridge(toy)
    J_fd = _fd_jac(lambda x: res.value(x), X)
    t = np.array([0.3, -0.7, 1.1])

    def jvp(x, t):
        return jax.jvp(res, (x,), (t,))[1]

    grad = jax.grad(lambda x: 0.5 * jnp.sum(res(x) ** 2))
    if jit:
        jvp, grad = jax.jit(jvp), jax.jit(grad)
    n_j = res.stats.n_jac_calls
    jt = np.asarray(jvp(jnp.asarray(X), jnp.asarray(t)))
    assert res.stats.n_jac_calls == n_j + 1  # one callback gives r and J together
    np.testing.assert_allclose(jt, J_fd @ t, rtol=1e-6, atol=1e-8 * np.abs(J_fd).max())
    g = np.asarray(grad(jnp.asarray(X)))
    r = res.value(X)
    np.testing.assert_allclose(g, J_fd.T @ r, rtol=1e-6)
    # reverse mode through jax.vjp with an arbitrary cotangent
    ct = np.random.default_rng(0).normal(size=res.m)
    _, vjp = jax.vjp(res, jnp.asarray(X))
    np.testing.assert_allclose(np.asarray(vjp(jnp.asarray(ct))[0]), J_fd.T @ ct, rtol=1e-6)


def test_float32_model_jacobian_matches_differences():
    """The shader runs in float32: the bridge casts to float64 and the AD Jacobian still
    agrees with a (coarser) central difference."""
    model = ToyModel(height=32, width=48, float32=True)
    vals = lambda x: {**TRUTH, **dict(zip(NAMES, map(float, x)))}  # noqa: E731
    res = make_jax_residual(
        lambda x: model.residual(vals(x)),
        lambda x: model.residual_and_jacobian(vals(x), NAMES),
        3,
        model.m,
    )
    J = np.asarray(jax.jacfwd(res)(jnp.asarray(X)))
    J_fd = _fd_jac(res.value, X, h=1e-3)
    assert J.dtype == np.float64
    np.testing.assert_allclose(J, J_fd, atol=2e-3 * np.abs(J_fd).max())


def test_nonfinite_residual_raises_clear_error(toy):
    res = _bridge(toy, nan_rate=1.4)  # the image is NaN for rate > 1.4
    bad = jnp.asarray([0.9, 1.5, 0.12])
    with pytest.raises(Exception, match="non-finite"):
        jax.jit(res)(bad).block_until_ready()
    assert isinstance(res.last_error, NonFiniteResidualError)
    with pytest.raises(NonFiniteResidualError, match="residual entries are non-finite"):
        res.value(np.asarray(bad))
    with pytest.raises(Exception, match="non-finite"):
        jax.jit(jax.grad(lambda x: jnp.sum(res(x) ** 2)))(bad).block_until_ready()
    # and it works where the model is finite
    assert np.all(np.isfinite(np.asarray(jax.jit(res)(jnp.asarray(X)))))


def test_nonfinite_parameters_are_refused_before_the_model_runs(toy):
    """A solver step that diverged (NaN in x) is a FloatingPointError the solvers report as a
    non-finite abort, never a shader's ValueError about a constant out of range."""
    res = _bridge(toy)
    bad = jnp.asarray([0.9, float("nan"), 0.12])
    with pytest.raises(Exception, match="non-finite parameters"):
        jax.jit(res)(bad).block_until_ready()
    assert isinstance(res.last_error, NonFiniteParameterError)
    assert isinstance(res.last_error, FloatingPointError)
    with pytest.raises(NonFiniteParameterError):
        res.value(np.asarray(bad))


def test_shape_errors_name_the_problem(toy):
    res = _bridge(toy)
    with pytest.raises(ValueError, match=r"expected \(3,\)"):
        res(jnp.zeros(4))
    bad = make_jax_residual(lambda x: np.zeros(5), lambda x: (np.zeros(5), np.zeros((5, 3))), 3, 6)
    with pytest.raises(ValueError, match=r"residual has shape \(5,\), expected \(6,\)"):
        bad.value(np.zeros(3))
    with pytest.raises(ValueError, match="need k >= 1"):
        make_jax_residual(lambda x: x, lambda x: x, 0, 3)
