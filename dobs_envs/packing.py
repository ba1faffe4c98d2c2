"""Named bundles of kernel arguments: one declaration, from which the packed buffers and the
unpacking (in Python and in compiled code) are derived.

A *bundle* is a :class:`typing.NamedTuple` class whose annotations declare its fields::

    class Example(NamedTuple):
        A: f64("n n")      # float64 array of shape (n, n); n: a size symbol
        idx: i64("N 3")    # int64 array (3: a literal size, checked)
        on: b1("N")        # bool array (0/1 int64 in compiled code)
        dt: f64()          # float scalar
        k: i64()           # int scalar
        flag: b1()         # bool scalar
        rows: Other        # a nested bundle (its own size symbols)

The class is the only place where a field is named, typed and ordered; compiled code reads
fields by name (``args.dt``, ``args.rows.E_bar``). From it:

- :func:`pack` turns an instance into two read-only 1-D buffers ``(KF float64, KI int64)``
  (two arguments to dispatch on the per-step path instead of dozens), checking every array's
  dimensions against the declared size symbols (a symbol is bound by the first field using it;
  nested bundles have their own);
- :func:`unpack` gives the instance back in Python (views of the buffers; bool arrays as
  ``bool`` copies);
- :func:`compiled_unpack` generates, compiles and returns the same unpacking for compiled
  code (views of the buffers; bool arrays as their 0/1 ``int64`` views).

Buffer format. ``KI`` starts with a header whose length and positions depend on the
declaration only (so the compiled unpacking reads them as constants); ``KF`` holds float data
only. Per leaf field, depth first in declaration order, the header holds: an array: its offset
(into ``KF`` for float64, into ``KI`` for int64/bool), then its shape; a float scalar: its
offset into ``KF``; an int or bool scalar: its value. Data follow in declaration order.

numba caches the generated function under the file and line of the :func:`compiled_unpack`
call; the source of a declaration is therefore part of the kernel cache's fingerprint
(:data:`dobs_envs.numba_cache.KERNEL_MODULES`).
"""
from __future__ import annotations

import operator
import sys
import typing
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = ["f64", "i64", "b1", "Leaf", "pack", "unpack", "compiled_unpack", "unpack_source", "is_bundle", "declaration", "leaves",
           "cast_scalar"]


@dataclass(frozen=True)
class Leaf:
    """A declared field: ``kind`` "f" (float64), "i" (int64) or "b" (bool); ``dims`` the size
    symbols (str) or literal sizes (int) of an array, ``()`` for a scalar."""

    kind: str
    dims: tuple

    @property
    def header(self) -> int:
        """Header entries of the field: offset and shape (array) or one (scalar)."""
        return 1 + len(self.dims) if self.dims else 1


def _leaf(kind: str, shape: str, py):
    dims = tuple(int(s) if s.isdigit() else s for s in shape.split())
    return typing.Annotated[np.ndarray if dims else py, Leaf(kind, dims)]


def f64(shape: str = ""):
    """A float64 array of the given shape (size symbols or literal sizes, blank-separated), or a
    float scalar (no shape)."""
    return _leaf("f", shape, float)


def i64(shape: str = ""):
    """An int64 array of the given shape, or an int scalar."""
    return _leaf("i", shape, int)


def b1(shape: str = ""):
    """A bool array of the given shape (0/1 int64 in compiled code), or a bool scalar."""
    return _leaf("b", shape, bool)


def is_bundle(cls) -> bool:
    return isinstance(cls, type) and issubclass(cls, tuple) and hasattr(cls, "_fields")


@lru_cache(maxsize=None)
def declaration(cls) -> tuple:
    """``((name, Leaf or bundle class), ...)`` of a bundle, in field order."""
    if not is_bundle(cls):
        raise TypeError(f"{cls!r} is not a NamedTuple bundle")
    hints = typing.get_type_hints(cls, include_extras=True)
    out = []
    for name in cls._fields:
        hint = hints.get(name)
        meta = [m for m in getattr(hint, "__metadata__", ()) if isinstance(m, Leaf)]
        if meta:
            out.append((name, meta[0]))
        elif is_bundle(hint):
            out.append((name, hint))
        else:
            raise TypeError(f"{cls.__name__}.{name}: declare it with f64/i64/b1(...) or a NamedTuple bundle, "
                            f"got {hint!r}")
    return tuple(out)


@lru_cache(maxsize=None)
def _tree(cls, h: int = 0) -> tuple:
    """``(cls, fields, end)``: ``fields`` are ``(name, Leaf, header position)`` or ``(name, subtree)``."""
    fields = []
    for name, spec in declaration(cls):
        if isinstance(spec, Leaf):
            fields.append((name, spec, h))
            h += spec.header
        else:
            sub = _tree(spec, h)
            fields.append((name, sub))
            h = sub[2]
    return cls, tuple(fields), h


def leaves(cls) -> list:
    """``[(dotted name, Leaf, header position)]`` of a bundle, depth first."""

    def walk(tree, prefix):
        out = []
        for item in tree[1]:
            if len(item) == 3:
                out.append((prefix + item[0], item[1], item[2]))
            else:
                out += walk(item[1], f"{prefix}{item[0]}.")
        return out

    return walk(_tree(cls), "")


def _as_array(value, leaf: Leaf, where: str, sizes: dict) -> np.ndarray:
    a = np.asarray(value)
    if leaf.kind == "f":
        if a.dtype.kind not in "biuf":
            raise TypeError(f"{where} must be a real array, got dtype {a.dtype}")
        a = a.astype(np.float64, copy=False)
    elif leaf.kind == "i":
        if a.dtype.kind not in "biu":
            raise TypeError(f"{where} must be an integer array, got dtype {a.dtype}")
        a = a.astype(np.int64, copy=False)
    else:
        if a.dtype.kind != "b":
            raise TypeError(f"{where} must be a bool array, got dtype {a.dtype}")
        a = a.astype(np.int64)
    if a.ndim != len(leaf.dims):
        raise ValueError(f"{where} must have {len(leaf.dims)} dimensions ({' x '.join(map(str, leaf.dims))}), "
                         f"got shape {a.shape}")
    for d, s in zip(leaf.dims, a.shape):
        want = d if isinstance(d, int) else sizes.setdefault(d, s)
        if s != want:
            why = f"declared size {d}" if isinstance(d, int) else f"{d} = {want} elsewhere in the bundle"
            raise ValueError(f"{where} has shape {a.shape}, which does not fit ({' x '.join(map(str, leaf.dims))}): "
                             f"{why}")
    return a


def pack(value) -> tuple:
    """``(KF, KI)``: the bundle instance ``value`` in two read-only 1-D buffers (module doc)."""
    cls = type(value)
    tree = _tree(cls)
    head = np.zeros(tree[2], dtype=np.int64)
    fdata, idata = [], []
    pos = [0, tree[2]]  # next free offset in KF, in KI

    def walk(tree, value, where):
        sub_cls, fields, _ = tree
        if not isinstance(value, sub_cls):
            raise TypeError(f"{where} must be a {sub_cls.__name__}, got {type(value).__name__}")
        sizes: dict = {}
        for item in fields:
            name = item[0]
            v = getattr(value, name)
            if len(item) == 2:
                walk(item[1], v, f"{where}.{name}")
                continue
            leaf, h = item[1], item[2]
            here = f"{where}.{name}"
            if leaf.dims:
                a = _as_array(v, leaf, here, sizes)
                k = 0 if leaf.kind == "f" else 1
                head[h] = pos[k]
                head[h + 1:h + 1 + a.ndim] = a.shape
                (fdata if k == 0 else idata).append(a.ravel())
                pos[k] += a.size
            elif leaf.kind == "f":
                head[h] = pos[0]
                fdata.append(np.array([float(v)]))
                pos[0] += 1
            elif leaf.kind == "i":
                if isinstance(v, (bool, np.bool_)):
                    raise TypeError(f"{here} must be an int, got {v!r}")
                head[h] = operator.index(v)
            else:
                if not isinstance(v, (bool, np.bool_)):
                    raise TypeError(f"{here} must be a bool, got {v!r}")
                head[h] = int(bool(v))

    walk(tree, value, cls.__name__)
    KF = np.concatenate([np.zeros(0)] + fdata)
    KI = np.concatenate([head] + idata)
    KF.flags.writeable = KI.flags.writeable = False
    return KF, KI


def unpack(cls, KF, KI):
    """The ``cls`` instance packed in ``(KF, KI)`` by :func:`pack` (numpy views; bool arrays copied as bool)."""

    def build(tree):
        sub_cls, fields, _ = tree
        args = []
        for item in fields:
            if len(item) == 2:
                args.append(build(item[1]))
                continue
            leaf, h = item[1], item[2]
            if leaf.dims:
                shape = tuple(int(s) for s in KI[h + 1:h + 1 + len(leaf.dims)])
                o, size = int(KI[h]), int(np.prod(shape))
                a = (KF if leaf.kind == "f" else KI)[o:o + size].reshape(shape)
                args.append(a != 0 if leaf.kind == "b" else a)
            elif leaf.kind == "f":
                args.append(float(KF[KI[h]]))
            elif leaf.kind == "i":
                args.append(int(KI[h]))
            else:
                args.append(bool(KI[h]))
        return sub_cls(*args)

    return build(_tree(cls))


def cast_scalar(leaf: Leaf, value):
    """A scalar field's value as its declared Python type (float, int or bool)."""
    return {"f": float, "i": int, "b": bool}[leaf.kind](value)


def _alias(cls) -> str:
    return f"_bundle_{cls.__name__}"


def _expr(tree, names: dict, indent: str = "    ") -> str:
    sub_cls, fields, _ = tree
    names[_alias(sub_cls)] = sub_cls
    inner = indent + "    "
    args = []
    for item in fields:
        if len(item) == 2:
            args.append(f"{inner}{_expr(item[1], names, inner)},  # {item[0]}")
            continue
        leaf, h = item[1], item[2]
        if leaf.dims:
            nd = len(leaf.dims)
            dims = [f"KI[{h + 1 + j}]" for j in range(nd)]
            buf = "KF" if leaf.kind == "f" else "KI"
            e = f"{buf}[KI[{h}]:KI[{h}] + {' * '.join(dims)}]"
            if nd > 1:
                e += f".reshape(({', '.join(dims)}))"
        elif leaf.kind == "f":
            e = f"KF[KI[{h}]]"
        elif leaf.kind == "i":
            e = f"KI[{h}]"
        else:
            e = f"KI[{h}] != 0"
        args.append(f"{inner}{e},  # {item[0]}")
    return f"{_alias(sub_cls)}(\n" + "\n".join(args) + f"\n{indent})"


def unpack_source(cls, name: str) -> tuple:
    """``(source, names)``: the Python source of ``def name(KF, KI)`` returning the ``cls`` instance
    packed in ``(KF, KI)``, and the globals it needs (the bundle classes)."""
    names: dict = {}
    expr = _expr(_tree(cls), names)
    src = (f"def {name}(KF, KI):\n"
           f"    \"\"\"The {cls.__name__} packed in (KF, KI) by dobs_envs.packing.pack (views of the buffers; "
           f"generated from its declaration).\"\"\"\n"
           f"    return {expr}\n")
    return src, names


def compiled_unpack(cls, njit, name: str):
    """``njit`` applied to the generated unpacking function of ``cls`` (:func:`unpack_source`).

    The function is compiled as if defined at the line of this call in the calling module (its
    ``__module__``, file and line: numba caches it beside the caller's kernels, and error
    messages point at the call).
    """
    frame = sys._getframe(1)
    src, names = unpack_source(cls, name)
    ns = {"__name__": frame.f_globals["__name__"], **names}
    code = compile("\n" * (frame.f_lineno - 1) + src, frame.f_code.co_filename, "exec")
    exec(code, ns)  # noqa: S102 -- source generated above from the declaration only
    fn = ns[name]
    fn.__generated_source__ = src
    return njit(fn)
