r"""Scenario files: YAML (``.yaml``/``.yml``) and JSON (``.json``).

A file is one mapping whose keys are the :class:`~dobs_envs.scenarios.scenario.Scenario`
fields, written for humans (0-based node and channel indices throughout):

=====================  =====================================================================
key                    value
=====================  =====================================================================
``name``               string (required)
``description``        string
``A``                  ``n x n`` nested list, eq. (LTIsys) (required unless ``mas_agents``)
``channels``           list of input matrices ``B^k`` (eq. Busplit): each an ``n x m_k``
                       nested list, or a flat list of length ``n`` (one column)
``C``                  list of output matrices ``C_i`` (eq. localmeasure): each a ``p_i x n``
                       nested list, or a flat list of length ``n`` (one row)
``known``              per node, the list of channels it knows (eq. splitinput); an int
                       means one channel
``graph``              mapping with exactly one of (Section commugraph):
                       ``topology: ring|path|star|complete`` (unit weights),
                       ``topology: random`` with ``edge_prob`` and ``seed``
                       (:func:`~dobs_envs.graphs.random_connected_graph`),
                       ``edges: [[0, 1], ...]`` with optional ``weights: [...]``
                       (default 1), or ``adjacency`` (``N x N``); optional ``n_nodes``
                       (default: the number of observer nodes)
``links``              controller ``k`` uses ``xhat_{links[k]}`` (eq. linearfeedback)
``x0``                 initial state, length ``n`` (required)
``B_v``, ``exosystem``,  unknown input ``B_v v`` with ``v' = S v`` (NE3)
``v0``
``K``                  ``m x n`` stacked gain; if omitted (and the controller is not
                       ``open_loop``) it is computed from the shifted ARE of NE2,
                       ``K = -B^T X``, ``(A + sI)^T X + X (A + sI) - X B B^T X + I = 0``
``K_shift``            the ``s`` above (default 0.2); only allowed when ``K`` is omitted
``P``                  ``n x n``; if omitted and the controller is a sliding mode,
                       ``(A + BK)^T P + P (A + BK) = -I`` (NE3)
``reference``,         sinusoids ``amplitude * sin(frequency * t + phase)``: mapping with
``prescribed_input``   ``amplitude`` (default 1), ``frequency`` (required), ``phase``
                       (default 0), each a number or a list of length ``m``
``x_r0``, ``controller``, ``Q``, ``R``, ``gamma0``, ``gamma_s0``, ``phi``, ``phi_s``,
``sigma``, ``sigma_s``, ``beta0``, ``sigma_beta``, ``phi_beta``, ``epsilon``,
``mas_shift``, ``x0_scale``, ``t_end``, ``dt``, ``metadata``   as the Scenario fields
``mas_agents``         list of mappings ``{A, B, C}`` (eq. HMAS); then ``A``, ``channels``,
                       ``C``, ``known`` (``[[i]]``) and ``links`` (``[0..N-1]``) default to
                       the composite system of Section AIHMAS
=====================  =====================================================================

Unknown keys are rejected (the error names them and lists the valid keys), and so are
a key given twice in one mapping, booleans where numbers are expected (YAML reads
``yes``/``no``/``on``/``off`` as booleans) and numbers beyond the float range;
every error raised while reading a file is a :class:`ScenarioFileError` naming
the file and the key. :func:`save_scenario` writes every field explicitly
(``K`` and ``P`` included), with floats in their shortest round-trip
representation, so ``load_scenario(save_scenario(sc, p))`` equals ``sc``
array for array (:meth:`Scenario.equals`) and gives the same design.
"""
from __future__ import annotations

import json
import os
import re
from typing import Any, Mapping

import numpy as np
import yaml

from ..design.gains import shifted_are_feedback, sliding_mode_P
from ..graphs import Graph, random_connected_graph
from .scenario import Scenario
from .composition import TOPOLOGIES, compose_mas
from .signals import Sinusoids

__all__ = [
    "ScenarioFileError",
    "scenario_from_dict",
    "scenario_to_dict",
    "load_scenario",
    "save_scenario",
    "VALID_KEYS",
    "example_path",
    "EXAMPLES",
]

_FIELDS = (
    "name", "description", "A", "channels", "C", "known", "graph", "links", "x0",
    "B_v", "exosystem", "v0", "K", "P", "reference", "x_r0", "prescribed_input",
    "controller", "Q", "R", "gamma0", "gamma_s0", "phi", "phi_s", "sigma", "sigma_s",
    "beta0", "sigma_beta", "phi_beta", "epsilon", "mas_agents", "mas_shift", "x0_scale",
    "t_end", "dt", "metadata",
)
#: Keys accepted at the top level of a scenario file.
VALID_KEYS = tuple(sorted(_FIELDS + ("K_shift",)))
_GRAPH_KEYS = ("topology", "edges", "weights", "adjacency", "n_nodes", "edge_prob", "seed")
_SIGNAL_KEYS = ("amplitude", "frequency", "phase")
_AGENT_KEYS = ("A", "B", "C")
_SLIDING = ("sliding_mode", "adaptive_sliding_mode")

#: Example files shipped with the package (``example_path(name)``).
EXAMPLES = ("ne2", "custom3")


class ScenarioFileError(ValueError):
    """A scenario file (or dict) is malformed. ``source`` names the file, ``key`` the key."""

    def __init__(self, source: str, key: str | None, detail: str):
        self.source, self.key, self.detail = source, key, detail
        where = f"{source}: key {key!r}: " if key else f"{source}: "
        super().__init__(where + detail)


class _DuplicateKeyError(ValueError):
    """A mapping of a scenario file lists ``key`` twice (YAML and JSON parsers keep the last value silently)."""

    def __init__(self, key, line: int | None = None):
        self.key, self.line = key, line
        super().__init__(key)


class _StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (merge keys ``<<`` may still be overridden)."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    dup = key in seen
                except TypeError:  # unhashable: the base class reports it
                    continue
                if dup:
                    raise _DuplicateKeyError(key, key_node.start_mark.line + 1)
                seen.add(key)
        return super().construct_mapping(node, deep)


def _unique_pairs(pairs):
    """``json.loads`` hook: a dict, refusing a key given twice."""
    out = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKeyError(k)
        out[k] = v
    return out


def example_path(name: str) -> str:
    """Path of a shipped example file (``"ne2"``: NE2 exactly, ``"custom3"``: a 3-node system)."""
    if name not in EXAMPLES:
        raise ValueError(f"unknown example {name!r}; examples are {EXAMPLES}")
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), f"{name}.yaml")


# ---------------------------------------------------------------------- reading
def _reject_unknown(d: Mapping, valid, source: str, where: str | None) -> None:
    unknown = sorted(str(k) for k in d if k not in valid)
    if unknown:
        raise ScenarioFileError(
            source, where, f"unknown key(s) {unknown}; valid keys are {sorted(valid)}"
        )


def _mapping(v, source, key) -> Mapping:
    if not isinstance(v, Mapping):
        raise ScenarioFileError(source, key, f"must be a mapping, got {type(v).__name__}")
    return v


def _list(v, source, key) -> list:
    if not isinstance(v, (list, tuple)):
        raise ScenarioFileError(source, key, f"must be a list, got {type(v).__name__}")
    return list(v)


def _array(v, source, key, ndim=None, finite: bool = False) -> np.ndarray:
    try:
        a = np.array(v, dtype=float)
    except OverflowError:
        raise ScenarioFileError(source, key, "holds a number too large for a float (|x| > 1.8e308)") from None
    except (TypeError, ValueError):
        raise ScenarioFileError(source, key, "must be a number, a list of numbers or a nested list "
                                             "of numbers with rows of equal length") from None
    if finite and not np.all(np.isfinite(a)):
        raise ScenarioFileError(source, key, "must be finite (no NaN or inf entries)")
    if ndim is not None and a.ndim != ndim:
        raise ScenarioFileError(source, key, f"must be {ndim}-D, got shape {a.shape}")
    return a


def _graph_from(spec, N: int, source: str) -> Graph:
    spec = _mapping(spec, source, "graph")
    _reject_unknown(spec, _GRAPH_KEYS, source, "graph")
    kinds = [k for k in ("topology", "edges", "adjacency") if k in spec]
    if len(kinds) != 1:
        raise ScenarioFileError(source, "graph", "give exactly one of 'topology', 'edges', 'adjacency'"
                                f" (got {kinds or 'none'})")
    kind = kinds[0]
    n_nodes = spec.get("n_nodes", N)
    if kind != "topology" and ("edge_prob" in spec or "seed" in spec):
        raise ScenarioFileError(source, "graph", "'edge_prob'/'seed' only apply to 'topology: random'")
    if kind != "edges" and "weights" in spec:
        raise ScenarioFileError(source, "graph.weights", "'weights' only applies with 'edges'")
    try:
        if kind == "topology":
            topo = spec["topology"]
            if topo == "random":
                if "seed" not in spec:
                    raise ScenarioFileError(source, "graph.seed", "'topology: random' needs an integer seed")
                return random_connected_graph(n_nodes, spec.get("edge_prob", 0.3), seed=spec["seed"])
            if "edge_prob" in spec or "seed" in spec:
                raise ScenarioFileError(source, "graph", "'edge_prob'/'seed' only apply to 'topology: random'")
            if topo not in TOPOLOGIES:
                raise ScenarioFileError(source, "graph.topology",
                                        f"must be one of {sorted(TOPOLOGIES) + ['random']}, got {topo!r}")
            return TOPOLOGIES[topo](n_nodes)
        if kind == "edges":
            edges = _list(spec["edges"], source, "graph.edges")
            return Graph.from_edges(n_nodes, [tuple(e) if isinstance(e, (list, tuple)) else (e,) for e in edges],
                                    spec.get("weights"))
        return Graph(_array(spec["adjacency"], source, "graph.adjacency", ndim=2))
    except ScenarioFileError:
        raise
    except (TypeError, ValueError) as exc:
        raise ScenarioFileError(source, f"graph.{kind}", str(exc)) from None


def _signal_from(spec, source, key) -> Sinusoids:
    spec = _mapping(spec, source, key)
    _reject_unknown(spec, _SIGNAL_KEYS, source, key)
    if "frequency" not in spec:
        raise ScenarioFileError(source, f"{key}.frequency", "is required")
    try:
        return Sinusoids(amplitude=spec.get("amplitude", 1.0), frequency=spec["frequency"],
                         phase=spec.get("phase", 0.0))
    except (TypeError, ValueError) as exc:
        raise ScenarioFileError(source, key, str(exc)) from None


def _agents_from(spec, source) -> list:
    agents = []
    for i, ag in enumerate(_list(spec, source, "mas_agents")):
        key = f"mas_agents[{i}]"
        ag = _mapping(ag, source, key)
        _reject_unknown(ag, _AGENT_KEYS, source, key)
        missing = [k for k in _AGENT_KEYS if k not in ag]
        if missing:
            raise ScenarioFileError(source, key, f"missing key(s) {missing}")
        Ai = np.atleast_2d(_array(ag["A"], source, f"{key}.A"))
        Bi = _array(ag["B"], source, f"{key}.B")
        Bi = Bi.reshape(Ai.shape[0], -1) if Bi.ndim < 2 else Bi
        Ci = np.atleast_2d(_array(ag["C"], source, f"{key}.C"))
        if Ai.ndim != 2 or Ai.shape[0] != Ai.shape[1]:
            raise ScenarioFileError(source, f"{key}.A", f"must be square, got shape {Ai.shape}")
        agents.append((Ai, Bi, Ci))
    if not agents:
        raise ScenarioFileError(source, "mas_agents", "must list at least one agent")
    return agents


_FLOAT_MAX = float(np.finfo(np.float64).max)
#: keys whose values are text or free-form (not numbers)
_TEXT_KEYS = ("metadata", "name", "description", "controller")


#: a number written as YAML 1.2 / JSON would (PyYAML reads YAML 1.1, where ``1e-3`` without a dot is a string)
_NUMBER = re.compile(r"[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?")


def _numbers(v):
    """``v`` with every string that spells a number (``"1e-3"``: YAML 1.1 reads it as a string) as a float."""
    if isinstance(v, str):
        return float(v) if _NUMBER.fullmatch(v.strip()) else v
    if isinstance(v, Mapping):
        return {k: _numbers(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_numbers(x) for x in v]
    return v


def _check_scalars(v, source: str, key: str) -> None:
    """Refuse, naming the key path, the scalars no Scenario field holds: booleans (YAML reads ``yes``,
    ``no``, ``on``, ``off``, ``true``, ``false`` as booleans; ``np.array([True], float)`` would make
    them 1.0 silently) and numbers beyond the float range (``1e400`` in JSON, a long integer)."""
    if isinstance(v, (bool, np.bool_)):
        raise ScenarioFileError(source, key, f"holds the boolean {v!r} where a number is expected (YAML reads "
                                             f"yes/no/on/off/true/false as booleans; write 1 or 0)")
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        if abs(int(v)) > _FLOAT_MAX:
            raise ScenarioFileError(source, key, "holds a number too large for a float (|x| > 1.8e308)")
    elif isinstance(v, Mapping):
        for k, x in v.items():
            _check_scalars(x, source, f"{key}.{k}")
    elif isinstance(v, (list, tuple)):
        for i, x in enumerate(v):
            _check_scalars(x, source, f"{key}[{i}]")


def scenario_from_dict(d: Mapping[str, Any], *, source: str = "<dict>") -> Scenario:
    """Build a :class:`Scenario` from the file format (module docstring). ``d`` is not modified.

    Raises
    ------
    ScenarioFileError
        Naming ``source`` and the offending key.
    """
    d = _mapping(d, source, None)
    _reject_unknown(d, VALID_KEYS, source, None)
    d = {k: v if k in _TEXT_KEYS else _numbers(v) for k, v in d.items()}
    for key, value in d.items():
        if key not in _TEXT_KEYS:
            _check_scalars(value, source, key)
    kw: dict = {}
    agents = None
    if "mas_agents" in d:
        agents = _agents_from(d["mas_agents"], source)
        try:
            mas = compose_mas(agents, name="mas_agents")  # Section AIHMAS: the defaults of A, channels, C, known, links
        except ValueError as exc:
            raise ScenarioFileError(source, "mas_agents", str(exc)) from None
        kw["mas_agents"] = mas.mas_agents
        defaults = mas._asdict()
    else:
        defaults = {}
    required = ["name", "graph", "x0"] + ([] if agents else ["A", "channels", "C", "known", "links"])
    missing = sorted(k for k in required if k not in d)
    if missing:
        raise ScenarioFileError(source, None, f"missing required key(s) {missing}")

    for key in ("A", "channels", "C", "known", "links"):
        kw[key] = d[key] if key in d else defaults[key]
    for key in ("channels", "C", "known", "links"):
        _list(kw[key], source, key)
    kw["channels"] = [_array(b, source, f"channels[{k}]") for k, b in enumerate(kw["channels"])]
    kw["C"] = [_array(c, source, f"C[{i}]") for i, c in enumerate(kw["C"])]
    for key in ("name", "description", "controller"):
        if key in d:
            if not isinstance(d[key], str):
                raise ScenarioFileError(source, key, f"must be a string, got {type(d[key]).__name__}")
            kw[key] = d[key]
    if "metadata" in d:
        kw["metadata"] = dict(_mapping(d["metadata"], source, "metadata"))
    N = len(kw["C"])
    kw["graph"] = _graph_from(d["graph"], N, source)
    for key in ("reference", "prescribed_input"):
        if key in d and d[key] is not None:
            kw[key] = _signal_from(d[key], source, key)
    for key in ("x0", "B_v", "exosystem", "v0", "K", "P", "x_r0", "Q", "R", "gamma0", "gamma_s0", "phi",
                "phi_s", "sigma", "sigma_s", "beta0", "sigma_beta", "phi_beta", "epsilon", "mas_shift",
                "x0_scale", "t_end", "dt"):
        if key in d and d[key] is not None:
            kw[key] = d[key]

    controller = kw.get("controller", "feedback")
    if "K_shift" in d and "K" in d:
        raise ScenarioFileError(source, "K_shift", "only applies when K is omitted (K is given)")
    A = _array(kw["A"], source, "A", finite=True)
    for k, b in enumerate(kw["channels"]):
        if not np.all(np.isfinite(b)):
            raise ScenarioFileError(source, f"channels[{k}]", "must be finite (no NaN or inf entries)")
    try:
        if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
            raise ValueError
        B = np.hstack([b.reshape(A.shape[0], -1) if b.ndim == 1 else b for b in kw["channels"]])
    except ValueError:
        A = B = None  # shapes inconsistent: Scenario's validation below names the field
    if "K" not in kw and controller != "open_loop" and A is not None:
        shift = d.get("K_shift", 0.2)
        try:
            _, kw["K"] = shifted_are_feedback(A, B, shift=float(shift))
        except (TypeError, ValueError) as exc:
            raise ScenarioFileError(source, "K", f"omitted, and the shifted ARE (K_shift = {shift}) failed: {exc}") from None
    K_arr = _array(kw["K"], source, "K") if "K" in kw else None
    if ("P" not in kw and controller in _SLIDING and A is not None and K_arr is not None
            and K_arr.shape == (B.shape[1], A.shape[0])):  # else Scenario names the bad K
        try:
            kw["P"] = sliding_mode_P(A, B, K_arr)
        except ValueError as exc:
            raise ScenarioFileError(source, "P", f"omitted, and (A + BK)^T P + P (A + BK) = -I failed: {exc}") from None
    try:
        return Scenario(**kw)
    except OverflowError:
        raise ScenarioFileError(source, None, "holds a number too large for a float (|x| > 1.8e308)") from None
    except (TypeError, ValueError) as exc:
        m = re.match(r"Scenario\.(\w+(?:\[\d+\])?(?:\.\w+)?)", str(exc))
        raise ScenarioFileError(source, m.group(1) if m else None, str(exc)) from None


# ---------------------------------------------------------------------- writing
def _plain(v, key: str):
    """Recursively convert to YAML/JSON-native types (lists, dicts, float, int, str, bool, None)."""
    if isinstance(v, np.ndarray):
        return _plain(v.tolist(), key)
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if v is None or isinstance(v, (bool, int, str)):
        return v
    if isinstance(v, (list, tuple)):
        return [_plain(x, key) for x in v]
    if isinstance(v, Mapping):
        out = {}
        for k, x in v.items():
            if not isinstance(k, str):
                raise ValueError(f"scenario_to_dict: {key} has a non-string key {k!r}")
            out[k] = _plain(x, f"{key}.{k}")
        return out
    raise ValueError(f"scenario_to_dict: {key} holds a {type(v).__name__}, which a scenario file cannot store")


def _graph_to(g: Graph) -> dict:
    edges = g.edges
    weights = [float(g.adjacency[i, j]) for i, j in edges]
    out = {"n_nodes": g.n_nodes, "edges": [[i, j] for i, j in edges]}
    if any(w != 1.0 for w in weights):
        out["weights"] = weights
    return out


def scenario_to_dict(scenario: Scenario) -> dict:
    """The file-format mapping of ``scenario`` (every field explicit; plain Python types)."""
    if not isinstance(scenario, Scenario):
        raise TypeError(f"scenario_to_dict expects a Scenario, got {type(scenario).__name__}")
    sc = scenario
    d: dict = {"name": sc.name, "description": sc.description}
    if sc.mas_agents is not None:
        d["mas_agents"] = [{"A": a.tolist(), "B": b.tolist(), "C": c.tolist()} for a, b, c in sc.mas_agents]
    d["A"] = sc.A.tolist()
    d["channels"] = [b[:, 0].tolist() if b.shape[1] == 1 else b.tolist() for b in sc.channels]
    d["C"] = [c[0].tolist() if c.shape[0] == 1 else c.tolist() for c in sc.C]
    d["known"] = [list(k) for k in sc.known]
    d["graph"] = _graph_to(sc.graph)
    d["links"] = list(sc.links)
    d["x0"] = sc.x0.tolist()
    if sc.B_v.shape[1]:
        d["B_v"] = sc.B_v.tolist()
        d["v0"] = sc.v0.tolist()
        if sc.exosystem is not None:
            d["exosystem"] = sc.exosystem.tolist()
    d["controller"] = sc.controller
    for key in ("K", "P", "x_r0"):
        v = getattr(sc, key)
        if v is not None:
            d[key] = v.tolist()
    for key in ("reference", "prescribed_input"):
        v = getattr(sc, key)
        if v is not None:
            d[key] = v.to_dict()
    d["Q"] = sc.Q.tolist()
    d["R"] = sc.R.tolist()
    for key in ("gamma0", "gamma_s0", "phi", "phi_s", "sigma", "sigma_s", "beta0", "sigma_beta",
                "phi_beta", "epsilon", "mas_shift", "t_end", "dt"):
        d[key] = float(getattr(sc, key))
    if sc.x0_scale is not None:
        d["x0_scale"] = float(sc.x0_scale)
    if sc.metadata:
        d["metadata"] = sc.metadata
    return _plain(d, "scenario")


# ---------------------------------------------------------------------- files
def _format(path: str) -> str:
    ext = os.path.splitext(str(path))[1].lower()
    if ext in (".yaml", ".yml"):
        return "yaml"
    if ext == ".json":
        return "json"
    raise ValueError(f"{path}: unsupported scenario file extension {ext!r}; use .yaml, .yml or .json")


def load_scenario(path) -> Scenario:
    """Read a scenario file (``.yaml``/``.yml`` or ``.json``; format in the module docstring).

    Raises
    ------
    ScenarioFileError
        Malformed file, unknown key, or a value the :class:`Scenario` rejects
        (message: ``"<path>: key '<key>': <what is wrong>"``).
    FileNotFoundError
    """
    path = os.fspath(path)
    fmt = _format(path)
    if os.path.isdir(path):
        raise ScenarioFileError(path, None, "is a directory, not a scenario file")
    if os.path.exists(path) and os.path.getsize(path) > MAX_FILE_BYTES:
        raise ScenarioFileError(path, None, f"is larger than {MAX_FILE_BYTES} bytes; not a scenario file")
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except UnicodeDecodeError as exc:
        raise ScenarioFileError(path, None, f"is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:
        data = yaml.load(text, Loader=_StrictLoader) if fmt == "yaml" else json.loads(text, object_pairs_hook=_unique_pairs)
    except _DuplicateKeyError as exc:
        where = f" (line {exc.line})" if exc.line else ""
        raise ScenarioFileError(path, str(exc.key), f"is given twice in one mapping{where}; give each key once") from None
    except (yaml.YAMLError, json.JSONDecodeError) as exc:
        raise ScenarioFileError(path, None, f"cannot parse {fmt.upper()}: {exc}") from None
    except (RecursionError, OverflowError, ValueError) as exc:  # pathological nesting / numbers
        raise ScenarioFileError(path, None, f"cannot parse {fmt.upper()}: {type(exc).__name__}: {exc}") from None
    if data is None:
        raise ScenarioFileError(path, None, "file is empty")
    n = _expanded_size(data)
    if n > MAX_ELEMENTS:
        raise ScenarioFileError(path, None, f"expands to more than {MAX_ELEMENTS} values (YAML aliases?); "
                                            "a scenario file holds at most that many")
    return scenario_from_dict(data, source=path)


#: caps of what a scenario file may hold (a 2 KB YAML with nested aliases can expand to 1e7 values)
MAX_FILE_BYTES = 64 * 2**20
MAX_ELEMENTS = 2_000_000


def _expanded_size(obj, _memo=None) -> int:
    """Number of scalar values ``obj`` expands to when every alias is copied out (linear time:
    shared sub-objects, which YAML aliases create, are counted once per reference from a memo)."""
    memo = {} if _memo is None else _memo
    key = id(obj)
    if key in memo:
        return memo[key]
    if isinstance(obj, Mapping):
        n = sum(_expanded_size(v, memo) for v in obj.values()) + len(obj)
    elif isinstance(obj, (list, tuple)):
        n = sum(_expanded_size(v, memo) for v in obj)
    else:
        n = 1
    memo[key] = min(n, 10 * MAX_ELEMENTS)  # saturate: no huge integers
    return memo[key]


def save_scenario(scenario: Scenario, path) -> str:
    """Write ``scenario`` to ``path`` (format from the extension). Returns the path.

    The file round-trips exactly: ``load_scenario(path).equals(scenario)``.
    """
    path = os.fspath(path)
    fmt = _format(path)
    d = scenario_to_dict(scenario)
    with open(path, "w", encoding="utf-8") as fh:
        if fmt == "yaml":
            fh.write(f"# dobs-envs scenario '{scenario.name}' (format: dobs_envs/scenarios/io.py)\n")
            yaml.safe_dump(d, fh, sort_keys=False, default_flow_style=None, width=100, allow_unicode=True)
        else:
            json.dump(d, fh, indent=1)
            fh.write("\n")
    return path
