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

Limitation: SBX (the jax backend of SAC / TD3 / CrossQ) keeps its networks' weights inside the cloudpickled
``policy`` entry itself (with flax ``TrainState`` objects holding code); :data:`SBX_WEIGHT_ENTRIES` are
still unpickled for runs whose ``config.json`` records ``library`` ``sbx-rl``.
"""
from __future__ import annotations

import base64
import io
import json
import pickle
import zipfile

from .runs import RunDirError

__all__ = ["PickleRefused", "RestrictedUnpickler", "restricted_load", "load_vecnormalize", "load_replay_buffer",
           "model_custom_objects", "REBUILT_ENTRIES", "DATA_ENTRIES", "SBX_WEIGHT_ENTRIES"]


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
    model.replay_buffer = buf


#: ``model.zip`` entries rebuilt from the run's recipe (``config.json``), never read from the file
REBUILT_ENTRIES = ("policy_class", "policy_kwargs", "learning_rate", "lr_schedule", "clip_range", "clip_range_vf",
                   "rollout_buffer_class", "rollout_buffer_kwargs", "replay_buffer_class", "replay_buffer_kwargs",
                   "action_noise")
#: ``model.zip`` entries of plain data, read with :data:`MODEL_DATA_CLASSES` only
DATA_ENTRIES = ("observation_space", "action_space", "_last_obs", "_last_episode_starts", "_last_original_obs",
                "ep_info_buffer", "ep_success_buffer", "train_freq", "target_entropy")
#: SBX's cloudpickled networks (weights inside): see the module's limitation
SBX_WEIGHT_ENTRIES = ("policy", "actor", "qf", "ent_coef", "ent_coef_state", "key")


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
    default), :data:`DATA_ENTRIES` restricted-unpickled; :data:`SBX_WEIGHT_ENTRIES` left to SBX when
    ``library`` is ``sbx-rl``. Any other payload raises :class:`PickleRefused` naming the file and entry."""
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
            continue
        else:
            raise PickleRefused(f"{path} holds a cloudpickled {key!r} ({val.get(':type:', 'object')}), which "
                                f"dobs-envs does not unpickle (a run directory's model may hold only the run's "
                                f"own data)")
    return custom
