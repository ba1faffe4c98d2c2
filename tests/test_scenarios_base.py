"""Scenario (scenarios/scenario.py): validation errors name the field, replace/equals, MAS consistency, x0 sampling."""
import numpy as np
import pytest

from dobs_envs.graphs import path_graph, ring_graph
from dobs_envs.scenarios import Scenario, Sinusoids, ne1, ne2, ne3


def small(**over):
    """A valid 3-state, 2-channel, 2-node scenario."""
    kw = dict(
        name="small",
        A=np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]),
        channels=[[0.0, 0.0, 1.0], np.array([[0.0], [1.0], [0.0]])],
        C=[[1.0, 0.0, 0.0], [[0.0, 1.0, 0.0]]],
        known=[(0,), (1,)],
        graph=path_graph(2),
        links=(0, 1),
        x0=[1.0, 0.0, -1.0],
        K=-np.ones((2, 3)),
    )
    kw.update(over)
    return Scenario(**kw)


def test_valid_small_and_normalisation():
    sc = small(known=[0, [1]])  # a bare int is one channel
    assert sc.known == ((0,), (1,))
    assert sc.channels[0].shape == (3, 1) and sc.C[0].shape == (1, 3)
    assert sc.n_inputs == 2 and sc.n_observers == 2 and sc.n_controllers == 2
    assert not sc.A.flags.writeable and not sc.K.flags.writeable


def test_user_input_not_mutated_and_copied():
    A = np.zeros((3, 3)); A[0, 1] = 1.0
    meta = {"a": 1}
    sc = small(A=A, metadata=meta)
    A[0, 1] = 5.0
    meta["b"] = 2
    assert sc.A[0, 1] == 1.0 and sc.metadata == {"a": 1}
    assert A.flags.writeable


@pytest.mark.parametrize(
    "over, field",
    [
        (dict(A=np.zeros((3, 2))), "Scenario.A"),
        (dict(A=[[0, "x"], [0, 0]]), "Scenario.A"),
        (dict(channels=[np.zeros((2, 1))]), "Scenario.channels[0]"),
        (dict(channels=[]), "Scenario.channels"),
        (dict(C=[np.zeros((1, 2)), [1.0, 0, 0]]), "Scenario.C[0]"),
        (dict(C=[[[1.0, 0, 0], [2.0, 0, 0]], [0, 1.0, 0]]), "Scenario.C[0]"),  # not full row rank
        (dict(known=[(0,)]), "Scenario.known"),
        (dict(known=[(0,), (2,)]), "Scenario.known[1]"),
        (dict(known=[(0, 0), (1,)]), "Scenario.known[0]"),
        (dict(known=[(0.5,), (1,)]), "Scenario.known[0]"),
        (dict(graph=ring_graph(3)), "Scenario.graph"),
        (dict(graph=[[0, 1], [2, 0]]), "Scenario.graph"),
        (dict(links=(0,)), "Scenario.links"),
        (dict(links=(0, 2)), "Scenario.links[1]"),
        (dict(links=(0, 1.5)), "Scenario.links[1]"),
        (dict(x0=[1.0, 2.0]), "Scenario.x0"),
        (dict(x0=[1.0, np.nan, 0.0]), "Scenario.x0"),
        (dict(K=np.ones((3, 3))), "Scenario.K"),
        (dict(P=np.ones((2, 2))), "Scenario.P"),
        (dict(P=np.array([[1.0, 2.0, 0], [0, 1.0, 0], [0, 0, 1.0]])), "Scenario.P"),  # not symmetric
        (dict(Q=-np.eye(3)), "Scenario.Q"),
        (dict(R=np.zeros((2, 2))), "Scenario.R"),
        (dict(B_v=np.ones((2, 1))), "Scenario.B_v"),
        (dict(B_v=np.ones((3, 2)), exosystem=np.zeros((3, 3))), "Scenario.exosystem"),
        (dict(B_v=np.ones((3, 2)), v0=[1.0]), "Scenario.v0"),
        (dict(reference=Sinusoids(1.0, [1.0, 2.0, 3.0], 0.0), controller="tracking"), "Scenario.reference"),
        (dict(reference={"amplitude": 1.0}), "Scenario.reference"),
        (dict(controller="pid"), "Scenario.controller"),
        (dict(controller="tracking"), "Scenario.controller='tracking'"),
        (dict(controller="sliding_mode"), "Scenario.controller='sliding_mode'"),
        (dict(K=None), "Scenario.controller='feedback'"),
        (dict(phi=-1.0), "Scenario.phi"),
        (dict(dt=0.0), "Scenario.dt"),
        (dict(t_end="long"), "Scenario.t_end"),
        (dict(x0_scale=-1.0), "Scenario.x0_scale"),
        (dict(name=""), "Scenario.name"),
        (dict(metadata=[1]), "Scenario.metadata"),
    ],
)
def test_validation_errors_name_the_field(over, field):
    with pytest.raises(ValueError) as info:
        small(**over)
    assert field in str(info.value)


def test_replace_validates_and_copies():
    sc = ne2()
    sc2 = sc.replace(phi=0.3, name="ne2-b")
    assert sc2.phi == 0.3 and sc.phi == 0.2 and sc2.name == "ne2-b"
    assert sc2.differences(sc) == ["name", "phi"]
    assert sc.replace().equals(sc)
    with pytest.raises(TypeError, match="no field"):
        sc.replace(not_a_field=1)
    with pytest.raises(ValueError, match="Scenario.links"):
        sc.replace(links=(0, 1, 2, 3, 9))


def test_equals_and_differences():
    assert ne2().equals(ne2()) and ne3().equals(ne3()) and ne1().equals(ne1())
    assert not ne2().equals(ne3())
    assert "K" in ne2().differences(ne2().replace(K=2 * ne2().K))
    assert ne2().replace(name="other", description="x").equals(ne2(), check_text=False)
    assert not ne2().equals("ne2")


def test_mas_agents_consistency_checked():
    sc = ne1()
    assert len(sc.mas_agents) == 5 and sc.mas_agents[4][0].shape == (3, 3)
    agents = list(sc.mas_agents)
    with pytest.raises(ValueError, match="Scenario.mas_agents has 4 agents"):
        sc.replace(mas_agents=tuple(agents[:4]))
    bad = list(agents); bad[2] = (2 * agents[2][0] + np.eye(2), agents[2][1], agents[2][2])
    with pytest.raises(ValueError, match=r"Scenario.mas_agents\[2\].A"):
        sc.replace(mas_agents=tuple(bad))
    bad = list(agents); bad[0] = (agents[0][0], agents[0][1], 2 * agents[0][2])
    with pytest.raises(ValueError, match=r"Scenario.C\[0\]"):
        sc.replace(mas_agents=tuple(bad))
    with pytest.raises(ValueError, match=r"Scenario.known\[1\]"):
        sc.replace(known=[(0,), (0,), (2,), (3,), (4,)])


def test_sample_x0():
    sc = ne2()
    assert np.array_equal(sc.sample_x0(), sc.x0)
    assert sc.sample_x0(batch=3).shape == (3, 9)
    sr = sc.replace(x0_scale=0.5)
    a = sr.sample_x0(np.random.default_rng(1), batch=100)
    b = sr.sample_x0(np.random.default_rng(1), batch=100)
    assert np.array_equal(a, b) and a.shape == (100, 9) and np.all(np.abs(a) <= 0.5)
    with pytest.raises(ValueError, match="rng"):
        sr.sample_x0()
