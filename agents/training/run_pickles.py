"""The pickles of a run directory, read without running code from them (issue 41).

A run directory is something people download and share; ``config.json`` cannot run code, and neither may
its pickles:

- ``vecnormalize.pkl`` (and a checkpoint's normaliser), ``replay_buffer.pkl``: unpickled by
  :class:`RestrictedUnpickler`, whose ``find_class`` admits only what these objects hold (listed by
  pickling real ones of the project's recipes, ``pickletools`` GLOBAL opcodes): SB3's ``VecNormalize`` /
  ``RunningMeanStd`` / ``ReplayBuffer``, gymnasium's ``Box``, numpy's array, dtype and scalar
  reconstruction and bit generators, ``torch.device`` and builtins containers. Anything else is refused
  with :class:`PickleRefused` (one line naming the file and the class) before it is looked up.
- ``model.zip``: SB3 stores the attributes JSON cannot hold as cloudpickle payloads (``":serialized:"``
  in its ``data`` entry) and unpickles those not given as ``custom_objects``. :func:`model_custom_objects`
  gives one for every payload: the recipe's objects rebuilt from ``config.json`` (policy class and
  ``policy_kwargs``, schedules, buffer classes, action noise), the plain data (spaces, last observations,
  episode buffers, ``train_freq``) restricted-unpickled as above, so SB3 unpickles nothing. A payload of
  any other entry is refused. Weights are read by SB3 with ``torch.load(weights_only=True)``.

- SBX (the jax backend of SAC / TD3 / CrossQ) keeps its networks inside the cloudpickled ``policy`` entry
  (flax ``TrainState`` objects, with functions and classes pickled by value). Those payloads are read by
  :class:`_OpaqueUnpickler`: numpy data and jax arrays (rebuilt from their numpy state) are real, anything
  else becomes an inert :class:`_Opaque` record of its arguments (nothing is imported, looked up or
  called); SBX builds a fresh policy from the rebuilt recipe objects and :func:`graft_sbx` copies the
  recorded arrays into it (parameters, target parameters, batch statistics, steps, optimizer states,
  the policy's PRNG keys), checking every array's shape against the fresh model's: the model equals SBX's
  own (unrestricted) load array for array.
"""
from __future__ import annotations

import base64
import io
import json
import pickle
import zipfile

import numpy as np

from .runs import RunDirError

__all__ = ["PickleRefused", "RestrictedUnpickler", "restricted_load", "load_vecnormalize", "load_replay_buffer",
           "model_custom_objects", "sbx_payloads", "graft_sbx", "REBUILT_ENTRIES", "DATA_ENTRIES", "SBX_WEIGHT_ENTRIES"]


class PickleRefused(RunDirError):
    """A run directory's pickle names a class that dobs-envs does not unpickle."""


_NUMPY = [(core, name) for core in ("numpy.core.multiarray", "numpy._core.multiarray")
          for name in ("_reconstruct", "scalar")] + [
    (numeric, "_frombuffer") for numeric in ("numpy.core.numeric", "numpy._core.numeric")] + [
    ("numpy", "ndarray"), ("numpy", "dtype"),
    ("numpy.random._pickle", "__bit_generator_ctor"), ("numpy.random._pickle", "__generator_ctor"),
    ("numpy.random._pickle", "__randomstate_ctor"),
    ("numpy.random._pcg64", "PCG64"), ("numpy.random.bit_generator", "SeedSequence"),
    ("numpy.random.bit_generator", "__pyx_unpickle_SeedSequence"), ("numpy.random._generator", "Generator"),
]
_BUILTINS = [("builtins", n) for n in ("dict", "list", "tuple", "set", "frozenset", "bytearray", "slice", "complex")] + [
    ("collections", "OrderedDict"), ("collections", "deque"), ("_collections", "deque")]
#: what an SB3 ``VecNormalize`` pickles (its ``__getstate__`` drops ``venv``): itself, its two
#: ``RunningMeanStd``, the spaces (gymnasium ``Box``, with the space's numpy generator), numpy data
VECNORMALIZE_CLASSES = frozenset(_NUMPY + _BUILTINS + [
    ("stable_baselines3.common.vec_env.vec_normalize", "VecNormalize"),
    ("stable_baselines3.common.running_mean_std", "RunningMeanStd"),
    ("gymnasium.spaces.box", "Box"),
])
#: what an SB3 ``ReplayBuffer`` pickles (``save_replay_buffer``): the buffer, its spaces and device, numpy data
REPLAY_BUFFER_CLASSES = frozenset(_NUMPY + _BUILTINS + [
    ("stable_baselines3.common.buffers", "ReplayBuffer"),
    ("gymnasium.spaces.box", "Box"),
    ("torch", "device"),
])
#: the plain-data payloads of ``model.zip`` (spaces, arrays, deques of episode infos, ``train_freq``)
MODEL_DATA_CLASSES = frozenset(_NUMPY + _BUILTINS + [
    ("gymnasium.spaces.box", "Box"),
    ("stable_baselines3.common.type_aliases", "TrainFreq"),
    ("stable_baselines3.common.type_aliases", "TrainFrequencyUnit"),
])


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler whose ``find_class`` admits only ``allowed`` ``(module, name)`` pairs; ``what`` names the
    file in the :class:`PickleRefused` message. No persistent ids."""

    def __init__(self, fh, allowed: frozenset, what: str):
        super().__init__(fh)
        self.allowed, self.what = allowed, what

    def find_class(self, module, name):
        if (module, name) not in self.allowed:
            raise PickleRefused(f"{self.what} holds {module}.{name}, which dobs-envs does not unpickle "
                                f"(a run directory's pickles may hold only the run's own data)")
        return super().find_class(module, name)

    def persistent_load(self, pid):
        raise PickleRefused(f"{self.what} holds a persistent id, which dobs-envs does not unpickle")


def restricted_load(data: bytes, allowed: frozenset, what: str):
    """``pickle.loads(data)`` through :class:`RestrictedUnpickler`."""
    return RestrictedUnpickler(io.BytesIO(data), allowed, what).load()


def _read(path: str) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as exc:
        raise RunDirError(f"{path} cannot be read ({type(exc).__name__}: {exc.strerror})") from None


def _restricted_file(path: str, allowed: frozenset, cls_path: tuple[str, str], what: str):
    """The object pickled in ``path``: refused classes raise :class:`PickleRefused`; a damaged file, or an
    object of another class than ``cls_path``, :class:`RunDirError`."""
    data = _read(path)
    try:
        obj = restricted_load(data, allowed, path)
    except PickleRefused:
        raise
    except Exception as exc:  # noqa: BLE001 -- a truncated/garbage pickle fails anywhere in pickle
        raise RunDirError(f"{path} cannot be loaded (corrupt or truncated file? {type(exc).__name__}: "
                          f"{(str(exc).splitlines() or [''])[0][:200]})") from None
    import importlib

    cls = getattr(importlib.import_module(cls_path[0]), cls_path[1])
    if not isinstance(obj, cls):
        raise RunDirError(f"{path} holds a {type(obj).__name__}, not the run's {what}")
    return obj


def load_vecnormalize(path: str, venv=None):
    """The ``VecNormalize`` saved in ``path`` (``VecNormalize.load`` without unpickling anything else); with
    ``venv``, wrapped around it (as SB3's ``load``), else without an env (only its statistics are used)."""
    vn = _restricted_file(path, VECNORMALIZE_CLASSES,
                          ("stable_baselines3.common.vec_env.vec_normalize", "VecNormalize"), "VecNormalize")
    if venv is not None:
        vn.set_venv(venv)
    return vn


def load_replay_buffer(model, path: str) -> None:
    """``model.load_replay_buffer(path)`` without unpickling anything but an SB3 ``ReplayBuffer``."""
    buf = _restricted_file(path, REPLAY_BUFFER_CLASSES, ("stable_baselines3.common.buffers", "ReplayBuffer"),
                           "replay buffer")
    if not hasattr(buf, "handle_timeout_termination"):  # as SB3's load_replay_buffer (buffers of SB3 < 2.1)
        import numpy as np

        buf.handle_timeout_termination = False
        buf.timeouts = np.zeros_like(buf.dones)
    if type(model).__module__.startswith("sbx."):  # as SBX's load_replay_buffer: numpy conversions on the cpu
        from stable_baselines3.common.utils import get_device

        buf.device = get_device("cpu")
    model.replay_buffer = buf


#: ``model.zip`` entries rebuilt from the run's recipe (``config.json``), never read from the file
REBUILT_ENTRIES = ("policy_class", "policy_kwargs", "learning_rate", "lr_schedule", "clip_range", "clip_range_vf",
                   "rollout_buffer_class", "rollout_buffer_kwargs", "replay_buffer_class", "replay_buffer_kwargs",
                   "action_noise")
#: ``model.zip`` entries of plain data, read with :data:`MODEL_DATA_CLASSES` only
DATA_ENTRIES = ("observation_space", "action_space", "_last_obs", "_last_episode_starts", "_last_original_obs",
                "ep_info_buffer", "ep_success_buffer", "train_freq", "target_entropy")
#: SBX's cloudpickled networks and PRNG key: rebuilt fresh by SBX, their arrays grafted (:func:`graft_sbx`)
SBX_WEIGHT_ENTRIES = ("policy", "actor", "qf", "ent_coef", "ent_coef_state", "key")


class _Opaque:
    """What :class:`_OpaqueUnpickler` makes of anything not admitted: a record of the arguments it was
    called / built with (``_args``, ``_state``, ``_items``); nothing it names is imported or run."""

    _name = "?"

    def __new__(cls, *args, **kwargs):  # NEWOBJ (e.g. a namedtuple: its fields) calls only this
        obj = object.__new__(cls if isinstance(cls, type) else type(cls))  # cls may be an opaque "class"
        obj._args, obj._state, obj._items = args, None, []
        return obj

    def __init__(self, *args, **kwargs):
        self._args = args

    def __call__(self, *args, **kwargs):
        return _Opaque(*args)

    def __setstate__(self, state):
        self._state = state

    def __setitem__(self, key, value):
        self._items.append((key, value))

    def append(self, value):
        self._items.append(value)

    def extend(self, values):
        self._items.extend(values)


def _jax_array(fun, args, arr_state, aval_state):
    """``jax._src.array._reconstruct_array`` for numpy-backed arrays only (the array stays numpy)."""
    if not isinstance(fun, type(pickle.loads)) or getattr(fun, "__name__", "") != "_reconstruct":
        raise pickle.UnpicklingError("a jax array not rebuilt from numpy")
    arr = fun(*args)
    arr.__setstate__(arr_state)
    return arr


class _OpaqueUnpickler(pickle.Unpickler):
    """:data:`MODEL_DATA_CLASSES` for real, jax arrays as numpy arrays, any other global an :class:`_Opaque`
    subclass named after it (never imported)."""

    def find_class(self, module, name):
        if (module, name) in MODEL_DATA_CLASSES:
            return super().find_class(module, name)
        if (module, name) == ("jax._src.array", "_reconstruct_array"):
            return _jax_array
        return type("Opaque", (_Opaque,), {"_name": f"{module}.{name}"})

    def persistent_load(self, pid):
        raise pickle.UnpicklingError("persistent id")


def _plain(o):
    """A recorded pytree as jax flattens it: an opaque ``FrozenDict`` its dict, an opaque namedtuple (optax
    states) the tuple of its fields; dicts, lists, tuples recursively; arrays and scalars as they are."""
    if isinstance(o, _Opaque):
        return tuple(_plain(a) for a in o._args) if not o._name.endswith("FrozenDict") else _plain(o._args[0])
    if isinstance(o, dict):
        return {k: _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return type(o)(_plain(v) for v in o)
    return o


def _leaves(o) -> list:
    """The leaves of :func:`_plain` ``o`` in jax's order (dict keys sorted, None no leaf)."""
    if o is None:
        return []
    if isinstance(o, dict):
        return [x for k in sorted(o) for x in _leaves(o[k])]
    if isinstance(o, (list, tuple)):
        return [x for v in o for x in _leaves(v)]
    return [o]


def sbx_payloads(path: str) -> dict:
    """The recorded SBX entries of ``path``'s ``data``: ``{entry: record}`` (:class:`_OpaqueUnpickler`)."""
    data = model_data(path)
    out = {}
    for key in SBX_WEIGHT_ENTRIES:
        val = data.get(key)
        if isinstance(val, dict) and ":serialized:" in val:
            try:
                out[key] = _OpaqueUnpickler(io.BytesIO(base64.b64decode(val[":serialized:"].encode()))).load()
            except Exception as exc:  # noqa: BLE001 -- a damaged payload fails anywhere in pickle
                raise RunDirError(f"{path} cannot be loaded (corrupt file? entry {key!r}: {type(exc).__name__})") \
                    from None
    return out


def _graft(path: str, what: str, fresh, recorded, *, optimizer: bool):
    """``fresh`` (a flax train state or a key) with the arrays of ``recorded`` (its record) in place of its own."""
    import jax
    import jax.numpy as jnp

    def arrays(name, fresh_tree, rec_tree):
        leaves, treedef = jax.tree_util.tree_flatten(fresh_tree)
        got = _leaves(_plain(rec_tree))
        shapes = [np.shape(x) for x in leaves]
        if len(got) != len(leaves) or any(np.shape(g) != sh for g, sh in zip(got, shapes)):
            raise RunDirError(f"{path}: the saved {what}.{name} does not fit the run's recipe ({len(got)} arrays, "
                              f"the model has {len(leaves)})")
        return jax.tree_util.tree_unflatten(treedef, [jnp.asarray(g, dtype=jnp.asarray(x).dtype)
                                                      for g, x in zip(got, leaves)])

    if not hasattr(fresh, "replace"):  # a PRNG key
        return arrays("key", fresh, recorded)
    state = recorded._state if isinstance(recorded, _Opaque) else None
    if not isinstance(state, dict):
        raise RunDirError(f"{path}: the saved {what} is not a train state")
    fields = [f for f in ("params", "target_params", "batch_stats", "target_batch_stats", "step")
              if f in state and hasattr(fresh, f)]
    if optimizer and hasattr(fresh, "opt_state"):
        fields.append("opt_state")
    return fresh.replace(**{f: arrays(f, getattr(fresh, f), state[f]) for f in fields})


def graft_sbx(model, path: str, payloads: dict, *, optimizer: bool) -> None:
    """Copy the arrays recorded in ``payloads`` (:func:`sbx_payloads`) into the fresh SBX ``model``: every train
    state of its policy (``*_state``) and of the model (``ent_coef_state``) and the policy's PRNG keys; ``optimizer``:
    the optimizer states too (training continues), else only what acting needs."""
    pol = payloads.get("policy")
    if not isinstance(pol, _Opaque) or not isinstance(pol._state, dict):
        raise RunDirError(f"{path}: its 'policy' entry is not an SBX policy")
    for name, rec in pol._state.items():
        if (name.endswith("_state") or name in ("key", "noise_key")) and hasattr(model.policy, name):
            setattr(model.policy, name, _graft(path, f"policy.{name}", getattr(model.policy, name), rec,
                                               optimizer=optimizer))
    if "ent_coef_state" in payloads and getattr(model, "ent_coef_state", None) is not None:
        model.ent_coef_state = _graft(path, "ent_coef_state", model.ent_coef_state, payloads["ent_coef_state"],
                                      optimizer=optimizer)
    # the model's own key is PRNGKey(seed) after SBX's load too (set_random_seed); gSDE noise is resampled
    # from the restored policy key, as SB3's load does after unpickling
    if getattr(model, "seed", None) is not None and getattr(model, "key", None) is not None:
        import jax

        model.key = jax.random.PRNGKey(model.seed)  # building the fresh policy drew from it
    if getattr(model, "use_sde", False):
        model.policy.reset_noise()


def model_data(path: str) -> dict:
    """The ``data`` JSON of the SB3 model ``path`` (a zip), unparsed payloads included."""
    try:
        with zipfile.ZipFile(path) as zf:
            return json.loads(zf.read("data"))
    except (OSError, KeyError, zipfile.BadZipFile, ValueError) as exc:
        raise RunDirError(f"{path} cannot be loaded (corrupt or truncated file? {type(exc).__name__}: "
                          f"{(str(exc).splitlines() or [''])[0][:200]})") from None


def _policy_kwargs(path: str, saved: dict, rebuilt: dict | None) -> dict:
    """The run's ``policy_kwargs``: the recipe's (``rebuilt``) plus the plain JSON values the algorithm added
    (e.g. SB3's ``use_sde``), read from the readable side of the saved entry (its ``repr`` of each key); a key
    the recipe does not give whose saved value is an object (``"<class ...>"``) is refused."""
    out = dict(rebuilt or {})
    for k, v in saved.items():
        if k.startswith(":") or k in out:
            continue
        if isinstance(v, str) and v.startswith("<"):
            raise PickleRefused(f"{path} holds policy_kwargs[{k!r}] = {v[:80]}, which the run's recipe does not "
                                f"give and dobs-envs does not unpickle")
        out[k] = v
    return out


def model_custom_objects(path: str, rebuilt: dict, *, library: str) -> dict:
    """``custom_objects`` for SB3's ``load(path)`` covering every cloudpickle payload of ``path``'s ``data``:
    :data:`REBUILT_ENTRIES` from ``rebuilt`` (the recipe's objects; an entry missing there is None, SB3's
    default), :data:`DATA_ENTRIES` restricted-unpickled; :data:`SBX_WEIGHT_ENTRIES` None when ``library`` is
    ``sbx-rl`` (SBX builds them fresh, :func:`graft_sbx` fills them). Any other payload raises :class:`PickleRefused` naming the file and entry."""
    data = model_data(path)
    if not isinstance(data, dict):
        raise RunDirError(f"{path} cannot be loaded (corrupt file? its data is not a JSON object)")
    custom = {}
    for key, val in data.items():
        if not (isinstance(val, dict) and ":serialized:" in val):
            continue
        if key == "policy_kwargs":
            custom[key] = _policy_kwargs(path, val, rebuilt.get(key))
        elif key in REBUILT_ENTRIES:
            custom[key] = rebuilt.get(key)
        elif key in DATA_ENTRIES:
            try:
                payload = base64.b64decode(val[":serialized:"].encode())
            except (ValueError, AttributeError):
                raise RunDirError(f"{path} cannot be loaded (corrupt file? entry {key!r} is not base64)") from None
            try:
                custom[key] = restricted_load(payload, MODEL_DATA_CLASSES, f"{path} (entry {key!r})")
            except PickleRefused:
                raise
            except Exception as exc:  # noqa: BLE001
                raise RunDirError(f"{path} cannot be loaded (corrupt file? entry {key!r}: {type(exc).__name__})") \
                    from None
        elif key in SBX_WEIGHT_ENTRIES and library == "sbx-rl":
            custom[key] = None  # SBX builds them fresh; graft_sbx copies the recorded arrays in
        else:
            raise PickleRefused(f"{path} holds a cloudpickled {key!r} ({val.get(':type:', 'object')}), which "
                                f"dobs-envs does not unpickle (a run directory's model may hold only the run's "
                                f"own data)")
    return custom
