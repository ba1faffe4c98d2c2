"""The ``Box`` space of the JAX environments, as gymnax's and JaxMARL's ``spaces.Box``.

Same attributes (``low``, ``high``, ``shape``, ``dtype``) and methods (``sample(key)``,
``contains(x)``), so code written for either library reads it; unbounded entries (``-inf``/``inf``)
are sampled from a standard normal, as Gymnasium's ``Box.sample`` does.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["Box"]


class Box:
    """A box in R^n: ``low <= x <= high`` element-wise (``low``/``high`` scalars or arrays of ``shape``)."""

    def __init__(self, low, high, shape: tuple, dtype=jnp.float32):
        self.shape = tuple(int(s) for s in shape)
        self.dtype = jnp.dtype(dtype)
        self.low = np.broadcast_to(np.asarray(low, dtype=np.float64), self.shape).astype(self.dtype)
        self.high = np.broadcast_to(np.asarray(high, dtype=np.float64), self.shape).astype(self.dtype)

    def __repr__(self) -> str:
        return f"Box(shape={self.shape}, dtype={self.dtype.name})"

    def sample(self, key: jax.Array) -> jax.Array:
        """A random element: uniform where both bounds are finite, else normal (shifted past a finite bound)."""
        lo, hi = jnp.asarray(self.low), jnp.asarray(self.high)
        ku, kn = jax.random.split(key)
        flo, fhi = jnp.isfinite(lo), jnp.isfinite(hi)
        u = jax.random.uniform(ku, self.shape, self.dtype, jnp.where(flo, lo, 0), jnp.where(fhi, hi, 1))
        nrm = jax.random.normal(kn, self.shape, self.dtype)
        out = jnp.where(flo & fhi, u, jnp.where(flo, lo + jnp.abs(nrm), jnp.where(fhi, hi - jnp.abs(nrm), nrm)))
        return out.astype(self.dtype)

    def contains(self, x) -> jax.Array:
        """Whether ``x`` has this box's shape and lies in it (a boolean array, jit-friendly)."""
        x = jnp.asarray(x)
        if x.shape != self.shape:
            return jnp.asarray(False)
        return jnp.all(x >= self.low) & jnp.all(x <= self.high)
