"""Scenario files: YAML/JSON round trips, shipped examples, defaults, errors naming file and key, registry."""
import json

import numpy as np
import pytest
import yaml

from dobs_envs.scenarios import (
    SCENARIOS,
    ScenarioFileError,
    example_path,
    load_scenario,
    make_scenario,
    ne1,
    ne2,
    ne3,
    random_mas_scenario,
    random_plant_scenario,
    rendezvous_scenario,
    save_scenario,
    scenario_from_dict,
    scenario_to_dict,
)
from dobs_envs.scenarios.io import VALID_KEYS


def _same_design(a, b):
    da, db = a.design, b.design
    for f in ("E_bar", "F_bar", "G_bar", "B_bar", "P_u", "C", "adjacency"):
        assert np.array_equal(getattr(da, f), getattr(db, f)), f


@pytest.mark.parametrize("ext", ["yaml", "yml", "json"])
@pytest.mark.parametrize("factory", [ne1, ne2, ne3, rendezvous_scenario,
                                     lambda: random_mas_scenario(3, 4, controller="tracking", input_dims=(1, 2)),
                                     lambda: random_plant_scenario(5, 2, 3, 4, unknown_input=True)])
def test_round_trip_exact(tmp_path, ext, factory):
    sc = factory()
    path = save_scenario(sc, tmp_path / f"s.{ext}")
    back = load_scenario(path)
    assert back.equals(sc), back.differences(sc)
    # and save -> load again is a fixed point of the file text
    path2 = save_scenario(back, tmp_path / f"t.{ext}")
    assert open(path).read().split("\n", 1)[1] == open(path2).read().split("\n", 1)[1]


@pytest.mark.parametrize("factory", [ne2, rendezvous_scenario, lambda: random_plant_scenario(5, 2, 3, 4)])
def test_round_trip_same_design(tmp_path, factory):
    sc = factory()
    _same_design(sc, load_scenario(save_scenario(sc, tmp_path / "s.yaml")))


def test_dict_round_trip_is_plain_and_does_not_mutate():
    d = scenario_to_dict(ne3())
    json.dumps(d)  # plain types only
    snapshot = json.dumps(d, sort_keys=True)
    sc = scenario_from_dict(d)
    assert json.dumps(d, sort_keys=True) == snapshot
    assert sc.equals(ne3())


def test_ne2_yaml_is_paper_ne2():
    sc = load_scenario(example_path("ne2"))
    ref = ne2()
    assert sc.equals(ref), sc.differences(ref)  # K from the shifted ARE: bit-identical
    _same_design(sc, ref)


def test_custom3_example_is_distributed():
    sc = load_scenario(example_path("custom3"))
    assert (sc.n_states, sc.n_controllers, sc.n_observers) == (4, 2, 3)
    assert sc.graph.adjacency[1, 2] == 2.0 and sc.known[2] == ()
    assert sorted(t.shape[1] for t in sc.design.T_d) == [1, 2, 2]  # no node sees everything
    assert np.max(np.linalg.eigvals(sc.A + sc.B @ sc.K).real) < -0.2


def _minimal(**over):
    d = dict(name="m", A=[[0, 1], [0, 0]], channels=[[0, 1]], C=[[1, 0], [0, 1]], known=[[0], []],
             graph={"topology": "path"}, links=[0], x0=[1, 0])
    d.update(over)
    return d


def test_defaults_K_from_are_P_from_lyapunov():
    from dobs_envs.design.gains import lyapunov_P, shifted_are_feedback

    sc = scenario_from_dict(_minimal())
    A, B = np.array([[0.0, 1], [0, 0]]), np.array([[0.0], [1]])
    assert np.array_equal(sc.K, shifted_are_feedback(A, B, 0.2)[1])
    sc = scenario_from_dict(_minimal(K_shift=0.5, controller="sliding_mode"))
    K = shifted_are_feedback(A, B, 0.5)[1]
    assert np.array_equal(sc.K, K) and np.array_equal(sc.P, lyapunov_P(A + B @ K))
    sc = scenario_from_dict(_minimal(controller="open_loop", prescribed_input={"frequency": 2.0}))
    assert sc.K is None and sc.prescribed_input.amplitude == (1.0,) and sc.prescribed_input.phase == (0.0,)
    sc = scenario_from_dict(_minimal(dt="1e-3"))  # YAML 1.1 reads 1e-3 as a string
    assert sc.dt == 1e-3


def test_graph_specs():
    for spec, edges in [({"topology": "path"}, [(0, 1)]), ({"edges": [[1, 0]]}, [(0, 1)]),
                        ({"adjacency": [[0, 3], [3, 0]]}, [(0, 1)]),
                        ({"topology": "random", "seed": 1, "edge_prob": 0.5}, [(0, 1)])]:
        assert scenario_from_dict(_minimal(graph=spec)).graph.edges == edges
    sc = scenario_from_dict(_minimal(graph={"edges": [[0, 1]], "weights": [2.5]}))
    assert sc.graph.adjacency[0, 1] == 2.5


def test_mas_agents_only():
    d = {"name": "mas", "mas_agents": [{"A": [[0]], "B": [[1]], "C": [[1]]},
                                       {"A": [[0, 1], [0, 0]], "B": [[0], [1]], "C": [[1, 0]]}],
         "graph": {"topology": "path"}, "x0": [1, 2, 3]}
    sc = scenario_from_dict(d)
    assert sc.n_states == 3 and sc.known == ((0,), (1,)) and sc.links == (0, 1)
    assert sc.mas_agents[1][0].shape == (2, 2)
    sc.design


def test_mas_agents_block_shapes_are_named_by_the_file_key(tmp_path):
    """A scenario file's agents are the key ``mas_agents``: the composition's shape error says ``mas_agents[i]``."""
    path = tmp_path / "bad_agents.yaml"
    path.write_text(yaml.safe_dump({
        "name": "bad", "graph": {"topology": "path"}, "x0": [1, 2, 3],
        "mas_agents": [{"A": [[0]], "B": [[1]], "C": [[1]]},
                       {"A": [[0, 1], [0, 0]], "B": [[0], [1]], "C": [[1, 0, 0]]}]}))  # C_1 with 3 columns
    with pytest.raises(ScenarioFileError, match=r"bad_agents\.yaml: key 'mas_agents': mas_agents\[1\]: B must have 2 rows "
                                                r"and C 2 columns, got B of shape \(2, 1\) and C of shape \(1, 3\)") as ei:
        load_scenario(path)
    assert ei.value.key == "mas_agents"


@pytest.mark.parametrize(
    "over, key, text",
    [
        (dict(foo=1), None, "unknown key(s) ['foo']"),
        (dict(graph={"topology": "ring", "colour": 1}), "graph", "unknown key(s) ['colour']"),
        (dict(graph={"topology": "torus"}), "graph.topology", "must be one of"),
        (dict(graph={"topology": "ring", "edges": [[0, 1]]}), "graph", "exactly one of"),
        (dict(graph={"edges": [[0, 5]]}), "graph.edges", "outside"),
        (dict(reference={"frequency": 1, "amp": 2}), "reference", "unknown key(s) ['amp']"),
        (dict(reference={"amplitude": 1}), "reference.frequency", "required"),
        (dict(A=[[0, 1], [0]]), "A", "nested list"),
        (dict(A=[[0, 1, 0], [0, 0, 1]]), "A", "square"),
        (dict(channels=[[0, 1, 2]]), "channels[0]", "length n = 2"),
        (dict(C="row"), "C", "must be a list"),
        (dict(known=[[0], [3]]), "known[1]", "valid channel indices"),
        (dict(links=[4]), "links[0]", "not an observer node"),
        (dict(x0=[1, 2, 3]), "x0", "shape"),
        (dict(K=[[1, 2, 3]]), "K", "shape"),
        (dict(K=[[-1, -1]], K_shift=0.3), "K_shift", "only applies when K is omitted"),
        (dict(phi=-1), "phi", ">= 0"),
        (dict(controller=3), "controller", "string"),
        (dict(mas_agents=[{"A": [[0]], "B": [[1]]}]), "mas_agents[0]", "missing key(s) ['C']"),
        (dict(metadata=[1, 2]), "metadata", "mapping"),
    ],
)
def test_errors_name_file_and_key(tmp_path, over, key, text):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_minimal(**over)))
    with pytest.raises(ScenarioFileError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert str(path) in msg and text in msg, msg
    assert info.value.key == key
    if key:
        assert f"key {key!r}" in msg


def test_unknown_key_lists_valid_keys():
    with pytest.raises(ScenarioFileError) as info:
        scenario_from_dict(_minimal(Kgain=1, zeta=2))
    msg = str(info.value)
    assert "['Kgain', 'zeta']" in msg and "valid keys are" in msg and "'K_shift'" in msg
    assert set(VALID_KEYS) >= {"A", "channels", "C", "known", "graph", "links", "x0", "K", "P"}


def test_missing_keys_and_bad_files(tmp_path):
    d = _minimal(); del d["links"]; del d["x0"]
    with pytest.raises(ScenarioFileError, match=r"missing required key\(s\) \['links', 'x0'\]"):
        scenario_from_dict(d)
    p = tmp_path / "x.txt"; p.write_text("{}")
    with pytest.raises(ValueError, match="extension"):
        load_scenario(p)
    p = tmp_path / "x.json"; p.write_text("{not json")
    with pytest.raises(ScenarioFileError, match="cannot parse JSON"):
        load_scenario(p)
    p = tmp_path / "e.yaml"; p.write_text("")
    with pytest.raises(ScenarioFileError, match="empty"):
        load_scenario(p)
    with pytest.raises(TypeError):
        scenario_to_dict({"name": "x"})


def test_registry(tmp_path):
    assert {"ne1", "ne2", "ne2-ablation", "ne3", "ne1-rendezvous", "random-mas", "random-plant", "custom3"} <= set(SCENARIOS)
    assert make_scenario("ne2").equals(ne2())
    assert make_scenario("custom3", t_end=5.0).t_end == 5.0
    assert make_scenario("random-plant", seed=3, n_states=5, verify=False).n_states == 5
    p = save_scenario(ne2(), tmp_path / "n.json")
    assert make_scenario(p).equals(ne2())
    with pytest.raises(KeyError, match="registered names"):
        make_scenario("nope")
