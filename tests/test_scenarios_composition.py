"""The MAS composition of Section AIHMAS (dobs_envs.scenarios.composition), shared by every MAS builder."""
import numpy as np
import pytest

from dobs_envs.graphs import path_graph, ring_graph
from dobs_envs.scenarios import ne1, random_mas_scenario, rendezvous_scenario, scenario_from_dict
from dobs_envs.scenarios.composition import TOPOLOGIES, compose_mas, ring_or_path


def _agents(rng):
    """Three agents of state dimensions 1, 2, 3 with 1, 2, 1 inputs and 1, 1, 2 outputs."""
    dims = [(1, 1, 1), (2, 2, 1), (3, 1, 2)]
    return [(rng.standard_normal((n, n)), rng.standard_normal((n, m)), rng.standard_normal((p, n))) for n, m, p in dims]


def test_composition_is_the_overall_system_of_eq_HMAS():
    """A = diag(A_i), B^i = [0 B_i^T 0]^T, C_i = [0 breve C_i 0] (Section AIHMAS), entry for entry."""
    rng = np.random.default_rng(0)
    agents = _agents(rng)
    mas = compose_mas(agents)
    assert mas.A.shape == (6, 6) and [b.shape for b in mas.channels] == [(6, 1), (6, 2), (6, 1)]
    assert [c.shape for c in mas.C] == [(1, 6), (1, 6), (2, 6)]
    rest = mas.A.copy()
    for (a, b, c), r, Bi, Ci in zip(agents, [slice(0, 1), slice(1, 3), slice(3, 6)], mas.channels, mas.C):
        np.testing.assert_array_equal(mas.A[r, r], a)
        rest[r, r] = 0.0
        np.testing.assert_array_equal(Bi[r], b)
        np.testing.assert_array_equal(np.delete(Bi, np.arange(6)[r], axis=0), 0.0)
        np.testing.assert_array_equal(Ci[:, r], c)
        np.testing.assert_array_equal(np.delete(Ci, np.arange(6)[r], axis=1), 0.0)
    np.testing.assert_array_equal(rest, 0.0)
    assert mas.known == [(0,), (1,), (2,)] and mas.links == (0, 1, 2)
    for (a, b, c), (a2, b2, c2) in zip(agents, mas.mas_agents):
        assert a2.dtype == b2.dtype == c2.dtype == np.float64
        np.testing.assert_array_equal(a, a2), np.testing.assert_array_equal(b, b2), np.testing.assert_array_equal(c, c2)


def test_vectors_and_scalars_follow_the_scenario_conventions():
    """A scalar A_i is (1, 1); a vector B_i is one column, a vector C_i one row (as Scenario reads mas_agents)."""
    mas = compose_mas([(0.0, 1.0, 1.0), ([[0, 1], [0, 0]], [0, 1], [1, 0])])
    np.testing.assert_array_equal(mas.channels[1], [[0.0], [0.0], [1.0]])
    np.testing.assert_array_equal(mas.C[1], [[0.0, 1.0, 0.0]])


@pytest.mark.parametrize("agent, shapes", [(([[0, 1], [0, 0]], [[1], [0], [0]], [[1, 0]]), r"\(3, 1\) and C of shape \(1, 2\)"),
                                           (([[0, 1], [0, 0]], [[1], [0]], [[1, 0, 0]]), r"\(2, 1\) and C of shape \(1, 3\)")])
def test_inconsistent_blocks_are_named(agent, shapes):
    """The message names the caller's argument (``agents`` by default, ``name=`` for scenario files) and the shapes."""
    with pytest.raises(ValueError, match=r"^agents\[1\]: B must have 2 rows and C 2 columns, got B of shape " + shapes):
        compose_mas([(0.0, 1.0, 1.0), agent])
    with pytest.raises(ValueError, match=r"^mas_agents\[1\]: B must have 2 rows"):
        compose_mas([(0.0, 1.0, 1.0), agent], name="mas_agents")


def test_design_layer_holds_the_composition():
    """One composition: the scenarios' names are the design layer's objects, and the MAS observer composes with it."""
    from dobs_envs.design import mas_composition
    from dobs_envs.design.observer import design_mas_observer
    from dobs_envs.scenarios import composition

    for name in mas_composition.__all__:
        assert getattr(composition, name) is getattr(mas_composition, name)
    agents = _agents(np.random.default_rng(1))  # n_i = 1, 2, 3; m_i = 1, 2, 1; p_i = 1, 1, 2
    agents[0] = (np.array([[-1.0]]), agents[0][1], agents[0][2])  # (A_0, C_0) detectable for the design
    d = design_mas_observer(agents, path_graph(3), shift=0.0)
    mas = compose_mas(agents)
    np.testing.assert_array_equal(d.A, mas.A)
    np.testing.assert_array_equal(d.B, np.hstack(mas.channels))
    assert d.channel_slices == (slice(0, 1), slice(1, 3), slice(3, 4))
    for i, Ci in enumerate(mas.C):
        np.testing.assert_array_equal(d.C_node(i), Ci)
        np.testing.assert_array_equal(d.known[i], np.isin(np.arange(4), np.arange(4)[d.channel_slices[i]]))


def test_builders_share_the_composition():
    """NE1, the random MAS, the rendezvous task and a mas_agents file give the composition of their own agents."""
    agents = list(ne1().mas_agents)
    scs = [ne1(), rendezvous_scenario(), random_mas_scenario(4, seed=3),
           scenario_from_dict({"name": "f", "mas_agents": [{"A": a.tolist(), "B": b.tolist(), "C": c.tolist()}
                                                           for a, b, c in agents],
                               "graph": {"topology": "ring"}, "x0": [0.0] * 9})]
    for sc in scs:
        mas = compose_mas(sc.mas_agents)
        np.testing.assert_array_equal(sc.A, mas.A)
        for got, want in zip(sc.channels + sc.C, mas.channels + mas.C):
            np.testing.assert_array_equal(got, want)
        assert sc.known == tuple(mas.known) and sc.links == mas.links


def test_default_graphs():
    assert ring_or_path(5) == ring_graph(5) and ring_or_path(2) == path_graph(2) and ring_or_path(1) == path_graph(1)
    assert set(TOPOLOGIES) == {"ring", "path", "star", "complete"}
    assert rendezvous_scenario(agents=list(ne1().mas_agents)[:2], x0=[1.0, 2.0]).graph == path_graph(2)
