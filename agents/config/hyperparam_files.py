"""The hyperparameter files, rl-zoo3-style YAML (``agents/config/hyperparams/<algo>.yaml``), read without
evaluating anything; environment names are :mod:`agents.config.envs`'s.

One YAML file per algorithm in rl-zoo3's format, so that the same file serves
``python -m rl_zoo3.train --algo ppo --env dobs_envs/Tracking-v0 --gym-packages dobs_envs
-conf agents/config/hyperparams/ppo.yaml`` and :func:`load_hyperparams`.

Sections read by rl-zoo3 (it takes one: the Gymnasium id's, else ``default``):
``default`` and one per Gymnasium id (``dobs_envs/Tracking-v0``). Every such section is
complete (it holds every key of ``default``; YAML's ``<<: *default`` copies them) and holds
only keys rl-zoo3 understands:

- ``n_envs``: environment copies (multi-agent: copies; each has one slot per agent)
- ``n_timesteps``: default training budget
- ``policy``: SB3 policy name (``MlpPolicy``; dotted names, which rl-zoo3 imports, are refused)
- ``normalize``: ``false`` or a mapping of ``VecNormalize`` arguments
  (``norm_obs``, ``norm_reward``, ...; ``gamma`` defaults to the algorithm's)
- ``env_kwargs``: training-only environment options of the recipe (e.g. a tighter
  ``state_bound``); ``dobs-envs evaluate``/``benchmark`` always evaluate on the task's own
  environment. rl-zoo3 does not: its evaluation env during training and ``rl_zoo3.enjoy`` use
  these ``env_kwargs`` unless given ``--eval-env-kwargs state_bound:1000.0`` (train) and
  ``--env-kwargs state_bound:1000.0`` (enjoy), the task's own bound (README, "RL recipes")
- ``env_wrapper``: ``[{gymnasium.wrappers.RescaleAction: {min_action: -1, max_action: 1}}]``
  (the agent acts in ``[-1, 1]``, mapped onto the env's bounds; the only wrapper accepted)
- ``policy_kwargs``: rl-zoo3's string ``"dict(net_arch=[64, 64], activation_fn=nn.Tanh)"``
- ``noise_type`` (``normal``, ``ornstein-uhlenbeck``) and ``noise_std``: off-policy action noise
  (:func:`agents.training.algos.make_action_noise`; ``pink`` too outside the sections rl-zoo3 reads)
- ``lin_<x>`` schedules for ``learning_rate`` / ``clip_range``; the algorithm's constructor arguments

Sections read by ``agents/`` only: ``<env>`` (settings rl-zoo3 cannot read, such as
``noise_type: pink``, for every recipe of the env), ``default-ma``, ``<env>-ma`` (parameter sharing),
``default-<variant>``, ``<env>-<variant>``, ``<env>-ma-<variant>`` (hybrids, ``variant`` in
:data:`VARIANTS`), ``<env>`` being the short name (``tracking``). They may also hold

- ``agent_id``: (multi-agent) append a one-hot agent id to observations
- ``residual_scale`` (``residual``): residual authority, fraction of the action bound
- ``bc`` (``bc``): ``{episodes, noise, epochs, lr}`` of the warm start

Lookup (each section replaces the keys it sets, as YAML's merge key does): ``default``,
``default-ma`` (multi-agent), the Gymnasium id's section, ``<env>``, ``<env>-ma`` (multi-agent),
then ``default-<variant>``, ``<env>-<variant>``, ``<env>-ma-<variant>`` (multi-agent), then for the jitted
trainer (``trainer="jax"``) ``default-jax`` and ``<env>-jax`` (centralised) or ``<env>-ma-jax`` (multi-agent). A
centralised, pure-RL recipe is therefore the section rl-zoo3 reads, updated by the env's ``<env>``
section where the file has one (rl-zoo3 trains without those settings).

Nothing named in a file is imported or evaluated here: ``policy_kwargs`` / ``normalize``
strings are parsed as literals, ``dict(...)`` and the activation names of
:data:`ACTIVATIONS` (``nn.Tanh``), and anything else is refused with an error naming the key.
:func:`load_hyperparams` returns the recipe in this module's vocabulary:
``policy_kwargs`` a mapping with ``activation_fn`` a name (``tanh``), ``normalize`` ``False``
or a mapping, ``normalize_actions`` a bool (from ``env_wrapper``).
"""
from __future__ import annotations

import ast
import copy
import os

import yaml

from .envs import ENVS, env_key, gym_id

__all__ = ["ALGOS", "MULTI_AGENT_ALGOS", "OFF_POLICY_ALGOS", "NOISE_TYPES", "HYPERPARAMS_DIR", "load_hyperparams",
           "read_hyperparams_file", "parse_kwargs_string", "HyperparamsError", "ACTIVATIONS", "VARIANTS",
           "TRAINERS"]

#: the hyperparameter files, ``<algo>.yaml`` (package data)
HYPERPARAMS_DIR = os.path.join(os.path.dirname(__file__), "hyperparams")

#: the algorithms (one hyperparameter file each)
ALGOS = ("ppo", "sac", "td3", "crossq")
MULTI_AGENT_ALGOS = ("ppo", "sac")
#: the off-policy algorithms (replay buffer; action noise ``noise_type`` / ``noise_std``)
OFF_POLICY_ALGOS = ("sac", "td3", "crossq")


#: hybrid variants with their own sections (``default-<variant>``; :mod:`agents.training.hybrid`)
VARIANTS = ("residual", "bc")
#: trainers with their own sections, read after all others (``default-jax``, then ``<env>-jax`` or, multi-agent,
#: ``<env>-ma-jax``: what
#: the jitted trainer, :mod:`agents.training.jax`, trains differently, e.g. its tuned recipe; ``sb3`` has none)
TRAINERS = ("sb3", "jax")

#: activation names accepted in ``policy_kwargs`` -> ``torch.nn`` class name
ACTIVATIONS = {"tanh": "Tanh", "relu": "ReLU", "elu": "ELU", "leaky_relu": "LeakyReLU", "gelu": "GELU"}
_ACTIVATION_BY_CLASS = {cls: name for name, cls in ACTIVATIONS.items()}
#: module prefixes under which rl-zoo3's ``policy_kwargs`` strings name the activations
_NN_PREFIXES = ("nn", "th.nn", "torch.nn")

#: keys only agents/ understands: refused in the sections rl-zoo3 reads (it would pass them to the algorithm)
AGENTS_ONLY_KEYS = ("agent_id", "residual_scale", "bc", "normalize_actions")
#: rl-zoo3 keys that import code, or that agents/ does not implement
_UNSUPPORTED_KEYS = ("frame_stack", "vec_env_wrapper", "callback", "monitor_kwargs", "replay_buffer_class",
                     "replay_buffer_kwargs")
#: the one wrapper accepted in ``env_wrapper``: the agent acts in [-1, 1]
RESCALE_WRAPPER = "gymnasium.wrappers.RescaleAction"
_RESCALE_ARGS = {"min_action": -1, "max_action": 1}
#: exploration noise types (``noise_type``; :func:`agents.training.algos.make_action_noise`)
NOISE_TYPES = ("normal", "ornstein-uhlenbeck", "pink")
#: the noise types rl-zoo3 understands (the only ones accepted in the sections it reads)
ZOO_NOISE_TYPES = ("normal", "ornstein-uhlenbeck")
#: longest ``policy_kwargs`` / ``normalize`` string parsed
_MAX_KWARGS_STRING = 10_000


class HyperparamsError(ValueError):
    """A hyperparameter file (or override) that agents/ cannot read; the message names the file,
    the section and the key."""


def _short(text: str, limit: int = 120) -> str:
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} characters)"


def _literal(node: ast.AST, where: str, key: str, text: str):
    """The value of one node of a ``policy_kwargs`` / ``normalize`` string: literals,
    lists/tuples/dicts of them, ``dict(k=v, ...)``, ``-x`` and the allowed activations."""
    if isinstance(node, ast.Constant) and (node.value is None or isinstance(node.value, (bool, int, float, str))):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)) \
            and isinstance(node.operand, ast.Constant) and type(node.operand.value) in (int, float):
        return -node.operand.value if isinstance(node.op, ast.USub) else node.operand.value
    if isinstance(node, (ast.List, ast.Tuple)):
        vals = [_literal(e, where, key, text) for e in node.elts]
        return vals if isinstance(node, ast.List) else tuple(vals)
    if isinstance(node, ast.Dict):
        if any(k is None or not isinstance(k, ast.Constant) or not isinstance(k.value, str) for k in node.keys):
            raise HyperparamsError(f"{where}: {key} = {_short(text)}: dictionary keys must be strings")
        return {k.value: _literal(v, where, key, text) for k, v in zip(node.keys, node.values)}
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" \
            and not node.args and all(kw.arg is not None for kw in node.keywords):
        return {kw.arg: _literal(kw.value, where, key, text) for kw in node.keywords}
    if isinstance(node, ast.Attribute):
        dotted = ast.unparse(node)
        prefix, _, cls = dotted.rpartition(".")
        if prefix in _NN_PREFIXES and cls in _ACTIVATION_BY_CLASS:
            return _ACTIVATION_BY_CLASS[cls]
    allowed = ", ".join(f"nn.{c}" for c in _ACTIVATION_BY_CLASS)
    raise HyperparamsError(
        f"{where}: {key} = {_short(text)}: {_short(ast.unparse(node), 80)} is not accepted; agents/ never evaluates code from a "
        f"hyperparameter file: use literals, lists, dict(...) and the activations {allowed}")


def parse_kwargs_string(text: str, where: str, key: str) -> dict:
    """rl-zoo3's ``"dict(a=1, activation_fn=nn.Tanh)"`` (or ``"{'a': 1}"``) as a mapping, parsed
    without evaluating anything (activations become names, ``nn.Tanh`` -> ``"tanh"``)."""
    if len(text) > _MAX_KWARGS_STRING:
        raise HyperparamsError(f"{where}: {key} is a string of {len(text)} characters (at most {_MAX_KWARGS_STRING})")
    try:
        tree = ast.parse(text.strip(), mode="eval")
        value = _literal(tree.body, where, key, text)
    except SyntaxError as exc:
        raise HyperparamsError(f"{where}: {key} = {_short(text)} is not a Python expression ({exc.msg})") from None
    except (RecursionError, ValueError) as exc:  # nesting too deep, NUL bytes
        if isinstance(exc, HyperparamsError):
            raise
        raise HyperparamsError(f"{where}: {key} = {_short(text)} cannot be parsed ({type(exc).__name__})") from None
    if not isinstance(value, dict):
        raise HyperparamsError(f"{where}: {key} = {_short(text)} must be dict(...) or a {{...}} mapping")
    return value


def _canonical(section: dict, where: str, *, zoo: bool) -> dict:
    """One section (or overrides) in this module's vocabulary; ``zoo``: a section rl-zoo3 may read."""
    if not isinstance(section, dict):
        raise HyperparamsError(f"{where} must be a mapping of hyperparameters, got {type(section).__name__}")
    out = {}
    for key, value in section.items():
        if not isinstance(key, str):
            raise HyperparamsError(f"{where}: key {key!r} must be a string")
        if key in _UNSUPPORTED_KEYS:
            raise HyperparamsError(f"{where}: key {key!r} is an rl-zoo3 option that agents/ does not implement")
        if zoo and key in AGENTS_ONLY_KEYS:
            raise HyperparamsError(
                f"{where}: key {key!r} is read by agents/ only, but rl-zoo3 reads this section and would pass it "
                f"to the algorithm; put it in an agents-only section (default-ma, <env>-ma, default-<variant>, ...)")
        if key == "policy":
            if not isinstance(value, str) or "." in value:
                raise HyperparamsError(f"{where}: policy must be an SB3 policy name such as 'MlpPolicy', got "
                                       f"{value!r} (dotted names are imported by rl-zoo3 and refused here)")
        elif key == "policy_kwargs":
            if isinstance(value, str):
                value = parse_kwargs_string(value, where, key)
            elif isinstance(value, dict):
                if zoo and "activation_fn" in value:
                    raise HyperparamsError(
                        f"{where}: policy_kwargs with activation_fn must be rl-zoo3's string form "
                        f"\"dict(..., activation_fn=nn.Tanh)\" (rl-zoo3 passes a mapping unchanged to SB3)")
                value = copy.deepcopy(value)
            elif value is not None:
                raise HyperparamsError(f"{where}: policy_kwargs must be a \"dict(...)\" string or a mapping, "
                                       f"got {value!r}")
            act = (value or {}).get("activation_fn")
            if act is not None and (not isinstance(act, str) or act.lower() not in ACTIVATIONS):
                raise HyperparamsError(f"{where}: policy_kwargs activation_fn {act!r} is not one of "
                                       f"{sorted(ACTIVATIONS)} (or nn.{', nn.'.join(_ACTIVATION_BY_CLASS)})")
            if act is not None:
                value["activation_fn"] = act.lower()
        elif key == "normalize":
            if isinstance(value, str):
                value = parse_kwargs_string(value, where, key)
            if not isinstance(value, (bool, dict)):
                raise HyperparamsError(f"{where}: normalize must be true/false or a mapping of VecNormalize "
                                       f"arguments, got {value!r}")
            value = copy.deepcopy(value) if value else False
        elif key == "env_kwargs":
            if not isinstance(value, dict):
                raise HyperparamsError(f"{where}: env_kwargs must be a mapping of environment options, got {value!r}")
            value = copy.deepcopy(value)
        elif key == "env_wrapper":
            out["normalize_actions"] = _rescale_wrapper(value, where)
            continue
        elif key == "noise_type":
            if value is not None and value not in NOISE_TYPES:
                raise HyperparamsError(f"{where}: noise_type must be one of {NOISE_TYPES} (or null: no action "
                                       f"noise), got {value!r}")
            if zoo and value is not None and value not in ZOO_NOISE_TYPES:
                raise HyperparamsError(
                    f"{where}: noise_type {value!r} is not an rl-zoo3 noise type ({', '.join(ZOO_NOISE_TYPES)}), "
                    f"but rl-zoo3 reads this section; use it in --hyperparams overrides or an agents-only section")
        elif key == "noise_std":
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
                raise HyperparamsError(f"{where}: noise_std must be a number >= 0, got {value!r}")
        out[key] = value
    return out


def _rescale_wrapper(value, where: str) -> bool:
    """``env_wrapper`` -> whether the agent acts in [-1, 1]; only :data:`RESCALE_WRAPPER` is accepted."""
    entries = [] if value is None else value if isinstance(value, list) else [value]
    for entry in entries:
        name, kwargs = (next(iter(entry.items())) if isinstance(entry, dict) and len(entry) == 1 else (entry, None))
        if name != RESCALE_WRAPPER or kwargs != _RESCALE_ARGS or len(entries) != 1:
            raise HyperparamsError(
                f"{where}: env_wrapper {value!r} is not accepted; agents/ imports no wrapper named in a file and "
                f"understands only [{{{RESCALE_WRAPPER}: {{min_action: -1, max_action: 1}}}}]")
    return bool(entries)


def _is_agents_only(section: str) -> bool:
    return (section in ENVS or section.endswith("-ma")
            or any(section.endswith(f"-{v}") for v in VARIANTS + TRAINERS[1:]))


#: parsed files: (real path, modification time in ns, size) -> the validated sections. PyYAML's parser is
#: pure Python (~60 ms for ppo.yaml): the benchmark resolved a recipe per planned run, 144 parses for
#: the quick table (12 % of the time its archive test takes to recompute it).
_PARSED: dict[tuple, dict[str, dict]] = {}


def read_hyperparams_file(path: str) -> dict[str, dict]:
    """Every section of the hyperparameter file ``path``, validated and in this module's
    vocabulary (see the module doc); raises :class:`HyperparamsError` naming the section and key.
    A file is parsed again when its modification time or size changes; each call returns a new copy."""
    try:
        st = os.stat(path)
        key = (os.path.realpath(path), st.st_mtime_ns, st.st_size)
    except OSError:
        key = None  # open() below says what is wrong
    if key in _PARSED:
        return copy.deepcopy(_PARSED[key])
    out = _read_hyperparams_file(path)
    if key is not None:
        _PARSED[key] = copy.deepcopy(out)
    return out


def _read_hyperparams_file(path: str) -> dict[str, dict]:
    try:
        with open(path) as fh:
            table = yaml.safe_load(fh) or {}
    except yaml.YAMLError as exc:
        raise HyperparamsError(f"{path} is not valid YAML: {exc}") from None
    if not isinstance(table, dict):
        raise HyperparamsError(f"{path} must map section names to hyperparameters, got {type(table).__name__}")
    default = table.get("default") or {}
    required = set(default) | {"n_timesteps"}
    out = {}
    for name, section in table.items():
        where = f"{path}, section {name!r}"
        zoo = not _is_agents_only(str(name))
        if zoo and isinstance(section, dict) and (required - set(section)):
            raise HyperparamsError(
                f"{where} lacks {sorted(required - set(section))}: rl-zoo3 reads this section alone, so it must be "
                f"complete (start it with `<<: *default`)")
        out[name] = _canonical(section, where, zoo=zoo)
    return out


def _hyperparams_path(algo: str) -> str:
    path = os.path.join(HYPERPARAMS_DIR, f"{algo}.yaml")
    if not os.path.exists(path):
        raise ValueError(f"no hyperparameter file for algorithm {algo!r} ({path}); algorithms: {ALGOS}")
    return path


def _merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in (over or {}).items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def load_hyperparams(algo: str, env: str, *, multi_agent: bool = False, overrides: dict | None = None,
                     variant: str | None = None, trainer: str = "sb3") -> dict:
    """Hyperparameters of ``algo`` on ``env`` (see the module doc for the lookup).

    File sections replace the keys they set (as rl-zoo3 and YAML's merge key do);
    ``overrides`` (this module's vocabulary, or rl-zoo3's strings) are merged into nested
    mappings (``{"policy_kwargs": {"net_arch": [8]}}`` keeps the activation).
    """
    algo = algo.lower()
    table = read_hyperparams_file(_hyperparams_path(algo))
    name = env_key(env) if isinstance(env, str) else "default"
    keys = ["default"] + (["default-ma"] if multi_agent else []) + [gym_id(name)] + ([name] if name in ENVS else [])
    keys += [f"{name}-ma"] if multi_agent else []
    if variant:
        keys += [f"default-{variant}", f"{name}-{variant}"] + ([f"{name}-ma-{variant}"] if multi_agent else [])
    if trainer not in TRAINERS:
        raise ValueError(f"trainer must be one of {TRAINERS}, got {trainer!r}")
    if trainer != "sb3":
        # the centralised recipe's section is not the shared one's: <env>-jax or <env>-ma-jax, not both
        keys += [f"default-{trainer}", f"{name}-ma-{trainer}" if multi_agent else f"{name}-{trainer}"]
    hp: dict = {}
    for k in dict.fromkeys(keys):  # "default" once even when env is "default"
        hp.update(copy.deepcopy(table.get(k, {})))
    return _merge(hp, _canonical(overrides or {}, "hyperparameter overrides (--hyperparams)", zoo=False))
