"""Property tests (issue 19, item 5): every public entry point, fed each class of bad input, raises a
named error of its documented type whose message names the argument.

Classes of bad input (:data:`BAD`): NaN, +-inf, complex, bool, negative and fractional sizes and
indices, strings / None / containers where a number belongs, wrong shapes, numbers beyond the
float range (``10**400``) and huge finite values where a bound applies. The contract:

- a bad *value* raises ``ValueError`` (or its subclasses: ``ScenarioFileError``,
  ``AssumptionError``, ``IllConditionedError``) whose message names the argument (option, field,
  file key, CLI option);
- an unknown *keyword* raises ``TypeError`` worded as Python's;
- on the command line: exit status 2, and the last line of stderr names the option.

Entry points covered (``ENTRY_POINTS`` below lists them for the report):

- design: ``strong_detectability``, ``design_distributed_observer``, ``shifted_are_feedback``,
  ``lyapunov_P``, ``observer_are_gain``;
- assumptions: ``check_collective_detectability``, ``check_stabilizable``, ``check_detectable``,
  ``check_matching``, ``check_exosystem_bounded``;
- graphs: ``Graph``, ``Graph.from_edges``, ``Graph.neighbors``, ``path_graph``, ``ring_graph``,
  ``star_graph``, ``complete_graph``, ``random_connected_graph``;
- scenarios: ``Scenario(...)``, ``scenario_from_dict``, ``load_scenario`` (YAML and JSON files),
  ``random_plant_scenario``, ``random_mas_scenario``, ``rendezvous_scenario``, ``Sinusoids``;
- environments: every registered env through ``<module>.parallel_env``, ``<module>.env``,
  ``gym.make``, ``gym.make_vec`` and ``EnvClass.make_core`` (each option of ``EnvOptions`` and of
  the env's own options dataclass, unknown keywords), then ``reset(seed, options)`` and ``step``
  of the PettingZoo, Gymnasium and vector adapters;
- the CLI parsers: ``dobs-envs train | evaluate | benchmark | reproduce``.

Hypothesis runs derandomised (the same examples every run) without deadlines; the whole module
takes well under a minute.
"""
from __future__ import annotations

import contextlib
import functools
import importlib
import io
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import dobs_envs  # noqa: F401  (registers the ids)
from dobs_envs import registry
from dobs_envs.assumptions import (check_collective_detectability, check_detectable, check_exosystem_bounded,
                                   check_matching, check_stabilizable)
from dobs_envs.design.gains import lyapunov_P, observer_are_gain, shifted_are_feedback
from dobs_envs.design.lemma2 import strong_detectability
from dobs_envs.design.observer import design_distributed_observer
from dobs_envs.graphs import (Graph, complete_graph, path_graph, random_connected_graph, ring_graph,
                              star_graph)
from dobs_envs.scenarios import load_scenario
from dobs_envs.scenarios.scenario import Scenario
from dobs_envs.scenarios.io import ScenarioFileError, example_path, scenario_from_dict, scenario_to_dict

SETTINGS = settings(derandomize=True, deadline=None, max_examples=25, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
FEW = settings(SETTINGS, max_examples=8)
MANY = settings(SETTINGS, max_examples=100)

ENTRY_POINTS = (
    "strong_detectability", "design_distributed_observer", "shifted_are_feedback", "lyapunov_P",
    "observer_are_gain", "check_collective_detectability", "check_stabilizable", "check_detectable",
    "check_matching", "check_exosystem_bounded", "Graph", "Graph.from_edges", "Graph.neighbors", "path_graph",
    "ring_graph", "star_graph", "complete_graph", "random_connected_graph", "Scenario", "scenario_from_dict",
    "load_scenario", "random_plant_scenario", "random_mas_scenario", "rendezvous_scenario", "Sinusoids", "<env>.parallel_env", "<env>.env", "gym.make", "gym.make_vec", "<EnvClass>.make_core",
    "ParallelEnv.reset/step", "gym Env.reset/step", "VectorEnv.reset/step",
    "dobs-envs train", "dobs-envs evaluate", "dobs-envs benchmark", "dobs-envs reproduce",
)

# ---------------------------------------------------------------------- classes of bad input
NAN, INF = float("nan"), float("inf")
TOO_LARGE = 10 ** 400  # a Python int no float holds

#: a bad scalar for a real number: NaN, +-inf, complex, bool, string, None, a container, beyond float range
bad_real = st.one_of(
    st.sampled_from([NAN, INF, -INF, 1 + 2j, True, False, "1.0", None, [1.0], {"a": 1}, TOO_LARGE, -TOO_LARGE]),
    st.complex_numbers(allow_nan=False, allow_infinity=False).filter(lambda z: z.imag != 0),
)
#: a bad positive real: the above, or zero / negative numbers
bad_positive = st.one_of(bad_real, st.floats(max_value=0.0, allow_nan=False, allow_infinity=False),
                         st.integers(max_value=0))
#: a bad non-negative real
bad_nonnegative = st.one_of(bad_real, st.floats(max_value=-1e-9, allow_nan=False, allow_infinity=False),
                            st.integers(max_value=-1))
#: a bad integer (size, index, seed): fractional, NaN/inf, bool, complex, string, None
bad_integer = st.one_of(
    st.sampled_from([NAN, INF, -INF, 1 + 2j, True, False, "2", None, [1], 2.5, -0.5]),
    st.floats(allow_nan=False, allow_infinity=False).filter(lambda x: x != int(x) if math.isfinite(x) else True),
)
#: a bad positive integer: the above or <= 0
bad_positive_int = st.one_of(bad_integer, st.integers(max_value=0))
#: a bad non-negative integer (seeds; None is a valid seed where a seed is optional)
bad_seed = st.one_of(bad_integer.filter(lambda v: v is not None), st.integers(max_value=-1),
                     st.sampled_from([1.0, np.float64(2.0)]))
#: a bad switch (True/False expected)
bad_flag = st.sampled_from(["no", "yes", "False", 0, 1, 1.0, None, NAN, [True]])


def bad_matrix(shape):
    """A bad matrix where ``shape`` is expected: a NaN/inf/complex/bool/string entry, the wrong shape,
    a ragged list, a number beyond the float range."""
    rows, cols = shape

    def entry(v):
        m = [[0.0] * cols for _ in range(rows)]
        m[0][0] = v
        return m

    return st.one_of(
        st.sampled_from([NAN, INF, -INF]).map(lambda v: np.full(shape, v)),
        st.just(np.eye(rows, cols) * 1j),
        st.just(np.ones(shape, dtype=bool)),
        st.just(entry("x")),
        st.just(entry(TOO_LARGE)),
        st.just(np.zeros((rows + 1, cols + 2))),
        st.just(np.zeros((rows, cols, 2))),
        st.just([[0.0] * cols, [0.0] * (cols + 1)][:max(rows, 2)]),
        st.just("matrix"),
    )


def raises_named(exc_type, names, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` raises ``exc_type`` whose message contains one of ``names``."""
    names = (names,) if isinstance(names, str) else tuple(names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(exc_type) as info:
            fn(*args, **kwargs)
    msg = str(info.value)
    assert any(n in msg for n in names), f"{type(info.value).__name__}: {msg!r} names none of {names}"
    assert "Traceback" not in msg
    return info.value


# ---------------------------------------------------------------------- design functions
A2 = np.array([[0.0, 1.0], [-2.0, -3.0]])
B2 = np.array([[0.0], [1.0]])
C2 = np.array([[1.0, 0.0]])


@SETTINGS
@given(arg=st.sampled_from(["A", "B_unknown", "C"]), data=st.data())
def test_strong_detectability_matrices(arg, data):
    shapes = {"A": (2, 2), "B_unknown": (2, 1), "C": (1, 2)}
    kw = {"A": A2, "B_unknown": B2, "C": C2}
    kw[arg] = data.draw(bad_matrix(shapes[arg]))
    raises_named(ValueError, [arg, arg.split("_")[0]], strong_detectability, **kw)


@SETTINGS
@given(arg=st.sampled_from(["tol", "margin"]), data=st.data())
def test_strong_detectability_scalars(arg, data):
    bad = data.draw(bad_positive)
    raises_named(ValueError, arg, strong_detectability, A2, B2, C2, **{arg: bad})


def _observer_kwargs():
    return dict(A=A2, channels=[B2], C=[C2, np.array([[0.0, 1.0]])], known=[[0], []], graph=path_graph(2))


@SETTINGS
@given(arg=st.sampled_from(["A", "channels", "C", "known", "graph", "B_v", "tol", "poles"]), data=st.data())
def test_design_distributed_observer(arg, data):
    kw = _observer_kwargs()
    bad = {
        "A": bad_matrix((2, 2)),
        "channels": st.one_of(bad_matrix((2, 1)).map(lambda m: [m]), st.just(B2 * 1j)),
        "C": st.one_of(bad_matrix((1, 2)).map(lambda m: [m, C2]), st.just([])),
        "known": st.one_of(bad_integer.map(lambda k: [[k], []]), st.just([[0]]), st.just([[5], []]),
                           st.just([[0, 0], []])),
        "graph": st.one_of(st.just(path_graph(3)), bad_matrix((2, 2))),
        "B_v": bad_matrix((2, 1)),
        "tol": bad_positive,
        "poles": st.one_of(st.just({5: [-1.0]}), st.just({True: [-1.0]}), st.just({0: [NAN, -1.0]}),
                           st.just({0: [1.0, 2.0]})),
    }[arg]
    kw[arg] = data.draw(bad)
    names = {"channels": ["channels", "B"], "C": ["C"], "graph": ["graph", "adjacency"],
             "A": ["A"], "known": ["known"], "B_v": ["B_v"], "tol": ["tol"], "poles": ["poles"]}[arg]
    raises_named(ValueError, names, design_distributed_observer, **kw)


@SETTINGS
@given(which=st.sampled_from(["shifted_are_feedback", "lyapunov_P", "observer_are_gain"]),
       arg=st.sampled_from(["M1", "M2", "shift", "Q"]), data=st.data())
def test_gains(which, arg, data):
    if which == "lyapunov_P":
        arg = "A_cl" if arg in ("M1", "M2", "shift") else "Q"
        kw = {"A_cl": A2}
        kw[arg] = data.draw(bad_matrix((2, 2)))
        raises_named(ValueError, arg, lyapunov_P, **kw)
        return
    names = {"shifted_are_feedback": ("A", "B"), "observer_are_gain": ("A", "C")}[which]
    fn = {"shifted_are_feedback": shifted_are_feedback, "observer_are_gain": observer_are_gain}[which]
    kw = {"A": A2, names[1]: B2 if names[1] == "B" else C2}
    if arg == "M1":
        kw["A"], name = data.draw(bad_matrix((2, 2))), "A"
    elif arg == "M2":
        kw[names[1]], name = data.draw(bad_matrix((2, 1) if names[1] == "B" else (1, 2))), names[1]
    elif arg == "shift":
        kw["shift"], name = data.draw(bad_nonnegative), "shift"
    else:
        if which == "observer_are_gain":
            kw["shift"], name = data.draw(bad_nonnegative), "shift"
        else:
            kw["Q"], name = data.draw(bad_matrix((2, 2))), "Q"
    raises_named(ValueError, name, fn, **kw)


@SETTINGS
@given(arg=st.sampled_from(["T_d_list", "n", "tol"]), data=st.data())
def test_check_collective_detectability(arg, data):
    kw = {"T_d_list": [np.eye(2)], "n": 2}
    if arg == "T_d_list":
        kw[arg] = data.draw(st.one_of(bad_matrix((2, 2)).map(lambda m: [m]), st.just(np.eye(2)), st.just(3)))
    elif arg == "n":
        kw[arg] = data.draw(bad_positive_int)
    else:
        kw[arg] = data.draw(bad_positive)
    raises_named(ValueError, [arg, "n (the state dimension)"], check_collective_detectability, **kw)


@SETTINGS
@given(fn=st.sampled_from(["check_stabilizable", "check_detectable", "check_matching", "check_exosystem_bounded"]),
       data=st.data())
def test_assumption_checks(fn, data):
    if fn == "check_stabilizable":
        arg = data.draw(st.sampled_from(["A", "B", "margin", "tol"]))
        kw = {"A": A2, "B": B2}
        f = check_stabilizable
    elif fn == "check_detectable":
        arg = data.draw(st.sampled_from(["A", "C", "margin", "tol"]))
        kw = {"A": A2, "C": C2}
        f = check_detectable
    elif fn == "check_matching":
        arg = data.draw(st.sampled_from(["B", "B_v", "rtol"]))
        kw = {"B": B2, "B_v": B2}
        f = check_matching
    else:
        arg = data.draw(st.sampled_from(["S", "axis_rtol"]))
        kw = {"S": np.array([[0.0, 1.0], [-1.0, 0.0]])}
        f = check_exosystem_bounded
    shapes = {"A": (2, 2), "B": (2, 1), "C": (1, 2), "B_v": (2, 1), "S": (2, 2)}
    if arg in shapes:
        kw[arg] = data.draw(bad_matrix(shapes[arg]))
    elif arg in ("tol", "rtol", "axis_rtol"):
        kw[arg] = data.draw(bad_positive)
    else:
        kw[arg] = data.draw(bad_real)
    raises_named(ValueError, arg, f, **kw)


# ---------------------------------------------------------------------- graphs
@SETTINGS
@given(data=st.data())
def test_graph_constructors(data):
    case = data.draw(st.sampled_from(["adjacency", "n_nodes", "edge", "weights", "N", "center", "edge_prob",
                                      "seed", "neighbors"]))
    if case == "adjacency":  # a boolean adjacency is accepted (True = an edge of weight 1)
        bad = data.draw(bad_matrix((3, 3)).filter(lambda m: getattr(m, "dtype", None) != bool))
        raises_named(ValueError, "adjacency", Graph, bad)
    elif case == "n_nodes":
        raises_named(ValueError, "number of nodes", Graph.from_edges, data.draw(bad_positive_int), [])
    elif case == "edge":
        e = data.draw(st.one_of(bad_integer.map(lambda i: [(0, i)]), st.just([(0, 7)]), st.just([(1, 1)]),
                                st.just([(0,)]), st.just([0, 1]), st.just(5)))
        raises_named(ValueError, ["edge", "Graph.from_edges"], Graph.from_edges, 3, e)
    elif case == "weights":
        w = data.draw(st.one_of(bad_positive.map(lambda v: [v]), st.just([1.0, 2.0])))
        raises_named(ValueError, "weight", Graph.from_edges, 3, [(0, 1)], w)
    elif case == "N":
        fn = data.draw(st.sampled_from([path_graph, ring_graph, star_graph, complete_graph, random_connected_graph]))
        raises_named(ValueError, "number of nodes", fn, data.draw(bad_positive_int))
    elif case == "center":
        raises_named(ValueError, "center", star_graph, 3, data.draw(st.one_of(bad_integer, st.sampled_from([3, -1]))))
    elif case == "edge_prob":
        raises_named(ValueError, "edge_prob", random_connected_graph, 4,
                     data.draw(st.one_of(bad_real, st.sampled_from([1.5, -0.1]))))
    elif case == "seed":
        raises_named(ValueError, "seed", random_connected_graph, 4, 0.3, data.draw(bad_seed))
    else:
        raises_named((ValueError, IndexError), "node", path_graph(3).neighbors,  # IndexError: out of range (documented)
                     data.draw(st.one_of(bad_integer, st.just(3))))


# ---------------------------------------------------------------------- scenarios and their files
@functools.lru_cache(maxsize=None)
def _custom3_json() -> str:
    import json

    return json.dumps(scenario_to_dict(load_scenario(example_path("custom3"))))


def _custom3() -> dict:
    """The shipped example ``custom3`` as a file dict (a fresh copy)."""
    import json

    return json.loads(_custom3_json())


#: Scenario fields and the class of bad value each is fed (matrices get bad_matrix of their shape)
SCALAR_FIELDS = {"gamma0": bad_nonnegative, "gamma_s0": bad_nonnegative, "phi": bad_nonnegative,
                 "phi_s": bad_nonnegative, "sigma": bad_nonnegative, "sigma_s": bad_nonnegative, "t_end": bad_positive,
                 "dt": bad_positive, "epsilon": bad_positive, "beta0": bad_nonnegative, "sigma_beta": bad_nonnegative,
                 "phi_beta": bad_nonnegative, "mas_shift": bad_nonnegative,
                 "x0_scale": bad_nonnegative.filter(lambda v: v is not None)}  # None: no x0 distribution


def _scenario_kwargs(d: dict) -> dict:
    sc = scenario_from_dict(d)
    return {f: getattr(sc, f) for f in Scenario.__dataclass_fields__}


@MANY
@given(field=st.sampled_from(sorted(SCALAR_FIELDS) + ["x0", "K", "x_r0", "links", "known", "graph", "controller",
                                                     "A", "C", "channels", "Q", "R"]), data=st.data())
def test_scenario_fields(field, data):
    custom3 = _custom3()
    kw = _scenario_kwargs(custom3)
    if field in SCALAR_FIELDS:
        kw[field] = data.draw(SCALAR_FIELDS[field])
    elif field in ("x0", "x_r0"):
        kw[field] = data.draw(st.one_of(bad_matrix((1, 4)).map(lambda m: np.asarray(m, dtype=object).reshape(-1)
                                                               if np.ndim(m) == 2 and np.shape(m)[0] == 1 else m),
                                        st.just(np.zeros(5))))
    elif field in ("K", "A", "Q"):
        kw[field] = data.draw(bad_matrix((2, 4) if field == "K" else (4, 4)))
    elif field == "R":
        kw[field] = data.draw(bad_matrix((2, 2)))
    elif field == "C":
        kw[field] = data.draw(bad_matrix((1, 4)).map(lambda m: (m,) + tuple(kw["C"][1:])))
    elif field == "channels":
        kw[field] = data.draw(bad_matrix((4, 1)).map(lambda m: (m,) + tuple(kw["channels"][1:])))
    elif field == "links":
        kw[field] = data.draw(bad_integer.map(lambda i: (i, 1)))
    elif field == "known":
        kw[field] = data.draw(bad_integer.map(lambda i: ((i,), (1,), ())))
    elif field == "graph":
        kw[field] = data.draw(st.one_of(st.just(path_graph(5)), st.just("ring"), bad_matrix((3, 3))))
    else:
        kw[field] = data.draw(st.sampled_from(["pid", 3, None]))
    raises_named(ValueError, field, Scenario, **kw)


YAML_VALUES = {  # a value of a file as YAML text, for the key it replaces
    "nan": ".nan", "inf": ".inf", "bool": "yes", "too_large": "1" + "0" * 400, "string": "'x'",
    "complex": "'1+2j'", "null_list": "[null]",
}


@SETTINGS
@given(key=st.sampled_from(["A[0][1]", "x0[0]", "gamma0", "phi", "t_end", "dt", "graph.weights[0]",
                            "graph.edges[0][1]", "links[0]", "known[0][0]", "C[0][0]", "channels[0][1]"]),
       bad=st.sampled_from(sorted(YAML_VALUES)), fmt=st.sampled_from(["yaml", "json"]))
def test_scenario_files(tmp_path_factory, key, bad, fmt):
    custom3 = _custom3()
    import json
    import re

    import yaml

    d = json.loads(json.dumps(custom3))
    path = re.findall(r"[A-Za-z_0-9]+|\[\d+\]", key)
    node = d
    for p in path[:-1]:
        node = node[int(p[1:-1])] if p.startswith("[") else node[p]
    last = path[-1]
    marker = "__BAD__"
    if last.startswith("["):
        node[int(last[1:-1])] = marker
    else:
        node[last] = marker
    if fmt == "yaml":
        text = yaml.safe_dump(d, sort_keys=False).replace(marker, YAML_VALUES[bad])
        if bad == "null_list":
            text = text.replace("'[null]'", "[null]")
    else:
        jv = {"nan": "NaN", "inf": "Infinity", "bool": "true", "too_large": "1e400", "string": '"x"',
              "complex": '"1+2j"', "null_list": "[null]"}[bad]
        text = json.dumps(d).replace(json.dumps(marker), jv)
    f = tmp_path_factory.mktemp("sc") / f"bad.{fmt}"
    f.write_text(text)
    top = path[0]
    err = raises_named(ScenarioFileError, [top], load_scenario, f)
    assert str(f) in str(err)


@FEW
@given(dup=st.sampled_from(["name", "gamma0", "graph.weights", "reference.frequency"]),
       fmt=st.sampled_from(["yaml", "json"]))
def test_scenario_files_duplicate_keys(tmp_path_factory, dup, fmt):
    custom3 = _custom3()
    import json

    import yaml

    *parents, key = dup.split(".")
    d = custom3
    node = d
    for p in parents:
        node = node[p]
    node["__DUP__"] = node[key]  # the same key twice in one mapping, written by the dumpers
    text = yaml.safe_dump(d, sort_keys=False) if fmt == "yaml" else json.dumps(d, indent=1)
    text = text.replace("__DUP__", key)
    f = tmp_path_factory.mktemp("dup") / f"dup.{fmt}"
    f.write_text(text)
    raises_named(ScenarioFileError, key, load_scenario, f)


@SETTINGS
@given(key=st.sampled_from(["gamma0", "t_end", "phi", "x0", "links", "graph", "name", "controller"]),
       data=st.data())
def test_scenario_from_dict(key, data):
    custom3 = _custom3()
    import copy

    d = copy.deepcopy(custom3)
    d[key] = data.draw({"x0": st.sampled_from([[NAN, 0, 0, 0], [True, 0, 0, 0], [1, 2], "x"]),
                        "links": st.sampled_from([[0.5, 1], [True, 1], ["0", 1], 3]),
                        "graph": st.sampled_from([{"edges": [[0, 1.5]]}, {"topology": "random", "seed": 1.5},
                                                  {"topology": "random", "seed": True}, "ring", {"edges": [[0, 1]], "x": 1}]),
                        "name": st.sampled_from([3, None, ["a"]]),
                        "controller": st.sampled_from([3, "pid"])}.get(key, bad_positive))
    raises_named(ScenarioFileError, key, scenario_from_dict, d)


@SETTINGS
@given(data=st.data())
def test_scenario_generators_and_signals(data):
    """random_plant_scenario, random_mas_scenario, rendezvous_scenario, Sinusoids."""
    from dobs_envs.scenarios.mas_tasks import rendezvous_scenario
    from dobs_envs.scenarios.random import MAX_SIZE, random_mas_scenario, random_plant_scenario
    from dobs_envs.scenarios.signals import Sinusoids

    huge_size = st.sampled_from([MAX_SIZE + 1, TOO_LARGE])
    case = data.draw(st.sampled_from(["n_states", "n_controllers", "n_observers", "seed", "edge_prob", "n_agents",
                                      "mas_seed", "q_rest", "r", "rho", "amplitude", "frequency", "phase"]))
    if case in ("n_states", "n_controllers", "n_observers"):
        kw = {"n_states": 4, "n_controllers": 2, "n_observers": 2, "seed": 0}
        kw[case] = data.draw(st.one_of(bad_positive_int, huge_size))
        raises_named(ValueError, case, random_plant_scenario, **kw)
    elif case in ("seed", "edge_prob"):
        bad = data.draw(bad_seed if case == "seed" else st.one_of(bad_real, st.just(1.5)))
        raises_named(ValueError, case, random_plant_scenario, 4, 2, 2, **{"seed": 0, case: bad})
    elif case in ("n_agents", "mas_seed"):
        kw = {"n_agents": 3, "seed": 0}
        kw["n_agents" if case == "n_agents" else "seed"] = data.draw(
            st.one_of(bad_positive_int, huge_size) if case == "n_agents" else bad_seed)
        raises_named(ValueError, "n_agents" if case == "n_agents" else "seed", random_mas_scenario, **kw)
    elif case in ("q_rest", "r", "rho"):
        raises_named(ValueError, case, rendezvous_scenario, **{case: data.draw(bad_positive if case == "r"
                                                                                 else bad_nonnegative)})
    else:
        kw = {"amplitude": 1.0, "frequency": 1.0, "phase": 0.0}
        kw[case] = data.draw(st.one_of(bad_real.filter(lambda v: not isinstance(v, (dict, list))),
                                       st.just([[1.0], [2.0, 3.0]]), st.just([1.0, True])))
        raises_named(ValueError, case, Sinusoids, **kw)


# ---------------------------------------------------------------------- environments
ENTRIES = list(registry.ENVIRONMENTS.values())


def _entry(name):
    return registry.get(name)


ENV_NAMES = sorted(e.name for e in ENTRIES)

#: option -> class of bad values (options validated before the system is built)
OPTION_BAD = {
    "dt": bad_positive, "substeps": bad_positive_int, "max_cycles": bad_positive_int,
    "horizon": st.one_of(bad_positive.filter(lambda v: not (isinstance(v, float) and v == INF)),
                         st.just(-INF)),
    "observation": st.sampled_from(["loc", ["y", "nope"], 3, [3]]), "obs_dtype": st.sampled_from(["int8", "float16", 3, None]),
    "init_noise": bad_nonnegative, "state_bound": st.one_of(bad_positive, st.just(1e200)),
    "termination_penalty": bad_flag, "reward": st.sampled_from(["cubic", 1, None]), "cost_scale": bad_positive,
    "render_mode": st.sampled_from(["ansi", 1, True]), "disturbance": st.sampled_from(["wind", None, 1]),
    "disturbance_amplitude": bad_nonnegative, "normalized_actions": bad_flag, "padded_observations": bad_flag,
    "action_bound": st.one_of(bad_positive.filter(lambda v: v is not None), st.just("big"), st.just([[1.0]])),
}
#: options of the env's own dataclass
TASK_BAD = {
    "hetero_mas": {"q_rest": bad_nonnegative, "r": bad_positive, "rho": bad_nonnegative},
    "random_network": {"system_seed": bad_seed, "n_states": bad_positive_int, "n_controllers": bad_positive_int,
                       "n_observers": bad_positive_int, "kind": st.sampled_from(["tree", 1, None]),
                       "graph": st.sampled_from(["torus", 1]), "edge_prob": st.one_of(bad_real, st.just(1.5)),
                       "unknown_input": bad_flag, "controller": st.sampled_from(["pid", 1])},
}


def _constructors(name):
    e = _entry(name)
    mod = importlib.import_module(e.module)
    cls = e.load_class()
    vec_ok = True
    return {
        "parallel_env": lambda **kw: mod.parallel_env(**kw),
        "env": lambda **kw: mod.env(**kw),
        "gym.make": lambda **kw: gym.make(e.gym_id, **kw),
        "gym.make_vec": (lambda **kw: gym.make_vec(e.gym_id, num_envs=2, vectorization_mode="vector_entry_point",
                                                   **kw)) if vec_ok else None,
        "make_core": lambda **kw: cls.make_core(2, **kw),
    }


@MANY
@given(env=st.sampled_from(ENV_NAMES), ctor=st.sampled_from(["parallel_env", "env", "gym.make", "gym.make_vec",
                                                            "make_core"]), data=st.data())
def test_env_constructors_options(env, ctor, data):
    opts = dict(OPTION_BAD, **TASK_BAD.get(env, {}))
    if ctor in ("gym.make", "gym.make_vec"):
        opts.pop("max_cycles"), opts.pop("horizon")
    opt = data.draw(st.sampled_from(sorted(opts)))
    bad = data.draw(opts[opt])
    fn = _constructors(env)[ctor]
    raises_named(ValueError, opt, fn, **{opt: bad})


@FEW
@given(env=st.sampled_from(ENV_NAMES), ctor=st.sampled_from(["parallel_env", "env", "gym.make", "gym.make_vec",
                                                            "make_core"]),
       kw=st.sampled_from(["substep", "seed", "num_envs_", "Dt"]))
def test_env_constructors_unknown_keywords(env, ctor, kw):
    with pytest.raises(TypeError, match=rf"got an unexpected keyword argument '{kw}'"):
        _constructors(env)[ctor](**{kw: 1})


@pytest.fixture(scope="module")
def envs():
    """One env of each adapter per registered environment (built once)."""
    out = {}
    for name in ENV_NAMES:
        e = _entry(name)
        c = _constructors(name)
        out[name] = {"parallel": c["parallel_env"](max_cycles=5), "gym": gym.make(e.gym_id),
                     "vector": c["gym.make_vec"]()}
    yield out
    for d in out.values():
        for env in d.values():
            env.close()


@SETTINGS
@given(env=st.sampled_from(ENV_NAMES), adapter=st.sampled_from(["parallel", "gym", "vector"]), data=st.data())
def test_reset_bad_seed_and_options(envs, env, adapter, data):
    e = envs[env][adapter]
    which = data.draw(st.sampled_from(["seed", "options", "x0", "v0"]))
    if which == "seed":
        bad = data.draw(bad_seed.filter(lambda s: s is not None and not isinstance(s, list)))
        raises_named((ValueError, gym.error.Error), ["seed", "Seed"], e.reset, seed=bad)
    elif which == "options":
        bad = data.draw(st.sampled_from([[1, 2], "x0", 3, (("x0", 1),)]))
        raises_named(ValueError, "options", e.reset, seed=0, options=bad)
    else:
        n = e.unwrapped.core.n_states if adapter != "vector" else e.core.n_states
        m_v = (e.unwrapped.core if adapter != "vector" else e.core).n_unknown
        if which == "v0" and not m_v:
            which = "x0"
        width = n if which == "x0" else m_v
        bad = data.draw(st.sampled_from([np.full(width, NAN), np.zeros(width + 1), np.ones(width) * 1j,
                                         np.ones(width, dtype=bool), "x", [INF] * width]))
        raises_named(ValueError, which, e.reset, seed=0, options={which: bad})


@SETTINGS
@given(env=st.sampled_from(ENV_NAMES), adapter=st.sampled_from(["parallel", "gym", "vector"]), data=st.data())
def test_step_bad_actions(envs, env, adapter, data):
    e = envs[env][adapter]
    e.reset(seed=0)
    kind = data.draw(st.sampled_from(["nan", "inf", "complex", "bool", "shape", "string"]))
    if adapter == "parallel":
        agents = e.possible_agents
        acts = {a: np.zeros(e.action_space(a).shape, dtype=np.float32) for a in agents}
        victim = data.draw(st.sampled_from(agents))
        shape = e.action_space(victim).shape
        acts[victim] = {"nan": np.full(shape, NAN), "inf": np.full(shape, INF), "complex": np.ones(shape) * 1j,
                        "bool": np.ones(shape, dtype=bool), "shape": np.zeros(shape[0] + 3),
                        "string": np.array(["a"] * shape[0])}[kind]
        raises_named(ValueError, [victim, "action"], e.step, acts)
    else:
        shape = e.action_space.shape
        bad = {"nan": np.full(shape, NAN), "inf": np.full(shape, INF), "complex": np.ones(shape) * 1j,
               "bool": np.ones(shape, dtype=bool), "shape": np.zeros((shape[-1] + 3,)),
               "string": np.full(shape, "a")}[kind]
        raises_named(ValueError, ["action", "controller", "input"], e.step, bad)


# ---------------------------------------------------------------------- the command line
def _cli(argv):
    """``dobs-envs argv`` in this process: (exit status, stderr)."""
    from dobs_envs.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


CLI_BAD = {  # (sub-command, option) -> bad values (argparse types or our checks)
    ("train", "--timesteps"): ["0", "-5", "1.5", "nan", "1e400", "x", ""],
    ("train", "--seed"): ["1.5", "nan", "x", "-1"],
    ("train", "--threads"): ["0", "-1", "2.5", "inf"],
    ("train", "--checkpoint-freq"): ["-1", "0.5", "x"],
    ("train", "--hyperparams"): ["{bad", "[1]", "1", "null", '{"learning_rate": NaN}'],
    ("train", "--env"): ["CartPol-v9", "os:system", ""],
    ("train", "--algo"): ["dqn", ""],
    ("evaluate", "--episodes"): ["0", "-1", "1.5", "x"],
    ("evaluate", "--seed"): ["1.5", "x", "-1"],
    ("evaluate", "--json"): ["."],
    ("benchmark", "--seeds"): ["0", "-2", "1.5"],
    ("benchmark", "--episodes"): ["0", "x"],
    ("benchmark", "--workers"): ["0", "nan"],
    ("benchmark", "--timesteps"): ["0", "1e3"],
    ("benchmark", "--seed"): ["1.5", "-1"],
    ("benchmark", "--eval-seed"): ["x", "-3"],
    ("benchmark", "--agents"): ["ppo,nope", "", ","],
    ("benchmark", "--budget"): ["huge"],
    ("benchmark", "--env"): ["pendulum"],
    ("reproduce", "--dt"): ["0", "-1e-3", "nan", "inf", "x"],
}


#: arguments that keep a wrongly accepted ``train`` tiny (a few env steps) instead of a default-budget run
_TINY_TRAIN = ["--timesteps=16", '--hyperparams={"n_envs": 1, "n_steps": 16, "batch_size": 16, "n_epochs": 1}']


@pytest.mark.parametrize("cmd,opt,bad", [(c, o, b) for (c, o), vals in sorted(CLI_BAD.items()) for b in vals])
def test_cli_usage_errors(tmp_path, cmd, opt, bad):
    """Every (option, bad value) of the table: exit status 2, the last stderr line names the option."""
    out = str(tmp_path / "out")
    if cmd == "train":
        safe = [] if opt in ("--timesteps", "--hyperparams") else _TINY_TRAIN
        argv = [cmd, "--out", out, "--no-progress", *safe, f"{opt}={bad}"]
    elif cmd == "benchmark":
        argv = [cmd, "--out", out, "--no-progress", "--dry-run", f"{opt}={bad}"]
    elif cmd == "evaluate":
        argv = [cmd, "--model", out, f"{opt}={bad}"]
    else:
        argv = [cmd, "ne2", f"{opt}={bad}", "--out", out]
    code, err = _cli(argv)
    assert code == 2, (argv, code, err)
    assert opt in err.strip().splitlines()[-1], (argv, err)
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()  # refused before anything was written


# ---------------------------------------------------------------------- issue 19, item 4: the reported cases
def _yaml_with(tmp_path, old, new, name="s.yaml"):
    text = open(example_path("custom3")).read()
    assert old in text
    f = tmp_path / name
    f.write_text(text.replace(old, new, 1))
    return f


@pytest.mark.parametrize("case", ["nan_T", "complex_T", "negative_n"])
def test_reported_collective_detectability(case):
    T, n = {"nan_T": ([np.full((2, 1), NAN)], 2), "complex_T": ([np.eye(2) * (1 + 1j)], 2),
            "negative_n": ([np.eye(2)], -2)}[case]
    raises_named(ValueError, ["T_d_list[0]", "n (the state dimension)"], check_collective_detectability, T, n)


@pytest.mark.parametrize("tol", [-1, NAN, 0.0, True, "1e-9"])
def test_reported_strong_detectability_tol_is_blamed_not_the_scaling(tol):
    err = raises_named(ValueError, "tol", strong_detectability, A2, B2, C2, tol=tol)
    assert "scaled" not in str(err) and "rank" not in str(err)


def test_reported_truncated_indices_and_seeds(tmp_path):
    raises_named(ValueError, "node index", Graph.from_edges, 3, [(0, 1.5), (1, 2)])
    raises_named(ValueError, "seed", random_connected_graph, 4, 0.3, 1.5)
    f = _yaml_with(tmp_path, "edges: [[0, 1], [1, 2]]", "edges: [[0, 1.7], [1, 2]]")
    raises_named(ScenarioFileError, "graph.edges", load_scenario, f)
    f = _yaml_with(tmp_path, "  edges: [[0, 1], [1, 2]]\n  weights: [1.0, 2.0]", "  topology: random\n  seed: 2.5",
                   "seed.yaml")
    raises_named(ScenarioFileError, "seed", load_scenario, f)
    from dobs_envs import tracking_v0

    env = tracking_v0.parallel_env(max_cycles=3)
    raises_named(ValueError, "seed", env.reset, seed=2.5)
    raises_named(ValueError, "system_seed", __import__("dobs_envs.random_network_v0", fromlist=["x"]).parallel_env,
                 system_seed=1.5)


def test_reported_termination_penalty_and_reset_options():
    from dobs_envs import tracking_v0

    raises_named(ValueError, "termination_penalty", tracking_v0.parallel_env, termination_penalty="no")
    env = tracking_v0.parallel_env(max_cycles=3)
    raises_named(ValueError, "options", env.reset, seed=0, options=[1, 2])


@pytest.mark.parametrize("old,new,key", [
    ("name: custom3", "name: custom3\nname: other", "name"),                                  # duplicated key
    ("  weights: [1.0, 2.0]", "  weights: [1.0, 2.0]\n  weights: [1.0, 3.0]", "weights"),     # ... nested
    ("[ 0.0,  1.0,  0.0,  0.0]", "[ 0.0,  yes,  0.0,  0.0]", "A[0][1]"),                      # YAML boolean
    ("x0: [1.0, 0.0, -1.0, 0.0]", "x0: [1.0, 0.0, -1.0, 1" + "0" * 400 + "]", "x0[3]"),      # too large
    ("gamma0: 0.1", "gamma0: 1" + "0" * 400, "gamma0"),
])
def test_reported_yaml_cases_name_the_key(tmp_path, old, new, key):
    err = raises_named(ScenarioFileError, key, load_scenario, _yaml_with(tmp_path, old, new))
    assert err.key == key


def test_yaml_numbers_written_without_a_dot_still_load(tmp_path):
    """YAML 1.1 (PyYAML) reads ``1e-3`` as a string: the file layer takes it as the number it spells."""
    sc = load_scenario(_yaml_with(tmp_path, "dt: 0.001", "dt: 1e-3"))
    assert sc.dt == 1e-3
