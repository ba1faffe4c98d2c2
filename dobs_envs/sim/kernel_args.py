"""The declaration of what the simulation kernel receives: its parameters and state arrays.

:class:`KernelArgs` (with :class:`RowMatrices` and :class:`Sparse`) is the single declaration of
the kernel's parameters: each field is named, typed and shaped once here
(:mod:`dobs_envs.packing`), and everything else is derived from it:

- :meth:`SimParams.kernel_args <dobs_envs.sim.state.SimParams.kernel_args>` fills every field
  from the :class:`~dobs_envs.sim.state.SimParams` attribute of the same name
  (:func:`kernel_args_of`; ``rows`` from :data:`ROW_MATRICES`);
- :func:`pack_kernel_args` packs it into the two buffers passed from Python
  (``SimParams.kernel_packed``), :func:`unpack_kernel_args` unpacks them in Python (the numpy
  references) and :func:`dobs_envs.sim.period_kernel.unpack_kernel_args` in compiled code (generated);
- the kernels read fields by name: ``ka.dt``, ``ka.rows.E_bar``.

Adding a parameter: one line in :class:`KernelArgs` (name, kind, shape), a
:class:`~dobs_envs.sim.state.SimParams` attribute of that name holding its value, and its uses
in the kernel (:mod:`.kernel`) and the numpy reference (:mod:`.numpy_step`). A row-compressed
matrix: one entry of :data:`ROW_MATRICES`.
"""
from typing import NamedTuple

import numpy as np

from ..packing import Leaf, b1, cast_scalar, declaration, f64, i64, pack, unpack

__all__ = ["KernelArgs", "RowMatrices", "Sparse", "StateArrays", "ROW_MATRICES", "compress_rows", "kernel_args_of",
           "pack_kernel_args", "unpack_kernel_args"]


class Sparse(NamedTuple):
    """A matrix without its exact zeros, row by row (:func:`compress_rows`): row ``q`` is
    ``val[ptr[q]:ptr[q+1]]`` at columns ``col[ptr[q]:ptr[q+1]]`` (increasing); ``row[j]`` is the
    row of entry ``j`` and ``gcol[j]`` its column in the vector the matrix multiplies."""

    ptr: i64("rows")  # (rows + 1,) start of each row
    col: i64("nnz")
    val: f64("nnz")
    row: i64("nnz")
    gcol: i64("nnz")


#: The row-compressed matrices of :attr:`KernelArgs.rows`, in order: the :class:`SimParams` matrix
#: of that name (``Q_projT``: ``Q_proj`` transposed) and the vector each row multiplies (per node
#: ``i`` where the name ends in ``_i``: node ``i`` multiplies its own vector, stored at ``i * L``).
ROW_MATRICES = (
    ("B_bar", "u"),  # (N, n, m): Bbar_i u (held input of node i)
    ("B", "u"),  # (n, m): B u and B r
    ("C", "x"),  # (N, p, n): y_i = C_i x
    ("G_bar", "y_i"),  # (N, n, p): Gbar_i y_i
    ("Q_projT", "d_i"),  # (N, r, n): Q_i^T d_i (the transposed thin projector basis)
    ("Q_proj", "cq_i"),  # (N, n, r): Q_i cq_i
    ("E_bar", "z_i"),  # (N, n, n)
    ("F_bar", "y_i"),  # (N, n, p)
    ("A", "x"),  # (n, n)
    ("B_v", "v"),  # (n, m_v)
    ("A_r", "x_r"),  # (n, n)
    ("Phi_v", "v"),  # (m_v, m_v)
)

#: One :class:`Sparse` per entry of :data:`ROW_MATRICES`, by name (``ka.rows.E_bar``).
RowMatrices = NamedTuple("RowMatrices", [(name, Sparse) for name, _ in ROW_MATRICES])


class KernelArgs(NamedTuple):
    """The constants of one control period as the compiled kernel receives them (module doc).

    Built once per :class:`~dobs_envs.sim.state.SimParams` (:attr:`SimParams.kernel_args`);
    all arrays are the read-only, C-contiguous arrays of the :class:`SimParams`. The kernel
    multiplies by the row-compressed matrices of :attr:`rows` (the paper's design matrices are
    sparse: NE2's ``Ebar`` has 55 nonzeros out of 486); the dense fields give the shapes and
    serve the numpy reference.
    """

    A: f64("n n")  # plant, eq. (LTIsys)
    B: f64("n m")
    B_v: f64("n mv")
    C: f64("N p n")  # node outputs, zero-padded rows (eq. localmeasure)
    E_bar: f64("N n n")  # eq. (barEFGB)
    F_bar: f64("N n p")
    G_bar: f64("N n p")
    B_bar: f64("N n m")
    Q_proj: f64("N n r")  # thin basis of Im T_iu (proj_range) or of Im T_id
    proj_range: b1("N")  # P_u,i = Q Q^T (True) or I - Q Q^T (False); 0/1 int64 in compiled code
    nbr_idx: i64("N D")  # neighbour indices (padding: weight 0)
    nbr_w: f64("N D")  # edge weights a_ij
    degree: f64("N")  # sum_j a_ij
    A_r: f64("n n")  # reference model A + B K (zeros without reference), eq. (refxdy)
    phi: f64("N")  # eq. (gammaiis) step sizes
    phi_s: f64("N")
    sigma: f64("N")  # eq. (gagasbeta) leakage
    sigma_s: f64("N")
    Phi_v: f64("mv mv")  # expm(S_v dt)
    dt: f64()  # Euler step (s)
    substeps: i64()  # Euler steps per control period
    has_reference: b1()
    rows: RowMatrices  # compress_rows of each of ROW_MATRICES


class StateArrays(NamedTuple):
    """The batched simulation state as compiled code receives it: the arrays of a
    :class:`~dobs_envs.sim.state.SimState`, same names and order (kernels get it as a plain
    tuple, cheaper to dispatch, and read it as ``StateArrays(*state)``)."""

    t: np.ndarray  # (B,)
    x: np.ndarray  # (B, n)
    z: np.ndarray  # (B, N, n)
    gamma: np.ndarray  # (B, N)
    gamma_s: np.ndarray  # (B, N)
    v: np.ndarray  # (B, m_v)
    x_r: np.ndarray  # (B, n)


def _ro(a, dtype):
    out = np.ascontiguousarray(np.array(a, dtype=dtype, copy=True))
    out.flags.writeable = False
    return out


def compress_rows(M, per_node_input: bool = False) -> Sparse:
    """The rows of ``M (..., K, L)`` (flattened to ``R`` rows in C order) without their exact zeros
    (:class:`Sparse`). ``gcol[j]`` is ``(q // K) * L + col[j]`` when each node ``i`` of a
    node-stacked ``M (N, K, L)`` multiplies its own vector stored at ``i * L`` (``per_node_input``),
    else ``col[j]``. A sum over a row in column order adds exactly the terms of the dense row
    except ``0 * x`` (``fma(0, x, s) = s`` for finite ``x``): the same result, fewer operations."""
    M = np.asarray(M, dtype=np.float64)
    K, L = M.shape[-2] if M.ndim > 1 else 1, M.shape[-1]
    rows = M.reshape(int(np.prod(M.shape[:-1])), L)
    nz = rows != 0.0
    row, col = np.nonzero(nz)
    ptr = np.concatenate([[0], np.cumsum(nz.sum(axis=1))])
    gcol = (row // K) * L + col if per_node_input else col
    return Sparse(_ro(ptr, np.int64), _ro(col, np.int64), _ro(rows[nz], np.float64), _ro(row, np.int64),
                  _ro(gcol, np.int64))


def kernel_args_of(params) -> KernelArgs:
    """:class:`KernelArgs` of a :class:`~dobs_envs.sim.state.SimParams`: every field the attribute of
    that name (scalars as float/int/bool), ``rows`` the compressed :data:`ROW_MATRICES`."""
    vals = {}
    for name, spec in declaration(KernelArgs):
        if name != "rows":
            v = getattr(params, name)
            vals[name] = cast_scalar(spec, v) if isinstance(spec, Leaf) and not spec.dims else v
    rows = RowMatrices(*(compress_rows(params.Q_proj.transpose(0, 2, 1) if name == "Q_projT" else getattr(params, name),
                                       per_node_input=vec.endswith("_i")) for name, vec in ROW_MATRICES))
    return KernelArgs(**vals, rows=rows)


def pack_kernel_args(ka: KernelArgs) -> tuple:
    """:class:`KernelArgs` packed into ``(KF float64, KI int64)`` buffers
    (:func:`dobs_envs.packing.pack`): two arrays to dispatch instead of ~80 on the per-step path."""
    return pack(ka)


def unpack_kernel_args(KF, KI) -> KernelArgs:
    """The :class:`KernelArgs` packed by :func:`pack_kernel_args`, in Python (views; ``proj_range``
    as bool). Compiled code: :func:`dobs_envs.sim.period_kernel.unpack_kernel_args`."""
    return unpack(KernelArgs, KF, KI)
