"""Counter-based random numbers of the fault model: draws addressed by (seed, stream, period, index).

A draw is a pure function of four unsigned 64-bit integers -- the copy's episode seed, a stream
id (which fault: :data:`STREAM_OO_LOSS`, ...), the control-period index since the copy's reset and
an index inside the period (a directed link, a C-O link, a measured output) -- so the fault
processes of every copy are reproducible from its seed alone, independent of the batch size, of
the copy's position in the batch and of the order in which the draws are made. No generator
object is kept per copy (a batch holds up to thousands of copies).

Hash: four rounds of the splitmix64 finaliser (:func:`mix64`, Steele, Lea & Flood 2014)::

    k0 = mix64(seed + G)                 # the copy's key
    k1 = mix64(k0 + (stream + 1) G)      # one key per stream
    k2 = mix64(k1 + (period + 1) G)      # one key per control period
    h  = mix64(k2 + (index + 1) G)       # the draw

with ``G = 0x9E3779B97F4A7C15``: for a fixed (seed, stream, period) the draws over consecutive
indices are exactly the outputs of a splitmix64 generator started at ``k2`` (a generator that
passes BigCrush), and each key is re-mixed before the next counter is added.

Uniform: the top 53 bits of ``h`` times ``2**-53``, in ``[0, 1)`` (exact). Standard normal:
Box-Muller from the two uniforms of indices ``2 index`` and ``2 index + 1``,
``sqrt(-2 log(1 - u1)) cos(2 pi u2)``, with ``log`` and ``cos`` evaluated here by fixed
polynomial series from ``+ - * /`` and ``sqrt`` only (IEEE correctly rounded operations):
numpy's and LLVM's ``log``/``cos`` may differ in the last bit, these do not.

Bit-identical in numpy and numba. Every function is written once with unsigned 64-bit integer
and float64 arithmetic and works elementwise on numpy ``uint64`` arrays (broadcasting) and on
numba ``uint64`` scalars: the functions are registered with
``numba.extending.register_jitable(fastmath=False)`` (plain Python functions when called from
Python, compiled when called from a numba kernel with their own flags: no FMA contraction even
inside a ``fastmath`` kernel; without ``fastmath=False`` they take the caller's flags, and a
contracting caller changed 2% of the normal draws in the last bit). Their
inputs must already be ``uint64`` (mixing int64 and uint64 gives float64 in numpy and numba);
the numpy entry points :func:`uniform` and :func:`normal` convert and broadcast their arguments.
``tests/test_faults_engine.py`` checks the numba-compiled draws against these bit for bit.
"""
from __future__ import annotations

import numpy as np

try:
    from numba.extending import register_jitable

    _jitable = register_jitable(fastmath=False)
except ImportError:  # pragma: no cover - numba is a dependency; the numpy path needs nothing from it
    def _jitable(f):
        return f

__all__ = ["STREAM_OO_LOSS", "STREAM_OO_BURST", "STREAM_CO_LOSS", "STREAM_SWITCHING", "STREAM_NOISE", "STREAMS",
           "mix64", "period_key", "hash_draw", "uniform_at", "normal_at", "uniform_bits", "normal_bits", "log1m_bits", "cos2pi_bits", "uniform", "normal",
           "as_seeds"]

_U = np.uint64
#: the splitmix64 increment (2**64 / golden ratio)
GOLDEN = _U(0x9E3779B97F4A7C15)
_M1 = _U(0xBF58476D1CE4E5B9)
_M2 = _U(0x94D049BB133111EB)
_S30, _S27, _S31, _S11, _S63, _S51 = _U(30), _U(27), _U(31), _U(11), _U(63), _U(51)
_ZERO, _ONE, _TWO = _U(0), _U(1), _U(2)
_TWO53 = _U(1 << 53)
_LOW51 = _U((1 << 51) - 1)
_Q1, _Q2, _Q3 = _U(1), _U(2), _U(3)
#: binary search steps of the exponent in :func:`log1m_bits`
_SH32, _SH16, _SH8, _SH4, _SH2, _SH1 = _U(32), _U(16), _U(8), _U(4), _U(2), _U(1)

#: stream ids (one per fault process; the index of a draw is given with each)
STREAM_OO_LOSS = 1  # Bernoulli loss of a directed O-O link in a period (index: link)
STREAM_OO_BURST = 2  # Gilbert-Elliott state: initial draw (period 0) and transitions (index: link)
STREAM_CO_LOSS = 3  # Bernoulli loss of a C-O link in a period (index: C-O link)
STREAM_SWITCHING = 4  # Markov chain of the O-O graph (index 0)
STREAM_NOISE = 5  # measurement noise (index: node * p + output row; two uniforms per normal)
STREAMS = {"oo_loss": STREAM_OO_LOSS, "oo_burst": STREAM_OO_BURST, "co_loss": STREAM_CO_LOSS,
           "switching": STREAM_SWITCHING, "measurement_noise": STREAM_NOISE}

_TWO_M53 = 2.0 ** -53
_LN2 = 0.6931471805599453
#: ``2**-e`` for ``e = 0 .. 53`` (exact)
_POW2NEG = np.array([2.0 ** -e for e in range(54)])
#: ``1 / (2 j + 1)``, ``j = 0 .. 12``: ``log f = 2 atanh(s) = 2 sum_j s^(2j+1) / (2j+1)``,
#: ``|s| = |f-1|/(f+1) < 0.172`` for ``f`` in ``[sqrt(1/2), sqrt(2))`` (first omitted term below ``0.172^27 / 27 < 1e-21``)
_ATANH = tuple(1.0 / (2 * j + 1) for j in range(13))
_SQRT2 = float(np.sqrt(2.0))
#: ``(-1)^j / (2j)!`` and ``(-1)^j / (2j+1)!``, ``j = 0 .. 12``: Taylor series of cos and sin on
#: ``[0, pi/2)`` (first omitted terms below ``(pi/2)^26 / 26! < 1e-21``)
_COS = tuple((-1.0) ** j / float(np.prod(np.arange(1, 2 * j + 1, dtype=float))) for j in range(13))
_SIN = tuple((-1.0) ** j / float(np.prod(np.arange(1, 2 * j + 2, dtype=float))) for j in range(13))
#: ``(pi / 2) 2**-51``: the angle of one unit of the 51 low bits of a quarter turn
_QUARTER_STEP = (np.pi / 2.0) * 2.0 ** -51


@_jitable
def mix64(z):
    """splitmix64 finaliser: a bijection of ``uint64`` with full avalanche (elementwise)."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@_jitable
def period_key(seed, stream, period):
    """The key ``k2`` of ``(seed, stream, period)`` (module doc): ``hash_draw(seed, stream, period, index)`` is
    ``mix64(k2 + (index + 1) G)``, so a kernel drawing many indices of one period computes it once
    (:func:`uniform_at`, :func:`normal_at`: the same bits as :func:`uniform_bits`, :func:`normal_bits`)."""
    k = mix64(seed + GOLDEN)
    k = mix64(k + (stream + _ONE) * GOLDEN)
    return mix64(k + (period + _ONE) * GOLDEN)


@_jitable
def hash_draw(seed, stream, period, index):
    """The 64 random bits of draw ``(seed, stream, period, index)`` (all ``uint64``; module doc)."""
    return mix64(period_key(seed, stream, period) + (index + _ONE) * GOLDEN)


@_jitable
def uniform_at(key, index):
    """:func:`uniform_bits` of the draw ``index`` of the period whose :func:`period_key` is ``key``."""
    return (mix64(key + (index + _ONE) * GOLDEN) >> _S11) * _TWO_M53


@_jitable
def normal_at(key, index):
    """:func:`normal_bits` of the draw ``index`` of the period whose :func:`period_key` is ``key``."""
    k1 = mix64(key + (_TWO * index + _ONE) * GOLDEN) >> _S11
    k2 = mix64(key + (_TWO * index + _TWO) * GOLDEN) >> _S11
    return np.sqrt(-2.0 * log1m_bits(k1)) * cos2pi_bits(k2)


@_jitable
def uniform_bits(seed, stream, period, index):
    """Uniform in ``[0, 1)`` on the grid ``k 2**-53`` of draw ``(seed, stream, period, index)``."""
    return (hash_draw(seed, stream, period, index) >> _S11) * _TWO_M53


@_jitable
def log1m_bits(k):
    """``log(1 - k 2**-53)`` for ``uint64`` ``0 <= k < 2**53`` (finite: ``1 - k 2**-53 >= 2**-53``).

    ``m = 2**53 - k = f 2**e`` with ``1 <= f < 2`` (``e`` by a branchless binary search on the
    bits of ``m``, ``f = m 2**-e`` exact; halved, ``e + 1``, when above ``sqrt 2``), then
    ``log f + (e - 53) log 2`` with ``log f`` from the atanh series (:data:`_ATANH`, Horner in ``s**2``)."""
    m0 = _TWO53 - k
    m = m0
    e = _ZERO
    t = m >> _SH32
    c = ((t | (_ZERO - t)) >> _S63) * _SH32  # 32 if t != 0 else 0
    e = e + c
    m = m >> c
    t = m >> _SH16
    c = ((t | (_ZERO - t)) >> _S63) * _SH16
    e = e + c
    m = m >> c
    t = m >> _SH8
    c = ((t | (_ZERO - t)) >> _S63) * _SH8
    e = e + c
    m = m >> c
    t = m >> _SH4
    c = ((t | (_ZERO - t)) >> _S63) * _SH4
    e = e + c
    m = m >> c
    t = m >> _SH2
    c = ((t | (_ZERO - t)) >> _S63) * _SH2
    e = e + c
    m = m >> c
    t = m >> _SH1
    c = ((t | (_ZERO - t)) >> _S63) * _SH1
    e = e + c
    f = m0 * _POW2NEG[e]  # in [1, 2), exact
    up = f > _SQRT2  # f in [sqrt(1/2), sqrt(2)): no cancellation near m = 2**53 (log(1 - u) ~ -u)
    f = f * (1.0 - 0.5 * up)
    s = (f - 1.0) / (f + 1.0)
    s2 = s * s
    acc = _ATANH[12]
    for j in range(11, -1, -1):
        acc = acc * s2 + _ATANH[j]
    return 2.0 * s * acc + (e * 1.0 + up - 53.0) * _LN2


@_jitable
def cos2pi_bits(k):
    """``cos(2 pi k 2**-53)`` for ``uint64`` ``0 <= k < 2**53``: quarter turn ``q`` from the top two of
    the 53 bits, the angle ``theta`` in ``[0, pi/2)`` from the 51 others, Taylor series of cos and
    sin of ``theta`` (:data:`_COS`, :data:`_SIN`), then ``cos(q pi/2 + theta)``."""
    q = k >> _S51
    theta = (k & _LOW51) * _QUARTER_STEP
    t2 = theta * theta
    c = _COS[12]
    s = _SIN[12]
    for j in range(11, -1, -1):
        c = c * t2 + _COS[j]
        s = s * t2 + _SIN[j]
    s = s * theta
    return c * (q == _ZERO) - s * (q == _Q1) - c * (q == _Q2) + s * (q == _Q3)


@_jitable
def normal_bits(seed, stream, period, index):
    """Standard normal draw ``(seed, stream, period, index)``: Box-Muller from the uniforms of indices
    ``2 index`` and ``2 index + 1`` (module doc)."""
    k1 = hash_draw(seed, stream, period, _TWO * index) >> _S11
    k2 = hash_draw(seed, stream, period, _TWO * index + _ONE) >> _S11
    return np.sqrt(-2.0 * log1m_bits(k1)) * cos2pi_bits(k2)


def _u64(a, name):
    arr = np.asarray(a)
    if arr.dtype.kind not in "iu" or (arr.dtype.kind == "i" and np.any(arr < 0)):
        raise ValueError(f"{name} must be non-negative integers, got {arr.dtype.name} {a!r}")
    return np.atleast_1d(arr.astype(np.uint64))


def uniform(seed, stream, period, index) -> np.ndarray:
    """Uniforms in ``[0, 1)`` of the draws ``(seed, stream, period, index)`` (non-negative integer
    arrays, broadcast together; at least 1-D float64 result)."""
    args = np.broadcast_arrays(*(_u64(a, n) for a, n in zip((seed, stream, period, index),
                                                             ("seed", "stream", "period", "index"))))
    with np.errstate(over="ignore"):
        return uniform_bits(*args)


def normal(seed, stream, period, index) -> np.ndarray:
    """Standard normals of the draws ``(seed, stream, period, index)`` (as :func:`uniform`)."""
    args = np.broadcast_arrays(*(_u64(a, n) for a, n in zip((seed, stream, period, index),
                                                             ("seed", "stream", "period", "index"))))
    with np.errstate(over="ignore"):
        return normal_bits(*args)


def as_seeds(seeds, batch: int, name: str = "seeds") -> np.ndarray:
    """``(batch,)`` ``uint64`` copy of per-copy fault seeds (non-negative integers below ``2**64``)."""
    # a list of Python ints: checked one by one (numpy would turn [1, 2**63] into float64)
    arr = np.asarray(seeds, dtype=object) if isinstance(seeds, (list, tuple)) else np.asarray(seeds)
    if arr.ndim == 0:
        arr = np.broadcast_to(arr, (batch,))
    if arr.shape != (batch,):
        raise ValueError(f"{name} must be one non-negative integer per copy, shape ({batch},), got shape {arr.shape}")
    if arr.dtype == object:
        vals = list(arr)
        if not all(isinstance(s, (int, np.integer)) and not isinstance(s, (bool, np.bool_)) and 0 <= s < 2**64
                   for s in vals):
            raise ValueError(f"{name} must be non-negative integers below 2**64, got {seeds!r}")
        return np.array([int(s) for s in vals], dtype=np.uint64)
    if arr.dtype.kind not in "iu" or (arr.dtype.kind == "i" and np.any(arr < 0)):
        raise ValueError(f"{name} must be non-negative integers below 2**64, got {arr.dtype.name} {seeds!r}")
    return np.ascontiguousarray(arr.astype(np.uint64))
