"""dobs_envs.packing: one NamedTuple declaration gives the packed buffers and the unpacking (Python and
compiled); the kernels' bundles (KernelArgs, FeatureArgs, StepConsts, StateArrays) follow it."""
from dataclasses import fields
from typing import NamedTuple

import numba
import numpy as np
import pytest

from dobs_envs.packing import b1, compiled_unpack, f64, i64, leaves, pack, unpack, unpack_source
from dobs_envs.sim import SimParams, SimState
from dobs_envs.sim.kernel_args import KernelArgs, Sparse, StateArrays, unpack_kernel_args


class Inner(NamedTuple):
    w: f64("k")
    j: i64("k 2")


class Toy(NamedTuple):
    A: f64("n m")
    idx: i64("n")
    on: b1("m")
    dt: f64()
    k: i64()
    flag: b1()
    inner: Inner
    T: f64("m n 3")


def _toy(n=3, m=4, k=5):
    rng = np.random.default_rng(0)
    return Toy(A=rng.normal(size=(n, m)), idx=np.arange(n) * 7, on=np.array([True, False, True, True][:m]),
               dt=0.25, k=11, flag=True, inner=Inner(w=rng.normal(size=k), j=np.arange(2 * k).reshape(k, 2)),
               T=rng.normal(size=(m, n, 3)))


def _same(a, b, compiled=False):
    assert type(a) is type(b)
    for x, y in zip(a, b):
        if isinstance(x, tuple):
            _same(x, y, compiled)
        elif np.ndim(x):
            y_ = np.asarray(y)
            assert y_.shape == np.shape(x)
            np.testing.assert_array_equal(y_, x)
        else:
            assert x == y and (compiled or type(x) is type(y))


_toy_unpack = compiled_unpack(Toy, numba.njit, "_toy_unpack")


def test_pack_unpack_round_trip_in_python_and_compiled_code():
    t = _toy()
    KF, KI = pack(t)
    assert KF.dtype == np.float64 and KI.dtype == np.int64 and not KF.flags.writeable and not KI.flags.writeable
    _same(t, unpack(Toy, KF, KI))
    back = _toy_unpack(KF, KI)  # compiled: bool arrays as their 0/1 int64 views
    assert back.on.dtype == np.int64
    _same(t._replace(on=t.on.astype(np.int64)), back, compiled=True)
    # the header layout depends on the declaration only
    assert [name for name, _, _ in leaves(Toy)] == ["A", "idx", "on", "dt", "k", "flag", "inner.w", "inner.j", "T"]
    KF2, KI2 = pack(_toy(n=2, m=3, k=1))
    assert unpack(Toy, KF2, KI2).A.shape == (2, 3) and _toy_unpack(KF2, KI2).inner.j.shape == (1, 2)
    src = unpack_source(Toy, "f")[0]
    assert "# inner" in src and "KI[" in src


@pytest.mark.parametrize("change, match", [
    (dict(idx=np.arange(4)), r"Toy\.idx has shape \(4,\).*n = 3"),  # n bound by A
    (dict(T=np.zeros((4, 3, 2))), r"Toy\.T has shape .*declared size 3"),  # literal size
    (dict(A=np.zeros(3)), r"Toy\.A must have 2 dimensions"),
    (dict(idx=np.zeros(3)), r"Toy\.idx must be an integer array"),
    (dict(on=np.ones(4)), r"Toy\.on must be a bool array"),
    (dict(k=True), r"Toy\.k must be an int"),
    (dict(flag=1), r"Toy\.flag must be a bool"),
    (dict(inner=(np.zeros(2), np.zeros((2, 2), int))), r"Toy\.inner must be a Inner"),
])
def test_pack_names_the_field_that_does_not_fit(change, match):
    with pytest.raises((ValueError, TypeError), match=match):
        pack(_toy()._replace(**change))


def test_nested_bundles_have_their_own_size_symbols():
    t = _toy()
    t2 = t._replace(inner=Inner(w=np.zeros(9), j=np.zeros((9, 2), np.int64)))  # k differs from nothing outside
    _same(t2, unpack(Toy, *pack(t2)))
    with pytest.raises(ValueError, match=r"Toy\.inner\.j"):
        pack(t._replace(inner=Inner(w=np.zeros(9), j=np.zeros((8, 2), np.int64))))


def _random_params(seed=0, N=4, n=5, p=2, m=3, mv=2):
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    P = np.zeros((N, n, n))
    for i in range(N):
        Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        k = int(rng.integers(1, n))
        P[i] = Q[:, :k] @ Q[:, :k].T
    adj = np.triu((rng.random((N, N)) < 0.6).astype(float), 1)
    d = SimpleNamespace(A=rng.normal(size=(n, n)), B=rng.normal(size=(n, m)), B_v=rng.normal(size=(n, mv)),
                        C=rng.normal(size=(N, p, n)), E_bar=rng.normal(size=(N, n, n)), F_bar=rng.normal(size=(N, n, p)),
                        G_bar=rng.normal(size=(N, n, p)), B_bar=rng.normal(size=(N, n, m)), P_u=P, adjacency=adj + adj.T)
    return SimParams.from_design(d, dt=2e-3, substeps=7, exosystem=np.array([[0, 0.5], [-0.5, 0]]),
                                 K_ref=rng.normal(size=(m, n)), sigma=0.1, phi=0.3)


def test_kernel_args_unpack_in_python_and_compiled_code_equal_the_declared_values():
    from dobs_envs.sim.period_kernel import unpack_kernel_args as compiled

    prm = _random_params()
    ka = prm.kernel_args
    assert ka.A is prm.A and ka.degree is prm.degree and ka.rows.E_bar.val.size == np.count_nonzero(prm.E_bar)
    assert isinstance(ka.rows.A, Sparse) and ka.rows._fields[4] == "Q_projT"
    KF, KI = prm.kernel_packed
    _same(ka, unpack_kernel_args(KF, KI))
    _same(ka._replace(proj_range=ka.proj_range.astype(np.int64)), compiled(KF, KI), compiled=True)


def test_a_new_kernel_field_is_one_declaration_line():
    """Packing, Python and compiled unpacking of KernelArgs plus one field, with no other change."""
    ns = {"__annotations__": {**KernelArgs.__annotations__, "link_loss": f64("N D")}}
    Extended = NamedTuple("Extended", list(ns["__annotations__"].items()))
    prm = _random_params(1)
    loss = np.linspace(0.0, 1.0, prm.nbr_w.size).reshape(prm.nbr_w.shape)
    ext = Extended(*prm.kernel_args, link_loss=loss)
    KF, KI = pack(ext)
    np.testing.assert_array_equal(unpack(Extended, KF, KI).link_loss, loss)
    np.testing.assert_array_equal(compiled_unpack(Extended, numba.njit, "_ext_unpack")(KF, KI).link_loss, loss)
    with pytest.raises(ValueError, match=r"Extended\.link_loss"):
        pack(ext._replace(link_loss=loss[:, :1] if loss.shape[1] > 1 else np.zeros((loss.shape[0], 2))))


def test_state_arrays_mirror_sim_state():
    assert StateArrays._fields == tuple(f.name for f in fields(SimState))


def test_env_core_step_constants_by_name():
    from dobs_envs.envs import TrackingEnv
    from dobs_envs.envs.step_kernel import StepConsts

    core = TrackingEnv.make_core(2, max_cycles=7)
    c = StepConsts(*core._consts)
    assert c.max_cycles == 7 and c.has_ref and c.period == core.control_period
    np.testing.assert_array_equal(c.u_hi, core.action_bound)
    core.max_cycles = None
    assert StepConsts(*core._consts).max_cycles == -1 and type(core._consts) is tuple
